import math
import re
from typing import Optional

import torch
from torch import Tensor
from torch_geometric.data import Data
from torch_geometric.data.datapipes import functional_transform

from tg_intrinsic.geometry.checks import check_points
from tg_intrinsic.surface_attributes import given_normals
from tg_intrinsic.transforms._batching import GraphTransform

_AXES = {'x': 0, 'y': 1, 'z': 2}
AXES = ('x', 'y', 'z', 'xyz')
_LEVEL = re.compile(r'_[1-9][0-9]*$')


def random_rotation_matrix(axis: Optional[str] = None,
                           generator: Optional[torch.Generator] = None,
                           dtype=torch.float64,
                           max_angle: float = 180.0) -> Tensor:
    """A rotation drawn uniformly from SO(3) (``axis=None``, from a random
    unit quaternion), about one coordinate axis (``'x'``, ``'y'``, ``'z'``)
    by an angle uniform in :math:`[-a, a]` with :math:`a` = ``max_angle``
    degrees, or about x, then y, then z, each by such an angle
    (``'xyz'``)."""
    if axis is None:
        q = torch.randn(4, generator=generator, dtype=torch.float64)
        w, x, y, z = (q / q.norm()).tolist()
        matrix = torch.tensor([
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ], dtype=torch.float64)
        return matrix.to(dtype)
    matrix = torch.eye(3, dtype=torch.float64)
    for name in axis:
        u = float(torch.rand(1, generator=generator, dtype=torch.float64))
        angle = math.radians(max_angle) * (2 * u - 1)
        c, s = math.cos(angle), math.sin(angle)
        i = _AXES[name]
        j, k = [a for a in range(3) if a != i]
        turn = torch.eye(3, dtype=torch.float64)
        turn[j, j], turn[j, k], turn[k, j], turn[k, k] = c, -s, s, c
        matrix = turn @ matrix
    return matrix.to(dtype)


@functional_transform('random_rotation')
class RandomRotation(GraphTransform):
    r"""Rotates a shape rigidly by a random rotation :math:`R`, uniform on
    SO(3) or about one axis (functional name: :obj:`random_rotation`).

    .. math::
        \mathbf{p}_i \mapsto R\,\mathbf{p}_i, \quad
        \mathbf{n}_i \mapsto R\,\mathbf{n}_i, \quad
        (e_u, e_v, n)_i \mapsto (R e_u, R e_v, R n)_i

    Unlike PyG's :class:`~torch_geometric.transforms.RandomRotate`, normals
    (``normal`` or ``norm``) and tangent frames (``frame``) turn with the
    points, on every level (``pos_1``, ``frame_1``, ...). Because the frames turn too, per-edge operators that are
    intrinsic to the surface (``grad_weight``, ``div_weight`` of
    :class:`MLSOperators`) stay valid and are kept. On a collated
    :class:`~torch_geometric.data.Batch` every graph gets a rotation of
    its own, as if rotated before collation.

    Args:
        axis (str, optional): :obj:`'x'`, :obj:`'y'` or :obj:`'z'` to rotate
            about that axis only, :obj:`'xyz'` to rotate about x, then y,
            then z (HSN's augmentation); :obj:`None` for all of SO(3).
            (default: :obj:`None`)
        max_angle (float, optional): The largest angle about an axis, in
            degrees: every angle is uniform in :math:`[-a, a]`. Not used
            with :obj:`axis=None`. (default: :obj:`180.0`)

    Shapes:
        - **input:** ``pos`` :math:`(N, 3)`, optional ``normal`` / ``norm``
          :math:`(N, 3)`, ``frame`` :math:`(N, 3, 3)`
        - **output:** the same attributes, rotated
    """
    def __init__(self, axis: Optional[str] = None, max_angle: float = 180.0):
        if axis is not None and axis not in AXES:
            raise ValueError(f"axis must be None, 'x', 'y', 'z' or 'xyz' "
                             f"(got {axis!r})")
        if not 0 < max_angle <= 180:
            raise ValueError(f"max_angle must be in (0, 180] degrees, got "
                             f"{max_angle}")
        self.axis = axis
        self.max_angle = float(max_angle)

    def forward(self, data: Data) -> Data:
        if getattr(data, 'pos', None) is None:
            raise ValueError("RandomRotation needs 'data.pos' of shape "
                             "[N, 3]")
        pos = check_points(data.pos, 'data.pos')
        given_normals(data)  # normals / frames must match pos
        data = data.clone()
        matrix = random_rotation_matrix(
            self.axis, max_angle=self.max_angle).to(pos.device, pos.dtype)
        for key, value in data.to_dict().items():
            name = _LEVEL.sub('', key)  # pos_1 -> pos
            if name not in ('pos', 'normal', 'norm', 'frame') \
                    or not isinstance(value, Tensor):
                continue
            level_pos = 'pos' + key[len(name):]  # normal_1 -> pos_1
            rows = data[level_pos].size(0) if level_pos in data else None
            shape = [rows, 3, 3] if name == 'frame' else [rows, 3]
            if value.dim() != len(shape) or value.shape[1:] != \
                    torch.Size(shape[1:]) or (rows is not None
                                              and value.size(0) != rows):
                raise ValueError(f"'data.{key}' must have shape "
                                 f"{shape} (rows: one per point), got "
                                 f"{list(value.shape)}")
            check_points(value.reshape(-1, 3), f'data.{key}',
                         min_points=0)
            data[key] = value @ matrix.T.to(value.dtype)
        return data

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}(axis={self.axis!r}, '
                f'max_angle={self.max_angle:g})')
