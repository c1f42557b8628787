"""Input validation shared by the whole library.

Every public function, transform, layer and solver calls these before doing
any maths, so that malformed input fails with a :class:`ValueError` that
names the argument, says what is wrong and what to do, instead of producing
NaNs further down. One check per kind of value, decided here only.

Inside a graph traced by ``torch.compile`` the checks of tensor *values*
(finite, in range, sorted) are skipped: they would break the graph at
every call, and the models validate their data once, eagerly, before the
compiled layers run. Checks of shapes and dtypes always run.
"""
from typing import Optional, Sequence, Tuple

import numpy as np
import torch
from torch import Tensor

FLOAT_DTYPES = (torch.float32, torch.float64)


def compiling() -> bool:
    """Whether the caller is being traced by ``torch.compile``: layers then
    skip their input checks (the data is validated once, outside the
    graph) and take gather/scatter paths instead of sparse CSR products and
    numba sweeps, which the compiler cannot trace."""
    return torch.compiler.is_compiling()


def check_tensor(value, name: str) -> Tensor:
    if not isinstance(value, Tensor):
        raise ValueError(f"'{name}' must be a torch.Tensor, got "
                         f"{type(value).__name__}; convert it with "
                         f"torch.as_tensor({name})")
    return value


def check_points(pos, name: str = 'pos', dim: Optional[int] = 3,
                 min_points: int = 1) -> Tensor:
    """Checks a point array: floating tensor of shape [N, dim], finite."""
    pos = check_tensor(pos, name)
    if pos.dim() != 2 or (dim is not None and pos.size(1) != dim):
        want = f'[N, {dim}]' if dim is not None else '[N, D]'
        raise ValueError(f"'{name}' must have shape {want}, got "
                         f"{list(pos.shape)}")
    if pos.dtype not in FLOAT_DTYPES:
        raise ValueError(f"'{name}' must be float32 or float64, got "
                         f"{pos.dtype}; convert it with {name}.float() or "
                         f"{name}.double()")
    if pos.size(0) < min_points:
        raise ValueError(f"'{name}' has {pos.size(0)} points but at least "
                         f"{min_points} are needed")
    if pos.numel() > 0 and not compiling() \
            and not bool(torch.isfinite(pos).all()):
        bad = (~torch.isfinite(pos)).any(dim=1).nonzero().flatten()
        raise ValueError(f"'{name}' contains NaN or infinite values at "
                         f"{bad.numel()} row(s) (first: {bad[:5].tolist()}); "
                         f"remove or repair those points first")
    return pos


def check_vectors(vec, name: str, num: int, like: Tensor) -> Tensor:
    """Checks a per-point 3-vector array (e.g. normals) against ``like``."""
    vec = check_points(vec, name)
    if vec.size(0) != num:
        raise ValueError(f"'{name}' has {vec.size(0)} rows but there are "
                         f"{num} points")
    same_device(vec, name, like)
    return vec


def same_device(value: Tensor, name: str, ref: Tensor, ref_name: str = 'pos'):
    if value.device != ref.device:
        raise ValueError(f"'{name}' is on {value.device} but '{ref_name}' is "
                         f"on {ref.device}; move both to the same device")


def check_batch(batch, num_points: int, ref: Tensor) -> Optional[Tensor]:
    """Checks a PyG batch vector: int64 [N], non-negative, sorted."""
    if batch is None:
        return None
    batch = check_tensor(batch, 'batch')
    if batch.dim() != 1 or batch.numel() != num_points:
        raise ValueError(f"'batch' must have shape [{num_points}] (one "
                         f"example index per point), got "
                         f"{list(batch.shape)}")
    if batch.dtype != torch.long:
        raise ValueError(f"'batch' must be torch.long, got {batch.dtype}")
    same_device(batch, 'batch', ref)
    if num_points > 0 and not compiling():
        if int(batch.min()) < 0:
            raise ValueError("'batch' contains negative example indices")
        if num_points > 1 and bool((batch[1:] < batch[:-1]).any()):
            raise ValueError("'batch' must be sorted (points of one example "
                             "stored contiguously, as PyG's Batch does)")
    return batch


def batch_sizes(batch: Optional[Tensor], num_points: int) -> Tensor:
    """Number of points per example (including empty examples in between)."""
    if batch is None:
        return torch.tensor([num_points], dtype=torch.long)
    if num_points == 0:
        return torch.zeros(0, dtype=torch.long)
    return torch.bincount(batch.cpu())


