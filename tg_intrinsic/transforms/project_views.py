import warnings

import torch
from torch import Tensor
from torch_geometric.data import Data
from torch_geometric.data.datapipes import functional_transform

from tg_intrinsic.geometry import knn
from tg_intrinsic.geometry.appearance.cameras import (camera_centers, project,
                                                      sample_images,
                                                      splat_depth)
from tg_intrinsic.geometry.appearance.dynamic_range import looks_clipped
from tg_intrinsic.geometry.checks import (check_cameras, check_points,
                                          check_positive_float, check_tensor)
from tg_intrinsic.geometry.appearance.photograph_stack import \
    PhotographStack
from tg_intrinsic.surface_attributes import given_normals
from tg_intrinsic.transforms._batching import GraphTransform

#: Pixels of the photographs projected into at once (a block of views):
#: 16 megapixels, 8 photographs of 1600 x 1200.
VIEW_PIXELS = 2 ** 24


@functional_transform('project_views')
class ProjectViews(GraphTransform):
    r"""Gathers, for every surface point, the radiance it shows in a set of
    calibrated HDR photographs (functional name: :obj:`project_views`), the
    input of frequency-domain SVBRDF recovery (Wiersma et al., SIGGRAPH
    2025).

    A point :math:`p` is observed by view :math:`v` when it projects inside
    the image, lies in front of the camera, faces it
    (:math:`n \cdot \omega_o > \cos\theta_{\max}`, when normals are given)
    and passes a depth test,

    .. math::
        z_v(p) \leq \min_{q \text{ splatted on } \pi_v(p)} z_v(q) +
        \tau\, \rho,

    where the depth buffer is made by splatting every point over a square
    of 0.75 times its nearest-neighbour distance (so the surface leaves no holes the far
    side could be seen through), :math:`\rho` is the radius of the bounding
    sphere and :math:`\tau` the :obj:`depth_tolerance`; the tolerance also
    grows by twice the splat's footprint times the surface slope
    :math:`\tan\theta_o` (at most 10), since neighbours on a tilted surface
    are legitimately nearer. The radiance is a
    bilinear sample of the image at :math:`\pi_v(p)`. Cameras follow the
    OpenCV convention of :mod:`tg_intrinsic.geometry.appearance.cameras`.

    Documented behaviour on imperfect input: observations that touch a NaN
    pixel are masked out (with a warning that counts them); infinite or
    negative pixels raise an error; 8-bit or clipped photographs raise a
    warning (the method needs linear HDR radiance); a camera that sees no
    point (e.g. behind the object or looking away) gets an all-false mask
    column and a warning, and if no camera sees anything the transform
    raises an error; points seen by no view keep all-false masks (counted
    in a warning) and later get zero outgoing coefficients and entropy 1.

    Args:
        depth_tolerance (float, optional): :math:`\tau`, relative to the
            bounding radius. (default: :obj:`0.02`)
        min_cos (float, optional): Smallest :math:`n \cdot \omega_o` kept.
            (default: :obj:`0.0`)
        splat_radius (int, optional): Splat half-width in pixels; by default
            it follows the projected point spacing. (default: :obj:`None`)

    Shapes:
        - **input:** ``pos`` :math:`(N, 3)`, ``normal`` :math:`(N, 3)`
          (optional), ``images`` :math:`(V, H, W, 3)`, ``intrinsics``
          :math:`(V, 3, 3)`, ``extrinsics`` :math:`(V, 3, 4)`
        - **output:** ``obs_radiance`` :math:`(N, V, 3)` (0 where masked),
          ``obs_dir`` :math:`(N, V, 3)` (unit, point to camera),
          ``obs_mask`` :math:`(N, V)` (bool), ``obs_left_out`` (the
          number of observations masked out for touching NaN pixels)
    """
    def __init__(self, depth_tolerance: float = 0.02, min_cos: float = 0.0,
                 splat_radius: int = None):
        self.depth_tolerance = check_positive_float(depth_tolerance,
                                                    'depth_tolerance')
        if not -1.0 <= min_cos < 1.0:
            raise ValueError(f"'min_cos' must lie in [-1, 1), got {min_cos}")
        self.min_cos = float(min_cos)
        if splat_radius is not None and (not isinstance(splat_radius, int)
                                         or splat_radius < 0):
            raise ValueError(f"'splat_radius' must be a non-negative integer "
                             f"or None, got {splat_radius!r}")
        self.splat_radius = splat_radius

    def forward(self, data: Data) -> Data:
        pos = check_points(data.pos, 'pos')
        normal = given_normals(data)
        images = getattr(data, 'images', None)
        if images is None:
            raise ValueError("ProjectViews needs 'data.images' [V, H, W, 3] "
                             "(linear HDR photographs) with "
                             "'data.intrinsics' and 'data.extrinsics'")
        if not isinstance(images, PhotographStack):
            images = check_tensor(images, 'images')
        if images.dim() != 4 or images.size(-1) != 3:
            raise ValueError(f"'images' must have shape [V, H, W, 3], got "
                             f"{list(images.shape)}")
        if not images.dtype.is_floating_point:
            raise ValueError(f"'images' must hold floating-point linear "
                             f"radiance, got {images.dtype}; 8-bit images "
                             f"are not HDR")
        num_views = check_cameras(getattr(data, 'intrinsics', None),
                                  getattr(data, 'extrinsics', None),
                                  like=pos)[0].size(0)
        if images.size(0) != num_views:
            raise ValueError(f"there are {images.size(0)} images but "
                             f"{num_views} cameras")
        height, width = images.shape[1:3]
        intrinsics = data.intrinsics.to(pos.dtype)
        extrinsics = data.extrinsics.to(pos.dtype)
        scale = (pos - pos.mean(0)).norm(dim=-1).max().clamp_min(1e-12)
        spacing = self._spacing(pos)
        radiance = pos.new_zeros(pos.size(0), num_views, 3)
        direction = pos.new_zeros(pos.size(0), num_views, 3)
        mask = torch.zeros(pos.size(0), num_views, dtype=torch.bool,
                           device=pos.device)
        stream = isinstance(images, PhotographStack)
        # a tensor is checked whole, before any work; a stack as it is read
        clipped, lost = (False if stream else self._check_radiance(images)
                         ), 0
        # a few views at a time: the photographs (read from disk when they
        # are a PhotographStack) and the depth buffers of a big capture do
        # not fit in memory at once
        step = max(1, VIEW_PIXELS // (height * width))
        for start in range(0, num_views, step):
            views = slice(start, min(start + step, num_views))
            block = images[views]
            if stream:
                clipped |= self._check_radiance(block)
            out = self._project(pos, normal, block.to(pos.device, pos.dtype),
                                intrinsics[views], extrinsics[views], scale,
                                spacing)
            radiance[:, views], direction[:, views], mask[:, views] = \
                (value.transpose(0, 1) for value in out[:3])
            lost += out[3]
        if clipped:
            warnings.warn("the images look 8-bit or clipped (values on a "
                          "1/255 grid or piled up at their maximum); the "
                          "recovery assumes linear, unclipped HDR radiance, "
                          "so highlights will be underestimated",
                          stacklevel=2)
        if lost:
            warnings.warn(f"{lost} observation(s) touch NaN pixels and are "
                          f"masked out", stacklevel=2)
        self._check_seen(mask)
        data = data.clone()
        data.obs_radiance = radiance
        data.obs_dir = direction
        data.obs_mask = mask
        # seen, but on pixels that carry no radiance (NaN: outside a mask,
        # clipped, outside after undistortion)
        data.obs_left_out = torch.tensor([lost], device=pos.device)
        return data

    @staticmethod
    def _check_radiance(images: Tensor) -> bool:
        """Refuses infinite or negative radiance; whether the photographs
        look 8-bit or clipped."""
        finite = torch.isfinite(images) | torch.isnan(images)
        if not bool(finite.all()) or bool((images < 0).any()):
            raise ValueError("'images' hold infinite or negative radiance; "
                             "linear HDR photographs must be finite and >= 0 "
                             "(mark missing pixels as NaN)")
        return looks_clipped(images)

    def _project(self, pos, normal, images, intrinsics, extrinsics, scale,
                 spacing):
        """The observations of a block of views, view-major: radiance
        (v, N, 3), directions (v, N, 3), mask (v, N), and how many
        observations touched NaN pixels."""
        num_views, height, width = images.shape[:3]
        uv, depth = project(pos, intrinsics, extrinsics)
        inside = (depth > 1e-6 * scale) & (uv[..., 0] >= 0) \
            & (uv[..., 0] < width) & (uv[..., 1] >= 0) & (uv[..., 1] < height)
        centers = camera_centers(extrinsics)
        to_camera = centers.unsqueeze(1) - pos.unsqueeze(0)  # (v, N, 3)
        direction = to_camera / to_camera.norm(dim=-1, keepdim=True
                                               ).clamp_min(1e-30)
        if normal is not None:
            n = normal / normal.norm(dim=-1, keepdim=True).clamp_min(1e-30)
            cos = (direction * n.unsqueeze(0)).sum(-1)
            inside &= cos > self.min_cos
            slope = (1 - cos * cos).clamp_min(0).sqrt() / cos.clamp_min(0.1)
        else:
            slope = torch.ones_like(depth)

        radius = self._radius(spacing, intrinsics, depth)
        buffer = splat_depth(uv, depth, inside, radius, height, width)
        col = uv[..., 0].floor().long().clamp(0, width - 1)
        row = uv[..., 1].floor().long().clamp(0, height - 1)
        nearest = buffer.view(num_views, -1).gather(1, row * width + col)
        # A splat is flat, but the surface under it is tilted: neighbours
        # may be nearer by up to their footprint times the slope.
        footprint = (radius + 1) * depth / intrinsics[:, 0, 0].unsqueeze(1)
        tolerance = self.depth_tolerance * scale + 2 * footprint * slope
        mask = inside & (depth <= nearest + tolerance)

        radiance, nan = sample_images(images, uv)
        lost = mask & nan
        mask &= ~nan
        radiance = torch.where(mask.unsqueeze(-1), radiance,
                               torch.zeros_like(radiance))
        return radiance, direction, mask, int(lost.sum())

    @staticmethod
    def _check_seen(mask: Tensor):
        """Errors and warnings on what the views see, (N, V)."""
        seen = mask.any(1)
        views_seeing = mask.any(0)
        if not bool(views_seeing.any()):
            raise ValueError("no camera sees any point: check that the "
                             "extrinsics are world-to-camera [R | t] (OpenCV, "
                             "looking along +z) and that the object lies in "
                             "front of the cameras")
        if not bool(views_seeing.all()):
            blind = (~views_seeing).nonzero().flatten().tolist()
            warnings.warn(f"camera(s) {blind[:10]} see no point (behind the "
                          f"object or looking away); they are ignored",
                          stacklevel=3)
        if not bool(seen.all()):
            warnings.warn(f"{int((~seen).sum())} of {seen.numel()} points are "
                          f"seen by no view; their outgoing radiance is "
                          f"unknown and their entropy will be 1",
                          stacklevel=3)

    def _spacing(self, pos):
        """Each point's own spacing: its nearest-neighbour distance, at
        most 3 median spacings (None with a fixed splat radius)."""
        if self.splat_radius is not None or pos.size(0) < 2:
            return None
        edge = knn(pos, 1)
        spacing = torch.zeros(pos.size(0), dtype=pos.dtype, device=pos.device)
        spacing[edge[1]] = (pos[edge[0]] - pos[edge[1]]).norm(dim=-1)
        return spacing.clamp_max(3 * spacing.median())

    def _radius(self, spacing, intrinsics, depth):
        """Splat half-widths (V, N): 0.75 of each point's spacing in
        pixels."""
        if self.splat_radius is not None:
            return torch.full_like(depth, self.splat_radius, dtype=torch.long)
        if spacing is None:
            return torch.zeros_like(depth, dtype=torch.long)
        focal = intrinsics[:, 0, 0].unsqueeze(1)
        pixels = 0.75 * spacing * focal / depth.clamp_min(1e-12)
        return pixels.ceil().clamp(0, 8).long()

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}(depth_tolerance='
                f'{self.depth_tolerance}, min_cos={self.min_cos}, '
                f'splat_radius={self.splat_radius})')
