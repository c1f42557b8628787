"""Meshes and point clouds on disk: OBJ, OFF, PLY and STL in (direct OBJ
and OFF parsers, the latter for ModelNet's malformed headers too; trimesh
for PLY and STL), binary PLY with per-vertex properties out, per-vertex
signals from ``.npy``, text or PLY properties. Every text format is read
with or without a UTF-8 byte-order mark (Notepad writes one)."""
import io
import os
import os.path as osp
import re
import stat
import warnings
from typing import Dict, Optional, Tuple

import numpy as np

from tg_intrinsic.utils import atomic_write, os_error_reason

from .hdr import read_npy

MESH_EXTENSIONS = ('.obj', '.off', '.ply', '.stl')
SIGNAL_EXTENSIONS = ('.npy', '.txt', '.csv')
# PLY vertex properties that are the geometry itself, not a signal
_GEOMETRY_PROPERTIES = ('x', 'y', 'z')
# the UTF-8 byte-order mark some editors (Notepad) put before the text
_BOM = b'\xef\xbb\xbf'
# the encoding that reads UTF-8 text with or without a byte-order mark
TEXT_ENCODING = 'utf-8-sig'


def check_file(path: str, what: str = '', give: str = 'a file') -> str:
    """Checks that ``path`` is a file that can be read (the first byte of
    a regular file is read) and returns it; ``what`` (e.g. ``'signal
    file'``) goes before the name in the messages, and ``give`` says what
    to give instead of a folder. Raises, on one line that names the file
    and what is wrong: :class:`FileNotFoundError` when it does not exist
    (a broken link, or a part of the path that is a file, is said), a
    :class:`ValueError` for a folder, :class:`PermissionError` when it may
    not be read, and a :class:`ValueError` for any other failure to read
    it (e.g. an input/output error)."""
    path = os.fspath(path)
    name = f"{what} '{path}'" if what else f"'{path}'"
    try:
        mode = os.stat(path).st_mode
    except (FileNotFoundError, NotADirectoryError):
        raise FileNotFoundError(f"{name} does not exist"
                                f"{_why_missing(path)}") from None
    except PermissionError:
        raise PermissionError(f"{name} cannot be read: permission denied "
                              f"(on a folder above it)") from None
    except OSError as error:
        raise ValueError(f"{name} cannot be read: "
                         f"{os_error_reason(error)}") from None
    if stat.S_ISDIR(mode):
        raise ValueError(f"{name} is a folder; give {give}")
    if not stat.S_ISREG(mode):  # a pipe: a byte read here would be lost
        return path
    try:
        with open(path, 'rb') as f:
            f.read(1)
    except PermissionError:
        raise PermissionError(f"{name} cannot be read: permission "
                              f"denied") from None
    except OSError as error:
        raise ValueError(f"{name} cannot be read: "
                         f"{os_error_reason(error)}") from None
    return path


def _why_missing(path: str) -> str:
    """Why a path that does not exist is missing, to end a sentence (a
    broken link, a part of the path that is a file), or ``''``."""
    if osp.islink(path):
        return f" (it is a link to '{os.readlink(path)}', which does not"\
            f" exist)"
    parent = osp.dirname(osp.abspath(path))
    while not osp.exists(parent) and osp.dirname(parent) != parent:
        parent = osp.dirname(parent)
    if osp.exists(parent) and not osp.isdir(parent):
        return f" ('{parent}' is a file, not a folder)"
    return ''


def read_mesh(path: str, weld: bool = True
              ) -> Tuple[np.ndarray, np.ndarray]:
    """Reads a triangle mesh: ``(pos [N, 3] float64, face [F, 3] int64)``,
    by the policy of :func:`read_surface` (vertices at the same position
    welded unless ``weld=False``; polygons become triangle fans).

    Raises a :class:`ValueError` that names the file if it cannot be read,
    holds no triangles, or breaks the rules of :func:`read_surface`.
    """
    pos, face, _ = read_surface(path, weld=weld)
    if face is None:
        raise ValueError(f"'{path}' holds a point cloud, not a triangle mesh")
    return pos, face