def check_positive_int(value, name: str, minimum: int = 1) -> int:
    """An integer (Python, numpy or a one-element integer tensor) of at
    least ``minimum``, as a Python int."""
    if isinstance(value, np.integer):
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int):
        if isinstance(value, Tensor) and value.numel() == 1 \
                and not value.is_floating_point():
            value = int(value)
        else:
            raise ValueError(f"'{name}' must be an integer, got {value!r}")
    if value < minimum:
        raise ValueError(f"'{name}' must be at least {minimum}, got {value}")
    return value


def check_channels(values, name: str, length: Optional[int] = None,
                   min_length: int = 1) -> Tuple[int, ...]:
    """A sequence of positive channel counts (exactly ``length`` if set)."""
    if isinstance(values, (str, bytes)) or not hasattr(values, '__len__'):
        raise ValueError(f"'{name}' must be a sequence of channel counts, "
                         f"got {values!r}")
    if (length is not None and len(values) != length) \
            or len(values) < min_length:
        want = f'exactly {length}' if length is not None \
            else f'at least {min_length}'
        raise ValueError(f"'{name}' must hold {want} channel count(s), got "
                         f"{len(values)}: {list(values)!r}")
    return tuple(check_positive_int(c, f'{name}[{i}]')
                 for i, c in enumerate(values))


def check_choice(value, name: str, options) -> str:
    """``value`` must be one of ``options``."""
    if value not in options:
        raise ValueError(f"'{name}' must be one of {tuple(options)}, got "
                         f"{value!r}")
    return value


def check_positive_float(value, name: str, allow_zero: bool = False) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"'{name}' must be a number, got {value!r}") from None
    if value != value or value in (float('inf'), float('-inf')):
        raise ValueError(f"'{name}' must be finite, got {value}")
    if value < 0 or (value == 0 and not allow_zero):
        raise ValueError(f"'{name}' must be positive, got {value}")
    return value


def check_faces(face, num_vertices: int, ref: Tensor, name: str = 'face',
                allow_degenerate_indices: bool = False) -> Tensor:
    """Checks a triangle index array in PyG layout ``[3, F]``."""
    face = check_tensor(face, name)
    if face.dim() != 2 or face.size(0) != 3:
        hint = (f' (it looks like [F, 3]; pass {name}.t())'
                if face.dim() == 2 and face.size(1) == 3 else '')
        raise ValueError(f"'{name}' must have shape [3, F] (PyG layout), got "
                         f"{list(face.shape)}{hint}")
    if face.dtype != torch.long:
        raise ValueError(f"'{name}' must be torch.long vertex indices, got "
                         f"{face.dtype}; convert it with {name}.long()")
    same_device(face, name, ref)
    if face.numel() > 0:
        lo, hi = int(face.min()), int(face.max())
        if lo < 0 or hi >= num_vertices:
            raise ValueError(f"'{name}' indexes vertices in [{lo}, {hi}] but "
                             f"there are only {num_vertices} vertices")
        if not allow_degenerate_indices:
            repeated = ((face[0] == face[1]) | (face[1] == face[2])
                        | (face[0] == face[2]))
            if bool(repeated.any()):
                bad = repeated.nonzero().flatten()
                raise ValueError(f"'{name}' has {bad.numel()} triangle(s) "
                                 f"that repeat a vertex (first: "
                                 f"{bad[:5].tolist()}); remove them")
    return face


def check_referenced(index: Tensor, num_vertices: int, what: str,
                     todo: str):
    """Every one of ``num_vertices`` vertices appears in ``index`` (the
    triangles or edges, ``what``); ``todo`` says why it matters and what to
    do."""
    used = torch.zeros(num_vertices, dtype=torch.bool, device=index.device)
    used[index.flatten()] = True
    if not bool(used.all()):
        bad = (~used).nonzero().flatten()
        raise ValueError(f"{bad.numel()} vertex/vertices are not referenced "
                         f"by any {what} (first: {bad[:5].tolist()}); {todo}")


def check_nondegenerate(area: Tensor, scale: Tensor, name: str = 'face'):
    """Raises if a triangle's area is (numerically) zero."""
    tol = torch.finfo(area.dtype).eps * 16
    degenerate = area <= tol * scale.clamp_min(torch.finfo(area.dtype).tiny)
    if bool(degenerate.any()):
        bad = degenerate.nonzero().flatten()
        raise ValueError(f"'{name}' has {bad.numel()} zero-area (degenerate) "
                         f"triangle(s) (first: {bad[:5].tolist()}); remove "
                         f"them, e.g. with trimesh's "
                         f"update_faces(mesh.nondegenerate_faces())")


