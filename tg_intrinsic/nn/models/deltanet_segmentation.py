from typing import Optional, Sequence

import torch
from torch import Tensor
from torch_geometric.data import Data

from tg_intrinsic.geometry.checks import check_positive_int
from tg_intrinsic.nn.delta_conv import scalar_mlp
from tg_intrinsic.pool.global_max_pool import global_max_pool
from tg_intrinsic.nn.models._batches import graph_batch
from tg_intrinsic.nn.models._deltanet_base import (DeltaNetBase,
                                                   category_one_hot)


class DeltaNetSegmentation(torch.nn.Module):
    r"""DeltaNet for per-point segmentation, from the `"DeltaConv"
    <https://arxiv.org/abs/2111.08799>`_ paper: :class:`DeltaConv` layers
    (MLP depth 2), a global max-pooled embedding broadcast back to every
    point, optionally an embedding of the object category (``data.category``,
    one-hot, as is usual for ShapeNet parts), and a per-point head
    (256 - 256 - 128 - :math:`C`, dropout 0.5). It computes

    .. math::
        \hat{y}_i = \mathrm{MLP}\big([\max_{i'} \mathbf{e}_{i'} \,\|\,
        \mathbf{c} \,\|\, \mathbf{x}^{(1)}_i \| \dots \|
        \mathbf{x}^{(L)}_i]\big).

    Args:
        in_channels (int): Input scalars per point.
        num_classes (int): Number of part classes.
        conv_channels (Sequence[int], optional): DeltaConv channels.
            (default: :obj:`(64, 128, 256)`)
        depth (int, optional): MLP depth inside every layer.
            (default: :obj:`2`)
        k (int, optional): Neighbours of the operators. (default: :obj:`20`)
        regularizer (float, optional): MLS regulariser.
            (default: :obj:`1e-3`)
        kernel_width (float, optional): MLS kernel width.
            (default: :obj:`1.0`)
        embedding_size (int, optional): Global embedding channels.
            (default: :obj:`1024`)
        num_categories (int, optional): If set, ``data.category`` (one-hot
            :math:`(B, \text{num\_categories})` or indices :math:`(B)`) is
            embedded and appended. (default: :obj:`None`)
        dropout (float, optional): Dropout in the head. (default: :obj:`0.5`)
        vector_stream (bool, optional): :obj:`False` drops the vector stream.
            (default: :obj:`True`)

    Shapes:
        - **input:** a (batched) :class:`~torch_geometric.data.Data`
        - **output:** logits :math:`(N, C)`
    """
    def __init__(self, in_channels: int, num_classes: int,
                 conv_channels: Sequence[int] = (64, 128, 256),
                 depth: int = 2, k: int = 20, regularizer: float = 1e-3,
                 kernel_width: float = 1.0, embedding_size: int = 1024,
                 num_categories: Optional[int] = None, dropout: float = 0.5,
                 vector_stream: bool = True):
        super().__init__()
        # torch builds zero-width layers without a word; DeltaNetBase
        # checks in_channels, conv_channels, depth and k.
        check_positive_int(num_classes, 'num_classes')
        check_positive_int(embedding_size, 'embedding_size')
        if num_categories is not None:
            check_positive_int(num_categories, 'num_categories')
        self.in_channels = in_channels
        self.num_classes = num_classes
        self.conv_channels = tuple(conv_channels)
        self.num_categories = num_categories
        self.vector_stream = vector_stream
        self.base = DeltaNetBase(in_channels, conv_channels, depth, k,
                                 regularizer, kernel_width,
                                 vector_stream=vector_stream)
        self.embedding = scalar_mlp([sum(conv_channels), embedding_size])
        extra = 0
        self.category = None
        if num_categories is not None:
            self.category = scalar_mlp([num_categories, 64])
            extra = 64
        self.head = torch.nn.Sequential(
            scalar_mlp([embedding_size + extra + sum(conv_channels), 256]),
            torch.nn.Dropout(dropout), scalar_mlp([256, 256]),
            torch.nn.Dropout(dropout), torch.nn.Linear(256, 128),
            torch.nn.LeakyReLU(0.2), torch.nn.Linear(128, num_classes))

    def reset_parameters(self):
        self.base.reset_parameters()
        self.embedding.reset_parameters()
        if self.category is not None:
            self.category.reset_parameters()
        for module in self.head:
            if hasattr(module, 'reset_parameters'):
                module.reset_parameters()

    def forward(self, data: Data) -> Tensor:
        r"""Classifies every point of a (batched) point cloud.

        Args:
            data (torch_geometric.data.Data): The points, as for
                :class:`DeltaNetClassification`: ``pos`` :math:`(N, 3)` and
                optionally ``x``, ``normal`` or ``frame``, ``batch``
                :math:`(N)` and the operators of
                :class:`~tg_intrinsic.transforms.MLSOperators`; with
                :obj:`num_categories`, also ``category`` (one-hot
                :math:`(B, \text{num\_categories})` or indices :math:`(B)`).

        Returns:
            torch.Tensor: Logits :math:`(N, C)`, one row per point.
        """
        conv_out = self.base(data)
        x = self.embedding(torch.cat(conv_out, dim=1))
        batch, size = graph_batch(data, x)
        parts = [global_max_pool(x, batch, size)[batch]]
        if self.category is not None:
            category = category_one_hot(getattr(data, 'category', None),
                                        self.num_categories, size, x)
            parts.append(self.category(category.to(x.dtype))[batch])
        return self.head(torch.cat(parts + conv_out, dim=1))

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({self.in_channels}, '
                f'{self.num_classes}, conv_channels={self.conv_channels}, '
                f'num_categories={self.num_categories}, '
                f'vector_stream={self.vector_stream})')
