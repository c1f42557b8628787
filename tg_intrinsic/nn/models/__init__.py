r"""Complete networks built from :mod:`tg_intrinsic.nn` layers."""
from .deltanet_classification import DeltaNetClassification
from .deltanet_segmentation import DeltaNetSegmentation
from .delta_u_resnet import DeltaUResNet
from .hsn_classification import HSNClassification
from .hsn_conv_classification import HSNConvClassification
from .hsn_segmentation import HSNSegmentation
from .hsn_u_resnet import HSNUResNet
from .hsn_correspondence import HSNCorrespondence

__all__ = ['DeltaNetClassification', 'DeltaNetSegmentation', 'DeltaUResNet',
           'HSNClassification', 'HSNConvClassification', 'HSNSegmentation',
           'HSNUResNet', 'HSNCorrespondence']
