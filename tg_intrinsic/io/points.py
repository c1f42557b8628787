"""Point clouds on disk: numeric tables (``.txt``, ``.xyz``, ``.pts``,
``.npy``; whitespace or comma separated) and PLY files, with normals and
an optional per-point label column."""
import os
import os.path as osp
import warnings
from typing import Optional, Tuple

import numpy as np

from .hdr import read_npy
from .mesh import TEXT_ENCODING, check_file, read_surface

POINT_EXTENSIONS = ('.ply', '.txt', '.xyz', '.npy', '.pts')
# PLY vertex properties read as a per-point label
PLY_LABEL_PROPERTIES = ('label', 'class')


def read_table(path: str, max_rows: Optional[int] = None) -> np.ndarray:
    """A numeric table, ``[R, C]`` float64: a 2-D (or 1-D, read as one
    column) ``.npy`` array, or a text file with one row per line whose
    values are separated by whitespace or by commas (decided from the first
    4 KiB of the file: commas if any). Blank lines and ``#`` comments are
    skipped, and so is a UTF-8 byte-order mark at the start. ``max_rows``
    reads only the first rows of a text file.

    Raises an error that names the file when it does not exist
    (:class:`FileNotFoundError`), is a folder or cannot be read
    (:func:`~tg_intrinsic.io.mesh.check_file`), and a
    :class:`ValueError` when it is empty, has rows of different lengths,
    non-numeric entries, or NaN or infinite values.
    """
    path = check_file(path)  # missing, a folder, unreadable: named
    if path.lower().endswith('.npy'):
        table = read_npy(path)  # names what is wrong with the file
        if table.ndim == 1:
            table = table[:, None]
        if max_rows is not None:
            table = table[:max_rows]
    else:
        try:
            with open(path, 'rb') as f:
                comma = b',' in f.read(4096)
            with warnings.catch_warnings():  # an empty file: error below
                warnings.simplefilter('ignore', UserWarning)
                table = np.loadtxt(path, delimiter=',' if comma else None,
                                   ndmin=2, max_rows=max_rows,
                                   encoding=TEXT_ENCODING)
        except OSError as error:
            raise ValueError(f"could not read '{path}': "
                             f"{(error.strerror or str(error)).lower()}"
                             ) from error
        except ValueError as error:
            raise ValueError(f"could not read '{path}': {error}") from error
    if table.ndim != 2 or table.size == 0:
        raise ValueError(f"'{path}' holds no table of numbers (shape "
                         f"{table.shape}); give one row per point")
    if table.dtype.kind not in 'biuf':
        raise ValueError(f"'{path}' is not numeric ({table.dtype})")
    table = table.astype(np.float64)
    if not np.isfinite(table).all():
        row = int(np.nonzero(~np.isfinite(table).all(1))[0][0])
        raise ValueError(f"'{path}' holds NaN or infinite values (first in "
                         f"row {row + 1}); repair or remove those rows")
    return table


def read_points(path: str, max_points: Optional[int] = None
                ) -> Tuple[np.ndarray, Optional[np.ndarray],
                           Optional[np.ndarray]]:
    """Reads a point cloud: ``(pos [N, 3], normal [N, 3] or None, label
    [N] or None)``, float64.

    Tables (``.txt``, ``.xyz``, ``.pts``, ``.npy``, see
    :func:`read_table`) hold ``x y z`` in columns 1-3, normals in columns
    4-6 when there are at least 6 columns, and a label in the last column
    when there are exactly 4 (``x y z label``) or 7 (``x y z nx ny nz
    label``, as in ShapeNet-Part's normal release) columns. PLY files give
    normals from the ``nx ny nz`` vertex properties and a label from a
    ``label`` or ``class`` property; their faces, if any, are ignored.
    ``max_points`` keeps the first points only.

    Raises a :class:`ValueError` that names the file.
    """
    path = os.fspath(path)
    ext = osp.splitext(path)[1].lower()
    if ext not in POINT_EXTENSIONS:
        raise ValueError(f"'{path}': unknown point cloud format "
                         f"{ext or '(none)'!r}; use one of "
                         f"{'/'.join(POINT_EXTENSIONS)}")
    normal = label = None
    if ext == '.ply':
        pos, _, props = read_surface(path, weld=False)  # points as stored
        if all(k in props for k in ('nx', 'ny', 'nz')):
            normal = np.stack([props[k] for k in ('nx', 'ny', 'nz')], 1)
        name = next((k for k in PLY_LABEL_PROPERTIES if k in props), None)
        if name is not None:
            label = np.asarray(props[name], dtype=np.float64)
        if max_points is not None:
            pos = pos[:max_points]
            normal = None if normal is None else normal[:max_points]
            label = None if label is None else label[:max_points]
    else:
        table = read_table(path, max_rows=max_points)
        columns = table.shape[1]
        if columns < 3:
            raise ValueError(f"'{path}' has {columns} column(s); a point "
                             f"needs at least 'x y z'")
        pos = table[:, :3]
        if columns >= 6:
            normal = table[:, 3:6]
        if columns in (4, 7):
            label = table[:, -1]
    normal = None if normal is None else np.asarray(normal, np.float64)
    if normal is not None and not np.isfinite(normal).all():
        raise ValueError(f"'{path}' has NaN or infinite normals")
    return pos, normal, label
