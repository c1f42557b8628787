"""Handwritten digits on a sphere, for Harmonic Surface Networks."""
import math
from typing import Callable, Optional, Sequence

import numpy as np
import torch
from torch_geometric.data import Dataset

from tg_intrinsic.data import IntrinsicData
from tg_intrinsic.geometry import log_map
from tg_intrinsic.geometry.checks import check_choice, check_positive_int
from tg_intrinsic.geometry.sphere_images import sample_image_on_sphere
from tg_intrinsic.transforms import (HarmonicPrecompute, LogMap,
                                     MultiscaleSupports)

from .common import check_split

ROTATIONS = ('none', 'axis', 'so3')
SUBDIVISIONS = 3  # 642 vertices


def load_digit_images():
    """scikit-learn's 8 x 8 digits (1797 images, values 0..16), read from the
    files inside the scikit-learn wheel (nothing is downloaded)."""
    try:
        from sklearn.datasets import load_digits
    except ImportError as error:  # pragma: no cover - the extra is absent
        raise ImportError(
            "SphereDigits reads scikit-learn's bundled 8x8 digits; install "
            "the extra with: pip install 'tg_intrinsic[digits]' (or pip "
            "install scikit-learn)") from error
    digits = load_digits()
    return (torch.from_numpy(digits.images / 16.0),
            torch.from_numpy(digits.target).long())


def rotation_about_z(angle: float, dtype=torch.float64) -> torch.Tensor:
    c, s = math.cos(angle), math.sin(angle)
    return torch.tensor([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]],
                        dtype=dtype)


def random_rotation(rng: np.random.Generator,
                    dtype=torch.float64) -> torch.Tensor:
    """A uniformly random rotation of space (QR of a Gaussian matrix with
    the signs fixed)."""
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return torch.from_numpy(q).to(dtype)


def covariant_clusters(data: IntrinsicData, levels: int,
                       method: str) -> IntrinsicData:
    """Pooling cells of the nested icospheres that turns about the pole
    permute like the vertices. Each fine point joins its nearest coarse
    vertex on the sphere; the graph Voronoi cells of
    :class:`MultiscaleSupports` break the exact ties of edge midpoints
    (equidistant from two coarse vertices, about 480 of 642 points) by
    index, which no turn respects. Here a tie goes to the candidate
    furthest counter-clockwise about the pole as seen from the point,
    then to the one nearer the pole: rules that turns about the pole keep.
    Rewrites ``cluster_l``, ``pool_transport_l`` and ``area_l``."""
    pos, frame = data.pos.double(), data.frame
    ids = torch.arange(pos.size(0))
    area = data.area
    for level in range(1, levels + 1):
        coarse = ids[data[f'sample_index_{level}']]
        fine, centre = pos[ids], pos[coarse]
        angle = torch.arccos((fine @ centre.t()).clamp(-1, 1))
        tied = angle <= angle.min(1, keepdim=True).values + 1e-9
        azimuth = torch.atan2(pos[:, 1], pos[:, 0])
        turn = torch.remainder(azimuth[coarse][None] - azimuth[ids][:, None]
                               + math.pi, 2 * math.pi) - math.pi
        on_axis = centre[:, :2].norm(dim=1) < 1e-9  # the pole: no azimuth
        turn = torch.where(on_axis[None], 0.0, turn)
        turn = torch.where(tied, turn, -math.inf)
        tied &= turn >= turn.max(1, keepdim=True).values - 1e-9
        height = torch.where(tied, centre[:, 2][None], -math.inf)
        cell = height.argmax(1)
        pairs = torch.stack([ids, coarse[cell]])
        _, _, phi = log_map(pos, pairs, frame, data.face, method=method)
        data[f'cluster_{level}'] = cell
        data[f'pool_transport_{level}'] = torch.where(
            pairs[0] == pairs[1], 0.0, phi).to(phi.dtype)
        area = torch.zeros(coarse.numel(), dtype=area.dtype).index_add_(
            0, cell, area)
        data[f'area_{level}'] = area
        ids = coarse
    return data


