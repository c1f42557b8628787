r"""Synthetic multi-view SVBRDF scenes with an independent ground truth, for
"Uncertainty for SVBRDF acquisition using frequency analysis" (Wiersma et
al., SIGGRAPH 2025)."""
import math
import os
from typing import Optional, Tuple, Union

import numpy as np
import torch
from torch import Tensor
from torch_geometric.data import Data

from tg_intrinsic.geometry.appearance.cameras import (camera_centers,
                                                      look_at_cameras)
from tg_intrinsic.geometry.appearance.envmap import (check_envmap,
                                                     sun_sky_envmap)
from tg_intrinsic.geometry.appearance.lighting import render_radiance
from tg_intrinsic.geometry.appearance.raster import point_visibility
from tg_intrinsic.geometry.appearance.sh import fibonacci_sphere
from tg_intrinsic.geometry.checks import (check_faces, check_image_size,
                                          check_points, check_positive_int)
from tg_intrinsic.geometry.mesh import vertex_normals
from tg_intrinsic.geometry.texture import uv_sphere
from tg_intrinsic.io.hdr import read_envmap

from .capture import render_images as _render_images


SHAPES = ('sphere', 'uv_sphere')
MATERIALS = ('metals', 'dielectrics', 'mixed')


def _icosphere(subdivisions):
    import trimesh
    mesh = trimesh.creation.icosphere(subdivisions=subdivisions)
    return (torch.tensor(mesh.vertices, dtype=torch.float64),
            torch.tensor(mesh.faces, dtype=torch.long).t().contiguous())


def _load_shape(shape, resolution, seed):
    if isinstance(shape, str) and shape == 'sphere':
        subdivisions = 4 if resolution is None else check_positive_int(
            resolution, 'resolution', 0)
        return _icosphere(subdivisions)
    if isinstance(shape, (str, os.PathLike)):
        import trimesh
        if not os.path.exists(shape):
            raise ValueError(f"'shape' must be 'sphere', (vertices, faces) "
                             f"or the path of a mesh file; {shape!r} does "
                             f"not exist")
        mesh = trimesh.load(shape, process=False, force='mesh')
        pos = torch.tensor(np.asarray(mesh.vertices), dtype=torch.float64)
        face = torch.tensor(np.asarray(mesh.faces),
                            dtype=torch.long).t().contiguous()
    elif isinstance(shape, (tuple, list)) and len(shape) == 2:
        pos, face = shape
        if isinstance(face, np.ndarray):  # trimesh layout [F, 3]
            face = torch.as_tensor(face, dtype=torch.long).t().contiguous()
        if isinstance(pos, np.ndarray):
            pos = torch.as_tensor(pos)
        pos = check_points(pos, 'vertices').double()
    else:
        raise ValueError(f"'shape' must be 'sphere', (vertices, faces) or "
                         f"the path of a mesh file, got {type(shape)}")
    face = check_faces(face, pos.size(0), pos)
    used = torch.zeros(pos.size(0), dtype=torch.bool)
    used[face.flatten()] = True
    if not bool(used.all()):  # drop unreferenced vertices
        remap = torch.cumsum(used.long(), 0) - 1
        pos, face = pos[used], remap[face]
    if resolution is not None and resolution < pos.size(0):
        from tg_intrinsic.geometry.mesh import is_closed_manifold
        from .quadric_decimation import decimate
        resolution = check_positive_int(resolution, 'resolution', 4)
        if not is_closed_manifold(face, pos.size(0)):
            raise ValueError("'resolution' (a target vertex count) needs a "
                             "closed manifold mesh to decimate; pass "
                             "resolution=None to keep the mesh as it is")
        V, F = decimate(pos.numpy(), face.t().numpy().astype(np.int64),
                        resolution, seed=seed)
        pos = torch.as_tensor(V, dtype=torch.float64)
        face = torch.as_tensor(F, dtype=torch.long).t().contiguous()
    return pos, face


def _normalise(pos):
    """Into the unit ball: bounding-box centre to the origin, the farthest
    vertex at distance 1."""
    centre = 0.5 * (pos.min(0).values + pos.max(0).values)
    pos = pos - centre
    return pos / pos.norm(dim=1).max()


