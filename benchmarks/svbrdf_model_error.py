"""Benchmark: how far the frequency-domain forward models are from the
true reflection integral at the true parameters: the floor under any
recovery that fits them.

Scene as in ``svbrdf_accuracy.py`` (icosphere of 642 vertices, metals,
roughness 0.2-0.8, 50 views, exact per-vertex observations from the
independent renderer). Per roughness bin, the relative L1 error
sum |B_model - B_obs| / sum |B_obs| of:

- ``eq5.11, l*=5``: the paper's model (shadowing refitted at the truth);
- ``split_sum, l*=8`` and ``l*=12``: our SH split-sum variant;
- ``exact split sum``: no spherical harmonics at all: the environment
  prefiltered exactly with the GGX lobe about the dominant direction
  (quadrature over every map pixel, light below the surface's horizon
  dropped) times the same exact directional albedo. What remains is the
  error of the factorisation itself.

Writes ``benchmarks/results/svbrdf_model_error.json`` and ``.png``.

    python benchmarks/svbrdf_model_error.py
"""
import math
import os
import sys

import matplotlib
import torch

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

sys.path.insert(0, os.path.join(os.path.dirname(__file__), '..'))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from svbrdf_accuracy import load_envmaps  # noqa: E402
from tg_intrinsic.datasets import svbrdf_scene  # noqa: E402
from tg_intrinsic.geometry.appearance.brdf import (MIN_ALPHA,  # noqa: E402
                                        dominant_direction, ggx_albedo)
from tg_intrinsic.geometry.appearance.envmap import (  # noqa: E402
    equirect_directions, equirect_solid_angles)
from tg_intrinsic.nn import FrequencySVBRDF  # noqa: E402
from tg_intrinsic.transforms import FitSphericalHarmonics  # noqa: E402
from tg_intrinsic.utils import atomic_write, atomic_write_json  # noqa: E402
from tg_intrinsic.utils import machine_info  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
BINS = ((0.2, 0.35), (0.35, 0.5), (0.5, 0.65), (0.65, 0.8))


def sh_model(prepared, specular_model):
    """The model's radiance with the true parameters of ``prepared``."""
    l_max = int(round(math.sqrt(prepared.sh_in.size(1)))) - 1
    model = FrequencySVBRDF(prepared.num_nodes,
                            specular_model=specular_model).double()
    with torch.no_grad():
        model.base_color.copy_(prepared.base_color)
        model.metallic.copy_(prepared.metallic)
        model.roughness.copy_(prepared.roughness)
        sh_in = (model.shadowed_light(prepared)
                 if specular_model == 'eq5.11' else prepared.sh_in)
        return model(prepared, sh_in, model._basis(prepared, l_max))


def exact_split_sum(data, prepared, envmap, chunk=256):
    """``prepared``: ``data`` after FitSphericalHarmonics (local frames and
    mirror directions)."""
    height, width = envmap.shape[:2]
    light_dirs = equirect_directions(height, width).reshape(-1, 3).double()
    solid_angle = equirect_solid_angles(height, width).double()
    solid_angle = solid_angle.reshape(height, -1).expand(height, width)
    solid_angle = solid_angle.reshape(-1)
    radiance = envmap.reshape(-1, 3).double()
    normal = data.normal.double()
    roughness = data.roughness.double()
    alpha = (roughness * roughness).clamp_min(MIN_ALPHA)
    mirror = prepared.mirror_dir.double()  # local: z is the normal
    dominant = dominant_direction(mirror, roughness) @ prepared.frame.double()
    point, view_index = data.obs_mask.nonzero(as_tuple=True)
    prefiltered = torch.empty(point.numel(), 3, dtype=torch.float64)
    for start in range(0, point.numel(), chunk):
        rows = slice(start, start + chunk)
        axis = dominant[point[rows], view_index[rows]]
        a2 = (alpha[point[rows]] ** 2).unsqueeze(-1)
        half = axis[:, None, :] + light_dirs[None]
        cos_h = (half * axis[:, None, :]).sum(-1) / half.norm(
            dim=-1).clamp_min(1e-12)
        ggx = a2 / (math.pi * (cos_h * cos_h * (a2 - 1) + 1) ** 2)
        above = (normal[point[rows]] @ light_dirs.t()) > 0
        weight = ggx * (axis @ light_dirs.t()).clamp_min(0) * above \
            * solid_angle
        prefiltered[rows] = (weight @ radiance) / weight.sum(
            1, keepdim=True).clamp_min(1e-30)
    albedo = ggx_albedo(mirror[..., 2], roughness, data.base_color.double())
    out = torch.zeros_like(mirror)
    out[point, view_index] = prefiltered * albedo[point, view_index]
    return out


def binned_error(prediction, data):
    out = []
    for lo, hi in BINS:
        select = data.obs_mask & ((data.roughness >= lo)
                                  & (data.roughness < hi))[:, None]
        observed = data.obs_radiance.double()[select]
        out.append(float((prediction[select] - observed).abs().sum()
                         / observed.abs().sum()))
    return out


def main():
    torch.set_num_threads(os.cpu_count())
    rows = []
    for name, envmap in load_envmaps(quick=False).items():
        data = svbrdf_scene('sphere', num_views=50, materials='metals',
                            roughness_range=(0.2, 0.8), resolution=3,
                            render_images=False, dtype=torch.float64,
                            envmap=envmap, seed=1)
        prepared = {l_max: FitSphericalHarmonics(l_max=l_max)(data.clone())
                    for l_max in (5, 8, 12)}
        models = {'eq5.11, l*=5': sh_model(prepared[5], 'eq5.11'),
                  'split_sum, l*=8': sh_model(prepared[8], 'split_sum'),
                  'split_sum, l*=12': sh_model(prepared[12], 'split_sum'),
                  'exact split sum': exact_split_sum(data, prepared[8],
                                                     envmap)}
        for model, prediction in models.items():
            errors = binned_error(prediction, data)
            rows.append({'envmap': name, 'model': model,
                         'relative_l1_per_roughness_bin': errors})
            print(f"{name:>16} {model:>17}: " + ' / '.join(
                f'{100 * e:.0f}%' for e in errors), flush=True)
    out = os.path.join(HERE, 'results')
    os.makedirs(out, exist_ok=True)
    atomic_write_json(os.path.join(out, 'svbrdf_model_error.json'), {
        'machine': machine_info(), 'roughness_bins': BINS,
        'scene': 'icosphere 642 vertices, metals, 50 views, seed 1',
        'rows': rows})
    envmaps = sorted({r['envmap'] for r in rows})
    fig, axes = plt.subplots(1, len(envmaps), figsize=(3.2 * len(envmaps),
                                                       3.4), sharey=True)
    centres = [(lo + hi) / 2 for lo, hi in BINS]
    for ax, name in zip(axes, envmaps):
        for r in rows:
            if r['envmap'] == name:
                ax.plot(centres, r['relative_l1_per_roughness_bin'], 'o-',
                        label=r['model'])
        ax.set_title(name, fontsize=9)
        ax.set_xlabel('roughness')
    axes[0].set_ylabel('relative L1 at the true parameters')
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    atomic_write(os.path.join(out, 'svbrdf_model_error.png'),
            lambda f: fig.savefig(f, format='png', dpi=120), 'wb')


if __name__ == '__main__':
    main()
