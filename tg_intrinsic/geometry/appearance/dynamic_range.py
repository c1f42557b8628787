"""Whether radiance is low-dynamic-range (8-bit or clipped): a test on the
values, used by the readers of images and by the view projection."""
import torch

__all__ = ['looks_clipped']


def looks_clipped(image) -> bool:
    r"""Whether an image looks low-dynamic-range: 8-bit or clipped.

    True when its largest value :math:`M \le 1` and either every value is
    a multiple of :math:`1/255` (an 8-bit image converted to float), or
    at least 1% of the pixels (and at least 4) reach :math:`M` in some
    channel (a pile-up at the sensor's or the format's ceiling). Real HDR
    radiance has neither. NaN pixels (masked) are ignored; an image with
    no positive value is not judged (False).

    Args:
        image (numpy.ndarray or torch.Tensor): Radiance :math:`(\ldots, C)`
            (e.g. :math:`(H, W, 3)` or :math:`(V, H, W, 3)`), any device.
    """
    image = torch.as_tensor(image).detach()
    if image.numel() == 0:
        return False
    if not image.is_floating_point():
        return True  # integer pixels are 8- or 16-bit by construction
    image = image.reshape(-1, image.size(-1)) if image.dim() > 1 \
        else image.reshape(-1, 1)
    masked = torch.isnan(image).any(-1)
    num_valid = image.size(0) - int(masked.sum())
    if num_valid == 0:
        return False
    if num_valid < image.size(0):
        # 0 is on the 1/255 grid and never the (positive) maximum
        image = image.masked_fill(masked[:, None], 0.0)
    largest = float(image.max())
    if not (0 < largest <= 1):
        return False
    scaled = image.double() * 255
    if bool(((scaled - scaled.round()).abs() <= 1e-3).all()):
        return True
    at_max = int((image == image.max()).any(-1).sum())
    return at_max >= max(4, 0.01 * num_valid)
