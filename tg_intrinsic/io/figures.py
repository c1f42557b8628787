r"""Figures a person can read: values drawn on a surface from a few
viewpoints with a titled colour bar, and line plots, saved atomically as
PNG.

Meshes are rasterised (:func:`~tg_intrinsic.geometry.appearance.raster.rasterize`),
values interpolated by the barycentrics of each pixel's triangle and shaded
by a headlight, :math:`c = \text{cmap}(v) (0.35 + 0.65 |n \cdot d|)`.
Point clouds are splatted as discs as wide as their spacing, nearest
point in front (:func:`splat_index`).
"""
import math
from typing import Optional, Sequence

import numpy as np
import torch

from tg_intrinsic.geometry.appearance.splat import splat_index
from tg_intrinsic.utils import atomic_write

# Viewing directions (from the object towards the camera), with a world z
# up on screen: three-quarter views from front-left, front-right and above.
VIEWS = {
    'front-left': (-1.0, -1.6, 0.7),
    'front-right': (1.6, -1.0, 0.7),
    'back': (0.6, 1.6, 0.5),
    'top': (0.2, -0.4, 1.6),
}


def _pyplot():
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    return plt


def save_figure(fig, path: str, dpi: int = 110) -> str:
    """Saves a matplotlib figure as PNG atomically and closes it."""
    plt = _pyplot()
    atomic_write(path, lambda f: fig.savefig(f, format='png', dpi=dpi), 'wb')
    plt.close(fig)
    return path


def _cameras(pos: torch.Tensor, directions, size: int):
    from tg_intrinsic.geometry.appearance.cameras import look_at_cameras
    centre = 0.5 * (pos.max(0).values + pos.min(0).values)
    radius = float((pos - centre).norm(dim=1).max()) or 1.0
    direction = torch.tensor(directions, dtype=torch.float64)
    direction = direction / direction.norm(dim=1, keepdim=True)
    distance = 4.0 * radius
    fov = 2 * math.degrees(math.asin(1 / 4.0)) * 1.1
    return look_at_cameras(centre + distance * direction, target=centre,
                           fov_degrees=fov, image_size=(size, size))


def value_range(values, vmin=None, vmax=None):
    """The colour range ``(lo, hi)`` of ``values``: the given limits, else
    the finite extremes; a constant signal gets a range of width 1."""
    values = np.asarray(values, dtype=np.float64)
    lo = float(np.nanmin(values)) if vmin is None else float(vmin)
    hi = float(np.nanmax(values)) if vmax is None else float(vmax)
    return (lo, hi) if hi > lo else (lo, lo + 1.0)


def render_surface(pos, face=None, values=None, colors=None, normal=None,
                   cmap='viridis', vmin=None, vmax=None,
                   views: Sequence[str] = ('front-left', 'front-right'),
                   size: int = 360):
    """Shaded RGB images ``(V, size, size, 3)`` in [0, 1] (white
    background) of a mesh (``face`` :math:`(3, F)`, PyG's layout) or a
    point cloud (``face`` None) coloured by per-vertex ``values``
    :math:`(N)` through ``cmap``, or by ``colors`` :math:`(N, 3)` in
    [0, 1], or grey."""
    import matplotlib
    from tg_intrinsic.geometry.appearance.raster import rasterize
    pos = torch.as_tensor(np.asarray(pos, dtype=np.float64))
    n = pos.size(0)
    if colors is not None:
        rgb = np.clip(np.asarray(colors, dtype=np.float64).reshape(n, 3),
                      0, 1)
    elif values is not None:
        values = np.asarray(values, dtype=np.float64).reshape(n)
        lo, hi = value_range(values, vmin, vmax)
        scaled = (values - lo) / (hi - lo)
        rgb = matplotlib.colormaps[cmap](np.clip(scaled, 0, 1))[:, :3]
        rgb[np.isnan(values)] = 0.5
    else:
        rgb = np.full((n, 3), 0.75)
    if face is not None:
        # one layout: a mesh of 3 triangles would make a guess ambiguous
        face = torch.as_tensor(np.asarray(face, dtype=np.int64))
        if face.dim() != 2 or face.size(0) != 3:
            raise ValueError(f"face must have shape (3, F), PyG's layout, "
                             f"got {tuple(face.shape)}")
        face = face.contiguous()
        from tg_intrinsic.geometry import vertex_normals
        normal = vertex_normals(pos, face).numpy()  # smooth shading
    K, E = _cameras(pos, [VIEWS[v] for v in views], size)
    images = np.ones((len(views), size, size, 3))
    for v in range(len(views)):
        R = E[v, :, :3]
        look = R[2].numpy()  # camera forward, world coordinates
        if face is not None:
            face_id, bary, _ = rasterize(pos, face, K[v], E[v], size, size)
            hit = face_id.numpy() >= 0
            fid = face_id.numpy()[hit]
            corners = face.numpy()[:, fid].T  # (hits, 3)
            weight = bary.numpy()[hit][..., None]
            colour = (weight * rgb[corners]).sum(1)
            shade = np.abs((weight * normal[corners]).sum(1) @ look)
        else:
            index = splat_index(pos, K[v], E[v], (size, size))
            hit = index >= 0
            colour = rgb[index[hit]]
            if normal is not None:
                nrm = np.asarray(normal, dtype=np.float64).reshape(n, 3)
                shade = np.abs(nrm[index[hit]] @ look)
            else:
                shade = np.ones(int(hit.sum()))
        images[v][hit] = colour * (0.35 + 0.65 * shade[:, None])
    return images


