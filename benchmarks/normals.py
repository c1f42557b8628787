"""Normal orientation: ``estimate_normals`` against the orientation it
replaced and against Open3D, side by side in one run.

Every method gets the same clouds and is scored against the true outward
normals: *agreement* is the fraction of points whose normal points to the
same side as the truth (sign of the dot product), the *median angle* the
median angle between the two (0-180 degrees, so it sees flips too), the
*unsigned angle* the same up to sign (the accuracy of the unoriented PCA
normal, the same for both of our methods). Clouds:

- SyntheticModelNet, test split, 10 shapes per class, 2048 points;
- SyntheticSHREC, test split (120 meshes), 2048 points drawn with
  ``SamplePoints`` (face normals are the truth);
- the scanned meshes under ``--data``/meshes (skipped if absent), 2048
  points drawn with ``SamplePoints``. Their faces are checked first: boundary
  edges, pairs of neighbouring faces with inconsistent orientation and the
  signed volume are recorded (a negative volume would mean inward faces).

Methods: ``new`` is ``estimate_normals(pos, k=10)``; ``old`` is the same PCA
normals oriented by the previous method (a copy of it lives in this file
only: a minimum spanning tree of the k-nn graph with cost
(1.05 - |n_i . n_j|) * length, BFS sign propagation, then an outward flip per
connected component by the flux about its centroid); ``open3d`` (if
``open3d`` imports, e.g. from ``--open3d PATH``) is
``estimate_normals(KNN(10))`` + ``orient_normals_consistent_tangent_plane(10)``
on the same points. Times are per cloud, best of 3, normals included, on the
threads the process is given (run it pinned to one core:
``OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 taskset -c 1``); compare them as
ratios within one run.

SyntheticModelNet assembles shapes from parts that may touch; its sampler
drops the faces where parts touch (since version 2), which would leave
coincident points with opposite true normals (a hidden contact face, no
outside). ``agreement_visible`` leaves any such points out (a point with a
truly opposite normal within 2e-3 of the shape's radius along its normal
among its 10 nearest neighbours); ``contact_fraction`` says how many.

Where the PCA normal's line is far from the truth (more than 60 degrees),
its sign says little and no orientation can be trusted: ``pca_over_60``
counts those points, ``agreement_resolved`` scores the others alone, and
``one_sided_over_60`` counts the points that stay that far off even for an
oracle PCA over the neighbours on the same side (chosen with the true
normals): what is left there is a sampling limit of a 2048-point cloud.

    python benchmarks/normals.py [--data ../shared/data] [--root DIR]
        [--open3d PATH] [--quick]

Writes benchmarks/results/normals.json and normals.png.
"""
import argparse
import glob
import os
import sys
import tempfile
import time

import matplotlib
import numba
import numpy as np
import scipy.sparse as sp
import torch
from numba import njit
from scipy.sparse.csgraph import connected_components, minimum_spanning_tree
from scipy.spatial import cKDTree

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, '..'))
from torch_geometric.data import Data  # noqa: E402
from torch_geometric.transforms import SamplePoints  # noqa: E402

from tg_intrinsic.datasets import SyntheticModelNet, SyntheticSHREC  # noqa
from tg_intrinsic.geometry import estimate_normals  # noqa: E402
from tg_intrinsic.geometry.pointcloud.neighbors import knn  # noqa: E402
from tg_intrinsic.io.mesh import read_mesh  # noqa: E402
from tg_intrinsic.utils import atomic_write_json, machine_info  # noqa: E402

RESULTS = os.path.join(HERE, 'results')
K = 10
NUM_POINTS = 2048
GOAL = 0.97
NOTES = ('agreement: fraction of points whose normal has a positive dot '
         'product with the true outward normal; median_angle_deg: median '
         'angle to the truth (0-180, sees flips); unsigned_angle_deg: the '
         'same up to sign (PCA accuracy); agreement_visible: agreement '
         'without the points on hidden contact faces (coincident points '
         'with opposite true normals, see contact_fraction); pca_over_60: '
         'fraction of points whose unoriented PCA normal is more than 60 '
         'degrees off the true line (there the normal says little about '
         'the side); one_sided_over_60: the same for an oracle PCA over '
         'the k nearest neighbours on the same side by the true normals '
         '(a sampling limit); agreement_resolved: agreement on the points '
         'whose PCA normal is within 60 degrees; seconds: best '
         'of 3 per cloud, normal estimation included, all methods in the '
         'same process; consistency: max(agreement, 1 - agreement), what '
         'is left if a whole cloud may be flipped (flipped_shapes: clouds '
         'below 50%); old: the previous MST + flux orientation on the '
         'same PCA normals; open3d: its own PCA + '
         'orient_normals_consistent_tangent_plane(k); a method that raises '
         'on a cloud is listed under failures and left out of its summary')


