from typing import Optional, Sequence

import torch
from torch_geometric.data import Data
from torch_geometric.data.datapipes import functional_transform

from tg_intrinsic.geometry.checks import (check_positive_float,
                                          check_positive_int)
from tg_intrinsic.data import IntrinsicData
from tg_intrinsic.geometry import fps, geodesic_neighbourhoods, log_map
from tg_intrinsic.geometry.geodesics.logmap import (MAX_DISC_MEMORY, METHODS,
                                          graph_bytes_per_edge,
                                          hsn_bytes_per_edge)
from tg_intrinsic.geometry.multigrid.voronoi import graph_voronoi
from tg_intrinsic.surface_attributes import resolve_frames
from tg_intrinsic.transforms._batching import GraphTransform
from tg_intrinsic.transforms.log_map import LogMap


@functional_transform('multiscale_supports')
class MultiscaleSupports(GraphTransform):
    r"""Builds the pooling levels of a Harmonic Surface Network and the
    geodesic discs of every level (functional name:
    :obj:`multiscale_supports`).

    Level :math:`l \geq 1` keeps ``ratios[l - 1]`` of the input points,
    chosen by farthest point sampling among the points of level
    :math:`l - 1`; every point of level :math:`l - 1` joins the cell of its
    geodesically nearest sample (a graph Voronoi diagram on the disc graph
    of level :math:`l - 1`, edge lengths :math:`r_{ij}`). Each level gets
    discs of radius ``radii[l - 1]`` among its own points, with log map and
    transport computed on the full surface:

    .. math::
        \mathcal{N}_l(c) = \{c' \in S_l : d(p_c, p_{c'}) < \epsilon_l\},
        \qquad A^{(l)}_c = \sum_{j : c(j) = c} A^{(l-1)}_j,

    where the area of a coarse point is the area of its cell. Pooling
    transports every fine point :math:`j` into the frame of its sample
    :math:`c(j)` by the angle :math:`\phi_{j \to c(j)}`.

    Level 0 (``edge_index``, ``logmap``, ``transport``, ``area``) is built
    with :class:`LogMap` (:obj:`level0_radius`) unless already present.
    Writes, per level :math:`l`: ``pos_l``, ``sample_index_l`` (the
    level-:math:`(l-1)` point of every sample), ``cluster_l``,
    ``pool_transport_l``, ``edge_index_l``, ``logmap_l``, ``transport_l``,
    ``area_l``, ``logmap_radius_l``; returns an
    :class:`~tg_intrinsic.data.IntrinsicData`, so these batch correctly.

    Args:
        ratios (Sequence[float]): Fraction of the input points kept on
            levels :math:`1, 2, \dots` (0.25 in the paper).
        radii (Sequence[float]): Disc radius of levels :math:`1, 2, \dots`
            (0.4 on unit-area meshes in the paper; grow by
            :math:`1/\sqrt{\text{ratio}}` per level).
        method (str, optional): Log map and transport method,
            :obj:`'fast'` or :obj:`'vector_heat'`. (default: :obj:`'fast'`)
        level0_radius (float, optional): Disc radius of level 0, if
            :class:`LogMap` has not run. (default: :obj:`None`)
        max_neighbors (int, optional): Cap on every disc.
            (default: :obj:`None`)
        samples (Sequence[Tensor], optional): The samples of every level
            as indices into the points of the level before (sorted, no
            repeats), instead of farthest point sampling; e.g. the vertices
            of the coarser icospheres, which an icosphere lists first.
            :obj:`ratios` is not used then. (default: :obj:`None`)
        max_memory (float, optional): Memory limit in bytes of every
            level's discs, checked before each is built: level 0 as in
            :class:`LogMap`; level :math:`l` marches from its samples over
            all the points and keeps the samples among them, so its
            estimate counts the marched edges
            (:func:`~tg_intrinsic.geometry.geodesics.logmap.graph_bytes_per_edge`)
            plus the kept fraction with their HSN data. :obj:`None`
            disables the check. (default: 2 GiB)
    """
    def __init__(self, ratios: Sequence[float], radii: Sequence[float],
                 method: str = 'fast', level0_radius: Optional[float] = None,
                 max_neighbors: Optional[int] = None,
                 max_memory: Optional[float] = MAX_DISC_MEMORY,
                 samples: Optional[Sequence[torch.Tensor]] = None):
        ratios, radii = list(ratios), list(radii)
        if samples is not None:
            samples = list(samples)
            if len(samples) != len(radii) or not all(
                    isinstance(s, torch.Tensor) and s.dim() == 1
                    and s.numel() > 0 and not s.is_floating_point()
                    and bool((s[1:] > s[:-1]).all()) and int(s.min()) >= 0
                    for s in samples):
                raise ValueError("'samples' must hold one non-empty, "
                                 "increasing 1-D index tensor per level "
                                 "(indices into the level before)")
        self.samples = samples
        if len(ratios) != len(radii) or not ratios:
            raise ValueError("'ratios' and 'radii' must be non-empty and of "
                             "equal length (one entry per pooling level)")
        previous = 1.0
        for ratio in ratios:
            if not 0 < ratio < previous:
                raise ValueError(f"'ratios' must decrease within (0, 1), got "
                                 f"{ratios}")
            previous = ratio
        if any(r <= 0 for r in radii):
            raise ValueError(f"'radii' must be positive, got {radii}")
        if method not in METHODS:
            raise ValueError(f"'method' must be one of {METHODS}, got "
                             f"{method!r}")
        self.ratios, self.radii = ratios, radii
        self.method = method
        self.level0_radius = (None if level0_radius is None else
                              check_positive_float(level0_radius,
                                                   'level0_radius'))
        self.max_neighbors = (None if max_neighbors is None else
                              check_positive_int(max_neighbors,
                                                 'max_neighbors'))
        if max_memory is not None and not max_memory > 0:
            raise ValueError(f"'max_memory' must be a positive number of "
                             f"bytes or None, got {max_memory!r}")
        self.max_memory = max_memory

    def forward(self, data: Data) -> IntrinsicData:
        if getattr(data, 'logmap', None) is None:
            if self.level0_radius is None:
                raise ValueError("level 0 has no discs: apply LogMap(radius) "
                                 "first or pass level0_radius")
            data = LogMap(self.level0_radius, self.method,
                          self.max_neighbors,
                          max_memory=self.max_memory)(data)
        data = IntrinsicData(**{k: v for k, v in data.to_dict().items()})
        pos, face = data.pos, getattr(data, 'face', None)
        frame = resolve_frames(data)
        num = pos.size(0)
        # level l points as indices of the input points
        ids = torch.arange(num, device=pos.device)
        graph, length, area = data.edge_index, data.logmap[:, 0], data.area
        for level, (ratio, eps) in enumerate(zip(self.ratios, self.radii),
                                             start=1):
            n_prev = ids.numel()
            n_next = max(1, int(round(ratio * num)))
            if self.samples is not None:
                sample = self.samples[level - 1].to(pos.device)
                if int(sample.max()) >= n_prev:
                    raise ValueError(f"'samples' of level {level} index "
                                     f"past the {n_prev} points of level "
                                     f"{level - 1}")
            else:
                sample = fps(pos[ids], ratio=min(1.0, n_next / n_prev),
                             random_start=False)
                sample = torch.sort(sample).values
            cell, _ = graph_voronoi(pos[ids], graph, sample,
                                    edge_length=length)
            coarse = ids[sample]
            # transport of every fine point into its sample's frame
            pairs = torch.stack([ids, coarse[cell]])
            _, _, pool_phi = log_map(pos, pairs, frame, face,
                                     method=self.method)
            pool_phi = torch.where(pairs[0] == pairs[1], 0.0, pool_phi)
            # discs among the samples, measured on the whole surface
            kept = hsn_bytes_per_edge(pos.dtype, coarse_fraction=0.0)
            edge_index, _ = geodesic_neighbourhoods(
                pos, eps, face=face, normal=frame[:, 2], centers=coarse,
                max_memory=self.max_memory,
                bytes_per_edge=graph_bytes_per_edge(pos.dtype)
                + kept * coarse.numel() / num)
            local = torch.full((num,), -1, dtype=torch.long,
                               device=pos.device)
            local[coarse] = torch.arange(coarse.numel(), device=pos.device)
            keep = local[edge_index[0]] >= 0
            edge_index = edge_index[:, keep]
            if self.max_neighbors is not None:
                edge_index = _cap(edge_index, self.max_neighbors,
                                  coarse.numel(), local)
            r, theta, phi = log_map(pos, edge_index, frame, face,
                                    method=self.method)
            coarse_area = torch.zeros(coarse.numel(), dtype=area.dtype,
                                      device=area.device).index_add_(
                                          0, cell, area)
            graph = local[edge_index]
            data[f'pos_{level}'] = pos[coarse]
            data[f'sample_index_{level}'] = sample
            data[f'cluster_{level}'] = cell
            data[f'pool_transport_{level}'] = pool_phi
            data[f'edge_index_{level}'] = graph
            data[f'logmap_{level}'] = torch.stack([r, theta], dim=1)
            data[f'transport_{level}'] = phi
            data[f'area_{level}'] = coarse_area
            data[f'logmap_radius_{level}'] = torch.tensor([float(eps)],
                                                          dtype=pos.dtype)
            ids, length, area = coarse, r, coarse_area
        data.frame = frame
        return data

    def __repr__(self) -> str:
        memory = ('' if self.max_memory == MAX_DISC_MEMORY
                  else f', max_memory={self.max_memory}')
        if self.samples is not None:
            memory += (f', samples={[int(s.numel()) for s in self.samples]}')
        return (f'{self.__class__.__name__}(ratios={self.ratios}, '
                f'radii={self.radii}, method={self.method!r}, '
                f'level0_radius={self.level0_radius}, '
                f'max_neighbors={self.max_neighbors}{memory})')


def _cap(edge_index, cap, num_centres, local):
    """Keeps the first ``cap`` neighbours of every centre (the edges come
    sorted by centre and distance)."""
    centre = local[edge_index[1]]
    count = torch.bincount(centre, minlength=num_centres)
    start = torch.cumsum(count, 0) - count
    rank = torch.arange(centre.numel(), device=centre.device) - start[centre]
    return edge_index[:, rank < cap]