def check_edge_index(edge_index, num: int, ref: Tensor,
                     what: str = 'points', ref_name: str = 'pos') -> Tensor:
    """Validates an ``edge_index [2, E]``: long, on ``ref``'s device, in
    range; ``what`` names the ``num`` things it indexes."""
    edge_index = _check_pairs(edge_index, 'edge_index', 'E')
    same_device(edge_index, 'edge_index', ref, ref_name)
    _check_range(edge_index, 'edge_index', num, what)
    return edge_index


def check_index(index, name: str, num: Optional[int], ref: Tensor,
                size: Optional[int] = None, what: str = 'points',
                ref_name: str = 'x') -> Tensor:
    """A ``[size]`` long index vector with values in ``[0, num)``."""
    index = check_tensor(index, name)
    if index.dim() != 1 or (size is not None and index.numel() != size):
        want = f'[{size}]' if size is not None else '[N]'
        raise ValueError(f"'{name}' must have shape {want} (one entry per "
                         f"point), got {list(index.shape)}")
    if index.dtype != torch.long:
        raise ValueError(f"'{name}' must hold integer indices of dtype "
                         f"torch.long, got {index.dtype}; convert it with "
                         f"{name}.long()")
    same_device(index, name, ref, ref_name)
    _check_range(index, name, num, what)
    return index


def _check_pairs(index, name: str, size: str) -> Tensor:
    """A ``[2, size]`` tensor of torch.long indices."""
    index = check_tensor(index, name)
    if index.dim() != 2 or index.size(0) != 2:
        raise ValueError(f"'{name}' must have shape [2, {size}], got "
                         f"{list(index.shape)}")
    if index.dtype != torch.long:
        raise ValueError(f"'{name}' must be torch.long, got {index.dtype}; "
                         f"convert it with {name}.long()")
    return index


def _check_range(index: Tensor, name: str, num: Optional[int], what: str):
    # Compiled and sparse kernels read out of bounds on such indices.
    if index.numel() == 0 or compiling():
        return
    lo, hi = int(index.min()), int(index.max())
    if num is not None and (lo < 0 or hi >= num):
        raise ValueError(f"'{name}' holds indices in [{lo}, {hi}], outside "
                         f"[0, {num}): there are only {num} {what}")
    if lo < 0:
        raise ValueError(f"'{name}' holds negative indices (down to {lo}); "
                         f"indices must be >= 0")


def check_rows(value: Tensor, name: str, num: int, source: str) -> Tensor:
    """``value`` must have ``num`` rows, one per node of ``source``."""
    value = check_tensor(value, name)
    if value.dim() == 0 or value.size(0) != num:
        rows = value.size(0) if value.dim() else 0
        raise ValueError(f"'{name}' has {rows} rows but there are {num} "
                         f"nodes in {source}; pass one row of '{name}' per "
                         f"node (features and graph of the same data)")
    return value


def check_streams(z, name: str = 'x') -> Tensor:
    """Complex stream features ``[N, S, C]`` (Harmonic Surface Networks)."""
    z = check_tensor(z, name)
    if z.dim() != 3 or not z.is_complex():
        raise ValueError(f"'{name}' must be complex stream features "
                         f"[N, streams, C], got {z.dtype} of shape "
                         f"{list(z.shape)}; lift real [N, C] features with "
                         f"torch.complex(x, torch.zeros_like(x))"
                         f".unsqueeze(1)")
    return z


def check_vector_features(v, name: str, channels: int,
                          num: Optional[int] = None) -> Tensor:
    """Float tangent vector features ``[N, channels, 2]`` (``N = num`` if
    given), checked before layers view them as planes, which would
    silently accept a wrong last dimension."""
    v = check_tensor(v, name)
    rows = 'N' if num is None else num
    if v.dim() != 3 or v.size(1) != channels or v.size(2) != 2 \
            or (num is not None and v.size(0) != num) \
            or not v.is_floating_point():
        raise ValueError(f"'{name}' must be float tangent vector features "
                         f"[{rows}, {channels}, 2], got {v.dtype} of shape "
                         f"{list(v.shape)}")
    return v


