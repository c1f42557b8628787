r"""The full reflection integral of direct environment lighting, tabulated
over the roughness, in torch (CPU or GPU): the model of the full-integral
refinement of :meth:`~tg_intrinsic.nn.FrequencySVBRDF.refine`.

For a principled material (Lambert + GGX, Smith, Schlick; the BRDF of
:mod:`~tg_intrinsic.geometry.appearance.lighting`) lit by a distant
environment :math:`L` with visibility :math:`V(\mathbf{p}, \omega)`, the
outgoing radiance is linear in the diffuse albedo :math:`K_d` and in
:math:`R_0`, and non-linear only in the roughness :math:`r`:

.. math::
    B(\mathbf{p}, \omega_o) = \frac{K_d}{\pi} E(\mathbf{p})
    + R_0\, A(\mathbf{p}, \omega_o; r) + C(\mathbf{p}, \omega_o; r),

with the shadowed irradiance :math:`E = \int L V \cos\theta_i\,d\omega_i`
and, from Schlick's :math:`F = R_0 (1 - s) + s`, :math:`s = (1 - \omega_o
\cdot \mathbf{h})^5`,

.. math::
    A = \int L V \frac{D\,G_1(\omega_i)\,G_1(\omega_o)}{4\cos\theta_o}
    (1 - s)\, d\omega_i, \qquad
    C = \int L V \frac{D\,G_1(\omega_i)\,G_1(\omega_o)}{4\cos\theta_o}\,
    s\, d\omega_i.

:func:`reflection_tables` evaluates :math:`A` and :math:`C` for every
observed (point, view) pair on a grid of roughness values, so that a fit
needs no more rendering: between grid values the model interpolates
linearly. The integrals are estimated by multiple importance sampling
(balance heuristic) of GGX visible normals (Heitz 2018) and of the
environment's pixels, with the same random numbers at every roughness
(the table is smooth in :math:`r`) and a fixed seed (it is
deterministic). :math:`E` is a quadrature over every pixel of the map.
"""
import math
from typing import Optional, Tuple

import numpy as np
import torch
from numba import prange
from torch import Tensor

from ..checks import (check_choice, check_points, check_positive_int,
                      check_seed, check_tensor)
from ..jit import jit
from ..pointcloud.frames import tangent_frames
from .brdf import model_alpha
from .cameras import look_at_cameras
from .envmap import (bilinear_rgb, check_envmap, direction_to_equirect,
                     env_coords, equirect_directions, equirect_lookup,
                     equirect_solid_angles)
from .raster import point_visibility
from .sh import smith_g1

__all__ = ['reflection_tables', 'direction_visibility']


def direction_visibility(points: Tensor, normal: Tensor, vertices: Tensor,
                         faces: Tensor, resolution: Tuple[int, int] = (16, 32),
                         offset: float = 1e-4) -> Tensor:
    r"""Which directions of the sky each point sees, on an equirectangular
    grid of :obj:`resolution` cells: a ray from the point (moved by
    :obj:`offset` times the object's size along its normal, so that it
    leaves its own triangles) towards each cell centre that crosses no
    triangle. Exact ray casting
    (:func:`~tg_intrinsic.geometry.appearance.raster.point_visibility`)
    from one distant camera per direction, so the cost is one rasterisation
    of the mesh per cell, the cells in parallel. A cell that lies wholly
    below a point's horizon is not cast (False: the integrands are zero
    there); one that crosses the horizon is. The rays are cast on
    the CPU, in float64 (exact hits decide visibility); the result is on
    the device of :obj:`points`.

    Args:
        points (torch.Tensor): :math:`(N, 3)`, on the mesh.
        normal (torch.Tensor): Unit normals :math:`(N, 3)`.
        vertices (torch.Tensor): Mesh positions :math:`(n, 3)`.
        faces (torch.Tensor): Triangles :math:`(3, F)`.
        resolution (tuple, optional): ``(rows, columns)`` of the grid.
            (default: :obj:`(16, 32)`)
        offset (float, optional): Normal offset relative to the bounding
            box diagonal. (default: :obj:`1e-4`)

    Returns:
        Bool :math:`(N, \text{rows} \cdot \text{columns})`.
    """
    points = check_points(points, 'points')
    rows, cols = (check_positive_int(r, 'resolution') for r in resolution)
    pos = vertices.detach().double().cpu()
    lo, hi = pos.min(0).values, pos.max(0).values
    centre, size = (lo + hi) / 2, float((hi - lo).norm())
    start = points.detach().double().cpu() \
        + offset * size * normal.detach().double().cpu()
    directions = equirect_directions(rows, cols).reshape(-1, 3)
    # distant pinhole cameras looking back along each direction; their
    # image just holds the object
    distance = 1e2 * size
    # the rays' candidate triangles come from a screen grid of about two
    # cells per triangle, at most four per pixel: enough pixels that a big
    # mesh gets its whole grid (a ray tests a handful of triangles, not
    # dozens)
    pixels = max(64, math.ceil(math.sqrt(faces.size(1) / 2) / 2))
    intrinsics, extrinsics = look_at_cameras(
        centre + distance * directions, centre.tolist(),
        2 * math.degrees(math.atan(0.6 * size / distance)), (pixels, pixels))
    # a direction whose whole cell lies below a point's horizon would
    # carry zero light: not cast (a cell's half diagonal is at most
    # pi / rows wide)
    needed = normal.detach().double().cpu() @ directions.T \
        >= -math.sin(min(math.pi / rows, math.pi / 2))
    # the lifted point is off its triangles: any hit in front occludes
    return point_visibility(start, pos, faces.detach().cpu(), intrinsics,
                            extrinsics, pixels, pixels, rel_tol=1e-12,
                            needed=needed).to(points.device)


