r"""Square images on the unit sphere: the elliptical grid mapping of the
square :math:`[-1, 1]^2` onto the unit disc (Fong, "Analytical methods for
squaring the disc", 2015), the azimuthal equidistant map of the disc onto
the upper hemisphere, and bilinear sampling of an image at points of the
sphere through both. Used by
:class:`~tg_intrinsic.datasets.SphereDigits` (Harmonic Surface Networks'
"rotated MNIST on a sphere")."""
import math

import torch
import torch.nn.functional as F
from torch import Tensor

from tg_intrinsic.geometry.checks import (check_float_tensor,
                                          check_points)


def _pair(xy: Tensor, name: str) -> Tensor:
    return check_points(xy, name, dim=2, min_points=0)


def square_to_disc(xy: Tensor) -> Tensor:
    r"""The elliptical grid mapping of the square :math:`[-1, 1]^2` onto the
    unit disc. It is

    .. math::
        u = x \sqrt{1 - y^2 / 2}, \qquad v = y \sqrt{1 - x^2 / 2};

    the square's edges go to the circle, its centre lines stay straight.

    Args:
        xy (Tensor): Points of the square :math:`(N, 2)`.

    Returns:
        Points of the disc :math:`(N, 2)`.
    """
    xy = _pair(xy, 'xy')
    if (xy.abs() > 1 + 1e-6).any():
        raise ValueError("'xy' must lie in the square [-1, 1]^2")
    x, y = xy.unbind(1)
    return torch.stack([x * torch.sqrt(1 - 0.5 * y * y),
                        y * torch.sqrt(1 - 0.5 * x * x)], 1)


def disc_to_square(uv: Tensor) -> Tensor:
    r"""The inverse of :func:`square_to_disc`. It is

    .. math::
        x = \tfrac12 \sqrt{2 + u^2 - v^2 + 2\sqrt2\, u}
          - \tfrac12 \sqrt{2 + u^2 - v^2 - 2\sqrt2\, u},

    and :math:`y` likewise with :math:`u, v` swapped. Points outside the
    unit disc are refused.

    Args:
        uv (Tensor): Points of the unit disc :math:`(N, 2)`.

    Returns:
        Points of the square :math:`(N, 2)`.
    """
    uv = _pair(uv, 'uv')
    if (uv.square().sum(1) > 1 + 1e-6).any():
        raise ValueError("'uv' must lie in the unit disc")
    u, v = uv.unbind(1)
    r2 = 2 * math.sqrt(2)

    def half(a, b):  # clamped: rounding makes the radicand -1e-16 on edges
        t = 2 + a * a - b * b
        return 0.5 * (torch.sqrt((t + r2 * a).clamp_min(0))
                      - torch.sqrt((t - r2 * a).clamp_min(0)))

    return torch.stack([half(u, v), half(v, u)], 1).clamp(-1, 1)


def disc_to_hemisphere(uv: Tensor) -> Tensor:
    r"""The azimuthal equidistant map of the unit disc onto the upper unit
    hemisphere: the disc's centre goes to the pole :math:`(0, 0, 1)`, its
    radius :math:`\rho` to the polar angle :math:`\vartheta = \rho\pi/2`
    (geodesic distances from the pole are kept up to the factor
    :math:`\pi/2`), its circle to the equator. The image of
    :math:`(u, v)` is

    .. math::
        \mathbf{p} = \big(\sin\vartheta\,\tfrac{u}{\rho},\
        \sin\vartheta\,\tfrac{v}{\rho},\ \cos\vartheta\big).

    Args:
        uv (Tensor): Points of the unit disc :math:`(N, 2)`.

    Returns:
        Points of the unit sphere :math:`(N, 3)`.
    """
    uv = _pair(uv, 'uv')
    rho = uv.norm(dim=1)
    if (rho > 1 + 1e-6).any():
        raise ValueError("'uv' must lie in the unit disc")
    theta = 0.5 * math.pi * rho
    # sin(theta) / rho, continuous at the centre (limit pi / 2)
    scale = torch.where(rho > 0, torch.sin(theta) / rho.clamp_min(1e-300),
                        torch.full_like(rho, 0.5 * math.pi))
    return torch.cat([uv * scale[:, None], torch.cos(theta)[:, None]], 1)


