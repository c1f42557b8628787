r"""Texture space of a UV-mapped triangle mesh: which texels the UV
triangles cover (a numba rasteriser in UV space), the 4-neighbour grid of
the covered texels, a UV-mapped sphere to test them on, UV atlases of
meshes without UVs (xatlas) and per-vertex values baked into textures.

Texture convention (OpenGL / OBJ ``vt``): :math:`(u, v) \in [0, 1]^2` with
:math:`v` pointing up, stored as an image of :math:`H` rows and :math:`W`
columns whose row 0 is the top (:math:`v = 1`). The texel in row :math:`r`,
column :math:`c` has the flat row-major index :math:`rW + c` and its centre
at

.. math::
    u_c = \frac{c + \frac12}{W}, \qquad v_r = 1 - \frac{r + \frac12}{H}.
"""
import math
from typing import Tuple

import numpy as np
import torch
from torch import Tensor

from .checks import (check_choice, check_faces, check_image_size,
                     check_index, check_points, check_positive_int,
                     check_unit_interval)
from .jit import jit

__all__ = ['rasterize_uv', 'texture_grid_edges', 'uv_sphere', 'uv_atlas',
           'grid_atlas',
           'bake_texture']

# A texel centre on a triangle's edge belongs to it (up to this much of
# the barycentric range), so that the two triangles of a shared edge leave
# no gap between them in floating point.
_EDGE_TOLERANCE = 1e-9


@jit
def _rasterize_uv_kernel(corners, height, width, tol):  # pragma: no cover
    """Owner triangle (-1: none) and barycentrics of every texel centre,
    triangles in index order, a texel keeping the first one that covers
    it. ``corners`` (F, 3, 2) are texel coordinates: column and row of
    the corner, texel centres at integers."""
    owner = np.full(height * width, -1, dtype=np.int64)
    bary = np.zeros((height * width, 3))
    for f in range(corners.shape[0]):
        x0, y0 = corners[f, 0, 0], corners[f, 0, 1]
        x1, y1 = corners[f, 1, 0], corners[f, 1, 1]
        x2, y2 = corners[f, 2, 0], corners[f, 2, 1]
        det = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if abs(det) <= 1e-14 * (abs(x1 - x0) + abs(x2 - x0) + abs(y1 - y0)
                                + abs(y2 - y0)) ** 2:
            continue  # zero area in UV space: covers nothing
        c0 = max(0, int(math.ceil(min(x0, x1, x2) - 1e-6)))
        c1 = min(width - 1, int(math.floor(max(x0, x1, x2) + 1e-6)))
        r0 = max(0, int(math.ceil(min(y0, y1, y2) - 1e-6)))
        r1 = min(height - 1, int(math.floor(max(y0, y1, y2) + 1e-6)))
        for r in range(r0, r1 + 1):
            for c in range(c0, c1 + 1):
                t = r * width + c
                if owner[t] >= 0:
                    continue
                w1 = ((c - x0) * (y2 - y0) - (x2 - x0) * (r - y0)) / det
                w2 = ((x1 - x0) * (r - y0) - (c - x0) * (y1 - y0)) / det
                w0 = 1.0 - w1 - w2
                if w0 < -tol or w1 < -tol or w2 < -tol:
                    continue
                # on an edge within the tolerance: onto the triangle
                w0, w1, w2 = max(w0, 0.0), max(w1, 0.0), max(w2, 0.0)
                total = w0 + w1 + w2
                owner[t] = f
                bary[t, 0] = w0 / total
                bary[t, 1] = w1 / total
                bary[t, 2] = w2 / total
    return owner, bary


