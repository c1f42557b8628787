from typing import Sequence

import torch
from torch import Tensor
from torch_geometric.data import Data
from torch_geometric.nn import global_mean_pool

from tg_intrinsic.geometry.checks import check_positive_int, compiling
from tg_intrinsic.nn.delta_conv import scalar_mlp
from tg_intrinsic.pool.global_max_pool import (dense_max_pool,
                                               global_max_pool)
from tg_intrinsic.nn.models._batches import graph_batch
from tg_intrinsic.nn.models._deltanet_base import DeltaNetBase
from tg_intrinsic.nn.models._embedding_pool import can_fuse, embed_and_pool


class DeltaNetClassification(torch.nn.Module):
    r"""DeltaNet for point cloud classification, from the `"DeltaConv"
    <https://arxiv.org/abs/2111.08799>`_ paper: :class:`DeltaConv` layers in
    DGCNN's layout (static k-nn graph), the concatenated layer outputs
    embedded to 1024 channels, global max and mean pooling, and an MLP head
    (2048 - 512 - 256 - :math:`C`, dropout 0.5). It computes

    .. math::
        \hat{y} = \mathrm{MLP}\Big(\big[\max_i \mathbf{e}_i \,\|\,
        \operatorname{mean}_i \mathbf{e}_i\big]\Big), \qquad
        \mathbf{e}_i = \mathrm{MLP}\big([\mathbf{x}^{(1)}_i \| \dots \|
        \mathbf{x}^{(L)}_i]\big).

    The operators come from the batch (:class:`~tg_intrinsic.transforms.
    MLSOperators`) when present, otherwise they are built once per forward
    on the batch's device and shared by all layers.

    Args:
        in_channels (int): Input scalars per point (``data.x``, or
            ``data.pos`` when there is no ``x``).
        num_classes (int): Number of classes.
        conv_channels (Sequence[int], optional): Channels of the DeltaConv
            layers. (default: :obj:`(64, 64, 128, 256)`)
        depth (int, optional): Depth of the MLPs inside every layer.
            (default: :obj:`1`)
        k (int, optional): Neighbours of the operators. (default: :obj:`20`)
        regularizer (float, optional): MLS regulariser. (default:
            :obj:`1e-3`)
        kernel_width (float, optional): MLS kernel width. (default:
            :obj:`1.0`)
        embedding_size (int, optional): Channels of the global embedding.
            (default: :obj:`1024`)
        dropout (float, optional): Dropout in the head. (default: :obj:`0.5`)
        vector_stream (bool, optional): :obj:`False` drops the vector stream
            (the paper's ablation). (default: :obj:`True`)

    Shapes:
        - **input:** a (batched) :class:`~torch_geometric.data.Data` with
          ``pos`` :math:`(N, 3)` and optionally ``x``, ``normal``, ``batch``
        - **output:** logits :math:`(B, C)`
    """
    def __init__(self, in_channels: int, num_classes: int,
                 conv_channels: Sequence[int] = (64, 64, 128, 256),
                 depth: int = 1, k: int = 20, regularizer: float = 1e-3,
                 kernel_width: float = 1.0, embedding_size: int = 1024,
                 dropout: float = 0.5, vector_stream: bool = True):
        super().__init__()
        # torch builds zero-width layers without a word; DeltaNetBase
        # checks in_channels, conv_channels, depth and k.
        check_positive_int(num_classes, 'num_classes')
        check_positive_int(embedding_size, 'embedding_size')
        self.in_channels = in_channels
        self.num_classes = num_classes
        self.conv_channels = tuple(conv_channels)
        self.vector_stream = vector_stream
        self.base = DeltaNetBase(in_channels, conv_channels, depth, k,
                                 regularizer, kernel_width,
                                 vector_stream=vector_stream)
        self.embedding = scalar_mlp([sum(conv_channels), embedding_size])
        self.head = torch.nn.Sequential(
            scalar_mlp([2 * embedding_size, 512]), torch.nn.Dropout(dropout),
            scalar_mlp([512, 256]), torch.nn.Dropout(dropout),
            torch.nn.Linear(256, num_classes))

    def reset_parameters(self):
        self.base.reset_parameters()
        self.embedding.reset_parameters()
        for module in self.head:
            if hasattr(module, 'reset_parameters'):
                module.reset_parameters()

    def forward(self, data: Data) -> Tensor:
        r"""Classifies every example of a (batched) point cloud.

        Args:
            data (torch_geometric.data.Data): The points, with ``pos``
                :math:`(N, 3)` and optionally ``x`` (the input scalars,
                ``pos`` otherwise), ``normal`` or ``frame`` (the tangent
                frames, estimated otherwise), ``batch`` :math:`(N)`, and the
                operators of :class:`~tg_intrinsic.transforms.MLSOperators`
                (built here otherwise).

        Returns:
            torch.Tensor: Logits :math:`(B, C)`, one row per example.
        """
        x = torch.cat(self.base(data), dim=1)
        batch, size = graph_batch(data, x)
        count = x.size(0) // size
        # the fused CPU sweep is numba: compiled graphs take the plain path
        if not compiling() and x.size(0) == size * count and bool(
                (torch.bincount(batch, minlength=size) == count).all()):
            pooled = self._embed_and_pool_equal(x, size, count)
        else:
            x = self.embedding(x)
            pooled = torch.cat([global_max_pool(x, batch, size),
                                global_mean_pool(x, batch, size)], dim=1)
        return self.head(pooled)

    def _embed_and_pool_equal(self, x: Tensor, size: int, count: int
                              ) -> Tensor:
        # The same layers as self.embedding (linear, batch norm, LeakyReLU)
        # with channels first, [C, N]: torch's CPU batch norm is ~5x faster
        # on [1, C, N] than on [N, C] for 1024 channels, and pooling then
        # reduces contiguous memory. Needs equally many points per example.
        lin, norm = self.embedding.lins[0], self.embedding.norms[0]
        if can_fuse(x, lin, norm.module):   # CPU: one fused operation
            return embed_and_pool(x, lin, norm.module,
                                  self.embedding.act.negative_slope, size)
        h = torch.mm(lin.weight, x.t())                       # [C, N]
        h = norm.module(h.unsqueeze(0)).squeeze(0)
        h = self.embedding.act(h).view(h.size(0), size, count)
        maximum = dense_max_pool(h.permute(1, 2, 0))              # [B, C]
        return torch.cat([maximum, h.mean(dim=-1).t()], dim=1)

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({self.in_channels}, '
                f'{self.num_classes}, conv_channels={self.conv_channels}, '
                f'vector_stream={self.vector_stream})')