class _Environment:
    """An environment map prepared for sampling: bilinear radiance,
    pixel probabilities proportional to solid angle times the brightest
    radiance of the 3 x 3 neighbourhood (every direction whose bilinear
    radiance is non-zero has a non-zero density) and their CDF."""
    def __init__(self, envmap: Tensor):
        self.map = envmap
        self.height, self.width = envmap.shape[:2]
        dtype, device = envmap.dtype, envmap.device
        luminance = envmap.mean(-1)
        padded = torch.cat([luminance[:, -1:], luminance, luminance[:, :1]],
                           1)
        padded = torch.nn.functional.pad(padded[None, None], (0, 0, 1, 1),
                                         mode='replicate')
        bright = torch.nn.functional.max_pool2d(padded, 3, 1)[0, 0]
        self.solid_angle = equirect_solid_angles(self.height, self.width,
                                                 dtype, device)
        weight = (bright * self.solid_angle).flatten()
        if float(weight.sum()) <= 0:
            weight = self.solid_angle.flatten().clone()
        self.probability = weight / weight.sum()
        self.cdf = torch.cumsum(self.probability, 0)
        self.cdf[-1] = 1.0
        # density per solid angle, uniform inside each pixel
        self.pixel_density = self.probability / self.solid_angle.flatten()

    def coordinates(self, directions: Tensor):
        """Continuous pixel coordinates ``(row, col)`` of ``directions``."""
        return direction_to_equirect(directions, self.height, self.width)

    def density(self, row: Tensor, col: Tensor) -> Tensor:
        """Density per solid angle of the pixel sampling at the pixel
        coordinates ``(row, col)``."""
        index = row.long().clamp(0, self.height - 1) * self.width \
            + col.long().clamp(0, self.width - 1)
        return self.pixel_density[index]

    def sample(self, u0: Tensor, u1: Tensor, u2: Tensor):
        """Directions from three uniform numbers: a pixel by the CDF, then
        uniform in solid angle inside it; and their density."""
        index = torch.searchsorted(self.cdf, u0.contiguous(), right=True
                                   ).clamp(max=self.cdf.numel() - 1)
        row, col = index // self.width, index % self.width
        top = torch.cos(row.to(u1.dtype) * (math.pi / self.height))
        bottom = torch.cos((row + 1).to(u1.dtype) * (math.pi / self.height))
        z = top + (bottom - top) * u1
        phi = (col.to(u2.dtype) + u2) * (2 * math.pi / self.width) - math.pi
        radius = (1 - z * z).clamp_min(0).sqrt()
        directions = torch.stack([radius * torch.cos(phi),
                                  radius * torch.sin(phi), z], -1)
        return directions, self.pixel_density[index]


def _ggx(cos_h: Tensor, alpha: Tensor) -> Tensor:
    a2 = alpha * alpha
    return a2 / (math.pi * ((cos_h * cos_h) * (a2 - 1) + 1) ** 2)