def rasterize_uv(face_uv: Tensor, height: int, width: int
                 ) -> Tuple[Tensor, Tensor, Tensor]:
    r"""The texels of an :math:`(H, W)` texture whose centres
    :math:`(u_c, v_r)` (see the module) lie in a UV triangle, with that
    triangle and the barycentric coordinates of the centre in it. The
    coordinates :math:`\lambda` satisfy

    .. math::
        (u_c, v_r) = \sum_{k=0}^{2} \lambda_k\, (u, v)_{f, k},
        \qquad \lambda_k \geq 0.

    A centre on a shared edge (to :math:`10^{-9}` of the barycentric range)
    counts as inside; a texel covered by several triangles (overlapping
    UV charts, or a shared edge) belongs to the one of lowest index.
    Triangles of zero area in UV space cover nothing. Flipped (clockwise)
    UV triangles are covered like the others.

    Args:
        face_uv (torch.Tensor): The UVs of every triangle corner, in
            :math:`[0, 1]^2`: ``face_uv[k, f]`` is corner :math:`k` of
            triangle :math:`f` (the layout of PyG's ``face``).
        height (int): Texture rows :math:`H`.
        width (int): Texture columns :math:`W`.

    Returns:
        (texel_index, texel_face, texel_bary): the covered texels' flat
        row-major indices :math:`rW + c` in increasing order, their
        triangles and barycentrics :math:`\lambda` (on ``face_uv``'s
        device, ``texel_bary`` in its dtype).

    Shapes:
        - **input:** face_uv :math:`(3, F, 2)`
        - **output:** :math:`(N)`, :math:`(N)`, :math:`(N, 3)`,
          :math:`N \leq HW`
    """
    height = check_positive_int(height, 'height')
    width = check_positive_int(width, 'width')
    if not isinstance(face_uv, Tensor) or face_uv.dim() != 3 \
            or face_uv.size(0) != 3 or face_uv.size(2) != 2:
        shape = list(face_uv.shape) if isinstance(face_uv, Tensor) \
            else type(face_uv).__name__
        raise ValueError(f"'face_uv' must have shape [3, F, 2] (the UV of "
                         f"corner k of triangle f at [k, f]), got {shape}")
    uv = check_unit_interval(face_uv, 'face_uv', face_uv.shape)
    # texel coordinates: column c and row r have their centres at c and r
    corners = torch.stack([uv[..., 0] * width - 0.5,
                           (1 - uv[..., 1]) * height - 0.5], -1)
    owner, bary = _rasterize_uv_kernel(
        corners.transpose(0, 1).contiguous().numpy(), height, width,
        _EDGE_TOLERANCE)
    texel_index = np.flatnonzero(owner >= 0)
    device = face_uv.device
    return (torch.from_numpy(texel_index).to(device),
            torch.from_numpy(owner[texel_index]).to(device),
            torch.from_numpy(bary[texel_index]).to(device, face_uv.dtype))