def read_surface(path: str, weld: bool = True, return_inverse: bool = False
                 ) -> Tuple[np.ndarray, Optional[np.ndarray],
                            Dict[str, np.ndarray]]:
    """Reads a mesh or a point cloud (OBJ, OFF, PLY binary or ASCII, STL):
    ``(pos [N, 3] float64, face [F, 3] int64 or None for a point cloud,
    properties)``, where ``properties`` holds the PLY vertex properties
    other than ``x, y, z`` by name (``nx``, ``red``, ``quality``, ...),
    an OBJ file's normals as ``nx ny nz`` when its faces give every vertex
    one normal (``f v//vn`` corners, smooth shading; a vertex with several
    normals, as flat shading stores them, leaves them out), and is empty
    for other formats.

    The vertices as stored are those of the file, in its order: every
    ``v`` line of an OBJ file, whatever object, group or material it
    belongs to (:func:`read_obj`), the vertex list of OFF and PLY files,
    three corners per triangle of an STL file. A UTF-8 byte-order mark
    before the text (OBJ, OFF, ASCII PLY and STL) is ignored.

    Every command reads surfaces by this one policy:

    - **welding**: the vertices of a mesh at exactly the same position are
      merged (STL files and many OBJ exporters store every triangle's
      corners separately), with a warning that says how many stored
      vertices were merged into another; each welded vertex keeps the
      properties of its first copy. Point clouds are kept as they are.
      ``weld=False`` reads the vertices as stored.
    - **refused**, with an error that names the file and the problem: a
      file that does not exist (:class:`FileNotFoundError`) or cannot be
      read (:func:`check_file`), and, with a :class:`ValueError`, fewer
      than 3 vertices, NaN or infinite coordinates, faces that index
      outside the vertices, and faces that repeat a vertex (e.g. the OBJ
      line ``f 1 1 2``, or a triangle whose corners coincide, found by
      welding). Such a face has no area; the message names the first one
      (its triangle index and, for OBJ and OFF files, its line) and says
      how to remove it. Triangles of distinct but collinear corners
      (zero area) are read; :func:`check_triangle_areas` refuses them
      where the cotan Laplacian needs a positive area.

    With ``return_inverse=True`` a fourth value gives, for every vertex
    as stored, its index after welding (``[N_stored]``).
    """
    path = os.fspath(path)
    ext = osp.splitext(path)[1].lower()
    check_file(path, give=f"a mesh or point cloud file "
               f"({'/'.join(MESH_EXTENSIONS)})")
    if ext not in MESH_EXTENSIONS:
        raise ValueError(f"'{path}': unknown format {ext or '(none)'!r}; "
                         f"use one of {'/'.join(MESH_EXTENSIONS)}")
    properties: Dict[str, np.ndarray] = {}
    try:
        if ext == '.off':
            pos, face = read_off(path)
        elif ext == '.obj':
            pos, face = read_obj(path)
            normal = _obj_vertex_normals(path, len(pos), face)
            if normal is not None:
                properties = {k: normal[:, i]
                              for i, k in enumerate(('nx', 'ny', 'nz'))}
        else:
            import trimesh
            loaded = _load_trimesh(path, ext)
            if isinstance(loaded, trimesh.Scene):
                loaded = loaded.to_geometry() if len(loaded.geometry) else \
                    None
            if loaded is None:
                raise ValueError('no geometry in the file')
            pos = np.asarray(loaded.vertices, dtype=np.float64)
            faces = getattr(loaded, 'faces', None)
            face = None if faces is None or len(faces) == 0 else \
                np.asarray(faces, dtype=np.int64).reshape(-1, 3)
            if ext == '.ply':
                properties = _ply_vertex_properties(loaded, len(pos))
                _check_ply_counts(path, len(pos), 0 if face is None
                                  else len(face))
    except OSError as error:  # checked readable above, yet it failed
        raise ValueError(f"could not read '{path}': "
                         f"{os_error_reason(error)}") from error
    except (ValueError, IndexError, KeyError, TypeError,
            AttributeError) as error:
        raise ValueError(f"could not read '{path}' as {ext[1:].upper()} (is "
                         f"it truncated, or of another format?): "
                         f"{type(error).__name__}: {error}") from error
    if pos.ndim != 2 or pos.shape[1] != 3 or len(pos) == 0:
        raise ValueError(f"'{path}' has no vertices")
    if not np.isfinite(pos).all():
        bad = int((~np.isfinite(pos)).any(1).sum())
        raise ValueError(f"'{path}' has NaN or infinite coordinates at {bad} "
                         f"vertex(es); repair or remove them")
    if face is not None and len(face) == 0:
        face = None  # e.g. an OFF point cloud
    if face is not None and (face.min() < 0 or face.max() >= len(pos)):
        raise ValueError(f"'{path}' has face indices outside [0, "
                         f"{len(pos) - 1}] (the vertex count is {len(pos)})")
    if face is not None:
        _check_repeated_corners(path, ext, face)
    inverse = np.arange(len(pos))
    if face is not None and weld:
        pos, face, properties, inverse = _weld(path, pos, face, properties)
    if len(pos) < 3:
        welded = ' after welding' if len(inverse) > len(pos) else ''
        raise ValueError(f"'{path}' has only {len(pos)} "
                         f"{'vertex' if len(pos) == 1 else 'vertices'}"
                         f"{welded}; a surface needs at least 3")
    if return_inverse:
        return pos, face, properties, inverse
    return pos, face, properties


