r"""Pinhole cameras: projection, a splatted depth test and image sampling.

Convention (OpenCV): ``intrinsics`` :math:`K` :math:`(V, 3, 3)` and
``extrinsics`` :math:`[R \mid t]` :math:`(V, 3, 4)` map a world point to
camera coordinates :math:`x_c = R x + t`; the camera looks along
:math:`+z_c` with :math:`x_c` right and :math:`y_c` down, and
:math:`(u, v) = (f_x x_c / z_c + c_x, f_y y_c / z_c + c_y)`. The pixel in
row :math:`i`, column :math:`j` covers :math:`u \in [j, j + 1)`,
:math:`v \in [i, i + 1)`. The camera centre is :math:`-R^\top t`.
"""
import math
from typing import Tuple

import numpy as np
import torch
from numba import prange
from torch import Tensor

from ..checks import check_image_size, check_points
from ..jit import jit

__all__ = ['camera_centers', 'project', 'splat_depth', 'sample_images',
           'look_at_cameras']


def camera_centers(extrinsics: Tensor) -> Tensor:
    r"""World positions :math:`-R^\top t` of the cameras, :math:`(V, 3)`."""
    rotation, translation = extrinsics[:, :, :3], extrinsics[:, :, 3:]
    return -(rotation.transpose(1, 2) @ translation).squeeze(-1)


def project(pos: Tensor, intrinsics: Tensor, extrinsics: Tensor):
    r"""Pixel coordinates :math:`(V, N, 2)` (as :math:`(u, v)`) and depths
    :math:`z_c` :math:`(V, N)` of world points :math:`(N, 3)`."""
    cam = pos.unsqueeze(0) @ extrinsics[:, :, :3].transpose(1, 2) \
        + extrinsics[:, None, :, 3]
    depth = cam[..., 2]
    safe = torch.where(depth.abs() > 0, depth, torch.ones_like(depth))
    # the whole K, skew included: u = fx x/z + s y/z + cx, v = fy y/z + cy
    uv = (cam / safe.unsqueeze(-1)) @ intrinsics[:, :2].transpose(1, 2)
    return uv, depth


def splat_depth(uv: Tensor, depth: Tensor, valid: Tensor, radius: Tensor,
                height: int, width: int) -> Tensor:
    r"""A depth buffer :math:`(V, H, W)` made by splatting every valid point
    as a square of :obj:`radius` pixels :math:`(V, N)` (integers) around its
    pixel, keeping the nearest depth; empty pixels are :math:`+\infty`.
    On the CPU a compiled loop over each point's own square; elsewhere
    vectorised over views and points (one ``scatter_reduce`` per stencil
    offset). Both give the same buffer (a minimum is exact)."""
    num_views = uv.size(0)
    if uv.device.type == 'cpu':
        buffer = np.full((num_views, height, width), np.inf)
        _splat_kernel(uv.detach().double().contiguous().numpy(),
                      depth.detach().double().contiguous().numpy(),
                      valid.contiguous().numpy(),
                      radius.long().contiguous().numpy(), buffer)
        return torch.from_numpy(buffer).to(depth.dtype)
    return _splat_depth_torch(uv, depth, valid, radius, height, width)


def _splat_depth_torch(uv: Tensor, depth: Tensor, valid: Tensor,
                       radius: Tensor, height: int, width: int) -> Tensor:
    """:func:`splat_depth` on any device."""
    num_views = uv.size(0)
    buffer = torch.full((num_views, height * width), math.inf,
                        dtype=depth.dtype, device=depth.device)
    col = uv[..., 0].floor().long()
    row = uv[..., 1].floor().long()
    view = torch.arange(num_views, device=uv.device)[:, None]
    reach = int(radius[valid].max()) if bool(valid.any()) else 0
    for dy in range(-reach, reach + 1):
        for dx in range(-reach, reach + 1):
            r, c = row + dy, col + dx
            keep = valid & (radius >= max(abs(dx), abs(dy))) & (r >= 0) \
                & (r < height) & (c >= 0) & (c < width)
            index = (view * (height * width) + r * width + c)[keep]
            buffer.view(-1).scatter_reduce_(0, index, depth[keep], 'amin')
    return buffer.view(num_views, height, width)


@jit(parallel=True)
def _splat_kernel(uv, depth, valid, radius, buffer):  # pragma: no cover
    """:func:`splat_depth` on the CPU: every view in parallel, each valid
    point's square of its radius."""
    num_views, height, width = buffer.shape
    for v in prange(num_views):
        for p in range(uv.shape[1]):
            if not valid[v, p]:
                continue
            col, row = math.floor(uv[v, p, 0]), math.floor(uv[v, p, 1])
            reach, z = radius[v, p], depth[v, p]
            for r in range(max(row - reach, 0), min(row + reach + 1,
                                                     height)):
                for c in range(max(col - reach, 0), min(col + reach + 1,
                                                         width)):
                    if z < buffer[v, r, c]:
                        buffer[v, r, c] = z