def _visible_normals(view: Tensor, alpha: Tensor, u1: Tensor, u2: Tensor):
    """GGX normals distributed as the normals visible from ``view`` (local
    frames, Heitz 2018), broadcast over ``view`` :math:`(C, 1, 1, 3)`,
    ``alpha`` :math:`(1, G, 1)` and the uniforms :math:`(C, 1, S)`."""
    vx, vy, vz = view.unbind(-1)
    stretched = torch.stack(torch.broadcast_tensors(alpha * vx, alpha * vy,
                                                    vz), -1)
    stretched = torch.nn.functional.normalize(stretched, dim=-1)
    sx, sy, sz = stretched.unbind(-1)
    length = (sx * sx + sy * sy).sqrt()
    flat = length < 1e-12
    safe = torch.where(flat, torch.ones_like(length), length)
    t1x = torch.where(flat, torch.ones_like(sx), -sy / safe)
    t1y = torch.where(flat, torch.zeros_like(sx), sx / safe)
    t2x, t2y, t2z = -sz * t1y, sz * t1x, sx * t1y - sy * t1x
    r = u1.sqrt()
    angle = 2 * math.pi * u2
    p1, p2 = r * torch.cos(angle), r * torch.sin(angle)
    blend = 0.5 * (1 + sz)
    p2 = (1 - blend) * (1 - p1 * p1).clamp_min(0).sqrt() + blend * p2
    p3 = (1 - p1 * p1 - p2 * p2).clamp_min(0).sqrt()
    hx = alpha * (p1 * t1x + p2 * t2x + p3 * sx)
    hy = alpha * (p1 * t1y + p2 * t2y + p3 * sy)
    hz = (p2 * t2z + p3 * sz).clamp_min(0)
    return torch.nn.functional.normalize(torch.stack([hx, hy, hz], -1),
                                         dim=-1)


def _uniforms(count: int, samples: int, dimension: int, seed: int, salt: int,
              dtype, device) -> Tensor:
    """Consecutive blocks of ``samples`` points of one scrambled Sobol
    sequence, :math:`(count, samples, dimension)`: each block is
    stratified in every coordinate and in their pairs (randomised
    quasi-Monte Carlo; independent coordinates matter: a pixel and the
    position inside it must not be drawn from correlated numbers). Drawn
    on the CPU, so the numbers do not depend on the device."""
    return torch.cat([block for _, block in _uniform_blocks(
        count, samples, dimension, seed, salt, dtype, device, max(count, 1))])


def _uniform_blocks(count: int, samples: int, dimension: int, seed: int,
                    salt: int, dtype, device, block: int):
    """:func:`_uniforms` drawn ``block`` rows at a time (the same numbers):
    ``(first row, (rows, samples, dimension))`` pairs, so that millions of
    pairs never hold all their samples at once."""
    engine = torch.quasirandom.SobolEngine(dimension, scramble=True,
                                           seed=seed * 7919 + salt)
    for start in range(0, max(count, 1), block):
        rows = min(block, count - start)
        yield start, engine.draw(rows * samples, dtype=torch.float64).view(
            rows, samples, dimension).to(device, dtype)