def read_face_uv(path: str, pos: np.ndarray, face: np.ndarray
                 ) -> Optional[np.ndarray]:
    """The texture coordinates of a mesh file, per triangle corner
    ``(3, F, 2)`` (the layout of :func:`~tg_intrinsic.geometry.rasterize_uv`),
    for the vertices ``pos`` and triangles ``face (F, 3)`` that
    :func:`read_surface` read from it; :obj:`None` when the file has none
    (OFF and STL never do). OBJ ``vt`` (seams included: a vertex may have
    a UV per triangle) and PLY ``s t`` / ``texture_u texture_v`` are read
    by trimesh. UVs outside :math:`[0, 1]` (tiling) are an error."""
    import trimesh
    ext = osp.splitext(path)[1].lower()
    if ext not in ('.obj', '.ply'):
        return None
    loaded = _load_trimesh(path, ext, **(
        dict(skip_materials=False) if ext == '.obj' else {}))
    if isinstance(loaded, trimesh.Scene):
        loaded = loaded.to_geometry() if len(loaded.geometry) else None
    uv = getattr(getattr(loaded, 'visual', None), 'uv', None)
    if uv is None or len(uv) != len(loaded.vertices):
        return None
    corners = np.asarray(loaded.faces, dtype=np.int64)
    # trimesh splits a vertex at every UV seam; its triangles must still be
    # ours, corner by corner
    if corners.shape != face.shape or not np.allclose(
            np.asarray(loaded.vertices)[corners], pos[face], rtol=0,
            atol=1e-9 * max(1.0, float(np.abs(pos).max()))):
        raise ValueError(f"'{path}': its texture coordinates could not be "
                         f"matched to its triangles; export the mesh again "
                         f"with one UV per corner")
    uv = np.asarray(uv, dtype=np.float64)[corners].transpose(1, 0, 2)
    if not np.isfinite(uv).all() or uv.min() < 0 or uv.max() > 1:
        raise ValueError(f"'{path}' has texture coordinates outside [0, 1] "
                         f"(tiled or UDIM textures); rescale them into [0, 1]"
                         f" or remove them to have an atlas made")
    return np.ascontiguousarray(uv)


def _weld(path: str, pos: np.ndarray, face: np.ndarray,
          properties: Dict[str, np.ndarray]):
    """Merges the vertices at the same position (warning how many);
    ``(pos, face, properties, inverse)``."""
    import torch

    from tg_intrinsic.geometry import weld_vertices
    welded, new_face, inverse = weld_vertices(
        torch.from_numpy(pos), torch.from_numpy(face).t())
    welded, new_face = welded.numpy(), new_face.t().numpy()
    inverse = inverse.numpy()
    merged = len(pos) - len(welded)
    if not merged:
        return pos, face, properties, inverse
    repeated = (new_face[:, 0] == new_face[:, 1]) | \
        (new_face[:, 1] == new_face[:, 2]) | (new_face[:, 0] == new_face[:, 2])
    if repeated.any():
        first = int(np.flatnonzero(repeated)[0])
        raise ValueError(
            f"'{path}' has {int(repeated.sum())} triangle(s) with two "
            f"corners at the same position (first: triangle {first}, "
            f"vertices {face[first].tolist()} counted from 0); such a face "
            f"has no area. Delete these faces, e.g. with trimesh: m = "
            f"trimesh.load(path); m.update_faces(m.nondegenerate_faces()); "
            f"m.export(path)")
    first_copy = np.full(len(welded), len(pos), dtype=np.int64)
    np.minimum.at(first_copy, inverse, np.arange(len(pos)))
    warnings.warn(f"'{path}': welded {merged} vertices at the same position "
                  f"as another ({len(pos)} -> {len(welded)}), which "
                  f"connects its triangles into one surface", stacklevel=3)
    properties = {name: values[first_copy]
                  for name, values in properties.items()}
    return welded, new_face, properties, inverse


def _check_repeated_corners(path: str, ext: str, face: np.ndarray):
    """Raises a :class:`ValueError` naming the file, the first triangle and
    (OBJ, OFF) the first face line that repeat a vertex."""
    repeated = (face[:, 0] == face[:, 1]) | (face[:, 1] == face[:, 2]) | \
        (face[:, 0] == face[:, 2])
    if not repeated.any():
        return
    bad = np.flatnonzero(repeated)
    first = int(bad[0])
    raise ValueError(
        f"'{path}' has {bad.size} triangle(s) that repeat a vertex (first: "
        f"triangle {first}, vertices {face[first].tolist()} counted from "
        f"0{_where(path, ext, first)}); such a face has no area and the "
        f"geometry code rejects it. Delete these faces from the file, or "
        f"repair it, e.g. with trimesh: m = trimesh.load(path, "
        f"process=False); m.update_faces(m.nondegenerate_faces()); "
        f"m.export(path)")


