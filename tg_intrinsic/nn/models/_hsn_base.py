from typing import (Dict, Iterable, List, NamedTuple, Optional, Sequence,
                    Tuple)

import torch
from torch import Tensor
from torch_geometric.data import Data

from tg_intrinsic.geometry.checks import (check_channels, check_choice,
                                          check_positive_int)
from tg_intrinsic.geometry.precision import complex_from, full_precision
from tg_intrinsic.nn.harmonic_resnet_block import (COMPLEX_NORMS,
                                                   DEFAULT_COMPLEX_NORM,
                                                   harmonic_operators,
                                                   norm_repr)
from tg_intrinsic.nn.models._batches import graph_batch
from tg_intrinsic.surface_attributes import check_operator_graph


class HSNBase(torch.nn.Module):
    """What every HSN model shares: its validated sizes, the lifting
    linear layer to the first width, the output bias and the repr; a model
    adds its blocks and :meth:`reset_parameters` of them."""
    def __init__(self, in_channels: int, num_classes: int,
                 channels: Sequence[int], max_order: int, rings: int,
                 norm: Optional[str] = DEFAULT_COMPLEX_NORM):
        super().__init__()
        self.in_channels = check_positive_int(in_channels, 'in_channels')
        self.num_classes = check_positive_int(num_classes, 'num_classes')
        self.channels = tuple(check_channels(channels, 'channels',
                                             length=2))
        self.max_order = max_order
        self.rings = rings
        self.norm = check_choice(norm, 'norm', COMPLEX_NORMS)
        self.lin = torch.nn.Linear(in_channels, self.channels[0])
        self.bias = torch.nn.Parameter(torch.zeros(num_classes))

    def reset_parameters(self):
        self.lin.reset_parameters()
        torch.nn.init.zeros_(self.bias)

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({self.in_channels}, '
                f'{self.num_classes}, channels={self.channels}, '
                f'max_order={self.max_order}, rings={self.rings}'
                + norm_repr(self.norm) + ')')


def level_key(name: str, level: int) -> str:
    return name if level == 0 else f'{name}_{level}'


def level_operators(data: Data, level: int, num_nodes: int,
                    pairs: Iterable[Tuple[int, int]]) -> Dict:
    """The harmonic operators of one level of a (batched) data object,
    built once per forward and shared by the level's layers."""
    needed = ('edge_index', 'harmonic', 'transport')
    missing = [level_key(k, level) for k in needed
               if getattr(data, level_key(k, level), None) is None]
    if missing:
        raise ValueError(f"the data lacks {missing}; build it with LogMap, "
                         f"ParallelTransport, MultiscaleSupports and "
                         f"HarmonicPrecompute (see HSNClassification)")
    if level == 0:  # PyG's edge transforms act on level 0 only
        check_operator_graph(data, 'logmap, transport, harmonic', 'LogMap')
    return harmonic_operators(
        data[level_key('edge_index', level)],
        data[level_key('harmonic', level)],
        data[level_key('transport', level)], num_nodes, pairs)


def level_batch(data: Data, level: int, size: int, like: Tensor
                ) -> Tuple[Tensor, int]:
    """The shape index of every point of level ``level`` (``size`` points)
    and the number of shapes (:func:`graph_batch` of level 0, ``like``
    its features)."""
    batch, shapes = graph_batch(data, like)
    if level == 0:
        return batch, shapes
    if hasattr(data, 'level_batch'):
        return data.level_batch(level), shapes
    return torch.zeros(size, dtype=torch.long, device=like.device), shapes


def pooling(data: Data, level: int) -> Tuple[Tensor, Tensor, int]:
    """``cluster_l``, ``pool_transport_l`` and the size of level ``l``."""
    for key in (f'cluster_{level}', f'pool_transport_{level}'):
        if getattr(data, key, None) is None:
            raise ValueError(f"the data lacks '{key}'; build the pooling "
                             f"levels with MultiscaleSupports")
    size = data.level_size(level) if hasattr(data, 'level_size') \
        else data[f'pos_{level}'].size(0)
    return data[f'cluster_{level}'], data[f'pool_transport_{level}'], size


class Level(NamedTuple):
    """What the layers of one level read: the harmonic operators by order
    pair, the shape of every point, the point count, and (from level 1)
    the pooling from the level above, ``cluster_l`` and
    ``pool_transport_l``."""
    operators: Dict
    batch: Tensor
    size: int
    cluster: Optional[Tensor]
    angle: Optional[Tensor]


@torch.compiler.disable
def prepare_levels(data: Data, x: Tensor, pairs: Sequence[Sequence[Tuple]],
                   operators: Optional[List[Dict]] = None
                   ) -> Tuple[List[Level], int]:
    """Every level's :class:`Level` (``pairs[l]``: the order pairs of level
    ``l``'s operators, or ``operators[l]`` built before) and the number of
    shapes. Always eager: the data is validated and the operators built
    here, once per forward, so that ``torch.compile`` traces only the
    layers (one graph break)."""
    if operators is not None and len(operators) != len(pairs):
        raise ValueError(f"'operators' must hold one dict per level "
                         f"({len(pairs)}), got {len(operators)}")
    levels = []
    shapes = 1
    for level, level_pairs in enumerate(pairs):
        if level == 0:
            size, cluster, angle = x.size(0), None, None
        else:
            cluster, angle, size = pooling(data, level)
        batch, shapes = level_batch(data, level, size, x)
        if operators is None:
            with full_precision(x.device.type):
                ops = level_operators(data, level, size, level_pairs)
        else:
            ops = operators[level]
        levels.append(Level(ops, batch, size, cluster, angle))
    return levels, shapes


def input_features(data: Data, in_channels: int) -> Tensor:
    """``data.x``, else ``data.pos``, checked against the model's width."""
    x = getattr(data, 'x', None)
    x = data.pos if x is None else x
    if x.size(-1) != in_channels:
        raise ValueError(f"the model expects {in_channels} input channels, "
                         f"data.x (or data.pos) has {x.size(-1)}")
    return x


def lift(x: Tensor) -> Tensor:
    """Real ``[N, C]`` features as the complex stream 0 ``[N, 1, C]``."""
    return complex_from(x).unsqueeze(1)


def invariant(z: Tensor) -> Tensor:
    """Gauge-invariant read-out: magnitudes summed over the streams."""
    return z.abs().sum(dim=1)
