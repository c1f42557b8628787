"""Benchmark: speed of the frequency-domain SVBRDF building blocks.

1. Spectral uncertainty (eqs. 5.19-5.25) for 100k points on a 32 x 32 grid,
   l* = 5, RGB: ours (the distance expanded into two small matrix products,
   chunked) against the direct formulation that broadcasts the distance
   over points x channels x grid x degrees (how the original evaluates it),
   on the same spectra; the answers are checked against each other.
2. Regularised SH fitting of 16k points x 100 views (l* = 5, RGB): ours
   (batched normal equations, one Cholesky-sized solve per point) against
   torch.linalg.lstsq on the equivalent augmented least-squares system.

Writes ``benchmarks/results/svbrdf_speed.json`` and ``svbrdf_speed.png``.

    python benchmarks/svbrdf_speed.py [--quick]
"""
import argparse
import math
import os
import sys
import time

import matplotlib
import torch

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

sys.path.insert(0, os.path.join(os.path.dirname(__file__), '..'))
from tg_intrinsic.geometry.appearance.brdf import (lobe_filter,  # noqa
                                                   observed_spectra,
                                                   spectral_grid,
                                                   spectral_uncertainty)
from tg_intrinsic.geometry.appearance.sh import fit_sh, real_sh  # noqa: E402
from tg_intrinsic.utils import (atomic_write, atomic_write_json,  # noqa: E402
                                machine_info)

RESULTS = os.path.join(os.path.dirname(os.path.abspath(__file__)), 'results')
L_MAX = 5


def best_of(fn, repeats):
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - start)
    return min(times), out


def direct_uncertainty(spectrum_in, spectrum_out, grid, sigma, chunk=4096):
    """Distance broadcast over (points, channels, Ks, r, degrees)."""
    ks, roughness = spectral_grid(*grid, spectrum_in.dtype)
    l = torch.arange(1, L_MAX + 1, dtype=spectrum_in.dtype)  # noqa: E741
    lobe = torch.exp(-2 * (roughness[:, None] ** 2) ** 2 * l * l)
    model = (ks ** 2)[:, None, None] * lobe[None]  # (Ks, r, L)
    entropy = []
    for s in range(0, spectrum_in.size(0), chunk):
        s_in = spectrum_in[s:s + chunk]
        s_out = spectrum_out[s:s + chunk]
        scale = s_in.sum(1, keepdim=True)
        s_in = (s_in[:, 1:] / scale).transpose(1, 2)[:, :, None, None]
        s_out = (s_out[:, 1:] / scale).transpose(1, 2)[:, :, None, None]
        distance = ((s_out - model * s_in) ** 2).sum(-1)
        p = torch.softmax(-distance.flatten(-2) / (2 * sigma ** 2), -1)
        h = -(p * torch.log(p.clamp_min(1e-30))).sum(-1) / math.log(
            grid[0] * grid[1])
        entropy.append(h.min(-1).values)
    return torch.cat(entropy)


def random_spectra(num, dtype, seed=0):
    g = torch.Generator().manual_seed(seed)
    d = torch.randn(num, 3, generator=g, dtype=torch.float64)
    light = real_sh(d / d.norm(dim=-1, keepdim=True), L_MAX)
    light = light.unsqueeze(-1) * torch.rand(num, 1, 3, generator=g,
                                             dtype=torch.float64)
    light = light + 0.2 * torch.randn(num, 36, 3, generator=g,
                                      dtype=torch.float64)
    alpha = torch.rand(num, generator=g, dtype=torch.float64) ** 2
    outgoing = torch.rand(num, 1, 3, generator=g, dtype=torch.float64) \
        * lobe_filter(L_MAX, alpha).unsqueeze(-1) * light
    return [s.to(dtype) for s in observed_spectra(light, outgoing)]