def draw_surface(path: str, pos, face=None, values=None, colors=None,
                 normal=None, title: str = '', label: str = '',
                 cmap: str = 'viridis', vmin: Optional[float] = None,
                 vmax: Optional[float] = None,
                 views: Sequence[str] = ('front-left', 'front-right'),
                 size: int = 360) -> str:
    """Draws per-vertex ``values`` (with a colour bar labelled ``label``,
    which should carry the units) or ``colors`` on a mesh or point cloud
    from the named ``views`` (keys of :data:`VIEWS`) and saves the figure
    as PNG at ``path`` atomically. Returns ``path``."""
    plt = _pyplot()
    import matplotlib
    images = render_surface(pos, face, values, colors, normal, cmap, vmin,
                            vmax, views, size)
    fig, axes = plt.subplots(1, len(views) + (values is not None and colors
                                              is None),
                             figsize=(3.2 * len(views) + 1.0, 3.6),
                             gridspec_kw=dict(
                                 width_ratios=[1] * len(views) + (
                                     [0.06] if values is not None and colors
                                     is None else [])))
    axes = np.atleast_1d(axes)
    for ax, image, view in zip(axes, images, views):
        ax.imshow(image, interpolation='lanczos')
        ax.set_title(f'view from {view}', fontsize=9)
        ax.set_axis_off()
    if values is not None and colors is None:
        norm = matplotlib.colors.Normalize(*value_range(values, vmin, vmax))
        fig.colorbar(matplotlib.cm.ScalarMappable(norm, cmap), cax=axes[-1],
                     label=label)
    fig.suptitle(title)
    fig.tight_layout()
    return save_figure(fig, path)


def line_figure(path: str, series, title: str, xlabel: str, ylabel: str,
                logy: bool = False, integer_x: bool = False,
                ylim=None, hlines=(), vlines=()) -> str:
    """A line plot of ``series`` (a list of ``(label, x, y, style)``) with
    a title, axis labels and a legend; ``hlines`` and ``vlines`` add
    labelled horizontal and vertical reference lines ``(label, value,
    linestyle)``. Saved atomically as PNG."""
    plt = _pyplot()
    from matplotlib.ticker import MaxNLocator
    fig, ax = plt.subplots(figsize=(5.6, 3.8))
    for label, x, y, style in series:
        ax.plot(x, y, style, label=label)
    for label, y, style in hlines:
        ax.axhline(y, linestyle=style, color='grey', label=label)
    for label, x, style in vlines:
        ax.axvline(x, linestyle=style, color='black', label=label)
    if logy:
        ax.set_yscale('log')
    if ylim is not None:
        ax.set_ylim(*ylim)
    if integer_x:
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return save_figure(fig, path)