def check_triangle_areas(path: str, pos: np.ndarray, face: np.ndarray,
                         advice: Optional[str] = None):
    """Refuses triangles of zero area, e.g. three distinct but collinear
    corners, which the cotan Laplacian divides by: a :class:`ValueError`
    that names the file, how many there are, the first (its index and,
    for OBJ and OFF files, its line) and what to do: ``advice``, or else
    how to delete them. A triangle counts as zero-area by the rule of the
    geometry code: its area at most 16 float64 epsilons times its
    longest squared edge. ``pos [N, 3]`` and ``face [F, 3]`` are what
    :func:`read_surface` read from ``path``."""
    face = np.asarray(face, dtype=np.int64).reshape(-1, 3)
    p = np.asarray(pos, dtype=np.float64)[face]
    edges = p[:, [1, 2, 0]] - p
    area = 0.5 * np.linalg.norm(np.cross(edges[:, 0], -edges[:, 2]), axis=1)
    scale = (edges ** 2).sum(-1).max(1)
    tiny = np.finfo(np.float64)
    bad = np.flatnonzero(area <= 16 * tiny.eps * np.maximum(scale,
                                                            tiny.tiny))
    if not bad.size:
        return
    first = int(bad[0])
    ext = osp.splitext(path)[1].lower()
    if advice is None:
        advice = ("delete these faces from the file, e.g. with trimesh: m "
                  "= trimesh.load(path, process=False); m.update_faces("
                  "m.nondegenerate_faces()); m.export(path)")
    raise ValueError(
        f"'{path}' has {bad.size} zero-area triangle(s) (collinear "
        f"corners; first: triangle {first}, vertices "
        f"{face[first].tolist()} counted from 0{_where(path, ext, first)}),"
        f" which the cotan Laplacian cannot weigh; {advice}")


def _where(path: str, ext: str, triangle: int) -> str:
    """``', from line N: TEXT'`` for the OBJ or OFF face line that made
    ``triangle`` (polygons make several), for a message; else ``''``."""
    try:
        line = _triangle_line(path, ext, triangle)
    except Exception:  # only for the message: never hide the real error
        line = None
    return '' if line is None else f", from line {line[0]}: {line[1]!r}"


def _triangle_line(path: str, ext: str, triangle: int
                   ) -> Optional[Tuple[int, str]]:
    """``(line number from 1, text up to 60 characters)`` of the OBJ or
    OFF face line that made ``triangle`` (counted as the readers count
    them), or :obj:`None`."""
    if ext == '.obj':
        number = int(_parse_obj(path, with_lines=True)[2][triangle])
    elif ext == '.off':
        number = None
        with open(path, 'r', encoding=TEXT_ENCODING, errors='replace') as f:
            numbered = [(k + 1, raw.split('#', 1)[0].split())
                        for k, raw in enumerate(f)]
        numbered = [item for item in numbered if item[1]]
        rest = ' '.join(numbered[0][1])
        rest = rest[rest.upper().index('OFF') + 3:]
        i = 1
        if not rest.split():
            rest, i = ' '.join(numbered[1][1]), 2
        nv, nf = (int(v) for v in rest.split()[:2])
        for k, tokens in numbered[i + nv:i + nv + nf]:
            triangle -= int(tokens[0]) - 2
            if triangle < 0:
                number = k
                break
        if number is None:
            return None
    else:
        return None
    with open(path, 'r', encoding=TEXT_ENCODING, errors='replace') as f:
        for k, raw in enumerate(f, 1):
            if k == number:
                return number, raw.strip()[:60]
    return None


def _check_ply_counts(path: str, vertices: int, triangles: int):
    """A truncated PLY file reads as fewer vertices or faces than its
    header announces (trimesh does not complain): a :class:`ValueError`."""
    announced = {}
    with open(path, 'rb') as f:
        for raw in f:
            words = raw.decode('ascii', 'replace').split()
            if words[:1] == ['end_header']:
                break
            if words[:1] == ['element'] and len(words) == 3:
                announced[words[1]] = int(words[2])
    vertex, face = announced.get('vertex', 0), announced.get('face', 0)
    # polygons become several triangles, so fewer triangles than faces
    # means some are missing
    if vertices != vertex or triangles < face:
        raise ValueError(f"its header announces {vertex} vertices and {face} "
                         f"faces but it holds {vertices} vertices and "
                         f"{triangles} triangles: the file is truncated")


def _ply_vertex_properties(loaded, num_vertices: int
                           ) -> Dict[str, np.ndarray]:
    """The PLY vertex properties other than x y z, by name: trimesh keeps
    them as a structured array (binary PLY) or a dict of columns (ASCII
    PLY)."""
    raw = getattr(loaded, 'metadata', {}).get('_ply_raw', {})
    data = raw.get('vertex', {}).get('data') if isinstance(raw, dict) \
        else None
    if isinstance(data, dict):
        columns = dict(data)
    elif data is not None and data.dtype.names is not None:
        columns = {name: data[name] for name in data.dtype.names}
    else:
        return {}
    out: Dict[str, np.ndarray] = {}
    for name, column in columns.items():
        if name in _GEOMETRY_PROPERTIES:
            continue
        if getattr(column.dtype, 'names', None):  # a list: (count, values)
            column = column[column.dtype.names[-1]]
        column = np.asarray(column)
        if column.ndim == 2 and column.shape[1] == 1:
            column = column[:, 0]
        if len(column) != num_vertices:
            continue
        out[name] = column
    return out