def bench_uncertainty(num, repeats):
    rows = []
    for dtype in (torch.float32, torch.float64):
        spectra = random_spectra(num, dtype)
        t_ours, ours = best_of(lambda: spectral_uncertainty(*spectra),
                               repeats)
        t_direct, direct = best_of(
            lambda: direct_uncertainty(*spectra, (32, 32), 1e-2), repeats)
        error = float((ours[0] - direct).abs().max())
        rows.append({'dtype': str(dtype).split('.')[-1], 'points': num,
                     'ours_s': t_ours, 'direct_s': t_direct,
                     'speedup': t_direct / t_ours,
                     'ms_per_100k': 1e3 * t_ours * 1e5 / num,
                     'max_entropy_difference': error})
        print(f"uncertainty {rows[-1]['dtype']}: ours {t_ours:.3f} s, "
              f"direct {t_direct:.3f} s ({t_direct / t_ours:.1f}x), "
              f"max |dH| {error:.1e}")
    return rows


def bench_fit(num, views, repeats):
    rows = []
    g = torch.Generator().manual_seed(1)
    for dtype in (torch.float32, torch.float64):
        d = torch.randn(num, views, 3, generator=g, dtype=torch.float64)
        d = d / d.norm(dim=-1, keepdim=True)
        d[..., 2] = d[..., 2].abs()
        d, values = d.to(dtype), torch.rand(num, views, 3, generator=g,
                                            dtype=torch.float64).to(dtype)
        weights = d[..., 2] * (torch.rand(num, views, generator=g) > 0.4
                               ).to(dtype)

        def lstsq():
            Y = real_sh(d, L_MAX)
            root = weights.sqrt().unsqueeze(-1)
            l = torch.arange(L_MAX + 1, dtype=dtype)  # noqa: E741
            l = l.repeat_interleave(2 * l.long() + 1)
            prior = torch.diag((1e-4 * l.exp()).sqrt()).expand(num, -1, -1)
            A = torch.cat([root * Y, prior], 1)
            b = torch.cat([root * values, values.new_zeros(num, 36, 3)], 1)
            return torch.linalg.lstsq(A, b).solution

        t_ours, ours = best_of(lambda: fit_sh(d, values, L_MAX, weights),
                               repeats)
        t_peer, peer = best_of(lstsq, repeats)
        error = float(((ours - peer).norm() / peer.norm()))
        rows.append({'dtype': str(dtype).split('.')[-1], 'points': num,
                     'views': views, 'ours_s': t_ours, 'lstsq_s': t_peer,
                     'speedup': t_peer / t_ours, 'relative_difference': error})
        print(f"fit {rows[-1]['dtype']}: ours {t_ours:.3f} s, lstsq "
              f"{t_peer:.3f} s ({t_peer / t_ours:.1f}x), rel. diff "
              f"{error:.1e}")
    return rows


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument('--quick', action='store_true')
    args = parser.parse_args()
    torch.set_num_threads(os.cpu_count())
    num = 10000 if args.quick else 100000
    repeats = 1 if args.quick else 3
    uncertainty = bench_uncertainty(num, repeats)
    fit = bench_fit(1600 if args.quick else 16000, 100, repeats)
    os.makedirs(RESULTS, exist_ok=True)
    atomic_write_json(os.path.join(RESULTS, 'svbrdf_speed.json'), {
        'machine': machine_info(), 'quick': args.quick,
        'uncertainty': uncertainty, 'sh_fit': fit})
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.5))
    for ax, rows, peer, title in (
            (axes[0], uncertainty, 'direct_s',
             f'uncertainty, {num // 1000}k points, 32x32 grid'),
            (axes[1], fit, 'lstsq_s', 'SH fit, 16k points x 100 views')):
        labels = [r['dtype'] for r in rows]
        x = torch.arange(len(rows)).numpy()
        ax.bar(x - 0.2, [r['ours_s'] for r in rows], 0.4, label='ours')
        ax.bar(x + 0.2, [r[peer] for r in rows], 0.4,
               label=peer.replace('_s', ''))
        ax.set_xticks(x, labels)
        ax.set_ylabel('seconds (CPU)')
        ax.set_title(title, fontsize=9)
        ax.legend()
    fig.tight_layout()
    atomic_write(os.path.join(RESULTS, 'svbrdf_speed.png'),
            lambda f: fig.savefig(f, format='png', dpi=120), 'wb')


if __name__ == '__main__':
    main()
