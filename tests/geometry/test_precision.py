import pytest
import torch

from tg_intrinsic.geometry.precision import (at_least_float32, complex_from,
                                             full_precision,
                                             refuse_low_precision)


@pytest.mark.parametrize('dtype, expected', [
    (torch.float16, torch.float32), (torch.bfloat16, torch.float32),
    (torch.float32, torch.float32), (torch.float64, torch.float64)])
def test_low_precision_is_raised_to_float32(dtype, expected):
    x = torch.linspace(-1, 1, 5).to(dtype)
    assert at_least_float32(x).dtype == expected
    z = complex_from(x, 2 * x)
    assert z.dtype == (torch.complex128 if expected == torch.float64
                       else torch.complex64)
    assert torch.equal(z.real, x.to(z.real.dtype))
    assert torch.equal(complex_from(x).imag, torch.zeros_like(z.imag))


def test_full_precision_turns_autocast_off():
    a = torch.randn(4, 4)
    with torch.autocast('cpu', dtype=torch.bfloat16):
        assert (a @ a).dtype == torch.bfloat16
        with full_precision('cpu'):
            assert (a @ a).dtype == torch.float32


def test_refusal_names_the_layer_and_the_way_out():
    refuse_low_precision(torch.zeros(2), 'weights', 'Layer')  # float32: ok
    with pytest.raises(ValueError, match=r'Layer got weights in '
                       r'torch.bfloat16.*torch.autocast'):
        refuse_low_precision(torch.zeros(2, dtype=torch.bfloat16), 'weights',
                             'Layer')
