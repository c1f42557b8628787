"""tg_intrinsic: learning and computing on curved surfaces with intrinsic
geometry, as PyTorch Geometric parts."""
import tg_intrinsic.geometry  # noqa: F401
from tg_intrinsic.data import IntrinsicData

#: The version, defined here only (``setup.py`` reads it).
__version__ = '0.1.0'

__all__ = ['IntrinsicData', '__version__']
