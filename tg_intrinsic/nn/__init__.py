r"""Layers: :class:`DeltaConv` and vector-feature building blocks."""
from .vector_linear import VectorLinear
from .vector_nonlin import VectorNonLin
from .vector_mlp import VectorMLP
from .delta_conv import DeltaConv
from . import models

__all__ = ['VectorLinear', 'VectorNonLin', 'VectorMLP', 'DeltaConv', 'models']
