from typing import Optional

import torch
from torch_geometric.data import Data
from torch_geometric.data.datapipes import functional_transform

from tg_intrinsic.geometry.checks import (check_positive_float,
                                          check_positive_int)
from tg_intrinsic.geometry import (geodesic_neighbourhoods, log_map,
                                   vertex_area_weights)
from tg_intrinsic.geometry.geodesics.logmap import (MAX_DISC_MEMORY, METHODS,
                                                    hsn_bytes_per_edge)
from tg_intrinsic.surface_attributes import (record_operator_graph,
                                             resolve_frames)
from tg_intrinsic.transforms._batching import GraphTransform


@functional_transform('log_map')
class LogMap(GraphTransform):
    r"""Builds geodesic discs and the log map of every neighbour in the
    tangent frame of its centre, for Harmonic Surface Networks (functional
    name: :obj:`log_map`). It computes

    .. math::
        \mathcal{N}(i) = \{j : d(p_i, p_j) < \epsilon\}, \qquad
        \log_i(p_j) = r_{ij} (\cos\theta_{ij}\, e_u(i) +
        \sin\theta_{ij}\, e_v(i)).

    Writes ``edge_index`` (the disc graph: ``[0]`` neighbour :math:`j`,
    ``[1]`` centre :math:`i`, self-loops included), ``logmap``
    :math:`(r_{ij}, \theta_{ij})` per edge, ``area`` (integration weight of
    every point: a third of the incident triangle areas, or a tangent-plane
    Voronoi area on point clouds), ``logmap_radius`` and ``frame``. With
    :obj:`transport=True` it also writes ``transport``, the angle
    :math:`\phi_{ji}` of :class:`ParallelTransport`, from the same solve.
    Frames are found by :func:`~tg_intrinsic.surface_attributes.
    resolve_frames`: ``data.frame`` as given, else from ``data.normal``,
    else vertex normals of a mesh, else estimated normals of a point cloud.

    Args:
        radius (float): Disc radius :math:`\epsilon` (0.2 on unit-area
            meshes in the paper).
        method (str, optional): :obj:`'fast'` (vectorised torch: tangent
            projection rescaled to arc length, any device) or
            :obj:`'vector_heat'` (the Vector Heat Method's log map and
            transport, as the original computes them with geometry-central,
            solved for all centres at once; point clouds need potpourri3d).
            (default: :obj:`'fast'`)
        max_neighbors (int, optional): Keep the nearest this many points of
            every disc. (default: :obj:`None`)
        transport (bool, optional): Also write ``transport``.
            (default: :obj:`True`)
        max_memory (float, optional): Most bytes that the per-edge data of
            the Harmonic Surface Network precomputation may take (the disc
            graph, log map, transport, harmonic terms with 6 rings and
            orders 0 and 1, and the coarser level, estimated as :math:`E`
            times :func:`~tg_intrinsic.geometry.geodesics.logmap.hsn_bytes_per_edge`,
            155 bytes in float32). The number of edges :math:`E` is
            estimated before any heavy work; above the limit a
            :class:`ValueError` says what would fit (a smaller radius, fewer
            points with :class:`Decimate` or :class:`FarthestPointResample`,
            or :obj:`max_neighbors`), above a quarter of it a warning is
            issued. :obj:`None` disables the check. (default: 2 GiB,
            :data:`~tg_intrinsic.geometry.geodesics.logmap.MAX_DISC_MEMORY`)

    Shapes:
        - **input:** ``pos`` :math:`(N, 3)` and ``face`` :math:`(3, F)`, or
          a point cloud (``normal`` / ``frame`` optional)
        - **output:** ``edge_index`` :math:`(2, E)`, ``logmap``
          :math:`(E, 2)`, ``transport`` :math:`(E)`, ``area`` :math:`(N)`,
          ``frame`` :math:`(N, 3, 3)`
    """
    def __init__(self, radius: float, method: str = 'fast',
                 max_neighbors: Optional[int] = None, transport: bool = True,
                 max_memory: Optional[float] = MAX_DISC_MEMORY):
        if method not in METHODS:
            raise ValueError(f"'method' must be one of {METHODS}, got "
                             f"{method!r}")
        self.radius = check_positive_float(radius, 'radius')
        self.method = method
        self.max_neighbors = (None if max_neighbors is None else
                              check_positive_int(max_neighbors,
                                                 'max_neighbors'))
        self.transport = transport
        if max_memory is not None and not max_memory > 0:
            raise ValueError(f"'max_memory' must be a positive number of "
                             f"bytes or None, got {max_memory!r}")
        self.max_memory = max_memory

    def forward(self, data: Data) -> Data:
        data = data.clone()
        face = getattr(data, 'face', None)
        frame = resolve_frames(data)
        edge_index, _ = geodesic_neighbourhoods(
            data.pos, self.radius, face=face, normal=frame[:, 2],
            max_neighbors=self.max_neighbors, max_memory=self.max_memory,
            bytes_per_edge=hsn_bytes_per_edge(data.pos.dtype))
        r, theta, phi = log_map(data.pos, edge_index, frame, face,
                                method=self.method)
        data.edge_index = edge_index
        data.logmap = torch.stack([r, theta], dim=1)
        if self.transport:
            data.transport = phi
        data.area = vertex_area_weights(data.pos, face, normal=frame[:, 2])
        data.frame = frame
        data.logmap_radius = torch.tensor([float(self.radius)],
                                          dtype=data.pos.dtype)
        return record_operator_graph(data)

    def __repr__(self) -> str:
        memory = ('' if self.max_memory == MAX_DISC_MEMORY
                  else f', max_memory={self.max_memory}')
        return (f'{self.__class__.__name__}(radius={self.radius}, '
                f'method={self.method!r}, '
                f'max_neighbors={self.max_neighbors}, '
                f'transport={self.transport}{memory})')
