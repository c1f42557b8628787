"""The models ``train`` builds from a protocol's options."""
from typing import Optional

import torch

from tg_intrinsic.training.sources import MODELS


def build_model(name: str, num_classes: int, args,
                num_categories: Optional[int] = None) -> torch.nn.Module:
    """The network of ``args``; DeltaNet segmentation embeds the object
    category when the data have :obj:`num_categories` (ShapeNet-Part)."""
    if name == 'deltanet':
        from tg_intrinsic.nn.models import (DeltaNetClassification,
                                            DeltaNetSegmentation)
        kwargs = dict(conv_channels=args.conv_channels, depth=args.mlp_depth,
                      k=args.k, regularizer=args.regularizer,
                      embedding_size=args.embedding_size,
                      vector_stream=not args.no_vector_stream)
        if getattr(args, 'dropout', None) is not None:
            kwargs['dropout'] = args.dropout
        if args.task == 'classification':
            return DeltaNetClassification(3, num_classes, **kwargs)
        return DeltaNetSegmentation(3, num_classes,
                                    num_categories=num_categories, **kwargs)
    if name == 'hsn':
        from tg_intrinsic.nn.models import (HSNClassification,
                                            HSNSegmentation)
        cls = HSNClassification if args.task == 'classification' \
            else HSNSegmentation
        return cls(3, num_classes, channels=args.hsn_channels,
                   max_order=args.max_order, rings=args.rings,
                   norm=None if args.hsn_norm == 'none' else args.hsn_norm)
    raise ValueError(f"unknown model {name!r}; choose one of {MODELS}")