def _load_trimesh(path: str, ext: str, **kwargs):
    """``trimesh.load(path, process=False, **kwargs)``, without the UTF-8
    byte-order mark that trimesh would read as text (a binary STL, whose
    80-byte header may begin with any bytes, is left as it is)."""
    import trimesh
    with open(path, 'rb') as f:
        head = f.read(84)
    size = os.path.getsize(path)
    binary_stl = ext == '.stl' and len(head) == 84 and size == \
        84 + 50 * int.from_bytes(head[80:84], 'little')
    if not head.startswith(_BOM) or binary_stl:
        return trimesh.load(path, process=False, **kwargs)
    with open(path, 'rb') as f:
        data = f.read()[len(_BOM):]
    return trimesh.load(io.BytesIO(data), file_type=ext[1:], process=False,
                        resolver=trimesh.resolvers.FilePathResolver(path),
                        **kwargs)


def read_obj(path: str) -> Tuple[np.ndarray, Optional[np.ndarray]]:
    """Reads the vertices and faces of an OBJ file as stored: ``(pos
    [N, 3] float64, face [F, 3] int64)``, ``face`` :obj:`None` when the
    file has no ``f`` lines (a point cloud). Every ``v`` line is one
    vertex, in file order, whatever object, group or material it belongs
    to (``o``, ``g``, ``usemtl``; colours after ``x y z`` are ignored).
    ``f`` lines give polygons (corners ``v``, ``v/vt``, ``v//vn`` or
    ``v/vt/vn``, counted from 1, negative ones back from the last vertex
    defined), split into triangle fans. Texture coordinates, normals,
    lines and the rest are not read; a UTF-8 byte-order mark, ``#``
    comments and ``\\`` line continuations are allowed.

    Raises a :class:`ValueError` that names the line of a malformed
    ``v`` or ``f`` line."""
    return _parse_obj(path)[:2]


def _obj_vertex_normals(path: str, num_vertices: int, face
                        ) -> Optional[np.ndarray]:
    """The per-vertex normals ``[N, 3]`` an OBJ file's ``vn`` lines and
    ``f v/vt/vn`` corners give, or :obj:`None` when it has none, a corner
    without one, a vertex with two different normals or a vertex on no
    face (then they are computed from the triangles)."""
    if face is None:
        return None
    with open(path, 'r', encoding=TEXT_ENCODING, errors='replace') as f:
        text = f.read()
    if '\nvn ' not in text and not text.startswith('vn '):
        return None
    normals = re.findall(r'^\s*vn\s+(\S+)\s+(\S+)\s+(\S+)', text, re.M)
    corners = re.findall(r'^\s*f\s+(.*)$', text, re.M)
    pairs = [token.split('/') for row in corners
             for token in row.split('#', 1)[0].split()]
    if not normals or any(len(p) != 3 or not p[2] for p in pairs):
        return None
    try:
        vn = np.array(normals, dtype=np.float64)
        index = np.array([(int(p[0]), int(p[2])) for p in pairs],
                         dtype=np.int64)
    except ValueError:
        return None
    if (index <= 0).any() or index[:, 1].max() > len(vn) or \
            index[:, 0].max() > num_vertices:
        return None  # relative indices, or read_obj's errors
    normal = np.full((num_vertices, 3), np.nan)
    normal[index[:, 0] - 1] = vn[index[:, 1] - 1]
    # one normal per vertex: every corner agrees with what was stored
    if np.isnan(normal).any() or not np.allclose(
            normal[index[:, 0] - 1], vn[index[:, 1] - 1], atol=1e-9):
        return None
    return normal


