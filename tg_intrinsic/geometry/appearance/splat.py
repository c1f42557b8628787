"""Points splatted into one pinhole camera's pixels: which point each pixel
sees, for figures and texture maps of sampled surfaces."""
import numpy as np
import torch

from ..pointcloud.neighbors import knn
from .cameras import project

__all__ = ['splat_index']


def splat_index(pos: torch.Tensor, intrinsics: torch.Tensor,
                extrinsics: torch.Tensor, image_size) -> np.ndarray:
    """The point seen in each pixel of one pinhole camera (-1 for the
    background): points are splatted as squares as wide as their median
    nearest-neighbour spacing (at most 24 pixels), nearest in front, so
    a sampled surface reads as a surface and hides what lies behind it.

    Args:
        pos: Points :math:`(N, 3)`.
        intrinsics: :math:`(1, 3, 3)` or :math:`(3, 3)`.
        extrinsics: :math:`(1, 3, 4)` or :math:`(3, 4)`, world to camera.
        image_size: ``(height, width)``.
    """
    pos = pos.detach().cpu().double()
    height, width = image_size
    K = intrinsics.detach().cpu().double().reshape(1, 3, 3)
    E = extrinsics.detach().cpu().double().reshape(1, 3, 4)
    uv, depth = project(pos, K, E)
    uv, depth = uv[0], depth[0]
    inside = (depth > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < width) \
        & (uv[:, 1] >= 0) & (uv[:, 1] < height)
    image = np.full((height, width), -1, dtype=np.int64)
    if not bool(inside.any()):
        return image
    if pos.size(0) > 1:
        edge = knn(pos, 1)
        spacing = float((pos[edge[0]] - pos[edge[1]]).norm(dim=-1).median())
    else:
        spacing = 0.0
    pixels = spacing * float(K[0, 0, 0]) / float(depth[inside].median())
    reach = int(min(max(round(0.75 * pixels), 1), 24))
    # paint far to near so the nearest point wins each pixel
    order = torch.argsort(depth, descending=True)
    order = order[inside[order]]
    col = uv[order, 0].floor().long().numpy()
    row = uv[order, 1].floor().long().numpy()
    index = order.numpy()
    depth_image = np.full((height, width), np.inf)
    point_depth = depth[order].numpy()
    for dy in range(-reach, reach + 1):
        for dx in range(-reach, reach + 1):
            if dx * dx + dy * dy > reach * reach + reach:
                continue  # round splats
            r = np.clip(row + dy, 0, height - 1)
            c = np.clip(col + dx, 0, width - 1)
            # numpy assignment keeps the last write: the nearest point
            nearer = point_depth <= depth_image[r, c]
            depth_image[r[nearer], c[nearer]] = point_depth[nearer]
            image[r[nearer], c[nearer]] = index[nearer]
    return image