# ---------------------------------------------------------------------------
# The previous orientation (baseline; kept here only)
# ---------------------------------------------------------------------------
def old_orient(pos, normal, edge_index):
    p = pos.numpy()
    n = normal.numpy().copy()
    num = p.shape[0]
    src, dst = edge_index.numpy()
    length = np.sqrt(((p[src] - p[dst]) ** 2).sum(1))
    cost = (1.0 - np.abs((n[src] * n[dst]).sum(1)) + 0.05) * (
        length / max(length.mean(), np.finfo(np.float64).tiny) + 1e-9)
    graph = sp.coo_matrix((cost, (dst, src)), shape=(num, num)).tocsr()
    graph = graph.maximum(graph.T)
    tree = minimum_spanning_tree(graph)
    tree = (tree + tree.T).tocsr()
    num_comp, label = connected_components(tree, directed=False)
    roots = np.unique(label, return_index=True)[1]
    _old_propagate(tree.indptr, tree.indices, roots.astype(np.int64), n)
    count = np.bincount(label, minlength=num_comp).astype(np.float64)
    centroid = np.stack([np.bincount(label, p[:, d], num_comp)
                         for d in range(3)], 1) / count[:, None]
    offset = p - centroid[label]
    flux = np.bincount(label, (n * offset).sum(1), num_comp)
    scale = np.bincount(label, np.sqrt((offset ** 2).sum(1)), num_comp)
    mean = np.stack([np.bincount(label, n[:, d], num_comp)
                     for d in range(3)], 1)
    dominant = mean[np.arange(num_comp), np.abs(mean).argmax(1)]
    flat = np.abs(flux) <= 1e-3 * scale
    sign = np.where(flat, np.sign(dominant), np.sign(flux))
    sign[sign == 0] = 1.0
    n *= sign[label][:, None]
    return torch.from_numpy(n)


@njit(cache=True)
def _old_propagate(indptr, indices, roots, normal):
    num = normal.shape[0]
    visited = np.zeros(num, dtype=np.bool_)
    queue = np.empty(num, dtype=np.int64)
    for root in roots:
        head = 0
        tail = 1
        queue[0] = root
        visited[root] = True
        while head < tail:
            u = queue[head]
            head += 1
            for e in range(indptr[u], indptr[u + 1]):
                v = indices[e]
                if visited[v]:
                    continue
                visited[v] = True
                dot = (normal[u, 0] * normal[v, 0] + normal[u, 1]
                       * normal[v, 1] + normal[u, 2] * normal[v, 2])
                if dot < 0.0:
                    normal[v] = -normal[v]
                queue[tail] = v
                tail += 1


def old_normals(pos):
    normal = estimate_normals(pos, k=K, orient=False)
    return old_orient(pos, normal, knn(pos, K, loop=False))


def new_normals(pos):
    return estimate_normals(pos, k=K)


def open3d_normals(o3d):
    def run(pos):
        cloud = o3d.geometry.PointCloud()
        cloud.points = o3d.utility.Vector3dVector(pos.numpy())
        cloud.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(K))
        cloud.orient_normals_consistent_tangent_plane(K)
        return torch.from_numpy(np.asarray(cloud.normals).copy())
    return run


# ---------------------------------------------------------------------------
# Data
# ---------------------------------------------------------------------------
def sample(pos, face, num, seed):
    torch.manual_seed(seed)
    data = SamplePoints(num, include_normals=True)(
        Data(pos=pos.float(), face=face))
    return data.pos.double(), data.normal.double()


def modelnet_clouds(root, quick):
    data = SyntheticModelNet(os.path.join(root, 'modelnet'), 'test',
                             num_points=NUM_POINTS, log=False)
    step = 5 if quick else 1
    return [(f'{data.classes[int(d.y)]}_{i:03d}', data.classes[int(d.y)],
             d.pos.double(), d.normal.double())
            for i, d in enumerate(data) if i % step == 0]


def shrec_clouds(root, quick):
    data = SyntheticSHREC(os.path.join(root, 'shrec'), 'test', log=False)
    step = 5 if quick else 1
    out = []
    for i, mesh in enumerate(data):
        if i % step:
            continue
        pos, normal = sample(mesh.pos, mesh.face, NUM_POINTS, i)
        out.append((f'{data.classes[int(mesh.y)]}_{i:03d}',
                    data.classes[int(mesh.y)], pos, normal))
    return out