def _make_envmap(envmap, seed, envmap_size):
    if isinstance(envmap, Tensor):
        return check_envmap(envmap).float()
    if isinstance(envmap, str) and envmap == 'sun_sky':
        rng = np.random.default_rng(np.random.SeedSequence([seed, 1]))
        elevation = rng.uniform(math.radians(20), math.radians(60))
        azimuth = rng.uniform(-math.pi, math.pi)
        sun = torch.tensor([math.cos(elevation) * math.cos(azimuth),
                            math.cos(elevation) * math.sin(azimuth),
                            math.sin(elevation)], dtype=torch.float64)
        height, width = envmap_size
        return check_envmap(sun_sky_envmap(height, width, sun)).float()
    if isinstance(envmap, (str, os.PathLike)):
        if not os.path.exists(envmap):
            raise ValueError(f"'envmap' must be 'sun_sky', an [H, W, 3] "
                             f"tensor or the path of an HDR image; "
                             f"{envmap!r} does not exist")
        return check_envmap(read_envmap(envmap)).float()
    raise ValueError(f"'envmap' must be 'sun_sky', an [H, W, 3] tensor or "
                     f"the path of an HDR image, got {type(envmap)}")


def _materials(pos, materials, roughness_range, num_patches, rng):
    """Smooth random material fields: ``num_patches`` patches centred at
    random vertices, blended by a softmax of :math:`-d^2 / (2\\sigma^2)`
    (:math:`\\sigma = 0.35` in the unit ball), so materials are constant
    inside patches and change smoothly across their borders."""
    n = pos.size(0)
    k = min(num_patches, n)
    centres = pos[torch.as_tensor(rng.choice(n, k, replace=False))]
    logits = -torch.cdist(pos, centres) ** 2 / (2 * 0.35 ** 2)
    weight = torch.softmax(logits / 0.5, dim=1)  # sharper borders
    if materials == 'metals':
        metal = np.ones(k)
    elif materials == 'dielectrics':
        metal = np.zeros(k)
    else:  # mixed: both kinds, for sure
        metal = (rng.permutation(k) % 2).astype(np.float64)
    hue = rng.uniform(0, 1, k)
    sat = np.where(metal > 0, rng.uniform(0.1, 0.6, k),
                   rng.uniform(0.2, 0.9, k))
    val = np.where(metal > 0, rng.uniform(0.6, 0.95, k),
                   rng.uniform(0.2, 0.85, k))
    import colorsys
    color = np.array([colorsys.hsv_to_rgb(h, s, v)
                      for h, s, v in zip(hue, sat, val)])
    lo, hi = roughness_range
    rough = rng.uniform(lo, hi, k)
    w = weight
    base_color = w @ torch.as_tensor(color)
    metallic = w @ torch.as_tensor(metal)
    roughness = w @ torch.as_tensor(rough)
    return (base_color.clamp(0, 1), metallic.clamp(0, 1),
            roughness.clamp(0, 1))


