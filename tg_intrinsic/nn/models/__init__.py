r"""Complete networks built from :mod:`tg_intrinsic.nn` layers."""
from .deltanet_classification import DeltaNetClassification
from .deltanet_segmentation import DeltaNetSegmentation

__all__ = ['DeltaNetClassification', 'DeltaNetSegmentation']
