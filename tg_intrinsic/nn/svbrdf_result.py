import os
from dataclasses import dataclass, field
from typing import List, Optional, Tuple

import numpy as np
import torch
from torch import Tensor

from tg_intrinsic.utils import atomic_write


@dataclass
class SVBRDFResult:
    r"""Recovered principled parameter maps of
    :meth:`~tg_intrinsic.nn.FrequencySVBRDF.fit` and their uncertainty.

    Attributes:
        base_color (torch.Tensor): :math:`(N, 3)`.
        metallic (torch.Tensor): :math:`(N)`.
        roughness (torch.Tensor): :math:`(N)`.
        entropy (torch.Tensor): Normalised entropy :math:`(N)` (or
            :obj:`None`).
        loss (list): Loss per step (the last entry after the final step).
        seconds (float): Wall time of the fit.
        texture_shape (tuple): ``(H, W)`` when the points are texels.
    """
    base_color: Tensor
    metallic: Tensor
    roughness: Tensor
    entropy: Optional[Tensor] = None
    loss: List[float] = field(default_factory=list)
    seconds: float = 0.0
    texture_shape: Optional[Tuple[int, int]] = None

    def maps(self) -> dict:
        """The maps as numpy arrays (reshaped to textures if texels)."""
        out = {'base_color': self.base_color, 'metallic': self.metallic,
               'roughness': self.roughness}
        if self.entropy is not None:
            out['entropy'] = self.entropy
        out = {k: v.detach().cpu().numpy() for k, v in out.items()}
        if self.texture_shape is not None:
            out = {k: v.reshape(self.texture_shape + v.shape[1:])
                   for k, v in out.items()}
        return out

    def save(self, directory: str, pos: Tensor = None,
             intrinsics: Tensor = None, extrinsics: Tensor = None,
             image_size=(512, 512)) -> List[str]:
        """Writes ``maps.npz`` and one PNG per map (entropy in the turbo
        colormap) into :obj:`directory`, each file atomically. Texel maps
        are written as textures; point maps are splatted into one view
        (the given camera, else an orthographic view from above, along
        :math:`-z`).
        Returns the written paths."""
        import matplotlib
        maps = self.maps()
        paths = [os.path.join(directory, 'maps.npz')]
        atomic_write(paths[0], lambda f: np.savez(f, **maps), 'wb')
        turbo = matplotlib.colormaps['turbo']
        if self.texture_shape is None:
            index = _splat_index(pos, intrinsics, extrinsics, image_size)
        for name, value in maps.items():
            if self.texture_shape is None:
                value = np.where((index >= 0).reshape(index.shape + (1, ) * (
                    value.ndim - 1)), value[index.clip(0)], np.nan)
            if name == 'entropy':
                image = turbo(np.nan_to_num(value, nan=0.0))[..., :3]
                image[np.isnan(value)] = 0
            elif value.ndim == 2:
                image = np.repeat(np.nan_to_num(value)[..., None], 3, -1)
            else:
                image = np.nan_to_num(value)
            image = (np.clip(image, 0, 1) * 255 + 0.5).astype(np.uint8)
            path = os.path.join(directory, f'{name}.png')
            atomic_write(path, lambda f, im=image: _write_png(f, im), 'wb')
            paths.append(path)
        return paths


def _write_png(f, image):
    import matplotlib.pyplot as plt
    plt.imsave(f, image, format='png')


def _splat_index(pos, intrinsics, extrinsics, image_size) -> np.ndarray:
    """The point seen in each pixel (-1 for background), points drawn as
    squares from back to front."""
    from tg_intrinsic.geometry.cameras import project, splat_depth
    if pos is None:
        raise ValueError("saving point maps as images needs 'pos' (and "
                         "optionally one camera); texel maps need "
                         "texture_shape")
    pos = pos.detach().cpu().double()
    height, width = image_size
    if intrinsics is None or extrinsics is None:
        centre = (pos.max(0).values + pos.min(0).values) / 2
        extent = float((pos - centre).abs().max()) * 1.05
        uv = torch.stack([(pos[:, 0] - centre[0]) / extent,
                          -(pos[:, 1] - centre[1]) / extent], -1)
        uv = (uv + 1) / 2 * torch.tensor([width, height], dtype=uv.dtype)
        # looking down -z from above: the highest points are nearest
        uv, depth = uv[None], (centre[2] + 2 * extent - pos[:, 2])[None]
    else:
        uv, depth = project(pos, intrinsics[:1].cpu().double(),
                            extrinsics[:1].cpu().double())
    inside = (depth > 0) & (uv[..., 0] >= 0) & (uv[..., 0] < width) \
        & (uv[..., 1] >= 0) & (uv[..., 1] < height)
    # splats as wide as the points' median spacing on the surface, so the
    # surface reads as a surface and hides what lies behind it
    from tg_intrinsic.geometry import knn
    edge = knn(pos, 1) if pos.size(0) > 1 else None
    spacing = float((pos[edge[0]] - pos[edge[1]]).norm(dim=-1).median()) \
        if edge is not None else 0.0
    if intrinsics is None or extrinsics is None:
        pixels = spacing * width / (2 * extent)
    else:
        pixels = spacing * float(intrinsics[0, 0, 0]) / float(
            depth[inside].median()) if bool(inside.any()) else 1.0
    reach = int(min(max(round(pixels), 1), 24))
    radius = torch.full_like(depth, reach, dtype=torch.long)
    buffer = splat_depth(uv, depth, inside, radius, height, width)[0]
    # paint back to front so the nearest point wins each pixel
    order = torch.argsort(depth[0], descending=True)
    order = order[inside[0, order]]
    image = np.full((height, width), -1, dtype=np.int64)
    col = uv[0, order, 0].floor().long()
    row = uv[0, order, 1].floor().long()
    for dy in range(-reach, reach + 1):
        for dx in range(-reach, reach + 1):
            r, c = (row + dy).clamp(0, height - 1), (col + dx).clamp(
                0, width - 1)
            front = depth[0, order] <= buffer[r, c] + 1e-9 + 0.02 * float(
                depth[0].abs().max())
            image[r[front].numpy(), c[front].numpy()] = order[front].numpy()
    return image