def svbrdf_scene(shape: Union[str, Tuple[Tensor, Tensor]] = 'sphere',
                 num_views: int = 50,
                 image_size: Tuple[int, int] = (256, 256),
                 envmap: Union[str, Tensor] = 'sun_sky',
                 materials: str = 'mixed',
                 roughness_range: Tuple[float, float] = (0.2, 0.8),
                 seed: int = 0, resolution: Optional[int] = None,
                 render_images: bool = True,
                 upper_hemisphere: bool = False,
                 camera_distance: float = 2.75,
                 fov_degrees: Optional[float] = None,
                 num_patches: int = 8,
                 envmap_size: Tuple[int, int] = (128, 256),
                 specular_samples: int = 96, light_samples: int = 128,
                 image_specular_samples: int = 16,
                 image_light_samples: int = 16,
                 dtype: torch.dtype = torch.float32) -> Data:
    r"""A synthetic multi-view capture of an object with a spatially varying
    principled BRDF under a distant environment map, whose ground truth is
    the full reflection integral, not the spherical-harmonic approximation
    of the method under test. The method is that of "Uncertainty for SVBRDF
    acquisition using frequency analysis" (Wiersma et al., SIGGRAPH 2025);
    the ground truth (:mod:`tg_intrinsic.geometry.appearance.lighting`) is

    .. math::
        B(\mathbf{p}, \omega_o) = \int_{\Omega^+} f_r(\omega_i, \omega_o;
        b, m, r)\, L(\omega_i) \cos\theta_i\, d\omega_i,

    direct lighting only (no self-shadowing of the environment, no
    interreflections).

    The object is normalised into the unit ball (bounding-box centre at the
    origin, farthest vertex at distance 1). The materials are smooth random
    fields: :obj:`num_patches` patches with their own base colour,
    roughness (uniform in :obj:`roughness_range`) and metallic (1 for
    ``'metals'``, with coloured base colours; 0 for ``'dielectrics'``;
    both for ``'mixed'``), blended softly across patch borders. The
    :obj:`num_views` cameras sit on a Fibonacci sphere (upper hemisphere
    only if :obj:`upper_hemisphere`) of radius :obj:`camera_distance`,
    looking at the origin, with a field of view that fits the unit ball
    with a 10% margin unless :obj:`fov_degrees` is given.

    Observations are exact per vertex: ``obs_radiance[i, v]`` is
    :math:`B(\mathbf{p}_i, \omega_{iv})` with :math:`\omega_{iv}` the unit
    direction ``obs_dir`` from the vertex to camera :math:`v`'s centre, and
    ``obs_mask[i, v]`` says whether camera :math:`v` sees the vertex: it
    projects inside the image in front of the camera,
    :math:`\mathbf{n}_i \cdot \omega_{iv} > 0`, and the segment to the
    camera crosses no triangle (exact ray casting,
    :func:`~tg_intrinsic.geometry.appearance.raster.point_visibility`).
    ``obs_radiance`` is 0 where ``obs_mask`` is False.

    Args:
        shape (str or tuple, optional): ``'sphere'`` (an icosphere),
            ``'uv_sphere'`` (a UV-mapped latitude-longitude unit sphere,
            :func:`~tg_intrinsic.geometry.texture.uv_sphere`, with its
            exact normals; for
            :class:`~tg_intrinsic.transforms.TextureTexels`), a
            mesh ``(vertices [n, 3], faces)`` (a torch ``[3, F]`` long
            tensor in PyG layout or a numpy ``[F, 3]`` array as trimesh
            gives), or the path of a mesh file read with trimesh
            (``process=False``). (default: :obj:`'sphere'`)
        num_views (int, optional): Cameras. (default: :obj:`50`)
        image_size (tuple, optional): ``(height, width)``.
            (default: :obj:`(256, 256)`)
        envmap (str or torch.Tensor, optional): ``'sun_sky'`` (a sky with
            a sun at a random elevation of 20 to 60 degrees), an
            equirectangular :math:`(H, W, 3)` tensor, or the path of an HDR
            file. (default: :obj:`'sun_sky'`)
        materials (str, optional): ``'metals'``, ``'dielectrics'`` or
            ``'mixed'``. (default: :obj:`'mixed'`)
        roughness_range (tuple, optional): Patch roughness range inside
            :math:`[0, 1]`. (default: :obj:`(0.2, 0.8)`)
        seed (int, optional): Everything random (materials, sun, lattice
            shifts) follows from it. (default: :obj:`0`)
        resolution (int, optional): Icosphere subdivisions for
            ``'sphere'`` (default 4: 2562 vertices), latitude bands for
            ``'uv_sphere'`` (twice as many longitude bands; default 16:
            527 vertices); for a mesh, a target
            vertex count reached by edge-collapse decimation (closed
            manifold meshes only). (default: :obj:`None`)
        render_images (bool, optional): Also render ``images``.
            (default: :obj:`True`)
        upper_hemisphere (bool, optional): Cameras only above the
            :math:`z = 0` plane. (default: :obj:`False`)
        camera_distance (float, optional): In units of the bounding radius.
            (default: :obj:`2.75`)
        fov_degrees (float, optional): Vertical field of view.
            (default: :obj:`None`, fitted)
        num_patches (int, optional): Material patches. (default: :obj:`8`)
        envmap_size (tuple, optional): Size of the ``'sun_sky'`` map.
            (default: :obj:`(128, 256)`)
        specular_samples (int, optional): For ``obs_radiance``, see
            :func:`~tg_intrinsic.geometry.appearance.lighting.render_radiance`.
            (default: :obj:`96`)
        light_samples (int, optional): Ditto. (default: :obj:`128`)
        image_specular_samples (int, optional): For ``images`` (noisier:
            they are for looking at; ``obs_radiance`` is the accurate
            quantity). (default: :obj:`16`)
        image_light_samples (int, optional): Ditto. (default: :obj:`16`)
        dtype (torch.dtype, optional): Of the float outputs (``images``
            are always float32). (default: :obj:`torch.float32`)

    Returns:
        :class:`~torch_geometric.data.Data` with ``pos`` :math:`(N, 3)`,
        ``normal`` :math:`(N, 3)` (area weighted), ``face`` :math:`(3, F)`,
        ``base_color`` :math:`(N, 3)`, ``metallic`` :math:`(N)`,
        ``roughness`` :math:`(N)`, ``envmap`` :math:`(H_e, W_e, 3)`,
        ``intrinsics`` :math:`(V, 3, 3)`, ``extrinsics`` :math:`(V, 3, 4)`,
        ``obs_radiance`` :math:`(N, V, 3)`, ``obs_dir`` :math:`(N, V, 3)`,
        ``obs_mask`` :math:`(N, V)` and, if :obj:`render_images`,
        ``images`` :math:`(V, H, W, 3)` (background 0); ``uv``
        :math:`(N, 2)` for ``'uv_sphere'``.

    Raises:
        ValueError: On bad arguments, and when a camera sees no vertex at
            all (cannot happen with the default cameras).
    """
    if not (isinstance(shape, (tuple, list)) or isinstance(shape, os.PathLike)
            or (isinstance(shape, str))):
        raise ValueError(f"'shape' must be 'sphere', (vertices, faces) or "
                         f"a path, got {type(shape)}")
    num_views = check_positive_int(num_views, 'num_views', 1)
    height, width = check_image_size(image_size)
    if materials not in MATERIALS:
        raise ValueError(f"'materials' must be one of {MATERIALS}, got "
                         f"{materials!r}")
    lo, hi = roughness_range
    if not (0 <= lo <= hi <= 1):
        raise ValueError(f"'roughness_range' must be (low, high) with 0 <= "
                         f"low <= high <= 1, got {roughness_range!r}")
    seed = check_positive_int(seed, 'seed', 0)
    num_patches = check_positive_int(num_patches, 'num_patches', 1)
    if not (camera_distance > 1):
        raise ValueError(f"'camera_distance' must exceed 1 (the bounding "
                         f"radius), got {camera_distance!r}")
    envmap_size = check_image_size(envmap_size, 'envmap_size')
    if dtype not in (torch.float32, torch.float64):
        raise ValueError(f"'dtype' must be torch.float32 or torch.float64, "
                         f"got {dtype}")

    uv = None
    if isinstance(shape, str) and shape == 'uv_sphere':
        # the unit sphere already; its exact normals, not the faceted ones
        rows = 16 if resolution is None else check_positive_int(
            resolution, 'resolution', 2)
        pos, face, uv = uv_sphere(rows, 2 * rows)
        normal = pos.clone()
    else:
        pos, face = _load_shape(shape, resolution, seed)
        pos = _normalise(pos)
        normal = vertex_normals(pos, face)
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0]))
    base_color, metallic, roughness = _materials(
        pos, materials, (lo, hi), num_patches, rng)
    env = _make_envmap(envmap, seed, envmap_size)

    # cameras on a Fibonacci sphere (or its upper half)
    if upper_hemisphere:
        k = torch.arange(num_views, dtype=torch.float64)
        z = 1 - (k + 0.5) / num_views
        ring = torch.sqrt(1 - z * z)
        phi = k * math.pi * (3 - math.sqrt(5))
        direction = torch.stack([ring * torch.cos(phi),
                                 ring * torch.sin(phi), z], 1)
    else:
        direction = fibonacci_sphere(num_views)
    if fov_degrees is None:
        fov_degrees = 2 * math.degrees(math.asin(1 / camera_distance)) * 1.1
    intrinsics, extrinsics = look_at_cameras(
        camera_distance * direction, fov_degrees=fov_degrees,
        image_size=(height, width))

    centres = camera_centers(extrinsics)
    to_camera = centres[None] - pos[:, None]
    obs_dir = to_camera / to_camera.norm(dim=-1, keepdim=True)
    facing = (obs_dir * normal[:, None]).sum(-1) > 0
    visible = point_visibility(pos, pos, face, intrinsics, extrinsics,
                               height, width)
    obs_mask = facing & visible
    empty = (~obs_mask.any(0)).nonzero().flatten()
    if empty.numel():
        raise ValueError(f"camera(s) {empty[:5].tolist()} see no vertex of "
                         f"the object; move them or drop them")
    obs_radiance = render_radiance(
        normal, base_color, metallic, roughness, obs_dir, env.double(),
        specular_samples=specular_samples, light_samples=light_samples,
        mask=obs_mask, seed=seed)

    data = Data(pos=pos.to(dtype), normal=normal.to(dtype), face=face,
                base_color=base_color.to(dtype), metallic=metallic.to(dtype),
                roughness=roughness.to(dtype), envmap=env.to(dtype),
                intrinsics=intrinsics.to(dtype),
                extrinsics=extrinsics.to(dtype),
                obs_radiance=obs_radiance.to(dtype),
                obs_dir=obs_dir.to(dtype), obs_mask=obs_mask)
    if uv is not None:
        data.uv = uv.to(dtype)
    if render_images:
        data.images = _render_images(
            pos, face, normal, base_color, metallic, roughness, intrinsics,
            extrinsics, height, width, env.double(),
            specular_samples=image_specular_samples,
            light_samples=image_light_samples, seed=seed + 1)
    return data
