"""Synthetic datasets: generation time, mesh validity, vertex counts and how
far a trivial classifier gets.

Generates the full default SyntheticSHREC (240 meshes, both splits) and
SyntheticModelNet (600 clouds) in a fresh temporary root, times them, checks
every SHREC mesh (closed, oriented, vertex-manifold, one component, genus 0,
positive volume), reports per-class vertex-count ranges and triangle
quality, and trains a nearest-centroid classifier on global shape features
(train split) evaluated on the test split, next to random chance. The
synthetic classes should not be separable by such trivial statistics.

Usage: python benchmarks/datasets.py
Writes benchmarks/results/datasets.json and .png.
"""
import os
import tempfile
import time

import matplotlib
import numpy as np
import scipy.sparse as sp
import torch
from scipy.sparse.csgraph import connected_components

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

from tg_intrinsic.datasets import SyntheticModelNet, SyntheticSHREC  # noqa
from tg_intrinsic.datasets.quadric_decimation import (  # noqa: E402
    self_intersections)
from tg_intrinsic.geometry import is_closed_manifold  # noqa: E402
from tg_intrinsic.utils import atomic_write_json, machine_info  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))


# ----------------------------------------------------------------- checks


def mesh_check(pos, face):
    """Validity and quality numbers of one closed mesh."""
    pos = pos.double().numpy()
    F = face.t().numpy()
    n = len(pos)
    he = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    key = he[:, 0] * n + he[:, 1]
    oriented = len(np.unique(key)) == len(key) and \
        bool(np.isin(he[:, 1] * n + he[:, 0], key).all())
    E = sp.coo_matrix((np.ones(len(he)), (he[:, 0], he[:, 1])), shape=(n, n))
    ncomp = connected_components(E, directed=False)[0]
    a, b, c = pos[F[:, 0]], pos[F[:, 1]], pos[F[:, 2]]
    cr = np.cross(b - a, c - a)
    area = 0.5 * np.linalg.norm(cr, axis=1)
    sq = ((b - a) ** 2).sum(1) + ((c - b) ** 2).sum(1) + ((a - c) ** 2).sum(1)
    quality = 4 * np.sqrt(3) * area / sq  # 1 for equilateral triangles
    volume = np.einsum('ij,ij->i', a, np.cross(b, c)).sum() / 6
    return {
        'closed_manifold': bool(is_closed_manifold(face, n)),
        'oriented': oriented,
        'components': int(ncomp),
        'euler': int(n - len(he) // 2 + len(F)),
        'volume': float(volume),
        'self_intersections': self_intersections(pos, F.astype(np.int64)),
        'area': float(area.sum()),
        'quality': quality,
    }


# --------------------------------------------------------------- features


def mesh_features(data):
    """Sorted bounding-box extents, surface area, volume, vertex count."""
    pos = data.pos.double().numpy()
    F = data.face.t().numpy()
    a, b, c = pos[F[:, 0]], pos[F[:, 1]], pos[F[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum()
    volume = np.einsum('ij,ij->i', a, np.cross(b, c)).sum() / 6
    ext = np.sort(pos.max(0) - pos.min(0))
    return np.r_[ext, area, volume, len(pos)]


def cloud_features(pos, sort=True):
    """Bounding-box extents (sorted or aligned), covariance eigenvalues,
    mean and spread of the distance to the centroid, point count."""
    ext = pos.max(0) - pos.min(0)
    if sort:
        ext = np.sort(ext)
    eig = np.linalg.eigvalsh(np.cov(pos.T))
    r = np.linalg.norm(pos - pos.mean(0), axis=1)
    return np.r_[ext, eig, r.mean(), r.std(), len(pos)]


def nearest_centroid(Xtr, ytr, Xte, yte, num_classes):
    mu, sd = Xtr.mean(0), Xtr.std(0)
    sd[sd == 0] = 1.0
    Ztr, Zte = (Xtr - mu) / sd, (Xte - mu) / sd
    C = np.stack([Ztr[ytr == k].mean(0) for k in range(num_classes)])
    pred = ((Zte[:, None] - C[None]) ** 2).sum(-1).argmin(1)
    return float((pred == yte).mean())


# ------------------------------------------------------------------- main


def main():
    out = {'machine': machine_info()}
    import numba
    import trimesh
    out['machine'].update(trimesh=trimesh.__version__,
                          numba_threads=numba.get_num_threads())
    root = tempfile.mkdtemp(prefix='tg_intrinsic_datasets_')

    # numba kernels are compiled (and cached) on first use: time separately
    t = time.perf_counter()
    SyntheticSHREC(os.path.join(root, 'warmup'), num_per_class=2,
                   num_train_per_class=1, log=False)
    warmup = time.perf_counter() - t

    t = time.perf_counter()
    shrec_train = SyntheticSHREC(os.path.join(root, 'shrec'), log=False)
    shrec_time = time.perf_counter() - t
    shrec_test = SyntheticSHREC(os.path.join(root, 'shrec'), split='test',
                                log=False)
    shrec_seg = SyntheticSHREC(os.path.join(root, 'shrec'),
                               task='segmentation', log=False)

    t = time.perf_counter()
    mn_train = SyntheticModelNet(os.path.join(root, 'modelnet'), log=False)
    mn_time = time.perf_counter() - t
    mn_test = SyntheticModelNet(os.path.join(root, 'modelnet'), split='test',
                                log=False)

    # ---- SHREC: validity, vertex counts, quality
    classes = shrec_train.classes
    checks, counts, qual = [], {k: [] for k in classes}, []
    for data in list(shrec_train) + list(shrec_test):
        r = mesh_check(data.pos, data.face)
        qual.append(r.pop('quality'))
        checks.append(r)
        counts[classes[int(data.y)]].append(data.num_nodes)
    qual = np.concatenate(qual)
    valid = [c['closed_manifold'] and c['oriented'] and c['components'] == 1
             and c['euler'] == 2 and c['volume'] > 0 for c in checks]
    crossing = sum(c['self_intersections'] > 0 for c in checks)
    parts = [len(torch.unique(d.y)) for d in shrec_seg]

    Xtr = np.stack([mesh_features(d) for d in shrec_train])
    Xte = np.stack([mesh_features(d) for d in shrec_test])
    ytr = np.array([int(d.y) for d in shrec_train])
    yte = np.array([int(d.y) for d in shrec_test])
    shrec_acc = nearest_centroid(Xtr, ytr, Xte, yte, len(classes))
    # the same plus rotation-invariant moments (covariance eigenvalues etc.)
    Ctr = np.stack([cloud_features(d.pos.double().numpy()) for d in
                    shrec_train])
    Cte = np.stack([cloud_features(d.pos.double().numpy()) for d in
                    shrec_test])
    shrec_acc_ext = nearest_centroid(np.c_[Xtr, Ctr[:, 3:8]], ytr,
                                     np.c_[Xte, Cte[:, 3:8]], yte,
                                     len(classes))
    out['shrec'] = {
        'classes': list(classes),
        'part_names': list(shrec_seg.part_names),
        'num_train': len(shrec_train),
        'num_test': len(shrec_test),
        # 24 small shapes first: includes the numba compilation if the
        # kernels were not cached yet
        'jit_warmup_s': round(warmup, 2),
        # all 240 meshes: both splits, both tasks, single process
        'generation_s': round(shrec_time, 2),
        'valid_closed_genus0_manifolds': f'{sum(valid)}/{len(valid)}',
        'self_intersecting_meshes': f'{crossing}/{len(checks)}',
        'surface_area (min, max)': [round(min(c['area'] for c in checks), 6),
                                    round(max(c['area'] for c in checks), 6)],
        'vertex_count_range': [int(min(map(min, counts.values()))),
                               int(max(map(max, counts.values())))],
        'vertex_count_per_class': {
            k: {'min': int(min(v)), 'max': int(max(v)),
                'mean': round(float(np.mean(v)), 1)}
            for k, v in counts.items()},
        'parts_per_shape (min, max)': [int(min(parts)), int(max(parts))],
        'triangle_quality (min, p5, median)': [
            round(float(qual.min()), 4),
            round(float(np.percentile(qual, 5)), 4),
            round(float(np.median(qual)), 4)],
        'nearest_centroid_accuracy': {
            'bbox_sorted+area+volume+num_vertices': round(shrec_acc, 4),
            '+covariance_eigenvalues+radial_stats': round(shrec_acc_ext, 4),
            'random_chance': round(1 / len(classes), 4),
        },
    }

    # ---- ModelNet
    mclasses = mn_train.classes

    def feats(ds, sort):
        return np.stack([cloud_features(d.pos.double().numpy(), sort)
                         for d in ds])

    mytr = np.array([int(d.y) for d in mn_train])
    myte = np.array([int(d.y) for d in mn_test])
    mn_acc = nearest_centroid(feats(mn_train, True), mytr,
                              feats(mn_test, True), myte, len(mclasses))
    mn_acc_al = nearest_centroid(feats(mn_train, False), mytr,
                                 feats(mn_test, False), myte, len(mclasses))
    nrm = torch.cat([d.normal for d in mn_train])
    out['modelnet'] = {
        'classes': list(mclasses),
        'num_train': len(mn_train),
        'num_test': len(mn_test),
        'num_points': mn_train.num_points,
        'generation_s': round(mn_time, 2),  # all 600 clouds
        'per_class_train_test': [
            np.bincount(mytr, minlength=len(mclasses)).tolist(),
            np.bincount(myte, minlength=len(mclasses)).tolist()],
        'normal_length_max_error': float((nrm.norm(dim=1) - 1).abs().max()),
        'nearest_centroid_accuracy': {
            'bbox_sorted+covariance_eigenvalues+radial_stats':
                round(mn_acc, 4),
            'bbox_aligned(upright)+covariance_eigenvalues+radial_stats':
                round(mn_acc_al, 4),
            'random_chance': round(1 / len(mclasses), 4),
        },
    }
    path = os.path.join(HERE, 'results', 'datasets.json')
    atomic_write_json(path, out)
    print(f'wrote {path}')
    plot(root, out, mn_test)


def plot(root, out, mn_test):
    gallery = SyntheticSHREC(os.path.join(root, 'gallery'), num_per_class=2,
                             num_train_per_class=1, rotate=False,
                             task='segmentation', log=False)
    fig = plt.figure(figsize=(19, 17))
    gs = fig.add_gridspec(5, 6, height_ratios=[1, 1, 1, 1, 1.1])
    cmap = plt.get_cmap('tab10')
    light = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    for i, data in enumerate(gallery):  # shape 0 of every class
        ax = fig.add_subplot(gs[i // 6, i % 6], projection='3d')
        V, F = data.pos.numpy(), data.face.t().numpy()
        n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        shade = 0.45 + 0.55 * np.clip(n @ light, 0, 1)
        lab = data.y.numpy()[F].max(1)
        col = cmap(lab % 10)[:, :3] * shade[:, None]
        tri = ax.plot_trisurf(V[:, 0], V[:, 1], V[:, 2], triangles=F,
                              linewidth=0.05, edgecolor=(0, 0, 0, 0.25))
        tri.set_facecolor(np.c_[col, np.ones(len(F))])
        r = np.abs(V).max()
        ax.set_xlim(-r, r)
        ax.set_ylim(-r, r)
        ax.set_zlim(-r, r)
        ax.view_init(elev=15, azim=-60)
        ax.set_axis_off()
        ax.set_title(f'SHREC: {gallery.classes[int(data.category)]} '
                     f'({data.num_nodes} v)', fontsize=10)
    seen = set()
    k = 0
    for data in mn_test:
        c = int(data.y)
        if c in seen:
            continue
        seen.add(c)
        ax = fig.add_subplot(gs[2 + k // 6, k % 6], projection='3d')
        p = data.pos.numpy()
        ax.scatter(p[:, 0], p[:, 1], p[:, 2], s=1.2,
                   c=0.5 + 0.5 * data.normal[:, 2].numpy(), cmap='viridis',
                   vmin=0, vmax=1)
        ax.set_xlim(-1, 1)
        ax.set_ylim(-1, 1)
        ax.set_zlim(-1, 1)
        ax.view_init(elev=20, azim=-60)
        ax.set_axis_off()
        ax.set_title(f'ModelNet: {mn_test.classes[c]}', fontsize=10)
        k += 1

    ax = fig.add_subplot(gs[4, :3])
    s, m = out['shrec'], out['modelnet']
    names = ['SHREC\nbbox+area+vol+#v', 'SHREC\n+moments',
             'ModelNet\nbbox sorted+moments', 'ModelNet\nbbox aligned+moments']
    vals = [*s['nearest_centroid_accuracy'].values()][:2] + \
        [*m['nearest_centroid_accuracy'].values()][:2]
    ax.bar(names, vals, color=['C0', 'C0', 'C1', 'C1'])
    ax.axhline(1 / 12, color='k', ls='--', label='random chance (1/12)')
    for x, v in enumerate(vals):
        ax.text(x, v + 0.01, f'{v:.0%}', ha='center')
    ax.set_ylim(0, 1)
    ax.set_ylabel('test accuracy')
    ax.set_title('nearest-centroid classifier on global features')
    ax.legend()

    ax = fig.add_subplot(gs[4, 3:])
    per = s['vertex_count_per_class']
    cls = list(per)
    lo = [per[k]['min'] for k in cls]
    hi = [per[k]['max'] for k in cls]
    mean = [per[k]['mean'] for k in cls]
    ax.vlines(range(len(cls)), lo, hi, lw=6, color='C2', alpha=0.6)
    ax.plot(range(len(cls)), mean, 'ko', ms=4, label='mean')
    ax.set_xticks(range(len(cls)))
    ax.set_xticklabels(cls, rotation=45, ha='right')
    ax.set_ylim(400, 2100)
    ax.set_ylabel('#vertices')
    ax.set_title(f"SHREC vertex count range per class (generation: SHREC "
                 f"{s['generation_s']:.1f} s, ModelNet "
                 f"{m['generation_s']:.1f} s)")
    ax.legend()
    fig.tight_layout()
    path = os.path.join(HERE, 'results', 'datasets.png')
    fig.savefig(path, dpi=70)
    print(f'wrote {path}')


if __name__ == '__main__':
    main()