def texture_grid_edges(texel_index: Tensor, texture_shape) -> Tensor:
    r"""The 4-neighbour grid among the given texels: an edge joins two of
    them whose texels share a side in the image (same row, adjacent
    columns, or same column, adjacent rows); texels that are not given
    break the grid, and nothing wraps around the image's borders. Both
    directions, sorted by centre (``edge_index[1]``) then neighbour, like
    :func:`~tg_intrinsic.geometry.mesh_edges`.

    The grid is the image's: texels of two UV charts that touch in the
    image are joined even if the charts lie far apart on the surface
    (pack charts with a gutter of one empty texel to keep them apart).

    Follows PyG's ``source_to_target`` flow: ``edge_index[0]`` is the
    neighbour :math:`j`, ``edge_index[1]`` the centre :math:`i`, both
    positions in :obj:`texel_index`.

    Args:
        texel_index (torch.Tensor): Distinct flat row-major texel indices
            :math:`rW + c` of the points.
        texture_shape (tuple): ``(H, W)``.

    Shapes:
        - **input:** texel_index :math:`(N)`
        - **output:** :math:`(2, E)`
    """
    height, width = check_image_size(texture_shape, 'texture_shape')
    texel_index = check_index(texel_index, 'texel_index', height * width,
                              texel_index, what='texels (H * W)')
    num = texel_index.numel()
    if torch.unique(texel_index).numel() != num:
        raise ValueError("'texel_index' repeats texels; every point must be "
                         "a different texel")
    slot = torch.full((height * width, ), -1, dtype=torch.long,
                      device=texel_index.device)
    slot[texel_index] = torch.arange(num, device=texel_index.device)
    grid = slot.view(height, width)
    first = torch.cat([grid[:, :-1].flatten(), grid[:-1, :].flatten()])
    second = torch.cat([grid[:, 1:].flatten(), grid[1:, :].flatten()])
    both = (first >= 0) & (second >= 0)
    first, second = first[both], second[both]
    src = torch.cat([first, second])
    dst = torch.cat([second, first])
    key = torch.sort(dst * max(num, 1) + src).values
    return torch.stack([key % max(num, 1), key // max(num, 1)])


def uv_sphere(rows: int = 16, cols: int = 32,
              dtype: torch.dtype = torch.float64
              ) -> Tuple[Tensor, Tensor, Tensor]:
    r"""A unit latitude-longitude sphere with per-vertex UVs. They follow the
    equirectangular map

    .. math::
        (u, v) = \left(\frac{\varphi}{2\pi}, 1 - \frac{\theta}{\pi}\right),
        \qquad p = (\sin\theta \cos\varphi, \sin\theta \sin\varphi,
        \cos\theta),

    with the north pole (:math:`\theta = 0`) at the top of the texture.
    Vertices on the seam :math:`\varphi = 0 \equiv 2\pi` are duplicated
    (:math:`u = 0` and :math:`u = 1`), and each pole has one copy per
    column (at :math:`u = (c + \frac12) / \text{cols}`), so the UVs are
    per vertex; triangles are counter-clockwise seen from outside and
    counter-clockwise in UV space. The texture is covered between the
    rings next to the poles; above and below them only inside the cap
    triangles (each pole is one point per column).

    Args:
        rows (int, optional): Latitude bands (at least 2).
            (default: :obj:`16`)
        cols (int, optional): Longitude bands (at least 3).
            (default: :obj:`32`)
        dtype (torch.dtype, optional): Of ``pos`` and ``uv``.
            (default: :obj:`torch.float64`)

    Returns:
        (pos, face, uv): :math:`(V, 3)`, :math:`(3, F)`, :math:`(V, 2)`
        with :math:`V = (\text{rows} - 1)(\text{cols} + 1) +
        2\,\text{cols}` and :math:`F = 2\,\text{cols}(\text{rows} - 1)`.
    """
    rows = check_positive_int(rows, 'rows', 2)
    cols = check_positive_int(cols, 'cols', 3)
    f64 = torch.float64
    # the rings between the poles: (rows - 1) x (cols + 1), seam doubled
    theta = torch.arange(1, rows, dtype=f64) * math.pi / rows
    phi = torch.arange(cols + 1, dtype=f64) * 2 * math.pi / cols
    t, p = torch.meshgrid(theta, phi, indexing='ij')
    ring = torch.stack([t.sin() * p.cos(), t.sin() * p.sin(), t.cos()],
                       -1).reshape(-1, 3)
    ring_uv = torch.stack([p / (2 * math.pi), 1 - t / math.pi],
                          -1).reshape(-1, 2)
    ring_uv[:, 0] = torch.arange(cols + 1, dtype=f64).repeat(rows - 1) \
        / cols  # exactly 0 and 1 on the seam
    middle = (torch.arange(cols, dtype=f64) + 0.5) / cols
    north = torch.tensor([0.0, 0.0, 1.0], dtype=f64).repeat(cols, 1)
    pos = torch.cat([ring, north, -north])
    uv = torch.cat([ring_uv, torch.stack([middle, torch.ones_like(middle)],
                                         -1),
                    torch.stack([middle, torch.zeros_like(middle)], -1)])
    index = torch.arange(ring.size(0)).view(rows - 1, cols + 1)
    first_north = ring.size(0)
    first_south = first_north + cols
    c = torch.arange(cols)
    a, b = index[:-1, :-1].flatten(), index[:-1, 1:].flatten()
    d, e = index[1:, :-1].flatten(), index[1:, 1:].flatten()
    # counter-clockwise from outside: from a ring (a, b) down to (d, e)
    quads = [torch.stack([a, d, e]), torch.stack([a, e, b])]
    caps = [torch.stack([first_north + c, index[0, :-1], index[0, 1:]]),
            torch.stack([first_south + c, index[-1, 1:], index[-1, :-1]])]
    face = torch.cat(quads + caps, 1)
    return pos.to(dtype), face.contiguous(), uv.to(dtype)


# xatlas is run in a child process: it crashes (SIGSEGV) on some meshes,
# e.g. an 82k-triangle icosphere (xatlas 0.0.11; jpcy/xatlas#151), and a
# crash must not end the command that asked for the atlas
_XATLAS_CHILD = (
    "import sys, numpy as np, xatlas\n"
    "given = np.load(sys.argv[1])\n"
    "mapping, indices, uvs = xatlas.parametrize(given['v'], given['f'])\n"
    "np.savez(sys.argv[2], mapping=mapping, indices=indices, uvs=uvs)\n")


def uv_atlas(pos: Tensor, face: Tensor, method: str = 'xatlas') -> Tensor:
    r"""A UV atlas of a triangle mesh: charts packed into :math:`[0, 1]^2`
    without overlap, as UVs per triangle corner, the layout
    :func:`rasterize_uv` and :func:`bake_texture` take.

    ``'xatlas'`` cuts the surface into charts and packs them with xatlas
    (the library Blender's and many engines' exporters use; ``pip install
    xatlas``, the ``[textures]`` extra), in a child process, so that a
    crash of xatlas raises a :class:`RuntimeError` instead of ending the
    program. ``'grid'`` (:func:`grid_atlas`) gives every pair of triangles
    its own square of a grid: no seams are saved, any mesh size works at
    once. Runs on the CPU; the result is on ``pos``'s device.

    Args:
        pos (torch.Tensor): Vertices :math:`(V, 3)`.
        face (torch.Tensor): Triangles :math:`(3, F)`.
        method (str, optional): ``'xatlas'`` or ``'grid'``.
            (default: :obj:`'xatlas'`)

    Returns:
        ``face_uv`` :math:`(3, F, 2)` in ``pos``'s dtype: the UV of corner
        :math:`k` of triangle :math:`f` at ``[k, f]``.
    """
    method = check_choice(method, 'method', ('xatlas', 'grid'))
    pos = check_points(pos)
    face = check_faces(face, pos.size(0), pos)
    if method == 'grid':
        return grid_atlas(face.size(1), pos.dtype).to(pos.device)
    try:
        import xatlas  # noqa: F401
    except ImportError:
        raise ImportError("a UV atlas needs the xatlas package: pip install "
                          "xatlas (or tg_intrinsic[textures]), or give the "
                          "mesh UVs ('vt' in an OBJ, s t in a PLY)") from None
    vertices = pos.detach().cpu().double().numpy().astype(np.float32)
    triangles = face.t().cpu().numpy().astype(np.uint32)
    mapping, indices, uvs = _xatlas_in_a_child(vertices, triangles)
    if len(indices) != len(triangles) or not np.array_equal(
            mapping[indices], triangles):  # one chart corner per corner
        raise RuntimeError('xatlas returned triangles in another order than '
                           'it was given; cannot map its UVs back')
    face_uv = torch.from_numpy(np.clip(uvs[indices], 0, 1)).transpose(0, 1)
    return face_uv.to(pos.device, pos.dtype).contiguous()


def _xatlas_in_a_child(vertices: np.ndarray, triangles: np.ndarray):
    import subprocess
    import sys
    import tempfile
    with tempfile.TemporaryDirectory(prefix='tg-intrinsic-atlas-') as work:
        given, made = f'{work}/mesh.npz', f'{work}/atlas.npz'
        np.savez(given, v=vertices, f=triangles)
        done = subprocess.run([sys.executable, '-c', _XATLAS_CHILD, given,
                               made], capture_output=True, text=True)
        if done.returncode != 0:
            why = f'crashed (signal {-done.returncode})' \
                if done.returncode < 0 else \
                (done.stderr.strip().splitlines() or ['failed'])[-1]
            raise RuntimeError(f"xatlas {why} on this mesh of "
                               f"{len(triangles)} triangles")
        with np.load(made) as atlas:
            return atlas['mapping'], atlas['indices'], atlas['uvs']


def grid_atlas(num_faces: int, dtype: torch.dtype = torch.float64
               ) -> Tensor:
    r"""A UV atlas that needs no charts: the :math:`F` triangles, in
    pairs, fill the squares of a :math:`G \times G` grid,
    :math:`G = \lceil \sqrt{\lceil F / 2 \rceil} \rceil`, the first of a
    pair in the lower-left half of its square and the second in the
    upper-right half, each shrunk by a tenth of the square so that texels
    do not bleed between triangles. Values are interpolated in a triangle
    by its barycentrics as in any atlas; the shapes are not kept, so a
    texture needs more texels than with xatlas' charts (at least about
    :math:`8 \sqrt{F}` on a side for every triangle to own texels).

    Args:
        num_faces (int): :math:`F`.
        dtype (torch.dtype, optional): (default: :obj:`torch.float64`)

    Returns:
        ``face_uv`` :math:`(3, F, 2)`.
    """
    num_faces = check_positive_int(num_faces, 'num_faces')
    pairs = (num_faces + 1) // 2
    side = math.ceil(math.sqrt(pairs))
    index = torch.arange(num_faces)
    cell = index // 2
    x0 = (cell % side).to(dtype) / side
    y0 = (cell // side).to(dtype) / side
    step, margin = 1.0 / side, 0.1 / side
    lo, hi = margin, step - 2 * margin
    lower = torch.tensor([[lo, lo], [hi, lo], [lo, hi]], dtype=dtype)
    upper = torch.tensor([[step - lo, step - lo], [step - hi, step - lo],
                          [step - lo, step - hi]], dtype=dtype)
    corners = torch.where((index % 2 == 0).view(-1, 1, 1), lower, upper)
    return (corners + torch.stack([x0, y0], -1).unsqueeze(1)).transpose(
        0, 1).contiguous()


def bake_texture(values: Tensor, face: Tensor, face_uv: Tensor,
                 texture_shape) -> Tuple[Tensor, Tensor]:
    r"""Per-vertex values as an :math:`(H, W)` texture. Every texel whose
    centre a UV triangle covers (:func:`rasterize_uv`) takes the values of
    the triangle's corners interpolated by its barycentrics,

    .. math::
        T(r, c) = \sum_{k=0}^{2} \lambda_k\, x_{f_k},

    and every other texel the value of the nearest covered texel (edge
    padding, scipy's Euclidean distance transform), so that filtering and
    mip-mapping across chart borders do not bleed the background in.
    Rasterising and padding run on the CPU; the results are on
    ``values``' device.

    Args:
        values (torch.Tensor): One row per vertex :math:`(V)` or
            :math:`(V, C)`.
        face (torch.Tensor): Triangles :math:`(3, F)`.
        face_uv (torch.Tensor): UVs per corner :math:`(3, F, 2)`.
        texture_shape (tuple): ``(H, W)``.

    Returns:
        ``(texture, coverage)``: :math:`(H, W)` or :math:`(H, W, C)` in
        ``values``' dtype, and the boolean :math:`(H, W)` mask of the
        texels a triangle covers.
    """
    from scipy.ndimage import distance_transform_edt
    height, width = check_image_size(texture_shape, 'texture_shape')
    if not isinstance(values, Tensor) or values.dim() not in (1, 2):
        raise ValueError(f"'values' must be a tensor of shape [V] or [V, C]"
                         f", got {getattr(values, 'shape', type(values))}")
    face = check_faces(face, values.size(0), values)
    if not isinstance(face_uv, Tensor) or face_uv.dim() != 3 or \
            tuple(face_uv.shape[::2]) != (3, 2) or \
            face_uv.size(1) != face.size(1):
        raise ValueError(f"'face_uv' must have shape [3, {face.size(1)}, 2] "
                         f"(a UV per corner of each triangle), got "
                         f"{list(face_uv.shape)}")
    texel, texel_face, bary = rasterize_uv(face_uv.detach().cpu().double(),
                                           height, width)
    if texel.numel() == 0:
        raise ValueError(f"no texel centre of the {height} x {width} "
                         f"texture lies in a UV triangle: the UVs have no "
                         f"area, or the texture is too small")
    flat = values.detach().cpu().double().reshape(values.size(0), -1)
    corners = flat[face.cpu()[:, texel_face]]            # (3, N, C)
    covered = (bary.t().unsqueeze(-1) * corners).sum(0)  # (N, C)
    coverage = np.zeros(height * width, dtype=bool)
    coverage[texel.numpy()] = True
    texture = np.zeros((height * width, flat.size(1)))
    texture[texel.numpy()] = covered.numpy()
    coverage = coverage.reshape(height, width)
    nearest = distance_transform_edt(~coverage, return_distances=False,
                                     return_indices=True)
    texture = texture.reshape(height, width, -1)[nearest[0], nearest[1]]
    if values.dim() == 1:
        texture = texture[..., 0]
    return (torch.from_numpy(texture).to(values.device, values.dtype),
            torch.from_numpy(coverage).to(values.device))