def _parse_obj(path: str, with_lines: bool = False):
    """:func:`read_obj`, plus the line (from 1) of every triangle
    ``[F]`` when ``with_lines`` (else :obj:`None`)."""
    with open(path, 'r', encoding=TEXT_ENCODING, errors='replace') as f:
        text = f.read()
    lines = text.split('\n')  # numbered as the file's lines
    numbers = None  # the line of every joined line, after continuations
    if '\\\n' in text:
        lines, numbers = _join_continuations(lines)
    vertex_rows, vertex_lines, face_rows, face_lines, defined = \
        [], [], [], [], []
    for k, line in enumerate(lines):
        if line[:1] in (' ', '\t'):
            line = line.lstrip()
        key = line[:2]
        if key == 'v ' or key == 'v\t':
            vertex_rows.append(line)
            vertex_lines.append(k)
        elif key == 'f ' or key == 'f\t':
            face_rows.append(line)
            face_lines.append(k)
            defined.append(len(vertex_rows))

    def malformed(what, rows, row_lines, parse):
        for row, k in zip(rows, row_lines):
            try:
                parse(row)
            except (ValueError, IndexError):
                line = k + 1 if numbers is None else numbers[k] + 1
                return ValueError(f"malformed {what} line {line}: "
                                  f"{row.strip()[:60]!r}")
        return ValueError(f'malformed {what} lines')

    def vertex(row):  # x y z of one vertex line
        values = [float(v) for v in row.split('#', 1)[0].split()[1:4]]
        if len(values) != 3:
            raise ValueError
        return values

    def corners(row):  # OBJ indices of one face line
        values = [int(t.split('/', 1)[0])
                  for t in row.split('#', 1)[0].split()[1:]]
        if len(values) < 3 or 0 in values:
            raise ValueError
        return values

    pos = np.zeros((0, 3))
    if vertex_rows:
        try:  # (w, or colours r g b, may follow x y z)
            pos = np.loadtxt(vertex_rows, usecols=(1, 2, 3), comments='#',
                             dtype=np.float64, ndmin=2)
        except ValueError:
            raise malformed('vertex', vertex_rows, vertex_lines,
                            vertex) from None
    if not face_rows:
        return pos, None, None
    try:
        body = '\n'.join(face_rows)
        if '#' in body:
            body = '\n'.join(row.split('#', 1)[0] for row in face_rows)
        # one number per corner: drop '/vt/vn' and the leading 'f'
        body = re.sub(r'^f', '', re.sub(r'/\S*', '', body), flags=re.M)
        if re.search(r'[^0-9+\-\s]', body):
            # (NumPy before 2.3 reads '3.5' as the index 3, with a warning)
            raise ValueError
        try:  # every face the same polygon (one loop in C)
            index = np.loadtxt(body.split('\n'), dtype=np.int64,
                               comments=None, ndmin=2)
            if len(index) != len(face_rows):  # it skips empty rows
                raise ValueError
            counts = np.full(len(index), index.shape[1])
            index = index.reshape(-1)
        except ValueError:  # mixed polygons
            rows = [row.split() for row in body.split('\n')]
            counts = np.array([len(row) for row in rows], dtype=np.int64)
            index = np.array([int(v) for row in rows for v in row],
                             dtype=np.int64)
        if counts.min() < 3 or (index == 0).any():
            raise ValueError
    except ValueError:
        raise malformed('face', face_rows, face_lines, corners) from None
    if (index < 0).any():  # counted back from the last vertex defined
        before = np.repeat(np.asarray(defined, dtype=np.int64), counts)
        index = np.where(index > 0, index - 1, before + index)
    else:
        index = index - 1
    triangles = counts - 2
    if (counts == 3).all():
        face = index.reshape(-1, 3)
    else:  # fans (0, j, j + 1) of every polygon
        start = np.repeat(np.cumsum(counts) - counts, triangles)
        j = np.arange(triangles.sum()) - np.repeat(
            np.cumsum(triangles) - triangles, triangles) + 1
        face = np.stack([index[start], index[start + j],
                         index[start + j + 1]], 1)
    if not with_lines:
        return pos, face, None
    line = np.asarray(face_lines, dtype=np.int64)
    if numbers is not None:
        line = np.asarray(numbers, dtype=np.int64)[line]
    return pos, face, np.repeat(line + 1, triangles)


def _join_continuations(lines):
    """OBJ lines with their ``\\``-continued lines joined, and the index
    of the line each begins at."""
    joined, numbers, parts = [], [], None
    for k, line in enumerate(lines):
        if parts is None:
            parts, start = [], k
        if line.endswith('\\'):
            parts.append(line[:-1])
            continue
        parts.append(line)
        joined.append(' '.join(parts))
        numbers.append(start)
        parts = None
    if parts is not None:
        joined.append(' '.join(parts))
        numbers.append(start)
    return joined, numbers


def read_off(path: str) -> Tuple[np.ndarray, np.ndarray]:
    """Reads an OFF file (also ``COFF``/``NOFF`` with extra columns, and
    ModelNet's ``OFF<nv> <nf> <ne>`` single-line header). Polygons are
    split into triangle fans. A UTF-8 byte-order mark is ignored."""
    with open(path, 'r', encoding=TEXT_ENCODING, errors='replace') as f:
        lines = [ln.split('#', 1)[0].strip() for ln in f]
    lines = [ln for ln in lines if ln]
    if not lines:
        raise ValueError('empty file')
    head = lines[0]
    keyword = head.split()[0]
    if not keyword.upper().lstrip('CN').startswith('OFF'):
        raise ValueError(f"missing 'OFF' header (first line: {head[:40]!r})")
    rest = head[head.upper().index('OFF') + 3:].split()
    i = 1
    if not rest:  # counts on the next line
        if len(lines) < 2:
            raise ValueError('the OFF header has no vertex and face counts')
        rest = lines[1].split()
        i = 2
    try:
        nv, nf = int(rest[0]), int(rest[1])
    except (IndexError, ValueError):
        raise ValueError(f'malformed OFF header {head!r}') from None
    if len(lines) < i + nv + nf:
        raise ValueError(f'OFF header announces {nv} vertices and {nf} faces '
                         f'but the file has only {len(lines) - i} data lines')
    vlines = lines[i:i + nv]
    try:
        pos = np.array([ln.split()[:3] for ln in vlines], dtype=np.float64)
    except ValueError:
        raise ValueError('malformed vertex line') from None
    if pos.shape != (nv, 3):
        raise ValueError('every vertex line needs 3 coordinates')
    ftok = [ln.split() for ln in lines[i + nv:i + nv + nf]]
    try:
        if all(len(t) >= 4 and t[0] == '3' for t in ftok):  # all triangles
            return pos, np.array([t[1:4] for t in ftok],
                                 dtype=np.int64).reshape(-1, 3)
        tris = []
        for tok in ftok:
            k = int(tok[0])
            if k < 3 or len(tok) < k + 1:
                raise ValueError(f"malformed face line {' '.join(tok)[:40]!r}")
            idx = [int(t) for t in tok[1:k + 1]]
            for j in range(1, k - 1):
                tris.append((idx[0], idx[j], idx[j + 1]))
    except ValueError as e:
        raise ValueError(f'malformed face line ({e})') from None
    return pos, np.array(tris, dtype=np.int64).reshape(-1, 3)


