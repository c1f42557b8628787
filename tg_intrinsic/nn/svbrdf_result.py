import math
import os
from dataclasses import dataclass, field
from typing import List, Optional, Tuple

import numpy as np
import torch
from torch import Tensor

from tg_intrinsic.geometry.appearance.splat import splat_index
from tg_intrinsic.utils import atomic_write

# What each map is, for figures and colour-mapped exports: a title, the
# colour-bar label (with units), the colormap of scalar maps and the range
# that colormaps and 8-bit images span.
MAP_INFO = {
    'base_color': {'title': 'base colour', 'label': 'linear RGB in [0, 1]',
                   'cmap': None, 'range': (0.0, 1.0)},
    'metallic': {'title': 'metallic', 'label': 'metallic (0 dielectric, '
                 '1 metal)', 'cmap': 'viridis', 'range': (0.0, 1.0)},
    'roughness': {'title': 'roughness', 'label': 'perceptual roughness r '
                  '(GGX alpha = r^2)', 'cmap': 'viridis', 'range': (0.0, 1.0)},
    'entropy': {'title': 'uncertainty', 'label': 'normalised entropy (0 '
                'certain, 1 unknown)', 'cmap': 'turbo', 'range': (0.0, 1.0)},
    'roughness_std': {'title': 'roughness uncertainty', 'label':
                      'roughness std (top: 0.1 or more)',
                      'cmap': 'turbo', 'range': (0.0, 0.1)},
}
#: The uncertainty maps, drawn through their colormap in images.
UNCERTAINTY_MAPS = ('entropy', 'roughness_std')


def scaled_to_range(name: str, value: np.ndarray) -> np.ndarray:
    """``value`` of the map ``name`` scaled from its :data:`MAP_INFO`
    range to [0, 1] and clipped, as colormaps and 8-bit images take it."""
    low, high = MAP_INFO[name]['range']
    return np.clip((value - low) / (high - low), 0.0, 1.0)


