from torch_geometric.data import Data
from torch_geometric.data.datapipes import functional_transform

from tg_intrinsic.geometry import log_map
from tg_intrinsic.geometry.geodesics.logmap import METHODS
from tg_intrinsic.surface_attributes import (check_operator_graph,
                                             resolve_frames)
from tg_intrinsic.transforms._batching import GraphTransform


@functional_transform('parallel_transport')
class ParallelTransport(GraphTransform):
    r"""Writes the parallel-transport angle of every edge of the disc graph
    (functional name: :obj:`parallel_transport`). Transporting
    :math:`e_u(j)` along the shortest geodesic from :math:`p_j` to
    :math:`p_i` gives

    .. math::
        P_{j \to i}\, e_u(j) = \cos\phi_{ji}\, e_u(i) +
        \sin\phi_{ji}\, e_v(i),

    so an order-:math:`M` feature moves from :math:`j` to :math:`i` as
    :math:`z \mapsto e^{iM\phi_{ji}} z`. Runs on the ``edge_index`` of
    :class:`LogMap` (``[0]`` neighbour :math:`j`, ``[1]`` centre
    :math:`i`) and overwrites a ``transport`` computed there, so the two
    may use different methods. ``data.frame`` is used as given if present.

    Args:
        method (str, optional): :obj:`'fast'` (the rotation that aligns the
            normals) or :obj:`'vector_heat'`. (default: :obj:`'fast'`)

    Shapes:
        - **output:** ``transport`` :math:`(E)`
    """
    def __init__(self, method: str = 'fast'):
        if method not in METHODS:
            raise ValueError(f"'method' must be one of {METHODS}, got "
                             f"{method!r}")
        self.method = method

    def forward(self, data: Data) -> Data:
        if getattr(data, 'logmap', None) is None:
            raise ValueError("ParallelTransport runs on the disc graph of "
                             "LogMap; apply LogMap(radius) first")
        check_operator_graph(data, 'logmap', 'LogMap')
        data = data.clone()
        frame = resolve_frames(data)
        _, _, phi = log_map(data.pos, data.edge_index, frame,
                            getattr(data, 'face', None), method=self.method)
        data.transport = phi
        data.frame = frame
        return data

    def __repr__(self) -> str:
        return f'{self.__class__.__name__}(method={self.method!r})'
