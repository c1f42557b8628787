r"""Complete networks built from :mod:`tg_intrinsic.nn` layers."""
from .deltanet_classification import DeltaNetClassification
from .deltanet_segmentation import DeltaNetSegmentation
from .hsn_classification import HSNClassification
from .hsn_segmentation import HSNSegmentation
from .hsn_conv_classification import HSNConvClassification

__all__ = ['DeltaNetClassification', 'DeltaNetSegmentation',
           'HSNClassification', 'HSNSegmentation',
           'HSNConvClassification']
