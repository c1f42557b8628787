r"""Point samples of a triangle mesh's surface."""
from typing import Optional, Tuple

import torch
from torch import Tensor

from ..checks import check_faces, check_points, check_positive_int
from ..mesh import face_areas
from .neighbors import fps


def sample_surface(pos: Tensor, face: Tensor, num_points: int,
                   oversample: int = 8,
                   generator: Optional[torch.Generator] = None
                   ) -> Tuple[Tensor, Tensor, Tensor, Tensor]:
    r"""Samples :obj:`num_points` points evenly spread over a mesh's
    surface, as DeltaConv prepares its inputs: :math:`s \cdot n` points
    drawn uniformly by area (triangle :math:`f` with probability
    :math:`A_f / \sum_g A_g`, uniform barycentric coordinates inside it),
    then :math:`n` of them kept by farthest point sampling, which removes
    the clumps of uniform sampling. Every point keeps the normal of its
    triangle. A mesh with fewer vertices than :obj:`num_points` is sampled
    the same way (points come from the surface, not the vertex list).

    .. math::
        \mathbf{p} = (1 - \sqrt{r_1})\,\mathbf{a} + \sqrt{r_1}(1 - r_2)\,
        \mathbf{b} + \sqrt{r_1}\, r_2\, \mathbf{c},
        \qquad r_1, r_2 \sim \mathcal{U}(0, 1).

    Args:
        pos (torch.Tensor): Mesh vertices.
        face (torch.Tensor): Triangles in PyG layout.
        num_points (int): Number of points :math:`n`.
        oversample (int, optional): The factor :math:`s` of candidates per
            kept point; 1 keeps the uniform samples. (default: :obj:`8`)
        generator (torch.Generator, optional): Random source, for a sampling
            that is the same on every call. (default: :obj:`None`)

    Shapes:
        - **input:** pos :math:`(N, 3)`, face :math:`(3, F)`
        - **output:** ``(points, normals, face_index, barycentric)``:
          :math:`(n, 3)`, :math:`(n, 3)` unit, :math:`(n)` the triangle of
          every point, :math:`(n, 3)` its barycentric coordinates
    """
    pos = check_points(pos, min_points=3)
    # Triangles that repeat a vertex have no area: they are never drawn.
    face = check_faces(face, pos.size(0), pos, allow_degenerate_indices=True)
    num_points = check_positive_int(num_points, 'num_points')
    oversample = check_positive_int(oversample, 'oversample')
    area = face_areas(pos, face).double()
    if not bool(area.sum() > 0):
        raise ValueError("the mesh has no surface area: every triangle is "
                         "degenerate, so no points can be sampled from it")
    count = num_points * oversample
    device = pos.device
    chosen = torch.multinomial(area.cpu(), count, replacement=True,
                               generator=generator).to(device)
    r = torch.rand(count, 2, generator=generator, dtype=torch.float64)
    r = r.to(device)
    root = r[:, 0].sqrt()
    bary = torch.stack([1 - root, root * (1 - r[:, 1]), root * r[:, 1]], 1)
    corners = pos.double()[face[:, chosen].t()]          # [count, 3, 3]
    points = (bary.unsqueeze(-1) * corners).sum(1)
    if oversample > 1:
        keep = fps(points, 1.0 / oversample, random_start=False)
        keep = keep[:num_points]
        points, chosen, bary = points[keep], chosen[keep], bary[keep]
    corners = pos.double()[face[:, chosen].t()]
    normals = torch.linalg.cross(corners[:, 1] - corners[:, 0],
                                 corners[:, 2] - corners[:, 0])
    normals = normals / normals.norm(dim=1, keepdim=True)
    return (points.to(pos.dtype), normals.to(pos.dtype), chosen,
            bary.to(pos.dtype))
