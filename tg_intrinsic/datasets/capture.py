r"""Rendered photographs of a mesh with per-vertex materials: the capture
generator of the synthetic SVBRDF scenes."""
import numpy as np
import torch
from torch import Tensor

from tg_intrinsic.geometry.appearance.cameras import camera_centers
from tg_intrinsic.geometry.appearance.envmap import check_envmap
from tg_intrinsic.geometry.appearance.lighting import render_radiance
from tg_intrinsic.geometry.appearance.raster import (cameras_numpy,
                                                     image_height_width,
                                                     mesh_numpy, rasterize)
from tg_intrinsic.geometry.checks import (check_points, check_unit_interval,
                                          check_unit_rows)

__all__ = ['render_images']


def render_images(vertices: Tensor, faces: Tensor, vertex_normals: Tensor,
                  base_color: Tensor, metallic: Tensor, roughness: Tensor,
                  intrinsics: Tensor, extrinsics: Tensor, height: int,
                  width: int, envmap: Tensor, specular_samples: int = 16,
                  light_samples: int = 16, diffuse_resolution: int = 256,
                  seed: int = 0) -> Tensor:
    r"""Images of a mesh with per-vertex principled materials under a
    distant environment map. The steps:
    :func:`~tg_intrinsic.geometry.appearance.raster.rasterize` every view,
    interpolate position, normal (renormalised) and material with the
    perspective correct barycentrics of the pixel centre's hit, and shade
    it towards the camera centre with
    :func:`~tg_intrinsic.geometry.appearance.lighting.render_radiance`,

    .. math::
        I_v(i, j) = B\big(\mathbf{n}(\mathbf{x}),
        \tfrac{\mathbf{c}_v - \mathbf{x}}{\|\mathbf{c}_v - \mathbf{x}\|}
        \big), \quad \mathbf{x} = \textstyle\sum_k \lambda_k
        \mathbf{p}_k.

    One sample per pixel (no anti-aliasing); the background is 0, and so
    is a pixel whose interpolated normal faces away from the camera (a thin
    rim at silhouettes of smooth-shaded meshes). Every pixel gets its own
    lattice shifts, so the specular noise is independent between pixels;
    the defaults are coarser than :func:`~tg_intrinsic.geometry.appearance.lighting.render_radiance`'s because there
    are many pixels, and the diffuse irradiance comes from a table over
    normals (``irradiance_table=True``).

    Args:
        vertices (torch.Tensor): :math:`(n, 3)`.
        faces (torch.Tensor): :math:`(3, F)`.
        vertex_normals (torch.Tensor): :math:`(n, 3)`.
        base_color (torch.Tensor): :math:`(n, 3)`.
        metallic (torch.Tensor): :math:`(n)`.
        roughness (torch.Tensor): :math:`(n)`.
        intrinsics (torch.Tensor): :math:`(V, 3, 3)`.
        extrinsics (torch.Tensor): :math:`(V, 3, 4)`.
        height (int): Image rows.
        width (int): Image columns.
        envmap (torch.Tensor): :math:`(H_e, W_e, 3)`.
        specular_samples (int, optional): See :func:`~tg_intrinsic.geometry.appearance.lighting.render_radiance`.
            (default: :obj:`16`)
        light_samples (int, optional): See :func:`~tg_intrinsic.geometry.appearance.lighting.render_radiance` (per
            pixel here). (default: :obj:`16`)
        diffuse_resolution (int, optional): See :func:`~tg_intrinsic.geometry.appearance.lighting.render_radiance`.
            (default: :obj:`256`)
        seed (int, optional): Seed of the lattice shifts.
            (default: :obj:`0`)

    Returns:
        float32 :math:`(V, H, W, 3)` linear radiance.
    """
    Vt = check_points(vertices, 'vertices')
    n = Vt.size(0)
    V, F = mesh_numpy(Vt, faces)
    normal = check_unit_rows(vertex_normals, 'vertex_normals', (n, 3))
    base_color = check_unit_interval(base_color, 'base_color', (n, 3))
    metallic = check_unit_interval(metallic, 'metallic', (n, ))
    roughness = check_unit_interval(roughness, 'roughness', (n, ))
    K, E = cameras_numpy(intrinsics, extrinsics, batched=True)
    height, width = image_height_width(height, width)
    check_envmap(envmap)
    centres = camera_centers(torch.from_numpy(E)).numpy()
    pixel_index, attributes = [], []
    for v in range(K.shape[0]):  # one compiled rasterisation per view
        face_id, bary, _ = (t.numpy() for t in rasterize(
            Vt, faces, torch.from_numpy(K[v]), torch.from_numpy(E[v]),
            height, width))
        covered = np.nonzero(face_id.ravel() >= 0)[0]
        corners = F[face_id.ravel()[covered]]  # (M, 3)
        lam = bary.reshape(-1, 3)[covered][..., None]  # (M, 3, 1)
        pos = (lam * V[corners]).sum(1)
        nrm = (lam * normal[corners]).sum(1)
        bc = (lam * base_color.numpy()[corners]).sum(1)
        mr = np.stack([(lam[..., 0] * metallic.numpy()[corners]).sum(1),
                       (lam[..., 0] * roughness.numpy()[corners]).sum(1)],
                      1)
        view = centres[v] - pos
        pixel_index.append(v * height * width + covered)
        attributes.append(np.concatenate([nrm, bc, mr, view], 1))
    image = np.zeros((K.shape[0] * height * width, 3))
    if sum(len(p) for p in pixel_index):
        pixel_index = np.concatenate(pixel_index)
        a = torch.from_numpy(np.concatenate(attributes))
        nrm = a[:, :3]
        nrm = nrm / nrm.norm(dim=1, keepdim=True).clamp_min(1e-300)
        view = a[:, 8:11]
        view = view / view.norm(dim=1, keepdim=True)
        # interpolation can leave tiny excursions outside [0, 1]
        radiance = render_radiance(
            nrm, a[:, 3:6].clamp(0, 1), a[:, 6].clamp(0, 1),
            a[:, 7].clamp(0, 1), view[:, None], envmap,
            specular_samples=specular_samples, light_samples=light_samples,
            diffuse_resolution=diffuse_resolution, seed=seed,
            irradiance_table=True)
        image[pixel_index] = radiance[:, 0].numpy()
    return torch.from_numpy(image.reshape(K.shape[0], height, width, 3)
                            ).float()