@dataclass
class SVBRDFResult:
    r"""Recovered principled parameter maps of
    :meth:`~tg_intrinsic.nn.FrequencySVBRDF.fit` and their uncertainty.

    Attributes:
        base_color (torch.Tensor): :math:`(N, 3)`.
        metallic (torch.Tensor): :math:`(N)`.
        roughness (torch.Tensor): :math:`(N)`.
        entropy (torch.Tensor): Normalised entropy :math:`(N)` of the
            spectrum's likelihood (the paper's uncertainty of the
            spherical-harmonic recovery), or :obj:`None`.
        roughness_std (torch.Tensor): Estimated standard deviation of the
            roughness :math:`(N)` at the fitted parameters (see
            :meth:`~tg_intrinsic.nn.FrequencySVBRDF.refine`), or
            :obj:`None`.
        loss (list): Loss per step (the last entry after the final step).
        seconds (float): Wall time of the fit.
        texture_shape (tuple): ``(H, W)`` when the points are texels.
        texel_index (torch.Tensor): :math:`(N)` flat row-major texel of
            every point when they are some of the texels (see
            :class:`~tg_intrinsic.transforms.TextureTexels`); :obj:`None`
            when they are all :math:`HW` texels, row by row.
        pipeline (dict): What :meth:`~tg_intrinsic.nn.FrequencySVBRDF.recover`
            ran: its steps, their seconds, the fit and refinement options,
            and why the refinement did not run (or :obj:`None`).
    """
    base_color: Tensor
    metallic: Tensor
    roughness: Tensor
    entropy: Optional[Tensor] = None
    roughness_std: Optional[Tensor] = None
    loss: List[float] = field(default_factory=list)
    seconds: float = 0.0
    texture_shape: Optional[Tuple[int, int]] = None
    texel_index: Optional[Tensor] = None
    pipeline: Optional[dict] = None

    def maps(self) -> dict:
        """The maps as numpy arrays; texel maps as :math:`(H, W[, 3])`
        textures. With a :obj:`texel_index`, the texels without a point
        are NaN and a boolean :math:`(H, W)` ``coverage`` map (True where a
        point is) comes last."""
        out = {'base_color': self.base_color, 'metallic': self.metallic,
               'roughness': self.roughness}
        for name in UNCERTAINTY_MAPS:
            if getattr(self, name) is not None:
                out[name] = getattr(self, name)
        out = {k: v.detach().cpu().numpy() for k, v in out.items()}
        if self.texture_shape is None:
            if self.texel_index is not None:
                raise ValueError("'texel_index' needs a 'texture_shape'")
            return out
        shape = tuple(self.texture_shape)
        if self.texel_index is None:
            return {k: v.reshape(shape + v.shape[1:]) for k, v in out.items()}
        index = _texel_positions(self.texel_index, shape, len(
            self.roughness))
        textures = {}
        for k, v in out.items():
            texture = np.full((math.prod(shape), ) + v.shape[1:], np.nan,
                              dtype=v.dtype)
            texture[index] = v
            textures[k] = texture.reshape(shape + v.shape[1:])
        coverage = np.zeros(math.prod(shape), dtype=bool)
        coverage[index] = True
        textures['coverage'] = coverage.reshape(shape)
        return textures

    def save_npz(self, path: str) -> str:
        """Writes :meth:`maps` as ``.npz`` atomically; returns ``path``."""
        maps = self.maps()
        atomic_write(path, lambda f: np.savez(f, **maps), 'wb')
        return path

    def save(self, directory: str, pos: Tensor = None,
             intrinsics: Tensor = None, extrinsics: Tensor = None,
             image_size=(512, 512), face: Tensor = None) -> List[str]:
        r"""Writes ``maps.npz`` and one PNG per map into :obj:`directory`,
        each file atomically: the base colour as RGB, metallic and
        roughness as grey values (so texel maps are usable textures), the
        uncertainty maps (:data:`UNCERTAINTY_MAPS`) through the colormap
        of :data:`MAP_INFO` (turbo) over its range. Texel maps are written
        as textures; with a :obj:`texel_index` the texels without a point
        are black (NaN in ``maps.npz``) and ``coverage.png`` is white
        where a point is. Point maps are drawn as seen by one
        camera (the first of :obj:`intrinsics` / :obj:`extrinsics`, else
        one above the object looking down :math:`-z`): on the surface
        when :obj:`face` is given (rasterised,
        :func:`~tg_intrinsic.geometry.appearance.raster.rasterize`, values
        interpolated by the barycentrics), else as splats as wide as the
        point spacing (:func:`~tg_intrinsic.geometry.appearance.splat.splat_index`); the
        background is black.

        Args:
            directory (str): Created if missing.
            pos (torch.Tensor, optional): Points :math:`(N, 3)` (needed for
                point maps).
            intrinsics (torch.Tensor, optional): :math:`(V, 3, 3)` or
                :math:`(3, 3)`.
            extrinsics (torch.Tensor, optional): :math:`(V, 3, 4)` or
                :math:`(3, 4)`, world to camera (OpenCV).
            image_size (tuple, optional): ``(height, width)`` of point-map
                images. (default: :obj:`(512, 512)`)
            face (torch.Tensor, optional): Triangles :math:`(3, F)` of a
                mesh whose vertices are the points. (default: :obj:`None`)

        Returns:
            The written paths, ``maps.npz`` first.
        """
        import matplotlib
        maps = self.maps()
        os.makedirs(directory, exist_ok=True)
        paths = [self.save_npz(os.path.join(directory, 'maps.npz'))]
        if self.texture_shape is None:
            pixels, weight = _point_map_pixels(pos, face, intrinsics,
                                               extrinsics, image_size)
        for name, value in maps.items():
            if self.texture_shape is None:
                hit = (pixels >= 0).all(-1)
                value = (weight[..., None] * value[pixels.clip(0)].reshape(
                    pixels.shape + (-1, ))).sum(-2)
                value[~hit] = np.nan
                if maps[name].ndim == 1:
                    value = value[..., 0]
            if value.dtype == bool:  # the coverage mask
                value = value.astype(np.float64)
            if name in UNCERTAINTY_MAPS:
                colormap = matplotlib.colormaps[MAP_INFO[name]['cmap']]
                image = colormap(scaled_to_range(
                    name, np.nan_to_num(value, nan=0.0)))[..., :3]
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

    @classmethod
    def merge_by_entropy(cls, results: List['SVBRDFResult']
                         ) -> Tuple['SVBRDFResult', Tensor]:
        r"""Merges recoveries of the same points (e.g. the same object
        under several lightings) by taking, at every point, the parameters
        of the recovery that is most certain there (Wiersma et al.,
        "Uncertainty for SVBRDF Acquisition using Frequency Analysis",
        SIGGRAPH 2025, Table 5.6),

        .. math::
            s_i = \operatorname*{arg\,min}_{k} H_k(i), \qquad
            x_i = x_{s_i}(i) \quad \text{for } x \in \{b, m, r, H\},

        the first input winning ties. No ground truth is used: the entropy
        alone decides. After the refinement the entropy (of the
        spherical-harmonic spectrum) no longer describes the maps:
        :meth:`merge_by_uncertainty` merges those.

        Args:
            results (sequence of SVBRDFResult): At least one, all with the
                same number of points (and texture shape) and a finite
                :obj:`entropy`.

        Returns:
            ``(merged, source)``: the merged :class:`SVBRDFResult` (its
            :obj:`entropy` the per-point minimum, :obj:`seconds` the sum of
            the inputs', :obj:`loss` empty, as no single objective was
            minimised) and ``source`` :math:`(N)` (long), the index into
            :obj:`results` each point was taken from.
        """
        results, entropy = cls._stack_for_merge(results, 'entropy')
        # argmin returns the first minimum: ties go to the earlier input
        source = entropy.argmin(0)
        points = torch.arange(source.numel(), device=source.device)

        def pick(name):
            return torch.stack([getattr(r, name).detach().to(source.device)
                                for r in results])[source, points]

        merged = cls(base_color=pick('base_color'),
                     metallic=pick('metallic'), roughness=pick('roughness'),
                     entropy=entropy[source, points],
                     seconds=sum(r.seconds for r in results),
                     texture_shape=results[0].texture_shape)
        return merged, source

    @classmethod
    def merge_by_uncertainty(cls, results: List['SVBRDFResult']
                             ) -> Tuple['SVBRDFResult', Tensor]:
        r"""Merges recoveries of the same points (e.g. the same object
        under several lightings) by weighting every recovery at every
        point by the inverse variance of its roughness,

        .. math::
            w_k(i) = \frac{s_k(i)^{-2}}{\sum_l s_l(i)^{-2}}, \qquad
            x_i = \sum_k w_k(i)\, x_k(i) \quad \text{for }
            x \in \{b, m, r\}, \qquad
            s_i = \Big(\sum_k s_k(i)^{-2}\Big)^{-1/2},

        with :math:`s` the :obj:`roughness_std` of
        :meth:`~tg_intrinsic.nn.FrequencySVBRDF.refine` (or
        :meth:`~tg_intrinsic.nn.FrequencySVBRDF.fit`). The roughness's
        uncertainty weights all maps: a point's base colour and metallic
        are as reliable as the lobe that the light reveals (on
        ``benchmarks/svbrdf_merge.py``, weights from the base colour's own
        variance merged its colour worse than plain averaging). No ground
        truth is used.

        Args:
            results (sequence of SVBRDFResult): At least one, all with the
                same number of points (and texture shape) and a finite,
                positive :obj:`roughness_std`.

        Returns:
            ``(merged, weight)``: the merged :class:`SVBRDFResult` (its
            :obj:`roughness_std` as above, :obj:`entropy` :obj:`None`,
            :obj:`seconds` the sum of the inputs', :obj:`loss` empty) and
            the weights :math:`(K, N)`, which sum to one at every point.
        """
        results, std = cls._stack_for_merge(results, 'roughness_std')
        if bool((std <= 0).any()):
            raise ValueError("a 'roughness_std' is zero or negative; an "
                             "uncertainty must be positive to weight a "
                             "recovery")
        precision = std.double() ** -2
        weight = precision / precision.sum(0)

        def average(name):
            maps = torch.stack([getattr(r, name).detach().to(std.device)
                                for r in results])
            return (weight.view(weight.shape + (1, ) * (maps.dim() - 2))
                    * maps.double()).sum(0).to(maps.dtype)

        merged = cls(base_color=average('base_color'),
                     metallic=average('metallic'),
                     roughness=average('roughness'),
                     roughness_std=precision.sum(0).rsqrt().to(std.dtype),
                     seconds=sum(r.seconds for r in results),
                     texture_shape=results[0].texture_shape)
        return merged, weight.to(std.dtype)

    @classmethod
    def _stack_for_merge(cls, results, key: str):
        """Checks that ``results`` are results of the same points, each
        with a finite ``key`` map; returns them as a list and that map
        stacked :math:`(K, N)` on the first one's device."""
        results = list(results) if isinstance(results, (list, tuple)) \
            else None
        if not results:
            raise ValueError("'results' must be a non-empty list or tuple "
                             "of SVBRDFResult")
        how = {'entropy': "run SpectralUncertainty before the fit",
               'roughness_std': "FrequencySVBRDF.fit, refine and recover "
                                "set it"}[key]
        num = None
        for k, res in enumerate(results):
            if not isinstance(res, cls):
                raise ValueError(f"results[{k}] is a {type(res).__name__}, "
                                 f"not an SVBRDFResult")
            if getattr(res, key) is None:
                raise ValueError(f"results[{k}] has no {key}; {how} so "
                                 f"that the merge can compare certainty")
            if num is None:
                num = res.roughness.size(0)
            shapes = {'base_color': (num, 3), 'metallic': (num, ),
                      'roughness': (num, ), key: (num, )}
            for name, shape in shapes.items():
                if tuple(getattr(res, name).shape) != shape:
                    raise ValueError(
                        f"results[{k}].{name} has shape "
                        f"{list(getattr(res, name).shape)}, expected "
                        f"{list(shape)}: every result must cover the same "
                        f"{num} points (results[0] has {num})")
            if not bool(torch.isfinite(getattr(res, key)).all()):
                raise ValueError(f"results[{k}].{key} holds NaN or "
                                 f"infinite values; a point without an "
                                 f"uncertainty cannot be compared")
            if res.texture_shape != results[0].texture_shape:
                raise ValueError(f"results[{k}] has texture_shape "
                                 f"{res.texture_shape}, results[0] "
                                 f"{results[0].texture_shape}")
        device = getattr(results[0], key).device
        return results, torch.stack([getattr(r, key).detach().to(device)
                                     for r in results])


