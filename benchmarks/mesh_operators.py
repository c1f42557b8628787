"""Mesh operators on real scans: our cotan Laplacian + lumped mass against
robust_laplacian (geometry-central) on the same run, plus PCA normals of the
vertices against the mesh's vertex normals.

Usage: python benchmarks/mesh_operators.py [--meshes ../shared/data/meshes]
Writes benchmarks/results/mesh_operators.json and .png.
"""
import argparse
import glob
import os
import time

import matplotlib
import numpy as np
import torch
import trimesh

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

from tg_intrinsic.geometry import (cotan_laplacian, estimate_normals,  # noqa
                                   lumped_mass, normalize_area, to_scipy,
                                   vertex_normals)
from tg_intrinsic.utils import atomic_write_json, machine_info  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))


def best_of(fn, repeat=3):
    times, out = [], None
    for _ in range(repeat):
        start = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - start)
    return min(times), out


def run_mesh(path):
    mesh = trimesh.load(path, process=False, force='mesh')
    pos = torch.tensor(mesh.vertices, dtype=torch.float64)
    face = torch.tensor(mesh.faces, dtype=torch.long).t().contiguous()
    pos = normalize_area(pos, face)
    import robust_laplacian

    ours_t, (S, M) = best_of(lambda: (to_scipy(cotan_laplacian(pos, face)),
                                      lumped_mass(pos, face).numpy()))
    peer_t, (L, M_peer) = best_of(lambda: robust_laplacian.mesh_laplacian(
        pos.numpy(), face.t().numpy(), mollify_factor=0.0))
    # robust_laplacian flips edges to an intrinsic Delaunay triangulation, so
    # the matrices differ where the scan is not Delaunay; compare the
    # Dirichlet energy of the coordinate functions, which both approximate.
    xyz = pos.numpy()
    energy = [(x @ (S @ x), x @ (L @ x)) for x in xyz.T]
    rel_energy = max(abs(a - b) / abs(b) for a, b in energy)
    mass_rel = float(np.abs(M - M_peer.diagonal()).max() / M.mean())
    nrm_t, pca = best_of(lambda: estimate_normals(pos.float(), k=10), 1)
    ref = vertex_normals(pos, face).float()
    cos = (pca * ref).sum(-1).clamp(-1, 1)
    angle = torch.rad2deg(torch.acos(cos.abs()))
    return {
        'mesh': os.path.basename(path),
        'vertices': pos.size(0),
        'faces': face.size(1),
        'ours_laplacian_mass_s': ours_t,
        'robust_laplacian_s': peer_t,
        'speedup': peer_t / ours_t,
        'max_rel_dirichlet_energy_difference': float(rel_energy),
        'max_mass_difference_rel_to_mean': mass_rel,
        'normals_s': nrm_t,
        'normals_median_angle_deg': float(angle.median()),
        'normals_fraction_oriented_like_mesh': float((cos > 0).float().mean()),
    }


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument('--meshes', default=os.path.join(
        HERE, '..', '..', 'shared', 'data', 'meshes'))
    parser.add_argument('--out', default=os.path.join(HERE, 'results'))
    args = parser.parse_args()
    paths = sorted(glob.glob(os.path.join(args.meshes, '*.obj')))
    if not paths:
        raise SystemExit(f'no .obj meshes under {args.meshes}; pass --meshes')
    rows = []
    for path in paths:
        rows.append(run_mesh(path))
        r = rows[-1]
        print(f"{r['mesh']:28s} {r['vertices']:6d} v  ours "
              f"{r['ours_laplacian_mass_s']:.3f}s  robust_laplacian "
              f"{r['robust_laplacian_s']:.3f}s  x{r['speedup']:.1f}  "
              f"energy diff {r['max_rel_dirichlet_energy_difference']:.1e}  "
              f"normals {r['normals_median_angle_deg']:.2f} deg, "
              f"{100 * r['normals_fraction_oriented_like_mesh']:.1f}% oriented")
    atomic_write_json(os.path.join(args.out, 'mesh_operators.json'),
                      {'machine': machine_info(), 'rows': rows})
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    names = [r['mesh'].replace('.obj', '') for r in rows]
    x = np.arange(len(rows))
    ax[0].bar(x - 0.2, [r['ours_laplacian_mass_s'] for r in rows], 0.4,
              label='tg_intrinsic cotan_laplacian + lumped_mass')
    ax[0].bar(x + 0.2, [r['robust_laplacian_s'] for r in rows], 0.4,
              label='robust_laplacian.mesh_laplacian')
    ax[0].set_xticks(x, names, rotation=30)
    ax[0].set_ylabel('seconds (best of 3)')
    ax[0].legend(fontsize=8)
    ax[1].bar(x, [r['normals_median_angle_deg'] for r in rows])
    ax[1].set_xticks(x, names, rotation=30)
    ax[1].set_ylabel('median angle to mesh normal (deg)')
    ax[1].set_title('estimate_normals(k=10) on the vertices')
    fig.tight_layout()
    fig.savefig(os.path.join(args.out, 'mesh_operators.png'), dpi=120)


if __name__ == '__main__':
    main()
