from typing import List, Optional, Sequence, Tuple

import torch
from torch import Tensor
from torch_geometric.data import Data

from tg_intrinsic.geometry.checks import (check_channels, check_index,
                                          check_positive_int, check_tensor)
from tg_intrinsic.geometry.pointcloud.mls import build_mls_operators
from tg_intrinsic.geometry.pointcloud.operators import SurfaceOperators
from tg_intrinsic.geometry.precision import full_precision
from tg_intrinsic.nn.delta_conv import DeltaConv
from tg_intrinsic.surface_attributes import (check_mls_parameters,
                                             check_operator_graph,
                                             resolve_frames)


@torch.compiler.disable
def operators_of(data: Data, k: int, regularizer: float, kernel_width: float
                 ) -> Tuple[Tensor, SurfaceOperators]:
    """The graph and MLS operators of a (batched) ``data``: the ones stored
    by :class:`~tg_intrinsic.transforms.MLSOperators` when present,
    otherwise built once here on the data's device. Always eager and in
    full precision (autocast off): the data is validated here, once, and
    ``torch.compile`` traces the layers that use the operators (one graph
    break)."""
    num_nodes = data.pos.size(0)
    if getattr(data, 'grad_weight', None) is not None:
        check_mls_parameters(data, k, regularizer, kernel_width)
        check_operator_graph(data, 'grad_weight, div_weight', 'MLSOperators')
        edge_index = data.edge_index
        grad_weight, div_weight = data.grad_weight, data.div_weight
    else:
        with full_precision(data.pos.device.type):
            edge_index, _, grad_weight, div_weight = build_mls_operators(
                data.pos, k, getattr(data, 'batch', None),
                frame=resolve_frames(data), kernel_width=kernel_width,
                regularizer=regularizer)
    return edge_index, SurfaceOperators(edge_index, grad_weight, div_weight,
                                        num_nodes)


class DeltaNetBase(torch.nn.Module):
    """A stack of :class:`DeltaConv` layers sharing one set of operators
    (DGCNN layout with a static graph); returns every layer's scalars."""
    def __init__(self, in_channels: int, conv_channels: Sequence[int],
                 depth: int = 1, k: int = 20, regularizer: float = 1e-3,
                 kernel_width: float = 1.0, centralize_first: bool = True,
                 vector_stream: bool = True):
        super().__init__()
        check_positive_int(in_channels, 'in_channels')
        conv_channels = check_channels(conv_channels, 'conv_channels')
        check_positive_int(depth, 'depth')
        check_positive_int(k, 'k')
        self.in_channels = in_channels
        self.k = k
        self.regularizer = regularizer
        self.kernel_width = kernel_width
        self.vector_stream = vector_stream
        channels = [in_channels] + list(conv_channels)
        self.convs = torch.nn.ModuleList()
        for layer, (c_in, c_out) in enumerate(zip(channels[:-1],
                                                  channels[1:])):
            last = layer == len(channels) - 2
            self.convs.append(DeltaConv(
                c_in, c_out, depth=depth,
                centralized=centralize_first and layer == 0,
                vector=vector_stream and not last,
                vector_input=vector_stream))

    def reset_parameters(self):
        for conv in self.convs:
            conv.reset_parameters()

    def input_features(self, data: Data) -> Tensor:
        x = getattr(data, 'x', None)
        x = data.pos if x is None else x
        if x.size(-1) != self.in_channels:
            raise ValueError(f"the model expects {self.in_channels} input "
                             f"channels but data.x (or data.pos) has "
                             f"{x.size(-1)}")
        return x

    def forward(self, data: Data) -> List[Tensor]:
        x = self.input_features(data)
        edge_index, operators = operators_of(data, self.k, self.regularizer,
                                             self.kernel_width)
        # The vector stream starts as the gradient of the input scalars.
        v: Optional[Tensor] = operators.grad(x) if self.vector_stream \
            else None
        out = []
        for conv in self.convs:
            x, v = conv(x, v, edge_index, operators if self.vector_stream
                        else None)
            out.append(x)
        return out


def category_one_hot(category: Optional[Tensor], num_categories: int,
                     size: int, x: Tensor) -> Tensor:
    """``data.category`` of a segmentation model built with
    ``num_categories``: indices :math:`(B)` or one-hot :math:`(B, n)`, as
    one-hot; one_hot and the embedding fail obscurely on wrong indices or
    widths, so both are checked."""
    n = num_categories
    if category is None:
        raise ValueError(f"this model was built with num_categories={n}; "
                         f"it needs 'data.category'")
    category = check_tensor(category, 'data.category')
    if category.dim() == 1 and category.numel() == size:
        category = check_index(category, 'data.category', n, x,
                               what=f'categories (num_categories={n})')
        return torch.nn.functional.one_hot(category, n)
    if tuple(category.shape) != (size, n):
        raise ValueError(f"'data.category' must hold a category index per "
                         f"example [B] = [{size}] or one-hot vectors "
                         f"[B, num_categories] = [{size}, {n}], got "
                         f"{list(category.shape)}")
    return category