def check_faces(pos, face):
    """Boundary edges, neighbouring faces with inconsistent orientation and
    the signed volume (positive: outward faces)."""
    f = face.numpy()
    directed = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    undirected = np.sort(directed, 1)
    _, counts = np.unique(undirected, axis=0, return_counts=True)
    _, directed_counts = np.unique(directed, axis=0, return_counts=True)
    p = pos.numpy()
    volume = np.einsum('ij,ij->i', p[f[:, 0]],
                       np.cross(p[f[:, 1]], p[f[:, 2]])).sum() / 6
    return dict(vertices=len(p), faces=len(f),
                boundary_edges=int((counts == 1).sum()),
                non_manifold_edges=int((counts > 2).sum()),
                inconsistent_face_pairs=int((directed_counts > 1).sum()),
                signed_volume=float(volume))


def mesh_clouds(data_dir):
    paths = sorted(glob.glob(os.path.join(data_dir, 'meshes', '*.obj')))
    out, checks = [], {}
    for path in paths:
        name = os.path.splitext(os.path.basename(path))[0]
        vertices, faces = read_mesh(path)
        pos = torch.as_tensor(np.asarray(vertices), dtype=torch.float64)
        face = torch.as_tensor(np.asarray(faces), dtype=torch.long)
        checks[name] = check_faces(pos, face)
        cloud, normal = sample(pos, face.t().contiguous(), NUM_POINTS, 0)
        out.append((name, name, cloud, normal))
    return out, checks


def one_sided_pca(pos, normal, pool=30):
    """Oracle for the unoriented normal: PCA of the point and its K nearest
    neighbours on the same side of the surface, chosen among its ``pool``
    nearest by the true normals (dot product above 0.3). What it still gets
    wrong is a sampling limit, not a neighbour-selection one."""
    p, n = pos.numpy(), normal.numpy()
    _, idx = cKDTree(p).query(p, pool + 1)
    same = (n[idx] * n[:, None]).sum(-1) > 0.3
    rank = np.where(same, np.arange(pool + 1), pool + 1)
    chosen = np.take_along_axis(idx, np.argsort(rank, 1)[:, :K + 1], 1)
    keep = np.take_along_axis(same, np.argsort(rank, 1)[:, :K + 1], 1)
    patch = p[chosen] * keep[..., None]
    mean = patch.sum(1) / keep.sum(1, keepdims=True)
    centred = (p[chosen] - mean[:, None]) * keep[..., None]
    _, vectors = np.linalg.eigh(np.einsum('nki,nkj->nij', centred, centred))
    return torch.from_numpy(vectors[:, :, 0])


def unsigned_over(normal, truth, degrees=60.0):
    """Points whose line (sign aside) is more than ``degrees`` off the truth:
    where a normal says little about the side."""
    cos = (normal * truth).sum(-1).abs() / normal.norm(dim=-1) \
        / truth.norm(dim=-1)
    return cos < np.cos(np.radians(degrees))


def contact_mask(pos, normal, tol=2e-3):
    """Points on a hidden contact face: a neighbour with a truly opposite
    normal lies (almost) in the point's own tangent plane."""
    p, n = pos.numpy(), normal.numpy()
    _, idx = cKDTree(p).query(p, K + 1)
    opposite = (n[idx] * n[:, None]).sum(-1) < -0.9
    offset = np.abs(((p[idx] - p[:, None]) * n[:, None]).sum(-1))
    radius = np.sqrt(((p - p.mean(0)) ** 2).sum(1)).max()
    return torch.from_numpy((opposite & (offset < tol * radius)).any(1))


# ---------------------------------------------------------------------------
# Scoring
# ---------------------------------------------------------------------------
def best_of(fn, pos, repeat=3):
    times, out = [], None
    for _ in range(repeat):
        start = time.perf_counter()
        out = fn(pos)
        times.append(time.perf_counter() - start)
    return min(times), out


def score(normal, truth, contact, resolved):
    normal = normal.double()
    cos = ((normal * truth).sum(-1) / normal.norm(dim=-1)
           / truth.norm(dim=-1)).clamp(-1, 1)
    ok = cos > 0
    agreement = float(ok.double().mean())
    return dict(
        agreement=agreement,
        agreement_resolved=float(ok[resolved].double().mean()),
        consistency=max(agreement, 1.0 - agreement),
        agreement_visible=float(ok[~contact].double().mean()),
        median_angle_deg=float(torch.rad2deg(torch.acos(cos)).median()),
        unsigned_angle_deg=float(
            torch.rad2deg(torch.acos(cos.abs())).median()))


