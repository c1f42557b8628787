r"""Equirectangular environment maps: directions, solid angles and lookup.

Convention (world :math:`z` is up, as the polar angle of
:mod:`tg_intrinsic.geometry.sh`): an environment map is an array
:math:`(H, W, 3)` of linear radiance. Pixel ``(row, col)`` covers polar
angles :math:`\theta \in [\pi\,\mathrm{row}/H, \pi(\mathrm{row}+1)/H]`
(row 0 looks up, at :math:`+z`) and azimuths :math:`\phi \in [2\pi\,
\mathrm{col}/W - \pi, 2\pi(\mathrm{col}+1)/W - \pi]`, with
:math:`\phi = \operatorname{atan2}(y, x)`: column 0 starts at :math:`-x`,
the middle column looks along :math:`+x`. The direction of
:math:`(\theta, \phi)` is :math:`(\sin\theta\cos\phi, \sin\theta\sin\phi,
\cos\theta)`; the lookup is bilinear between pixel centres, wrapping in
azimuth.
"""
import math

import torch
from torch import Tensor

from ._checks import check_tensor


def check_envmap(envmap, name: str = 'envmap') -> Tensor:
    """Checks an environment map: a floating, finite, non-negative
    :math:`(H, W, 3)` tensor."""
    envmap = check_tensor(envmap, name)
    if envmap.dim() != 3 or envmap.size(-1) != 3 or min(envmap.shape[:2]) < 2:
        raise ValueError(f"'{name}' must be an equirectangular image of shape "
                         f"[H, W, 3] (usually W = 2 H), got "
                         f"{list(envmap.shape)}")
    if not envmap.is_floating_point():
        raise ValueError(f"'{name}' must hold floating-point linear radiance, "
                         f"got {envmap.dtype}; an 8-bit image is not HDR: "
                         f"read a .hdr/.exr file instead")
    bad = ~torch.isfinite(envmap)
    if bool(bad.any()):
        raise ValueError(f"'{name}' has {int(bad.any(-1).sum())} pixel(s) "
                         f"with NaN or infinite radiance; repair or replace "
                         f"them first")
    if bool((envmap < 0).any()):
        raise ValueError(f"'{name}' has negative radiance; an environment map "
                         f"must be non-negative")
    return envmap


def equirect_angles(height: int, width: int, dtype=torch.float64,
                    device=None):
    r"""Polar and azimuthal angles :math:`(\theta, \phi)` of the pixel
    centres, each :math:`(H, W)`."""
    theta = (torch.arange(height, dtype=dtype, device=device) + 0.5) \
        * (math.pi / height)
    phi = (torch.arange(width, dtype=dtype, device=device) + 0.5) \
        * (2 * math.pi / width) - math.pi
    return torch.broadcast_tensors(theta[:, None], phi[None, :])


def equirect_directions(height: int, width: int, dtype=torch.float64,
                        device=None) -> Tensor:
    """Unit directions of the pixel centres, :math:`(H, W, 3)`."""
    theta, phi = equirect_angles(height, width, dtype, device)
    sin_theta = torch.sin(theta)
    return torch.stack([sin_theta * torch.cos(phi), sin_theta * torch.sin(phi),
                        torch.cos(theta)], -1)


def equirect_solid_angles(height: int, width: int, dtype=torch.float64,
                          device=None) -> Tensor:
    r"""Exact solid angle of every pixel, :math:`(H, W)`; they sum to
    :math:`4\pi`."""
    edges = torch.arange(height + 1, dtype=dtype, device=device) \
        * (math.pi / height)
    band = torch.cos(edges[:-1]) - torch.cos(edges[1:])
    return (band * (2 * math.pi / width))[:, None].expand(height, width)


def direction_to_equirect(directions: Tensor, height: int, width: int):
    r"""Continuous pixel coordinates ``(row, col)`` of unit directions
    :math:`(\ldots, 3)`: pixel centres sit at integers + 0.5."""
    z = directions[..., 2].clamp(-1.0, 1.0)
    theta = torch.acos(z)
    phi = torch.atan2(directions[..., 1], directions[..., 0])
    return theta * (height / math.pi), (phi + math.pi) * (width / (2 *
                                                                   math.pi))


def equirect_lookup(envmap: Tensor, directions: Tensor) -> Tensor:
    r"""Radiance of :obj:`envmap` :math:`(H, W, C)` in unit
    :obj:`directions` :math:`(\ldots, 3)`, bilinear between pixel centres
    (wrapping in azimuth, clamped at the poles): :math:`(\ldots, C)`."""
    height, width = envmap.shape[:2]
    row, col = direction_to_equirect(directions.to(envmap.dtype), height,
                                     width)
    row = (row - 0.5).clamp(0, height - 1)
    col = col - 0.5
    r0 = row.floor().clamp(max=height - 2)
    c0 = col.floor()
    fr = (row - r0).unsqueeze(-1)
    fc = (col - c0).unsqueeze(-1)
    r0 = r0.long()
    c0 = c0.long() % width
    c1 = (c0 + 1) % width
    flat = envmap.reshape(height * width, -1)

    def at(r, c):
        return flat[r * width + c]

    top = at(r0, c0) * (1 - fc) + at(r0, c1) * fc
    bottom = at(r0 + 1, c0) * (1 - fc) + at(r0 + 1, c1) * fc
    return top * (1 - fr) + bottom * fr
