r"""Lens distortion of photographs: OpenCV's radial-tangential model (the
Brown-Conrady model of COLMAP's SIMPLE_RADIAL, RADIAL and OPENCV cameras
and of nerfstudio's ``k1 k2 p1 p2``), and undistorting a photograph into
the pinhole camera that the rest of the library projects with.

A camera point :math:`(x_c, y_c, z_c)` has normalised coordinates
:math:`x = x_c / z_c`, :math:`y = y_c / z_c`, :math:`r^2 = x^2 + y^2`, and
the lens moves it to

.. math::
    x' = x (1 + k_1 r^2 + k_2 r^4) + 2 p_1 x y + p_2 (r^2 + 2 x^2), \quad
    y' = y (1 + k_1 r^2 + k_2 r^4) + p_1 (r^2 + 2 y^2) + 2 p_2 x y,

which :math:`K` maps to pixels. Pixel centres are at half-integers, as in
:mod:`tg_intrinsic.geometry.appearance.cameras`.
"""
import torch
from torch import Tensor

from .cameras import sample_images

__all__ = ['distort', 'undistort_image']


def _coefficients(distortion, like: Tensor) -> Tensor:
    distortion = torch.as_tensor(distortion, dtype=like.dtype,
                                 device=like.device)
    if distortion.shape != (4, ):
        raise ValueError(f"'distortion' must hold the 4 coefficients (k1, "
                         f"k2, p1, p2), got shape {list(distortion.shape)}")
    if not bool(torch.isfinite(distortion).all()):
        raise ValueError("'distortion' holds NaN or infinite coefficients")
    return distortion


def distort(xy: Tensor, distortion) -> Tensor:
    r"""Moves normalised image coordinates :math:`(\ldots, 2)` as the lens
    does (the formula of the module).

    Args:
        xy (torch.Tensor): :math:`(x, y) = (x_c / z_c, y_c / z_c)`.
        distortion (sequence or torch.Tensor): :math:`(k_1, k_2, p_1, p_2)`.

    Returns:
        :math:`(x', y')`, same shape, dtype and device as :obj:`xy`.
    """
    k1, k2, p1, p2 = _coefficients(distortion, xy).unbind()
    x, y = xy[..., 0], xy[..., 1]
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2 * r2
    return torch.stack([
        x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
        y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y], -1)


def undistort_image(image: Tensor, intrinsics: Tensor, distortion) -> Tensor:
    r"""The photograph a pinhole camera with the same :math:`K` would take:
    every output pixel centre is unprojected with :math:`K^{-1}`, moved by
    :func:`distort` and sampled bilinearly from :obj:`image` (what OpenCV's
    ``initUndistortRectifyMap`` + ``remap`` do). Pixels whose source lies
    outside the photograph are NaN (missing), as are those next to a NaN.
    Runs on the image's device.

    Args:
        image (torch.Tensor): :math:`(H, W, C)` floating point.
        intrinsics (torch.Tensor): :math:`K` :math:`(3, 3)` of the
            photograph (skew allowed).
        distortion (sequence or torch.Tensor): :math:`(k_1, k_2, p_1,
            p_2)`; all zero returns :obj:`image` unchanged.

    Returns:
        :math:`(H, W, C)`, the image's dtype.
    """
    if image.dim() != 3 or not image.is_floating_point():
        raise ValueError(f"'image' must be a floating-point [H, W, C] "
                         f"tensor, got {image.dtype} {list(image.shape)}")
    height, width = image.shape[:2]
    work = torch.float64
    K = torch.as_tensor(intrinsics, dtype=work, device=image.device)
    coefficients = _coefficients(distortion, K)
    if not bool(coefficients.any()):
        return image
    fx, skew, cx, fy, cy = K[0, 0], K[0, 1], K[0, 2], K[1, 1], K[1, 2]
    row = torch.arange(height, dtype=work, device=image.device) + 0.5
    col = torch.arange(width, dtype=work, device=image.device) + 0.5
    v, u = torch.meshgrid(row, col, indexing='ij')
    y = (v - cy) / fy
    x = (u - cx - skew * y) / fx
    moved = distort(torch.stack([x, y], -1), coefficients)
    source = torch.stack([fx * moved[..., 0] + skew * moved[..., 1] + cx,
                          fy * moved[..., 1] + cy], -1)
    value, nan = sample_images(image.unsqueeze(0),
                               source.reshape(1, -1, 2).to(image.dtype))
    outside = (source[..., 0] < 0) | (source[..., 0] > width) | \
        (source[..., 1] < 0) | (source[..., 1] > height)
    missing = nan.view(height, width) | outside
    value = value.view(height, width, -1)
    return torch.where(missing.unsqueeze(-1),
                       torch.full_like(value, float('nan')), value)