def hemisphere_to_disc(pos: Tensor) -> Tensor:
    r"""The inverse of :func:`disc_to_hemisphere`, extended to the whole
    sphere: a point at polar angle :math:`\vartheta` and azimuth
    :math:`\varphi` goes to radius :math:`\rho = 2\vartheta/\pi` (so the
    lower hemisphere lands outside the unit disc, up to radius 2).

    Args:
        pos (Tensor): Points of the unit sphere :math:`(N, 3)` (directions
            are normalised first).

    Returns:
        Points of the plane :math:`(N, 2)`.
    """
    pos = check_points(pos, 'pos', min_points=0)
    length = pos.norm(dim=1)
    if (length == 0).any():
        raise ValueError("'pos' holds the origin, which has no direction")
    pos = pos / length[:, None]
    planar = pos[:, :2].norm(dim=1)
    theta = torch.atan2(planar, pos[:, 2])
    rho = theta * (2 / math.pi)
    scale = torch.where(planar > 0, rho / planar.clamp_min(1e-300),
                        torch.zeros_like(rho))
    return pos[:, :2] * scale[:, None]


def sample_image_on_sphere(image: Tensor, pos: Tensor) -> Tensor:
    r"""Values of an image at points of the unit sphere, the image laid on
    the upper hemisphere by :func:`square_to_disc` and
    :func:`disc_to_hemisphere`: a point :math:`\mathbf{p}` reads the image
    at :math:`(x, y) = \mathrm{disc\_to\_square}(\mathrm{hemisphere\_to\_
    disc}(\mathbf{p}))` by bilinear interpolation of the image framed by
    a border of zero pixels, whose centres lie on the square's edges: the
    signal is continuous on the whole sphere, zero on the equator and on
    the lower hemisphere. Pixel :math:`(r, c)` of an :math:`H \times W`
    image has its centre at

    .. math::
        x = \frac{2(c + 1)}{W + 1} - 1, \qquad y = 1 - \frac{2(r + 1)}{H + 1}

    (row 0 at the top, :math:`y` up).

    Args:
        image (Tensor): Image :math:`(H, W)` or channels :math:`(C, H, W)`.
        pos (Tensor): Points of the unit sphere :math:`(N, 3)`.

    Returns:
        Values :math:`(N)` or :math:`(N, C)`.
    """
    if getattr(image, 'dim', lambda: 0)() not in (2, 3) \
            or min(image.shape[-2:]) < 1:
        raise ValueError(f"'image' must be an [H, W] or [C, H, W] tensor, "
                         f"got {getattr(image, 'shape', type(image))}")
    check_float_tensor(image, 'image', image.shape)
    uv = hemisphere_to_disc(pos)
    inside = uv.square().sum(1) <= 1
    xy = disc_to_square(torch.where(inside[:, None], uv,
                                    torch.zeros_like(uv)))
    # grid_sample: x right, y down, -1/+1 the centres of the zero border
    grid = torch.stack([xy[:, 0], -xy[:, 1]], 1).to(image.dtype)
    channels = F.pad(image if image.dim() == 3 else image[None],
                     (1, 1, 1, 1))
    out = F.grid_sample(channels[None], grid.view(1, 1, -1, 2),
                        mode='bilinear', padding_mode='zeros',
                        align_corners=True)[0, :, 0].t()
    out = out * inside[:, None].to(out.dtype)
    return out if image.dim() == 3 else out[:, 0]


__all__ = ['square_to_disc', 'disc_to_square', 'disc_to_hemisphere',
           'hemisphere_to_disc', 'sample_image_on_sphere']