def draw_cameras(path: str, pos, intrinsics, extrinsics, image_size,
                 title: str = '', max_points: int = 4000) -> str:
    r"""A figure of a capture's cameras around its surface, to see at once
    whether they look at it: the surface's points (grey) and every
    camera's frustum (its centre, the four image corners at a tenth of the
    scene's size, the optical axis in red) in a perspective view, from
    above (:math:`x, y`) and from the side (:math:`x, z`); world :math:`z`
    up. Cameras that see none of the points are drawn in orange and
    counted in the title.

    Args:
        path (str): The PNG file.
        pos (torch.Tensor): Surface points :math:`(N, 3)`.
        intrinsics (torch.Tensor): :math:`(V, 3, 3)`.
        extrinsics (torch.Tensor): :math:`(V, 3, 4)` (world to camera).
        image_size (tuple): :math:`(H, W)` of the photographs.
        title (str, optional): The first line of the title.
        max_points (int, optional): Points drawn at most (a random
            subset). (default: :obj:`4000`)
    """
    from tg_intrinsic.geometry.appearance.cameras import project
    plt = _pyplot()
    pos = torch.as_tensor(pos).detach().cpu().double()
    K = torch.as_tensor(intrinsics).detach().cpu().double()
    E = torch.as_tensor(extrinsics).detach().cpu().double()
    height, width = image_size
    uv, depth = project(pos, K, E)
    sees = ((depth > 0) & (uv[..., 0] >= 0) & (uv[..., 0] < width)
            & (uv[..., 1] >= 0) & (uv[..., 1] < height)).any(1)
    size = float((pos.max(0).values - pos.min(0).values).norm()) or 1.0
    R, t = E[:, :, :3], E[:, :, 3]
    centres = -(R.transpose(1, 2) @ t.unsqueeze(-1)).squeeze(-1)
    corners = torch.tensor([[0, 0], [width, 0], [width, height],
                            [0, height]], dtype=torch.float64)
    pixels = torch.cat([corners, torch.ones(4, 1, dtype=torch.float64)], 1)
    # camera-space rays of the corners and the axis, at depth size / 10
    rays = torch.linalg.solve(K.unsqueeze(1), pixels.T.unsqueeze(0)
                              .expand(len(K), 3, 4).transpose(1, 2)
                              .unsqueeze(-1)).squeeze(-1)
    rays = torch.cat([rays, torch.tensor([0.0, 0, 1]).expand(len(K), 1, 3)],
                     1) * (0.1 * size)
    tips = centres.unsqueeze(1) + rays @ R  # R^T x, row-wise
    shown = pos[torch.randperm(len(pos), generator=torch.Generator()
                               .manual_seed(0))[:max_points]].numpy()
    fig = plt.figure(figsize=(13, 4.6))
    panels = [fig.add_subplot(1, 3, 1, projection='3d'),
              fig.add_subplot(1, 3, 2), fig.add_subplot(1, 3, 3)]
    for panel, axes in zip(panels, (None, (0, 1), (0, 2))):
        keep = (0, 1, 2) if axes is None else axes

        def xy(points):
            return [points[..., k] for k in keep]

        panel.scatter(*xy(shown), s=1, c='0.6', depthshade=False) \
            if axes is None else panel.scatter(*xy(shown), s=1, c='0.6')
        for v in range(len(K)):
            colour = 'tab:blue' if bool(sees[v]) else 'tab:orange'
            c, tip = centres[v].numpy(), tips[v].numpy()
            for k in range(4):
                panel.plot(*xy(np.stack([c, tip[k]])), color=colour, lw=0.6)
                panel.plot(*xy(np.stack([tip[k], tip[(k + 1) % 4]])),
                           color=colour, lw=0.6)
            panel.plot(*xy(np.stack([c, tip[4] * 3 - 2 * c])), color='red',
                       lw=0.6)
        if axes is not None:
            panel.set_aspect('equal')
            panel.set_xlabel('xyz'[axes[0]])
            panel.set_ylabel('xyz'[axes[1]])
            panel.set_title('from above' if axes == (0, 1) else
                            'from the side')
        else:
            panel.set_box_aspect((1, 1, 1))
    blind = int((~sees).sum())
    fig.suptitle(f"{title}\n{len(K)} cameras, {len(K) - blind} see the "
                 f"surface" + (f", {blind} (orange) see none of it"
                               if blind else ''))
    return save_figure(fig, path)
