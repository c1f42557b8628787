"""looks_clipped: 8-bit and clipped images are told from real HDR radiance
(also re-exported as ``tg_intrinsic.io.looks_clipped``)."""
import numpy as np
import torch

from tg_intrinsic.geometry.appearance.dynamic_range import looks_clipped
from tg_intrinsic.geometry.appearance.envmap import sun_sky_envmap
from tg_intrinsic.io import looks_clipped as io_looks_clipped


def hdr_image(seed, shape):
    """Five decades of radiance with colour, some exact zeros."""
    rng = np.random.default_rng(seed)
    image = np.exp(rng.normal(0, 2.5, shape + (3, ))).astype(np.float32)
    image[0, :3] = 0
    return image


def test_looks_clipped():
    rng = np.random.default_rng(4)
    eight_bit = rng.integers(0, 256, (32, 64, 3)) / 255.0
    assert looks_clipped(eight_bit)
    assert looks_clipped(torch.from_numpy(eight_bit).float())
    assert looks_clipped(rng.integers(0, 256, (8, 8, 3)).astype(np.uint8))
    # an HDR image scaled and clipped at 1: highlights pile up
    clipped = np.minimum(hdr_image(5, (32, 64)) / 4, 1.0)
    assert looks_clipped(clipped)
    assert not looks_clipped(sun_sky_envmap(64, 128))
    assert not looks_clipped(hdr_image(6, (32, 64)))
    # floats in [0, 1] with a single brightest pixel are not clipped
    assert not looks_clipped(rng.uniform(0, 1, (32, 64, 3)))
    # NaN pixels (masked) are ignored; views x H x W x 3 is fine
    views = torch.from_numpy(eight_bit).repeat(2, 1, 1, 1)
    views[0, :4] = float('nan')
    assert looks_clipped(views)
    assert not looks_clipped(np.zeros((4, 4, 3)))


def test_the_io_name_is_the_same_function():
    assert io_looks_clipped is looks_clipped