def read_signal(source: str, num_vertices: int,
                properties: Optional[Dict[str, np.ndarray]] = None,
                inverse: Optional[np.ndarray] = None) -> np.ndarray:
    """A per-vertex signal, ``(N)`` or ``(N, C)`` float64, from ``source``:
    a ``.npy`` file, a ``.txt`` / ``.csv`` file with one row per vertex,
    ``FILE.ply:NAME`` (vertex property ``NAME`` of a PLY file) or ``NAME``
    alone, a vertex property of the input (``properties``, from
    :func:`read_surface`).

    ``inverse`` (from :func:`read_surface` with ``return_inverse=True``)
    also accepts a signal with one row per vertex as stored in the file,
    before welding: the copies of a welded vertex must hold the same row.

    Raises a :class:`ValueError` when the source is a folder, unreadable
    (:func:`check_file`; :class:`FileNotFoundError` when missing), not
    finite, or has another number of rows than ``num_vertices``. Text
    files may begin with a UTF-8 byte-order mark.
    """
    properties = properties or {}
    give = (f"a {'/'.join(SIGNAL_EXTENSIONS)} file with one row per "
            f"vertex, or FILE.ply:NAME")
    ply, _, name = source.rpartition(':')
    if ply.lower().endswith('.ply'):
        _, _, props = read_surface(ply)
        if name not in props:
            raise ValueError(f"'{ply}' has no vertex property {name!r}; it "
                             f"has {sorted(props) or 'none'}")
        values = props[name]
    elif osp.splitext(source)[1].lower() in SIGNAL_EXTENSIONS:
        check_file(source, 'signal file', give)
        if source.lower().endswith('.npy'):
            values = read_npy(source)  # names what is wrong with the file
        else:
            try:
                values = np.loadtxt(source, delimiter=',' if source.lower(
                ).endswith('.csv') else None, ndmin=1,
                    encoding=TEXT_ENCODING)
            except OSError as error:
                raise ValueError(f"could not read the signal '{source}': "
                                 f"{os_error_reason(error)}") from error
            except ValueError as error:
                raise ValueError(f"could not read the signal '{source}': "
                                 f"{error}") from error
    elif source in properties:
        values = properties[source]
    elif osp.isdir(source):
        raise ValueError(f"signal '{source}' is a folder; give {give}")
    else:
        raise ValueError(
            f"signal {source!r} is neither a {'/'.join(SIGNAL_EXTENSIONS)} "
            f"file, FILE.ply:PROPERTY, nor a vertex property of the input "
            f"(it has {sorted(properties) or 'none'})")
    values = np.asarray(values)
    if values.dtype.kind not in 'biuf':
        raise ValueError(f"signal {source!r} is not numeric "
                         f"({values.dtype})")
    values = values.astype(np.float64)
    if values.ndim not in (1, 2):
        raise ValueError(f"signal {source!r} has {values.ndim} dimensions "
                         f"{values.shape}; give one value, or one row of "
                         f"values, per vertex: shape ({num_vertices},) or "
                         f"({num_vertices}, C)")
    if inverse is not None and len(inverse) != num_vertices and \
            values.shape[0] == len(inverse):
        values = _follow_weld(source, values, inverse, num_vertices)
    if values.shape[0] != num_vertices:
        stored = '' if inverse is None or len(inverse) == num_vertices \
            else f" ({len(inverse)} as stored in the file, before welding)"
        raise ValueError(f"signal {source!r} has {values.shape[0]} rows but "
                         f"the surface has {num_vertices} vertices{stored}; "
                         f"give one row per vertex")
    if not np.isfinite(values).all():
        raise ValueError(f"signal {source!r} holds NaN or infinite values")
    return values