def run_set(name, clouds, methods, repeat):
    rows = []
    for shape, group, pos, truth in clouds:
        contact = contact_mask(pos, truth)
        unresolved = unsigned_over(estimate_normals(pos, K, orient=False),
                                   truth)
        row = dict(dataset=name, shape=shape, group=group,
                   points=pos.size(0),
                   contact_fraction=float(contact.double().mean()),
                   pca_over_60=float(unresolved.double().mean()),
                   one_sided_over_60=float(unsigned_over(
                       one_sided_pca(pos, truth), truth).double().mean()))
        for method, fn in methods.items():
            try:
                seconds, normal = best_of(fn, pos, repeat)
            except RuntimeError as error:  # open3d's qhull on some clouds
                row[method] = dict(failed=str(error).strip()[:200])
                continue
            row[method] = dict(seconds=seconds, **score(
                normal, truth, contact, ~unresolved))
        rows.append(row)
        print(f"{name:9s} {shape:24s} " + '  '.join(
            f"{m} {row[m]['agreement']:.3f} {1e3 * row[m]['seconds']:.0f}ms"
            if 'agreement' in row[m] else f'{m} failed'
            for m in methods), flush=True)
    return rows


def summarize(rows, methods):
    out = {}
    every = rows
    for method in methods:
        rows = [r for r in every if 'agreement' in r[method]]
        agree = np.array([r[method]['agreement'] for r in rows])
        visible = np.array([r[method]['agreement_visible'] for r in rows])
        worst = rows[int(agree.argmin())]['shape']
        out[method] = dict(
            mean_agreement=float(agree.mean()),
            min_agreement=float(agree.min()), worst_shape=worst,
            shapes_at_goal=int((agree >= GOAL).sum()), shapes=len(rows),
            mean_consistency=float(np.mean(
                [r[method]['consistency'] for r in rows])),
            flipped_shapes=int((agree < 0.5).sum()),
            mean_agreement_visible=float(visible.mean()),
            mean_agreement_resolved=float(np.mean(
                [r[method]['agreement_resolved'] for r in rows])),
            min_agreement_visible=float(visible.min()),
            median_angle_deg=float(np.median(
                [r[method]['median_angle_deg'] for r in rows])),
            unsigned_angle_deg=float(np.median(
                [r[method]['unsigned_angle_deg'] for r in rows])),
            median_seconds=float(np.median(
                [r[method]['seconds'] for r in rows])),
            failures=len(every) - len(rows))
    rows = every
    groups = {}
    for group in dict.fromkeys(r['group'] for r in rows):
        these = [r for r in rows if r['group'] == group]
        groups[group] = {}
        for m in methods:
            agree = [r[m]['agreement'] for r in these if 'agreement' in r[m]]
            groups[group][m] = dict(
                mean_agreement=float(np.mean(agree)) if agree else None,
                min_agreement=float(np.min(agree)) if agree else None)
        for key in ('contact_fraction', 'pca_over_60', 'one_sided_over_60'):
            groups[group][key] = float(np.mean([r[key] for r in these]))
    return dict(methods=out, groups=groups,
                pca_over_60=float(np.mean([r['pca_over_60'] for r in rows])),
                one_sided_over_60=float(np.mean(
                    [r['one_sided_over_60'] for r in rows])))


# ---------------------------------------------------------------------------
# Plot
# ---------------------------------------------------------------------------
COLORS = {'old': 'tab:gray', 'new': 'tab:blue', 'open3d': 'tab:orange'}
LABELS = {'old': 'previous (MST + flux)', 'new': 'estimate_normals (new)',
          'open3d': 'Open3D tangent plane'}