def reflection_tables(normal: Tensor, view_dirs: Tensor, mask: Tensor,
                      envmap: Tensor, roughness: Tensor,
                      visibility: Optional[Tensor] = None,
                      light_samples: int = 64, brdf_samples: int = 32,
                      seed: int = 0, chunk: int = 512,
                      backend: str = 'auto'):
    r"""The shadowed irradiance :math:`E` and the specular integrals
    :math:`A, C` of the module docstring at every roughness of a grid.

    Args:
        normal (torch.Tensor): Unit normals :math:`(N, 3)`.
        view_dirs (torch.Tensor): Unit directions to the cameras
            :math:`(N, V, 3)`.
        mask (torch.Tensor): Observed pairs :math:`(N, V)`; the others
            get zeros.
        envmap (torch.Tensor): Equirectangular radiance :math:`(H, W, 3)`,
            :math:`z` up.
        roughness (torch.Tensor): Increasing grid :math:`(G)` of
            perceptual roughness (:math:`\alpha = r^2`, at least
            :data:`~tg_intrinsic.geometry.appearance.brdf.MIN_ALPHA`).
        visibility (torch.Tensor, optional): :math:`(N, R \cdot Q)` from
            :func:`direction_visibility` on an :math:`(R, Q)` grid (any
            :math:`R = Q / 2`); :obj:`None` sees every direction above the
            horizon. (default: :obj:`None`)
        light_samples (int, optional): Environment samples per point,
            shared by its views. (default: :obj:`64`)
        brdf_samples (int, optional): Visible-normal samples per pair and
            roughness. (default: :obj:`32`)
        seed (int, optional): Seed of the sample shifts. (default: :obj:`0`)
        chunk (int, optional): Pairs evaluated at once by the torch
            backend (memory). (default: :obj:`512`)
        backend (str, optional): :obj:`'numba'` (compiled, on the CPU: the
            inputs are moved there and the tables back), :obj:`'torch'`
            (on the inputs' device) or :obj:`'auto'` (numba for CPU
            tensors, torch otherwise). Both take the same samples and
            agree to rounding. (default: :obj:`'auto'`)

    Returns:
        ``(irradiance, tables)``: :math:`E` :math:`(N, 3)` and
        :math:`(A, C)` as :math:`(N, V, G, 2, 3)`.
    """
    normal = check_tensor(normal, 'normal')
    num, views = view_dirs.shape[:2]
    if normal.shape != (num, 3) or view_dirs.shape != (num, views, 3) \
            or mask.shape != (num, views):
        raise ValueError(f"'normal' (N, 3), 'view_dirs' (N, V, 3) and "
                         f"'mask' (N, V) must agree, got {tuple(normal.shape)}"
                         f", {tuple(view_dirs.shape)}, {tuple(mask.shape)}")
    envmap = check_envmap(envmap).to(normal.device, normal.dtype)
    roughness = check_tensor(roughness, 'roughness').to(normal)
    if roughness.dim() != 1 or roughness.numel() < 2 \
            or bool((roughness.diff() <= 0).any()) \
            or float(roughness[0]) < 0 or float(roughness[-1]) > 1:
        raise ValueError("'roughness' must be an increasing grid of at least "
                         "2 values in [0, 1]")
    light_samples = check_positive_int(light_samples, 'light_samples')
    brdf_samples = check_positive_int(brdf_samples, 'brdf_samples')
    chunk = check_positive_int(chunk, 'chunk')
    seed = check_seed(seed)
    backend = check_choice(backend, 'backend', ('auto', 'numba', 'torch'))
    dtype, device = normal.dtype, normal.device
    grid_rows = 0
    if visibility is not None:
        if visibility.dim() != 2 or visibility.size(0) != num:
            raise ValueError(f"'visibility' must be (N, cells) with N = {num},"
                             f" got {tuple(visibility.shape)}")
        cells = visibility.size(1)
        grid_rows = int(round(math.sqrt(cells / 2)))
        if 2 * grid_rows * grid_rows != cells:
            raise ValueError(f"'visibility' must hold an (R, 2R) grid of "
                             f"cells per point, got {cells} cells")
        # kept as booleans: a float copy of (N, cells) is the largest
        # array of a big capture
        visibility = visibility.to(device).bool()

    environment = _Environment(envmap)

    def visible(points: Tensor, row: Tensor, col: Tensor) -> Tensor:
        """Visibility of the points in the directions at the map's pixel
        coordinates ``(row, col)``."""
        if visibility is None:
            return torch.ones(row.shape, dtype=dtype, device=device)
        cell = _visibility_cell(row, col, grid_rows, environment.height,
                                environment.width)
        return visibility[points.view(-1, *([1] * (cell.dim() - 1))),
                          cell].to(dtype)

    frames = tangent_frames(normal)
    compiled = backend == 'numba' or (backend == 'auto'
                                      and device.type == 'cpu')
    irradiance = _irradiance_numba(normal, envmap, visibility, grid_rows) \
        if compiled else _irradiance(normal, environment, visible)
    alpha = model_alpha(roughness).view(1, -1, 1)

    # environment samples: one set per point, shared by its views
    light_dir, light_density = environment.sample(*_uniforms(
        num, light_samples, 3, seed, 1, dtype, device).unbind(-1))
    light = equirect_lookup(envmap, light_dir) * visible(
        torch.arange(num, device=device),
        *environment.coordinates(light_dir)).unsqueeze(-1)
    light_local = torch.einsum('nij,nsj->nsi', frames, light_dir)

    point, view = mask.nonzero(as_tuple=True)
    # the pairs' samples, drawn a block at a time (all at once, millions of
    # pairs would hold gigabytes)
    blocks = _uniform_blocks(point.numel(), brdf_samples, 2, seed, 2, dtype,
                             device, PAIRS_PER_BLOCK)
    if compiled:
        # one compiled pass, nothing per sample stored; sums in float64,
        # stored at the inputs' precision
        def numpy(t):
            return t.detach().cpu().to(torch.float64).contiguous().numpy()
        tables = np.zeros((num, views, roughness.numel(), 2, 3),
                          dtype=np.float32 if dtype == torch.float32
                          else np.float64)
        no_grid = np.zeros((0, 0), dtype=np.uint8)
        inputs = (numpy(frames), numpy(view_dirs))
        shared = (numpy(alpha.flatten()), )
        lights = (numpy(light_local), numpy(light), numpy(light_density),
                  numpy(envmap), numpy(environment.pixel_density),
                  no_grid if visibility is None else _uint8(visibility),
                  grid_rows if visibility is not None else 0)
        point, view = point.cpu().numpy(), view.cpu().numpy()
        for start, uniforms in blocks:
            pairs = slice(start, start + uniforms.size(0))
            _tables_kernel(*inputs, point[pairs], view[pairs], *shared,
                           numpy(uniforms), *lights, tables)
        return irradiance, torch.from_numpy(tables).to(device, dtype)
    tables = torch.zeros(num, views, roughness.numel(), 2, 3, dtype=dtype,
                         device=device)
    for block_start, uniforms in blocks:
        for start in range(block_start, block_start + uniforms.size(0),
                           chunk):
            end = min(start + chunk, block_start + uniforms.size(0))
            tables[point[start:end], view[start:end]] = _torch_tables(
                point[start:end], view[start:end],
                uniforms[start - block_start:end - block_start], frames,
                view_dirs, alpha, envmap, environment, visible, light_local,
                light, light_density, brdf_samples, light_samples)
    return irradiance, tables


