r"""Layers: :class:`DeltaConv`, :class:`HarmonicConv` and their vector and
complex building blocks, the learned diffusion :class:`GravoDiffusion`
solved by Gravo MG, and the frequency-domain SVBRDF model
:class:`FrequencySVBRDF`."""
from .vector_linear import VectorLinear
from .vector_nonlin import VectorNonLin
from .vector_mlp import VectorMLP
from .delta_conv import DeltaConv
from .complex_relu import ComplexReLU
from .complex_linear import ComplexLinear
from .complex_batch_norm import ComplexBatchNorm
from .complex_instance_norm import ComplexInstanceNorm
from .harmonic_conv import HarmonicConv
from .harmonic_resnet_block import HarmonicResNetBlock
from .gravo_diffusion import GravoDiffusion
from .frequency_svbrdf import FrequencySVBRDF
from .svbrdf_result import SVBRDFResult
from .sync_complex_batch_norm import SyncComplexBatchNorm
from .sync_batch_norm import SyncBatchNorm, convert_sync_batch_norm
from .recalibrate_batch_norm import recalibrate_batch_norm
from . import models

__all__ = ['VectorLinear', 'VectorNonLin', 'VectorMLP', 'DeltaConv',
           'ComplexReLU', 'ComplexLinear', 'ComplexBatchNorm',
           'ComplexInstanceNorm', 'HarmonicConv', 'HarmonicResNetBlock',
           'GravoDiffusion', 'FrequencySVBRDF', 'SVBRDFResult', 'models',
           'SyncBatchNorm', 'SyncComplexBatchNorm', 'convert_sync_batch_norm',
           'recalibrate_batch_norm']