def plot(result, path):
    sets = list(result['datasets'])
    methods = result['methods']
    fig, axes = plt.subplots(1, len(sets) + 1,
                             figsize=(4.2 * (len(sets) + 1), 4.2))
    for ax, name in zip(axes, sets):
        rows = result['datasets'][name]['rows']
        for j, method in enumerate(methods):
            values = 100 * np.array([r[method]['agreement'] for r in rows
                                     if 'agreement' in r[method]])
            x = j + np.linspace(-0.25, 0.25, len(values)) \
                if len(values) > 1 else np.array([j])
            ax.scatter(x, values, s=8, alpha=0.6, color=COLORS[method])
            ax.hlines(values.mean(), j - 0.35, j + 0.35,
                      color=COLORS[method], lw=2)
        ax.axhline(100 * GOAL, color='k', ls='--', lw=0.8,
                   label=f'goal {100 * GOAL:.0f}%')
        ax.set_xticks(range(len(methods)), [m for m in methods])
        ax.set_ylabel('points oriented like the truth (%)')
        ax.set_title(f"{name} ({len(rows)} clouds of "
                     f"{rows[0]['points']} points)", fontsize=9)
        ax.set_ylim(0, 101)
        ax.legend(fontsize=7, loc='lower left')
    ax = axes[-1]
    x = np.arange(len(sets))
    width = 0.8 / len(methods)
    for j, method in enumerate(methods):
        ax.bar(x + (j - (len(methods) - 1) / 2) * width,
               [1e3 * result['datasets'][s]['summary']['methods'][method]
                ['median_seconds'] for s in sets], width,
               color=COLORS[method], label=LABELS[method])
    ax.set_xticks(x, [s.replace('Synthetic', 'Synthetic\n') for s in sets])
    ax.set_ylabel('median time per cloud (ms, normals included)')
    ax.set_title(f"time, {result['threads']} thread(s)", fontsize=9)
    ax.legend(fontsize=7)
    fig.suptitle('Normal orientation: per-shape agreement with the true '
                 'outward normals (bars: means) and time per cloud, k = 10',
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--data', default=os.path.join(HERE, '..', '..',
                                                       'shared', 'data'))
    parser.add_argument('--root', default=None,
                        help='where the synthetic data sets are generated '
                             '(default: a temporary directory)')
    parser.add_argument('--open3d', default=None,
                        help='a directory to append to sys.path for open3d')
    parser.add_argument('--quick', action='store_true')
    parser.add_argument('--out', default=RESULTS)
    args = parser.parse_args()
    start = time.perf_counter()
    if args.open3d:
        sys.path.append(args.open3d)
    methods = {'old': old_normals, 'new': new_normals}
    versions = {}
    try:
        import open3d as o3d
        methods['open3d'] = open3d_normals(o3d)
        versions['open3d'] = o3d.__version__
    except ImportError as error:
        print(f'open3d not available ({error}); comparing old and new only')
    root = args.root or tempfile.mkdtemp(prefix='normals_')
    clouds = {'SyntheticModelNet': modelnet_clouds(root, args.quick),
              'SyntheticSHREC': shrec_clouds(root, args.quick)}
    checks = None
    if glob.glob(os.path.join(args.data, 'meshes', '*.obj')):
        clouds['scanned meshes'], checks = mesh_clouds(args.data)
    else:
        print(f'no meshes under {args.data}/meshes; skipping them')
    for fn in methods.values():  # compile / warm up
        fn(clouds['SyntheticModelNet'][0][2])
    repeat = 1 if args.quick else 3
    datasets = {}
    for name, these in clouds.items():
        rows = run_set(name, these, methods, repeat)
        datasets[name] = dict(summary=summarize(rows, methods), rows=rows)
    info = machine_info()
    info.update(numba_threads=numba.get_num_threads(),
                affinity=sorted(os.sched_getaffinity(0)))
    threads = max(info['torch_threads'], info['numba_threads'],
                  len(info['affinity']))
    result = dict(
        benchmark='normals', quick=args.quick, k=K, goal=GOAL,
        threads=threads, methods=list(methods), versions=versions,
        machine=info, notes=NOTES,
        mesh_checks=checks, datasets=datasets,
        total_s=time.perf_counter() - start)
    os.makedirs(args.out, exist_ok=True)
    atomic_write_json(os.path.join(args.out, 'normals.json'), result)
    plot(result, os.path.join(args.out, 'normals.png'))
    print(f"\n{'data set':18s} {'method':7s} {'mean':>6s} {'min':>6s} "
          f"{'>=97%':>6s} {'visible':>8s} {'angle':>6s} {'ms':>6s}")
    for name, d in datasets.items():
        for method, s in d['summary']['methods'].items():
            print(f"{name:18s} {method:7s} {100 * s['mean_agreement']:6.1f} "
                  f"{100 * s['min_agreement']:6.1f} "
                  f"{s['shapes_at_goal']:3d}/{s['shapes']:<3d}"
                  f"{100 * s['mean_agreement_visible']:7.1f} "
                  f"{s['median_angle_deg']:6.1f} "
                  f"{1e3 * s['median_seconds']:6.1f}")
    print(f"total {result['total_s']:.0f} s")


if __name__ == '__main__':
    main()