def _torch_tables(p, v, uniforms, frames, view_dirs, alpha, envmap,
                  environment, visible, light_local, light, light_density,
                  brdf_samples, light_samples):
    """The tables of the pairs ``(p, v)`` by the torch backend of
    :func:`reflection_tables`, their visible-normal samples
    ``uniforms``."""
    dtype = frames.dtype
    out = torch.einsum('cij,cj->ci', frames[p], view_dirs[p, v].to(dtype))
    out = torch.nn.functional.normalize(out, dim=-1)
    cos_o = out[:, 2].clamp_min(1e-6)
    out = out.view(-1, 1, 1, 3)
    g1_out = smith_g1(cos_o.view(-1, 1, 1), alpha)
    b1, b2 = (u.unsqueeze(1) for u in uniforms.unbind(-1))

    def accumulate(incoming, half, radiance, env_density):
        # balance heuristic: every sample of either strategy is
        # weighted by the sum of both sample densities
        cos_i = incoming[..., 2]
        ggx = _ggx(half[..., 2].clamp_min(0), alpha)
        brdf_density = g1_out * ggx / (4 * cos_o.view(-1, 1, 1))
        integrand = brdf_density * smith_g1(cos_i, alpha)
        weight = torch.where(
            cos_i > 0, integrand / (brdf_samples * brdf_density
                                    + light_samples * env_density
                                    ).clamp_min(1e-300),
            torch.zeros_like(integrand))
        schlick = (1 - (out * half).sum(-1).clamp(0, 1)) ** 5
        a = (weight * (1 - schlick)).unsqueeze(-1) * radiance
        c = (weight * schlick).unsqueeze(-1) * radiance
        return torch.stack([a.sum(2), c.sum(2)], 2)

    # visible-normal samples
    half = _visible_normals(out, alpha, b1, b2)
    incoming = 2 * (out * half).sum(-1, keepdim=True) * half - out
    world = torch.einsum('cij,cgsi->cgsj', frames[p], incoming)
    row, col = environment.coordinates(world)
    radiance = equirect_lookup(envmap, world) \
        * visible(p, row, col).unsqueeze(-1)
    result = accumulate(incoming, half, radiance,
                        environment.density(row, col))
    # environment samples
    incoming = light_local[p].unsqueeze(1)
    half = torch.nn.functional.normalize(incoming + out, dim=-1)
    return result + accumulate(incoming, half, light[p].unsqueeze(1),
                               light_density[p].unsqueeze(1))


