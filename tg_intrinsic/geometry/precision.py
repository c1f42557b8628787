"""Mixed precision, decided once: sparse products, numba sweeps and complex
arithmetic have no half or bfloat16 kernels (and lose too much there), so
the library runs them in float32 whatever ``torch.autocast`` or
``model.half()`` chose for the dense layers around them."""
import torch
from torch import Tensor

#: The dtypes that are raised to float32 before sparse or complex maths.
LOW_PRECISION = (torch.float16, torch.bfloat16)


def at_least_float32(x: Tensor) -> Tensor:
    """``x`` in float32 if it is half or bfloat16, else unchanged."""
    return x.float() if x.dtype in LOW_PRECISION else x


def complex_from(real: Tensor, imag: Tensor = None) -> Tensor:
    """``real + i imag`` (``imag`` 0 if :obj:`None`), in complex64 at least:
    there is no complex bfloat16, and complex32 lacks most kernels."""
    real = at_least_float32(real)
    imag = torch.zeros_like(real) if imag is None else at_least_float32(imag)
    return torch.complex(real, imag)


def refuse_low_precision(value: Tensor, what: str, owner: str):
    """Complex maths cannot run on half or bfloat16 tensors: ``owner``
    (a layer) refuses ``value`` (``what`` it is) in those dtypes."""
    if value.dtype in LOW_PRECISION:
        raise ValueError(
            f"{owner} got {what} in {value.dtype}, but its complex maths has "
            f"no half or bfloat16 kernels: keep the model and data in "
            f"float32 and use torch.autocast for mixed precision (train "
            f"--precision bf16-mixed), which runs it in float32 inside")


def full_precision(device_type: str):
    """A context in which ``torch.autocast`` does not lower operations."""
    return torch.autocast(device_type, enabled=False)


__all__ = ['LOW_PRECISION', 'at_least_float32', 'complex_from',
           'refuse_low_precision', 'full_precision']
