"""All-pairs geodesic distances on a mesh, by fast marching."""
from typing import Optional

import torch
from torch import Tensor

from tg_intrinsic.geometry.checks import check_faces, check_points

from .logmap import geodesic_neighbourhoods


def geodesic_distances(pos: Tensor, face: Tensor,
                       sources: Optional[Tensor] = None) -> Tensor:
    r"""Geodesic distances on a connected triangle mesh from every source
    vertex to every vertex, :math:`D_{sk} = d(p_{s}, p_k)`, by untruncated
    fast marching (the marching of :func:`geodesic_neighbourhoods` with a
    radius longer than every path over the edges). Used to measure
    correspondence errors on a template (the "Princeton benchmark" curves
    of Kim et al., 2011), usually divided by the geodesic diameter
    :math:`\max D`.

    Shapes:
        - **input:** pos :math:`(N, 3)`, face :math:`(3, F)`, sources
          :math:`(S)` (default: every vertex)
        - **output:** :math:`(S, N)` in :obj:`pos`'s dtype; a vertex that
          no path reaches raises a :class:`ValueError`
    """
    pos = check_points(pos, min_points=2)
    face = check_faces(face, pos.size(0), pos)
    num = pos.size(0)
    sources = torch.arange(num, device=pos.device) if sources is None \
        else sources
    # no geodesic is longer than the sum of all edge lengths
    j, i = face[[0, 1, 2]], face[[1, 2, 0]]
    bound = float((pos[j] - pos[i]).norm(dim=-1).sum()) + 1.0
    edge_index, dist = geodesic_neighbourhoods(pos, bound, face=face,
                                               centers=sources,
                                               max_memory=None)
    if edge_index.size(1) != sources.numel() * num:
        raise ValueError("the mesh is not connected: some vertices cannot be "
                         "reached from a source; compute distances per "
                         "connected component")
    # every source's row holds all N vertices, in the order of `sources`
    slot = torch.arange(sources.numel(), device=pos.device
                        ).repeat_interleave(num)
    out = torch.empty(sources.numel(), num, dtype=pos.dtype,
                      device=pos.device)
    out[slot, edge_index[0]] = dist
    return out