def _visibility_cell(row, col, grid_rows: int, height: int, width: int):
    """The visibility cell (row-major on the (R, 2R) grid) of the map's
    pixel coordinates ``(row, col)``."""
    return (row * (grid_rows / height)).long().clamp(0, grid_rows - 1) \
        * (2 * grid_rows) + (col * (2 * grid_rows / width)).long().clamp(
            0, 2 * grid_rows - 1)


def _uint8(visibility: Tensor) -> np.ndarray:
    return visibility.detach().cpu().to(torch.uint8).contiguous().numpy()


#: Pairs whose samples are drawn at once (about 64 MB in float64).
PAIRS_PER_BLOCK = 2 ** 17
#: Most environment pixels the compiled irradiance sums over per point;
#: a larger map is summed in blocks of 2 x 2 (its radiance times solid
#: angle added up, at the block's centre) until it fits: the cosine moves
#: by at most a block's width, 0.7 degrees at this size.
IRRADIANCE_PIXELS = 256 * 512


def _irradiance_numba(normal: Tensor, envmap: Tensor,
                      visibility: Optional[Tensor], grid_rows: int
                      ) -> Tensor:
    r""":func:`_irradiance` compiled, on the CPU (the inputs are moved
    there and the result back): per point, the sum over the pixels with
    light that lie above its horizon and in a visible cell."""
    light = envmap.detach().cpu().double() * equirect_solid_angles(
        *envmap.shape[:2]).unsqueeze(-1)
    while light.shape[0] * light.shape[1] > IRRADIANCE_PIXELS \
            and light.shape[0] % 2 == 0 and light.shape[1] % 2 == 0:
        height, width = light.shape[0] // 2, light.shape[1] // 2
        light = light.view(height, 2, width, 2, 3).sum((1, 3))
    height, width = light.shape[:2]
    directions = equirect_directions(height, width).reshape(-1, 3)
    light = light.reshape(-1, 3)
    lit = (light > 0).any(1)
    cell = np.zeros(0, dtype=np.int64)
    grid = np.zeros((0, 0), dtype=np.uint8)
    if visibility is not None:
        row = (torch.arange(height, dtype=torch.float64) + 0.5)[:, None
                                                                ].expand(
            height, width).reshape(-1)
        col = (torch.arange(width, dtype=torch.float64) + 0.5)[None, :
                                                               ].expand(
            height, width).reshape(-1)
        cell = _visibility_cell(row, col, grid_rows, height, width)[lit
                                                                    ].numpy()
        grid = _uint8(visibility)
    out = np.zeros((normal.size(0), 3))
    _irradiance_kernel(normal.detach().cpu().double().contiguous().numpy(),
                       directions[lit].contiguous().numpy(),
                       light[lit].contiguous().numpy(), cell, grid, out)
    return torch.from_numpy(out).to(normal.device, normal.dtype)


@jit(parallel=True, fastmath=True)
def _irradiance_kernel(normal, directions, light, cell, visibility,
                       out):  # pragma: no cover (numba)
    """Irradiance of every point: its light above the horizon, in the
    visible cells when ``visibility`` has rows."""
    shadowed = visibility.shape[0] > 0
    for p in prange(normal.shape[0]):
        nx, ny, nz = normal[p, 0], normal[p, 1], normal[p, 2]
        red = green = blue = 0.0
        for j in range(directions.shape[0]):
            cosine = nx * directions[j, 0] + ny * directions[j, 1] \
                + nz * directions[j, 2]
            if cosine <= 0 or (shadowed and visibility[p, cell[j]] == 0):
                continue
            red += cosine * light[j, 0]
            green += cosine * light[j, 1]
            blue += cosine * light[j, 2]
        out[p, 0], out[p, 1], out[p, 2] = red, green, blue