def sample_images(images: Tensor, uv: Tensor):
    r"""Bilinear samples of :obj:`images` :math:`(V, H, W, C)` at pixel
    coordinates :math:`(V, N, 2)` (pixel centres at integers + 0.5,
    clamped to the border): :math:`(V, N, C)`, and whether any of the four
    taps is NaN :math:`(V, N)`."""
    num_views, height, width, channels = images.shape
    x = (uv[..., 0] - 0.5).clamp(0, width - 1)
    y = (uv[..., 1] - 0.5).clamp(0, height - 1)
    x0 = x.floor().clamp(max=max(width - 2, 0))
    y0 = y.floor().clamp(max=max(height - 2, 0))
    fx, fy = (x - x0).unsqueeze(-1), (y - y0).unsqueeze(-1)
    x0, y0 = x0.long(), y0.long()
    x1 = (x0 + 1).clamp(max=width - 1)
    y1 = (y0 + 1).clamp(max=height - 1)
    flat = images.reshape(num_views, height * width, channels)

    def tap(r, c):
        index = (r * width + c).unsqueeze(-1).expand(-1, -1, channels)
        return flat.gather(1, index)

    taps = (tap(y0, x0), tap(y0, x1), tap(y1, x0), tap(y1, x1))
    weights = ((1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy)
    nan = torch.zeros(uv.shape[:2], dtype=torch.bool, device=uv.device)
    value = torch.zeros(uv.shape[:2] + (channels, ), dtype=images.dtype,
                        device=images.device)
    for t, w in zip(taps, weights):
        bad = torch.isnan(t)
        nan |= bad.any(-1)
        value = value + torch.where(bad, torch.zeros_like(t), t) * w
    return value, nan


def look_at_cameras(positions: Tensor, target=(0.0, 0.0, 0.0),
                    fov_degrees: float = 45.0,
                    image_size: Tuple[int, int] = (256, 256),
                    up=(0.0, 0.0, 1.0)):
    r"""Pinhole cameras at :obj:`positions` looking at :obj:`target`,
    OpenCV style (:math:`z_c` forward, :math:`x_c` right, :math:`y_c` down
    in the image, world :math:`z` up on screen). Their poses are

    .. math::
        z_c = \frac{\mathbf{t} - \mathbf{c}}{\|\mathbf{t} - \mathbf{c}\|},
        \quad x_c = \frac{z_c \times \mathbf{u}}{\|z_c \times
        \mathbf{u}\|}, \quad y_c = z_c \times x_c, \quad
        R = [x_c; y_c; z_c], \quad t = -R\,\mathbf{c},

    and :math:`K` with :math:`f_x = f_y = \frac{H/2}{\tan(\mathrm{fov}/2)}`
    (:obj:`fov_degrees` spans the image height) and the principal point at
    the image centre :math:`(W/2, H/2)`. A camera looking along
    :math:`\pm` :obj:`up` uses the world :math:`y` axis as up instead.

    Args:
        positions (torch.Tensor): Camera centres :math:`(V, 3)`.
        target (sequence, optional): The point looked at.
            (default: origin)
        fov_degrees (float, optional): Vertical field of view.
            (default: :obj:`45.0`)
        image_size (tuple, optional): ``(height, width)``.
            (default: :obj:`(256, 256)`)
        up (sequence, optional): World up. (default: :math:`+z`)

    Returns:
        ``(intrinsics, extrinsics)``: :math:`(V, 3, 3)` and
        :math:`(V, 3, 4)`, in the dtype of :obj:`positions`.
    """
    positions = check_points(positions, 'positions')
    height, width = check_image_size(image_size)
    if not (0 < float(fov_degrees) < 180):
        raise ValueError(f"'fov_degrees' must lie in (0, 180), got "
                         f"{fov_degrees!r}")
    dtype = positions.dtype
    target = torch.as_tensor(target, dtype=dtype).reshape(3)
    up = torch.as_tensor(up, dtype=dtype).reshape(3)
    forward = target - positions
    dist = forward.norm(dim=1, keepdim=True)
    if bool((dist <= 1e-12).any()):
        raise ValueError("a camera position coincides with 'target'; "
                         "move it away")
    forward = forward / dist
    right = torch.cross(forward, up.expand_as(forward), dim=1)
    # looking straight along up: any other up will do
    along = right.norm(dim=1) < 1e-6
    alt = torch.tensor([0.0, 1.0, 0.0], dtype=dtype).expand_as(forward)
    right = torch.where(along[:, None],
                        torch.cross(forward, alt, dim=1), right)
    right = right / right.norm(dim=1, keepdim=True)
    down = torch.cross(forward, right, dim=1)
    R = torch.stack([right, down, forward], 1)
    t = -(R @ positions.unsqueeze(-1))
    extrinsics = torch.cat([R, t], 2)
    focal = 0.5 * height / math.tan(math.radians(float(fov_degrees)) / 2)
    K = torch.tensor([[focal, 0.0, width / 2], [0.0, focal, height / 2],
                      [0.0, 0.0, 1.0]], dtype=dtype)
    intrinsics = K.expand(positions.size(0), 3, 3).clone()
    return intrinsics, extrinsics