def pole_rotation(direction: torch.Tensor) -> torch.Tensor:
    """The rotation that takes the unit vector ``direction`` to the pole
    :math:`(0, 0, 1)` about the axis perpendicular to both."""
    z = torch.tensor([0.0, 0.0, 1.0], dtype=direction.dtype)
    axis = torch.linalg.cross(direction, z)
    s, c = axis.norm(), torch.dot(direction, z)
    if s < 1e-12:
        return torch.eye(3, dtype=direction.dtype) * torch.sign(c)
    k = axis / s
    cross = torch.tensor([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]],
                          [-k[1], k[0], 0.0]], dtype=direction.dtype)
    return torch.eye(3, dtype=direction.dtype) + s * cross \
        + (1 - c) * cross @ cross


class SphereDigits(Dataset):
    r"""Handwritten digits on a 642-vertex icosphere, the "rotated MNIST on
    a sphere" experiment of the `"CNNs on Surfaces using Rotation-Equivariant
    Features" <https://doi.org/10.1145/3386569.3392437>`_ paper, made with
    scikit-learn's 8 x 8 digits (bundled with scikit-learn, no download;
    the extra ``tg_intrinsic[digits]``) instead of MNIST.

    Every image is laid on the upper unit hemisphere: the square
    :math:`[-1, 1]^2` goes to the unit disc by the elliptical grid mapping,
    the disc to the hemisphere by the azimuthal equidistant map (image
    centre at the pole :math:`(0, 0, 1)`, image border on the equator), see
    :func:`~tg_intrinsic.geometry.sphere_images.sample_image_on_sphere`.
    A rotation :math:`R` of the digit gives the vertex signal

    .. math::
        x_i = I\big(R^{\top} \mathbf{p}_i\big),

    with :math:`I` the bilinearly interpolated image on the sphere:
    :obj:`rotate='axis'` turns the digit in place about the pole by a
    random angle (the paper's rotated test set), :obj:`'so3'` applies a
    uniformly random rotation of space (the digit also moves over the
    sphere), :obj:`'none'` keeps it upright. The angles are drawn from
    :obj:`seed` and the example's index, so the data set is deterministic.

    The mesh (a third subdivision of the icosahedron, a vertex at the pole)
    and its precomputation are shared by all examples and built once:
    :class:`~tg_intrinsic.transforms.LogMap` with radius ``radii[0]``,
    :class:`~tg_intrinsic.transforms.MultiscaleSupports` with
    ``radii[1:]`` whose pooling levels are the vertices of the coarser
    icospheres (162 and 42 vertices, which the finer icosphere lists first;
    about the paper's ratio of 1/4 per level), and
    :class:`~tg_intrinsic.transforms.HarmonicPrecompute`. Nested icospheres
    keep every level symmetric under the icosahedron's rotations, e.g.
    turns by 72 degrees about the pole, where farthest point sampling would
    not, and :func:`covariant_clusters` makes the pooling cells follow
    those turns too.

    Splits: every fourth image (index :math:`i \equiv 0 \bmod 4`, 450) is
    :obj:`'test'`, the others (1347) are :obj:`'train'`.

    Args:
        split (str, optional): :obj:`'train'` or :obj:`'test'`.
            (default: :obj:`'train'`)
        rotate (str, optional): :obj:`'none'`, :obj:`'axis'` or
            :obj:`'so3'`. (default: :obj:`'none'`)
        seed (int, optional): Seed of the rotations. (default: :obj:`0`)
        radii (Sequence[float], optional): Disc radius of every level (the
            paper's 0.3, 0.45, 0.8 on the unit sphere; at most 4 levels).
            (default: :obj:`(0.3, 0.45, 0.8)`)
        rings (int, optional): Rings of the radial profiles.
            (default: :obj:`6`)
        max_order (int, optional): Highest rotation order precomputed.
            (default: :obj:`1`)
        method (str, optional): Log map method, see
            :class:`~tg_intrinsic.transforms.LogMap`.
            (default: :obj:`'fast'`)
        limit (int, optional): Keep only the first this many examples of the
            split. (default: :obj:`None`)
        dtype (torch.dtype, optional): Floating point type of the signal and
            the precomputation (complex terms follow it).
            (default: :obj:`torch.float32`)
        transform (callable, optional): Applied to every example.
            (default: :obj:`None`)

    Shapes:
        - **output:** :class:`~tg_intrinsic.data.IntrinsicData` with ``x``
          :math:`(642, 1)` (intensity in :math:`[0, 1]`), ``y``
          :math:`(1)`, ``pos``, ``face``, ``normal`` and the levels of the
          precomputation
    """
    def __init__(self, split: str = 'train', rotate: str = 'none',
                 seed: int = 0,
                 radii: Sequence[float] = (0.3, 0.45, 0.8), rings: int = 6,
                 max_order: int = 1, method: str = 'fast',
                 limit: Optional[int] = None,
                 dtype: torch.dtype = torch.float32,
                 transform: Optional[Callable] = None):
        check_split(split)
        self.split = split
        self.rotate = check_choice(rotate, 'rotate', ROTATIONS)
        self.seed = check_positive_int(seed, 'seed', 0)
        radii = [float(r) for r in radii]
        if not 2 <= len(radii) <= SUBDIVISIONS + 1:
            raise ValueError(f"'radii' needs one entry per level, 2 to "
                             f"{SUBDIVISIONS + 1} levels (icospheres of "
                             f"subdivision {SUBDIVISIONS} down to 0), got "
                             f"{len(radii)}")
        self.radii = radii
        self.rings = check_positive_int(rings, 'rings')
        self.max_order = check_positive_int(max_order, 'max_order', 0)
        self.method = method
        if dtype not in (torch.float32, torch.float64):
            raise ValueError(f"'dtype' must be torch.float32 or "
                             f"torch.float64, got {dtype}")
        self.dtype = dtype
        super().__init__(None, transform)
        images, labels = load_digit_images()
        index = torch.arange(labels.numel())
        index = index[(index % 4 == 0) == (split == 'test')]
        if limit is not None:
            index = index[:check_positive_int(limit, 'limit')]
        self.index = index
        self.images, self.labels = images[index], labels[index]
        self.mesh = self.build_mesh()
        if rotate == 'none':  # all images at once, as channels
            self.signals = sample_image_on_sphere(
                self.images, self.mesh.pos.double()).t()[..., None] \
                .to(dtype)
        else:
            self.signals = torch.stack([self.signal(i, self.rotation(i))
                                        for i in range(len(index))])

    def build_mesh(self) -> IntrinsicData:
        import trimesh
        sphere = trimesh.creation.icosphere(subdivisions=SUBDIVISIONS)
        pos = torch.from_numpy(np.asarray(sphere.vertices)).double()
        pos = pos / pos.norm(dim=1, keepdim=True)
        pos = pos @ pole_rotation(pos[0]).t()  # vertex 0 at the pole
        data = IntrinsicData(
            pos=pos, normal=pos.clone(),
            face=torch.from_numpy(np.asarray(sphere.faces)).long().t()
            .contiguous())
        data = LogMap(self.radii[0], self.method)(data)
        # the coarser icospheres' vertices come first: 10 * 4^s + 2
        sizes = [10 * 4 ** (SUBDIVISIONS - level) + 2
                 for level in range(1, len(self.radii))]
        data = MultiscaleSupports(
            [size / pos.size(0) for size in sizes], self.radii[1:],
            self.method,
            samples=[torch.arange(size) for size in sizes])(data)
        data = covariant_clusters(data, len(sizes), self.method)
        data = HarmonicPrecompute(self.rings, self.max_order)(data)
        complex_dtype = (torch.complex64 if self.dtype == torch.float32
                         else torch.complex128)
        for key, value in data.items():
            if value.is_complex():
                data[key] = value.to(complex_dtype)
            elif value.is_floating_point():
                data[key] = value.to(self.dtype)
        return data

    def rotation(self, idx: int) -> torch.Tensor:
        """The rotation :math:`R` of example ``idx``."""
        if self.rotate == 'none':
            return torch.eye(3, dtype=torch.float64)
        rng = np.random.default_rng([self.seed, int(self.index[idx])])
        if self.rotate == 'axis':
            return rotation_about_z(rng.uniform(0, 2 * math.pi))
        return random_rotation(rng)

    def signal(self, idx: int, rotation: torch.Tensor) -> torch.Tensor:
        """The vertex values of example ``idx`` turned by ``rotation``."""
        # (R^T p)^T = p^T R
        return sample_image_on_sphere(self.images[idx],
                                      self.mesh.pos.double() @ rotation
                                      )[:, None].to(self.dtype)

    def len(self) -> int:
        return self.labels.numel()

    def get(self, idx: int) -> IntrinsicData:
        data = IntrinsicData(**dict(self.mesh.to_dict()))  # tensors shared
        data.x = self.signals[idx]
        data.y = self.labels[idx:idx + 1]
        return data

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({len(self)}, split='
                f'{self.split!r}, rotate={self.rotate!r})')