def _irradiance(normal: Tensor, environment: _Environment, visible
                ) -> Tensor:
    r""":math:`E = \sum_p L_p V_p \Omega_p \max(0, n \cdot \omega_p)`
    over every pixel of the map, a chunk of points at a time."""
    env = environment.map
    height, width = env.shape[:2]
    directions = equirect_directions(height, width, env.dtype, env.device
                                     ).reshape(-1, 3)
    light = env.reshape(-1, 3) * environment.solid_angle.reshape(-1, 1)
    # pixel centres sit at half-integer coordinates
    row = (torch.arange(height, dtype=env.dtype, device=env.device) + 0.5
           )[:, None].expand(height, width).reshape(1, -1)
    col = (torch.arange(width, dtype=env.dtype, device=env.device) + 0.5
           )[None, :].expand(height, width).reshape(1, -1)
    out = []
    for start in range(0, normal.size(0), 256):
        n = normal[start:start + 256]
        points = torch.arange(start, start + n.size(0), device=n.device)
        cosine = (n @ directions.T).clamp_min(0) * visible(
            points, row.expand(n.size(0), -1), col.expand(n.size(0), -1))
        out.append(cosine @ light)
    return torch.cat(out)


@jit(inline='always')
def _smith_g1(c, alpha):  # pragma: no cover (numba)
    """:func:`~tg_intrinsic.geometry.appearance.sh.smith_g1` of one
    cosine."""
    c = min(max(c, 0.0), 1.0)
    if c <= 0:
        return 0.0
    root = math.sqrt(alpha * alpha + (1 - alpha * alpha) * c * c)
    return 2 * c / max(c + root, 1e-30)


@jit(inline='always')
def _sample_weight(cos_o, g1_out, alpha, in_z, cos_h, env_density,
                   brdf_samples, light_samples):  # pragma: no cover (numba)
    """The balance-heuristic weight of one sample of either strategy, as
    ``accumulate`` in :func:`reflection_tables` (0 below the horizon;
    ``cos_h`` clamped at 0)."""
    if in_z <= 0:
        return 0.0
    a2 = alpha * alpha
    d = (cos_h * cos_h) * (a2 - 1) + 1
    brdf_density = g1_out * a2 / (math.pi * d * d) / (4 * cos_o)
    integrand = brdf_density * _smith_g1(in_z, alpha)
    return integrand / max(brdf_samples * brdf_density
                           + light_samples * env_density, 1e-300)


@jit(inline='always')
def _schlick(ox, oy, oz, hx, hy, hz):  # pragma: no cover (numba)
    """Schlick's weight (1 - o . h)^5, the dot clamped to [0, 1]."""
    t = 1 - min(max(ox * hx + oy * hy + oz * hz, 0.0), 1.0)
    t2 = t * t
    return t2 * t2 * t