def _follow_weld(source: str, values: np.ndarray, inverse: np.ndarray,
                 num_vertices: int) -> np.ndarray:
    """One row per welded vertex from one row per stored vertex; the copies
    of a vertex must agree."""
    first_copy = np.full(num_vertices, len(inverse), dtype=np.int64)
    np.minimum.at(first_copy, inverse, np.arange(len(inverse)))
    welded = values[first_copy]
    differ = np.flatnonzero((welded[inverse] != values).reshape(
        len(values), -1).any(1))
    if differ.size:
        raise ValueError(f"signal {source!r} has one row per vertex as "
                         f"stored, but {differ.size} copies of welded "
                         f"vertices hold other values than their first "
                         f"copy (first: row {int(differ[0])}); give one row "
                         f"per welded vertex")
    return welded


def write_ply(path: str, pos: np.ndarray, face: Optional[np.ndarray] = None,
              properties: Optional[Dict[str, np.ndarray]] = None,
              colors: Optional[np.ndarray] = None,
              typed_properties: Optional[Dict[str, np.ndarray]] = None
              ) -> str:
    """Writes a binary little-endian PLY atomically. It holds positions
    as doubles, then every entry of ``typed_properties`` in its own
    numeric type (e.g. the vertex properties of an input file from
    :func:`read_surface`, kept as they were: ``uchar`` colours stay
    ``uchar``, ``float`` stays ``float``; 64-bit integers become ``int``
    or ``uint`` when they fit, else ``double``), ``colors`` (``(N, 3)``
    in [0, 1]) as ``red green blue`` bytes, every entry of
    ``properties`` as double vertex properties, and triangles
    ``face (F, 3)``. A property of shape ``(N)`` is written as ``name``,
    one of shape ``(N, C)`` as ``name_0`` to ``name_{C-1}``; two of one
    name are a :class:`ValueError`. MeshLab, CloudCompare, Blender and
    trimesh read it. Returns ``path``."""
    pos = np.asarray(pos, dtype=np.float64)
    n = len(pos)
    fields = [('x', '<f8'), ('y', '<f8'), ('z', '<f8')]
    columns = [pos[:, 0], pos[:, 1], pos[:, 2]]

    def add(name, values, kind=None):
        values = np.asarray(values).reshape(n, -1)
        kind = kind or _ply_type(values)
        names = [name] if values.shape[1] == 1 else \
            [f'{name}_{k}' for k in range(values.shape[1])]
        for k, column in enumerate(names):
            if column in (field for field, _ in fields):
                raise ValueError(f"two vertex properties named {column!r}")
            fields.append((column, kind))
            columns.append(values[:, k])

    for name, values in (typed_properties or {}).items():
        add(name, values)
    if colors is not None:
        colors = np.asarray(colors, dtype=np.float64).reshape(n, 3)
        rgb = (np.clip(np.nan_to_num(colors), 0, 1) * 255 + 0.5).astype(
            np.uint8)
        for k, name in enumerate(('red', 'green', 'blue')):
            add(name, rgb[:, k], 'u1')
    for name, values in (properties or {}).items():
        add(name, np.asarray(values, dtype=np.float64), '<f8')
    vertices = np.empty(n, dtype=fields)
    for (name, _), column in zip(fields, columns):
        vertices[name] = column
    types = {'<f8': 'double', '<f4': 'float', 'u1': 'uchar', 'i1': 'char',
             '<u2': 'ushort', '<i2': 'short', '<u4': 'uint', '<i4': 'int'}
    header = ['ply', 'format binary_little_endian 1.0',
              'comment written by tg_intrinsic', f'element vertex {n}']
    header += [f'property {types[t]} {name}' for name, t in fields]
    if face is not None:
        face = np.asarray(face, dtype=np.int64).reshape(-1, 3)
        header += [f'element face {len(face)}',
                   'property list uchar int vertex_indices']
        triangles = np.empty(len(face), dtype=[('n', 'u1'),
                                               ('v', '<i4', (3, ))])
        triangles['n'] = 3
        triangles['v'] = face
    header.append('end_header')

    def write(f):
        f.write(('\n'.join(header) + '\n').encode('ascii'))
        f.write(vertices.tobytes())
        if face is not None:
            f.write(triangles.tobytes())

    atomic_write(path, write, 'wb')
    return path


def _ply_type(values: np.ndarray) -> str:
    """The little-endian numpy type code of the PLY type that holds
    ``values`` exactly (double when none does)."""
    kind, size = values.dtype.kind, values.dtype.itemsize
    if kind == 'b':
        return 'u1'
    if kind in 'iu' and size == 8:  # PLY has no 64-bit integers
        for code in ('<i4', '<u4'):
            info = np.iinfo(code)
            if values.size == 0 or (values.min() >= info.min and
                                    values.max() <= info.max):
                return code
        return '<f8'
    if kind in 'iu':
        return {1: kind + '1'}.get(size, f'<{kind}{size}')
    if kind == 'f' and size <= 4:
        return '<f4'
    return '<f8'