def check_float_tensor(value, name: str, shape: Sequence[int]) -> Tensor:
    """A finite floating-point tensor of exactly ``shape``."""
    value = check_tensor(value, name)
    if tuple(value.shape) != tuple(shape):
        raise ValueError(f"'{name}' must have shape {list(shape)}, got "
                         f"{list(value.shape)}")
    if not value.is_floating_point():
        raise ValueError(f"'{name}' must be a float tensor, got "
                         f"{value.dtype}")
    if value.numel() and not compiling() \
            and not bool(torch.isfinite(value).all()):
        raise ValueError(f"'{name}' contains NaN or infinite values; "
                         f"repair those rows first")
    return value


def check_unit_rows(value, name: str, shape: Sequence[int]) -> np.ndarray:
    """Directions of ``shape`` (no zero rows), normalised, float64 numpy."""
    value = check_float_tensor(value, name, shape)
    norm = value.double().norm(dim=-1, keepdim=True)
    if value.numel() and bool((norm <= 1e-12).any()):
        raise ValueError(f"'{name}' has zero-length direction(s); every "
                         f"row must be a (unit) direction")
    return (value.double() / norm).cpu().numpy()


def check_unit_interval(value, name: str, shape: Sequence[int]) -> Tensor:
    """Values of ``shape`` in [0, 1], as a float64 CPU tensor."""
    value = check_float_tensor(value, name, shape)
    if value.numel() and bool(((value < 0) | (value > 1)).any()):
        raise ValueError(f"'{name}' must lie in [0, 1], got values in "
                         f"[{float(value.min()):g}, {float(value.max()):g}]"
                         f"; clamp it first")
    return value.double().cpu()