@jit(parallel=True, fastmath=True)
def _tables_kernel(frames, view_dirs, pair_point, pair_view, alphas,
                   uniforms, light_local, light, light_density, env,
                   pixel_density, visibility, grid_rows,
                   tables):  # pragma: no cover (numba)
    """The torch loop of :func:`reflection_tables` on the CPU, the same
    samples and arithmetic, one pair per iteration, the sums in
    registers."""
    height, width = env.shape[0], env.shape[1]
    brdf_samples, light_samples = uniforms.shape[1], light_local.shape[1]
    for c in prange(pair_point.size):
        p, v = pair_point[c], pair_view[c]
        frame = frames[p]
        wx, wy, wz = view_dirs[p, v, 0], view_dirs[p, v, 1], view_dirs[p, v, 2]
        ox = frame[0, 0] * wx + frame[0, 1] * wy + frame[0, 2] * wz
        oy = frame[1, 0] * wx + frame[1, 1] * wy + frame[1, 2] * wz
        oz = frame[2, 0] * wx + frame[2, 1] * wy + frame[2, 2] * wz
        norm = max(math.sqrt(ox * ox + oy * oy + oz * oz), 1e-12)
        ox, oy, oz = ox / norm, oy / norm, oz / norm
        cos_o = max(oz, 1e-6)
        # the environment samples' geometry is the same at every roughness
        light_cos_h = np.empty(light_samples)
        light_schlick = np.empty(light_samples)
        for s in range(light_samples):
            hx = light_local[p, s, 0] + ox
            hy = light_local[p, s, 1] + oy
            hz = light_local[p, s, 2] + oz
            norm = max(math.sqrt(hx * hx + hy * hy + hz * hz), 1e-12)
            hx, hy, hz = hx / norm, hy / norm, hz / norm
            light_cos_h[s] = max(hz, 0.0)
            light_schlick[s] = _schlick(ox, oy, oz, hx, hy, hz)
        for g in range(alphas.size):
            alpha = alphas[g]
            g1_out = _smith_g1(cos_o, alpha)
            a_r = a_g = a_b = c_r = c_g = c_b = 0.0
            # the stretched view of the visible-normal sampling (Heitz)
            sx, sy, sz = alpha * ox, alpha * oy, oz
            norm = max(math.sqrt(sx * sx + sy * sy + sz * sz), 1e-12)
            sx, sy, sz = sx / norm, sy / norm, sz / norm
            length = math.sqrt(sx * sx + sy * sy)
            if length < 1e-12:
                t1x, t1y = 1.0, 0.0
            else:
                t1x, t1y = -sy / length, sx / length
            t2x, t2y, t2z = -sz * t1y, sz * t1x, sx * t1y - sy * t1x
            blend = 0.5 * (1 + sz)
            for s in range(brdf_samples):
                r = math.sqrt(uniforms[c, s, 0])
                angle = 2 * math.pi * uniforms[c, s, 1]
                p1, p2 = r * math.cos(angle), r * math.sin(angle)
                p2 = (1 - blend) * math.sqrt(max(1 - p1 * p1, 0.0)) \
                    + blend * p2
                p3 = math.sqrt(max(1 - p1 * p1 - p2 * p2, 0.0))
                hx = alpha * (p1 * t1x + p2 * t2x + p3 * sx)
                hy = alpha * (p1 * t1y + p2 * t2y + p3 * sy)
                hz = max(p2 * t2z + p3 * sz, 0.0)
                norm = max(math.sqrt(hx * hx + hy * hy + hz * hz), 1e-12)
                hx, hy, hz = hx / norm, hy / norm, hz / norm
                d = 2 * (ox * hx + oy * hy + oz * hz)
                ix, iy, iz = d * hx - ox, d * hy - oy, d * hz - oz
                if iz <= 0:  # no contribution: skip the lookups
                    continue
                # to the world: the frame's rows are the local axes
                x = frame[0, 0] * ix + frame[1, 0] * iy + frame[2, 0] * iz
                y = frame[0, 1] * ix + frame[1, 1] * iy + frame[2, 1] * iz
                z = frame[0, 2] * ix + frame[1, 2] * iy + frame[2, 2] * iz
                row, col = env_coords(x, y, z, height, width)
                seen = 1.0
                if grid_rows > 0:
                    cell_row = min(max(np.int64(row * (grid_rows / height)),
                                       0), grid_rows - 1)
                    cell_col = min(max(np.int64(
                        col * (2 * grid_rows / width)), 0), 2 * grid_rows - 1)
                    seen = visibility[p, cell_row * 2 * grid_rows + cell_col]
                    if seen == 0:
                        continue
                pixel = min(max(np.int64(row), 0), height - 1) * width \
                    + min(max(np.int64(col), 0), width - 1)
                weight = seen * _sample_weight(
                    cos_o, g1_out, alpha, iz, hz, pixel_density[pixel],
                    brdf_samples, light_samples)
                schlick = _schlick(ox, oy, oz, hx, hy, hz)
                red, green, blue = bilinear_rgb(env, row, col)
                a, f = weight * (1 - schlick), weight * schlick
                a_r += a * red
                a_g += a * green
                a_b += a * blue
                c_r += f * red
                c_g += f * green
                c_b += f * blue
            for s in range(light_samples):
                weight = _sample_weight(
                    cos_o, g1_out, alpha, light_local[p, s, 2],
                    light_cos_h[s], light_density[p, s], brdf_samples,
                    light_samples)
                a, f = weight * (1 - light_schlick[s]), \
                    weight * light_schlick[s]
                a_r += a * light[p, s, 0]
                a_g += a * light[p, s, 1]
                a_b += a * light[p, s, 2]
                c_r += f * light[p, s, 0]
                c_g += f * light[p, s, 1]
                c_b += f * light[p, s, 2]
            tables[p, v, g, 0, 0] = a_r
            tables[p, v, g, 0, 1] = a_g
            tables[p, v, g, 0, 2] = a_b
            tables[p, v, g, 1, 0] = c_r
            tables[p, v, g, 1, 1] = c_g
            tables[p, v, g, 1, 2] = c_b