def _texel_positions(texel_index, texture_shape, num_points) -> np.ndarray:
    """``texel_index`` as numpy, checked against the texture and the
    points: one distinct texel per point."""
    index = np.asarray(torch.as_tensor(texel_index).detach().cpu())
    size = math.prod(texture_shape)
    if index.shape != (num_points, ) or index.dtype.kind not in 'iu':
        raise ValueError(f"'texel_index' must hold one integer texel per "
                         f"point ({num_points}), got {index.dtype} of shape "
                         f"{list(index.shape)}")
    if index.size and (index.min() < 0 or index.max() >= size):
        raise ValueError(f"'texel_index' holds texels outside [0, {size}) "
                         f"of the {tuple(texture_shape)} texture")
    if len(np.unique(index)) != len(index):
        raise ValueError("'texel_index' repeats texels")
    return index


def _write_png(f, image):
    import matplotlib.pyplot as plt
    plt.imsave(f, image, format='png')


def _point_map_pixels(pos, face, intrinsics, extrinsics, image_size):
    """What each pixel of one camera shows: ``(index (H, W, k), weight
    (H, W, k))``, the points whose values are blended (k = 3 triangle
    corners weighted by barycentrics, or k = 1 splatted point), index -1
    on the background."""
    from tg_intrinsic.geometry.appearance.cameras import look_at_cameras
    from tg_intrinsic.geometry.appearance.raster import rasterize
    if pos is None:
        raise ValueError("saving point maps as images needs 'pos' (and "
                         "optionally one camera and the faces); texel maps "
                         "need texture_shape")
    pos = pos.detach().cpu().double()
    height, width = image_size
    if intrinsics is None or extrinsics is None:
        # above the object, looking down -z, the bounding sphere in view
        centre = (pos.max(0).values + pos.min(0).values) / 2
        radius = float((pos - centre).norm(dim=1).max()) or 1.0
        fov = 2 * math.degrees(math.asin(1 / 4.0)) * 1.05
        intrinsics, extrinsics = look_at_cameras(
            (centre + torch.tensor([0.0, 0.0, 4 * radius],
                                   dtype=pos.dtype))[None],
            target=centre.tolist(), fov_degrees=fov,
            image_size=(height, width))
    K = intrinsics.detach().cpu().double().reshape(-1, 3, 3)[0]
    E = extrinsics.detach().cpu().double().reshape(-1, 3, 4)[0]
    if face is None:
        index = splat_index(pos, K, E, (height, width))[..., None]
        return index, np.ones(index.shape)
    face = torch.as_tensor(face).detach().cpu().long()
    if face.dim() == 2 and face.size(0) != 3 and face.size(1) == 3:
        face = face.t()  # trimesh layout (F, 3)
    face_id, bary, _ = rasterize(pos, face.contiguous(), K, E, height, width)
    face_id, bary = face_id.numpy(), bary.numpy()
    corners = face.t().numpy()[face_id.clip(0)]  # (H, W, 3)
    corners[face_id < 0] = -1
    return corners, np.where(face_id[..., None] >= 0, bary, 0.0)