def check_seed(seed) -> int:
    """A non-negative integer seed."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) \
            or seed < 0:
        raise ValueError(f"'seed' must be a non-negative integer, got "
                         f"{seed!r}")
    return int(seed)


def check_image_size(image_size, name: str = 'image_size') -> Tuple[int, int]:
    """``(height, width)``, two positive integers."""
    if not (isinstance(image_size, (tuple, list)) and len(image_size) == 2):
        raise ValueError(f"'{name}' must be (height, width), got "
                         f"{image_size!r}")
    return (check_positive_int(image_size[0], f'{name}[0]'),
            check_positive_int(image_size[1], f'{name}[1]'))


def check_cameras(intrinsics, extrinsics, like: Optional[Tensor] = None,
                  batched: bool = True) -> Tuple[Tensor, Tensor]:
    """Pinhole cameras, OpenCV style: ``intrinsics`` ``[V, 3, 3]`` matrices
    ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]`` with ``fx, fy > 0`` and
    ``extrinsics`` ``[V, 3, 4]`` world-to-camera ``[R | t]`` with ``R`` a
    rotation (``[3, 3]`` and ``[3, 4]`` with :obj:`batched=False`), finite,
    on the device of ``like`` if given. Returns both as ``[V, 3, 3]`` and
    ``[V, 3, 4]``."""
    intrinsics = check_tensor(intrinsics, 'intrinsics')
    extrinsics = check_tensor(extrinsics, 'extrinsics')
    dims = 3 if batched else 2
    if intrinsics.dim() != dims or tuple(intrinsics.shape[-2:]) != (3, 3) \
            or extrinsics.dim() != dims \
            or tuple(extrinsics.shape[-2:]) != (3, 4):
        names = ('[V, 3, 3] (one pinhole matrix K per view) and [V, 3, 4] '
                 '(world-to-camera [R | t] per view)' if batched
                 else '[3, 3] and [3, 4]')
        raise ValueError(f"'intrinsics' and 'extrinsics' must have shapes "
                         f"{names}, got {list(intrinsics.shape)} and "
                         f"{list(extrinsics.shape)}")
    intrinsics = intrinsics.reshape(-1, 3, 3)
    extrinsics = extrinsics.reshape(-1, 3, 4)
    if intrinsics.size(0) == 0 or extrinsics.size(0) == 0:
        raise ValueError("there are no views (0 cameras); a capture needs "
                         "at least one camera and its image")
    if intrinsics.size(0) != extrinsics.size(0):
        raise ValueError(f"'intrinsics' has {intrinsics.size(0)} views but "
                         f"'extrinsics' has {extrinsics.size(0)}")
    for name, value in (('intrinsics', intrinsics),
                        ('extrinsics', extrinsics)):
        if not value.is_floating_point() or not bool(
                torch.isfinite(value).all()):
            raise ValueError(f"'{name}' must be finite floating-point "
                             f"matrices")
        if like is not None:
            same_device(value, name, like, 'points')
    K = intrinsics.detach().double()
    if bool((K[:, 1, 0] != 0).any() or (K[:, 2, :2] != 0).any()
            or (K[:, 2, 2] != 1).any() or (K[:, 0, 0] <= 0).any()
            or (K[:, 1, 1] <= 0).any()):
        raise ValueError("'intrinsics' must be pinhole matrices [[fx, s, "
                         "cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0")
    R = extrinsics.detach().double()[:, :, :3]
    eye = torch.eye(3, dtype=torch.float64, device=R.device)
    error = (R @ R.transpose(1, 2) - eye).abs().amax((1, 2))
    bad = ((error > 1e-4) | (torch.linalg.det(R) < 0)).nonzero().flatten()
    if bad.numel():
        raise ValueError(f"'extrinsics' must be world-to-camera [R | t] "
                         f"with R a rotation; camera(s) {bad[:5].tolist()} "
                         f"are not (re-orthonormalise R)")
    return intrinsics, extrinsics


def check_frames(frame, num: int, like: Tensor) -> Tensor:
    """Validates user-supplied frames ``[N, 3, 3]`` (rows e_u, e_v, n)."""
    if not isinstance(frame, Tensor) or frame.dim() != 3 \
            or tuple(frame.shape[1:]) != (3, 3):
        raise ValueError("'frame' must be a tensor of shape [N, 3, 3] with "
                         "rows (e_u, e_v, normal)")
    check_vectors(frame.reshape(-1, 3), 'frame', 3 * num, like)
    eye = torch.eye(3, dtype=frame.dtype, device=frame.device)
    gram = frame @ frame.transpose(1, 2)
    tol = 1e-4 if frame.dtype == torch.float32 else 1e-8
    if not bool(((gram - eye).abs() <= tol).all()):
        raise ValueError("'frame' rows must be orthonormal; build frames "
                         "with tangent_frames(normal)")
    if not bool((torch.linalg.det(frame) > 0).all()):
        raise ValueError("'frame' must be right-handed (e_u x e_v = normal)")
    return frame


def check_prolongation(x: Tensor, prolong_index: Tensor,
                       prolong_weight: Tensor, rows: int, side: str,
                       other: Optional[int] = None):
    """A prolongation ``[2, nnz]`` (fine, coarse) with one finite weight per
    entry, whose ``side`` ('fine' or 'coarse') indexes the rows of x and
    whose other side indexes ``other`` points."""
    x = check_tensor(x, 'x')
    if x.dim() == 0 or not (x.is_floating_point() or x.is_complex()):
        raise ValueError(f"'x' must be float features [N, *], got "
                         f"{x.dtype} of shape {list(x.shape)}")
    prolong_index = _check_pairs(prolong_index, 'prolong_index', 'nnz')
    prolong_weight = check_tensor(prolong_weight, 'prolong_weight')
    if prolong_weight.shape != prolong_index.shape[1:]:
        raise ValueError("'prolong_weight' must hold one weight per column "
                         "of 'prolong_index'")
    check_float_tensor(prolong_weight, 'prolong_weight',
                       prolong_weight.shape)
    same_device(prolong_index, 'prolong_index', x, 'x')
    same_device(prolong_weight, 'prolong_weight', x, 'x')
    _check_range(prolong_index[0 if side == 'fine' else 1], 'prolong_index',
                 rows, f'rows in x ({side} points)')
    if other is not None:
        far = 'coarse' if side == 'fine' else 'fine'
        _check_range(prolong_index[1 if side == 'fine' else 0],
                     'prolong_index', other, f'{far} points (num_{far})')


def check_view_indices(views, name: str, num_views: int) -> list:
    """Distinct view indices in ``[0, num_views)`` as a list of ints (a
    sequence or an integer tensor, possibly empty)."""
    if isinstance(views, Tensor):
        if views.is_floating_point() or views.dtype == torch.bool \
                or views.dim() > 1:
            raise ValueError(f"'{name}' must be a sequence of integer view "
                             f"indices, got a tensor of shape "
                             f"{list(views.shape)} and dtype {views.dtype}")
        views = views.reshape(-1).tolist()
    try:
        views = [check_positive_int(v, name, minimum=0) for v in views]
    except TypeError:
        raise ValueError(f"'{name}' must be a sequence of view indices, got "
                         f"{views!r}") from None
    bad = [v for v in views if v >= num_views]
    if bad:
        raise ValueError(f"'{name}' holds view indices {bad[:5]} outside "
                         f"[0, {num_views}): there are only {num_views} "
                         f"views")
    if len(set(views)) != len(views):
        raise ValueError(f"'{name}' lists a view more than once: {views}")
    return views
