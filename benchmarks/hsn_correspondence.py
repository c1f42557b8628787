"""Dense shape correspondence with the HSN U-ResNet (HSNCorrespondence)
against a non-equivariant baseline of matched size, on
SyntheticCorrespondence (one humanoid template in near-isometric limb
poses; the FAUST experiment of Harmonic Surface Networks in miniature).

Protocol: template of 800 vertices (unit area), 24 training and 12 test
poses, 20 epochs (--quick: 500 vertices, 8 + 4 poses, 3 epochs). Every
vertex is classified as one of the template's vertices (cross entropy);
the error of a prediction is the geodesic distance on the template between the
predicted and the true vertex, divided by the template's geodesic
diameter (fast marching, tg_intrinsic.geometry.geodesics.distance); we
report the fraction of test vertices within thresholds 0 .. 0.1 (the
Princeton-benchmark curve of the HSN paper's FAUST plot).

Input features: the heat kernel signature (16 times log-spaced over the
spectrum of the cotan Laplacian, 64 eigenpairs, normalised per time) of
every pose. The HSN paper feeds FAUST's xyz, which works there because
its scans are aligned and in similar poses; here the limbs swing freely,
so raw xyz would mostly encode the pose. The HKS is intrinsic, so it is
nearly the same in every pose (up to the joints' stretch), and both
networks get the same input.

Models: HSN = HSNCorrespondence, the paper's correspondence net (two
levels, four stacks of two ResNet blocks, 16 / 32 features, rotation
orders 0 and 1, 2 rings, discs 0.08 / 0.16 on unit area, a quarter of the
vertices on level 1, FC 256 + dropout 0.5 + FC to the template's
vertices). Reference without learning: every vertex matched to the
template vertex of nearest HKS (an intrinsic descriptor cannot tell
left from right limbs apart: the humanoid is mirror-symmetric by
construction, up to its meshing). Baseline =
the same head on a PointNet++-style backbone: PyG's
PointNetConv on the same level-0 discs, messages from
[h_j, p_j - p_i] with p in global xyz coordinates, residual layers, its
width chosen so that its backbone has at least the HSN backbone's
parameters. It is not rotation equivariant: its filters see the offsets
in the global frame, so a limb turned by a pose looks different to it
(the HSN sees only gauge-invariant quantities). Both: Adam, lr 1e-2
(HSN paper) for 2/3 of the epochs then 1e-3, batch 1 mesh; the two
trainings run side by side in two processes of one thread each (the two
cores); seconds per epoch are then timed again one model after the
other (one thread, one epoch each).

Usage: python benchmarks/hsn_correspondence.py [--quick] [--epochs 20]
Writes benchmarks/results/hsn_correspondence.json and .png.
"""
import argparse
import multiprocessing
import os
import time

import matplotlib
import numpy as np
import torch
import torch.nn.functional as F

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
from torch_geometric.nn import PointNetConv  # noqa: E402
from torch_geometric.transforms import Compose  # noqa: E402

from tg_intrinsic.datasets import (SyntheticCorrespondence,  # noqa: E402
                                   correspondence_accuracy)
from tg_intrinsic.geometry.geodesics.distance import (  # noqa: E402
    geodesic_distances)
from tg_intrinsic.geometry.mesh import (cotan_laplacian,  # noqa: E402
                                        lumped_mass)
from tg_intrinsic.geometry.sparse import to_scipy  # noqa: E402
from tg_intrinsic.nn.models import HSNCorrespondence  # noqa: E402
from tg_intrinsic.transforms import (HarmonicPrecompute, LogMap,  # noqa
                                     MultiscaleSupports)
from tg_intrinsic.utils import atomic_write_json, machine_info  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
THRESHOLDS = [round(0.01 * k, 2) for k in range(11)]
RADII, RINGS, HKS_TIMES = (0.08, 0.16), 2, 16


def heat_kernel_signature(pos, face, times=HKS_TIMES, k=64):
    """HKS of every vertex: sum_j exp(-lambda_j t) phi_j(x)^2 for
    log-spaced t, each time normalised by its mean over the surface."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as sla
    pos = pos.double()
    S = to_scipy(cotan_laplacian(pos, face))
    mass = lumped_mass(pos, face).numpy()
    start = np.random.default_rng(0).standard_normal(pos.size(0))
    lam, phi = sla.eigsh(S, k=k, M=sp.diags(mass), sigma=-1e-8, v0=start)
    lam = np.clip(lam, 0, None)
    t = np.geomspace(4 * np.log(10) / lam[-1], 4 * np.log(10) / lam[1],
                     times)
    hks = (phi ** 2) @ np.exp(-lam[:, None] * t[None, :])
    hks /= (mass[:, None] * hks).sum(0) / mass.sum()
    return torch.from_numpy(np.log(hks)).float()


class AddHKS:
    def __call__(self, data):
        data = data.clone()
        data.x = heat_kernel_signature(data.pos, data.face)
        return data

    def __repr__(self):
        return f'AddHKS(times={HKS_TIMES})'


class PointNetBackbone(torch.nn.Module):
    """Residual PointNetConv layers on the level-0 discs (global xyz
    offsets): the non-equivariant baseline."""
    def __init__(self, in_channels, width, layers=8):
        super().__init__()
        self.lin = torch.nn.Linear(in_channels, width)
        self.convs = torch.nn.ModuleList([
            PointNetConv(torch.nn.Sequential(
                torch.nn.Linear(width + 3, width), torch.nn.ReLU(),
                torch.nn.Linear(width, width)),
                torch.nn.Sequential(torch.nn.BatchNorm1d(width)),
                add_self_loops=False) for _ in range(layers)])
        self.width = width

    def forward(self, data):
        h = F.relu(self.lin(data.x))
        for conv in self.convs:
            h = F.relu(h + conv(h, data.pos, data.edge_index))
        return h


class Correspondence(torch.nn.Module):
    """A backbone and the paper's two FC layers over template vertices."""
    def __init__(self, backbone, width, num_vertices, hidden=256):
        super().__init__()
        self.backbone = backbone
        self.lin1 = torch.nn.Linear(width, hidden)
        self.lin2 = torch.nn.Linear(hidden, num_vertices)

    def forward(self, data):
        h = F.relu(self.lin1(self.backbone(data)))
        return self.lin2(F.dropout(h, 0.5, self.training))


def count(module):
    return sum(p.numel() for p in module.parameters())


def matched_width(target, in_channels):
    width = 8
    while count(PointNetBackbone(in_channels, width)) < target:
        width += 1
    return width


def train_and_test(model, train_set, test_set, dist, epochs, log):
    opt = torch.optim.Adam(model.parameters(), lr=1e-2)
    history, seconds = [], []
    for epoch in range(1, epochs + 1):
        if epoch == int(round(2 * epochs / 3)) + 1:
            for group in opt.param_groups:
                group['lr'] = 1e-3
        model.train()
        start = time.perf_counter()
        total = 0.0
        for i in torch.randperm(len(train_set)).tolist():
            data = train_set[i]
            opt.zero_grad()
            loss = F.cross_entropy(model(data), data.y)
            loss.backward()
            opt.step()
            total += float(loss.detach())
        seconds.append(time.perf_counter() - start)
        curve = evaluate(model, test_set, dist)
        history.append({'epoch': epoch, 'loss': total / len(train_set),
                        'seconds': seconds[-1], 'exact': curve[0],
                        'within_0.05': curve[5]})
        log(f'  epoch {epoch}: loss {history[-1]["loss"]:.3f}, exact '
            f'{curve[0]:.3f}, within 0.05: {curve[5]:.3f} '
            f'({seconds[-1]:.1f} s)')
    return history, evaluate(model, test_set, dist), float(
        np.median(seconds))


@torch.no_grad()
def evaluate(model, test_set, dist):
    model.eval()
    pred, target = [], []
    for data in test_set:
        pred.append(model(data).argmax(1))
        target.append(data.y)
    return correspondence_accuracy(torch.cat(pred), torch.cat(target), dist,
                                   THRESHOLDS).tolist()


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument('--root', default=os.path.join('data', 'corr'))
    parser.add_argument('--quick', action='store_true')
    parser.add_argument('--epochs', type=int, default=None)
    parser.add_argument('--out', default=os.path.join(HERE, 'results'))
    parser.add_argument('--plot-only', action='store_true',
                        help='redraw the PNG from the JSON')
    args = parser.parse_args()
    path = os.path.join(args.out, 'hsn_correspondence.json')
    if args.plot_only:
        import json
        with open(path) as f:
            return plot(json.load(f), args.out)
    nv, n_train, n_test = (500, 8, 4) if args.quick else (800, 24, 12)
    epochs = args.epochs or (3 if args.quick else 20)
    start = time.perf_counter()
    train_set, test_set = datasets(args.root, nv, n_train, n_test)
    prep = time.perf_counter() - start
    template = train_set.template
    dist = geodesic_distances(template.pos.double(), template.face).float()
    print(f'data: {n_train} + {n_test} poses of {nv} vertices '
          f'({prep:.0f} s to generate and precompute)')
    results = {
        'benchmark': 'hsn_correspondence', 'machine': machine_info(),
        'quick': args.quick, 'num_vertices': nv, 'num_train': n_train,
        'num_test': n_test, 'epochs': epochs, 'thresholds': THRESHOLDS,
        'input': f'heat kernel signature, {HKS_TIMES} times',
        'radii': list(RADII), 'rings': RINGS,
        'geodesic_diameter': float(dist.max()),
        'prepare_seconds': prep, 'runs': []}
    # reference without learning: the template vertex of nearest HKS
    reference = nearest_descriptor(template, test_set, dist)
    results['hks_nearest_neighbour'] = {
        'curve': reference, 'exact': reference[0],
        'within_0.05': reference[5], 'within_0.1': reference[10]}
    print(f'HKS nearest neighbour: exact {reference[0]:.3f}, within 0.05: '
          f'{reference[5]:.3f}')
    # the two trainings run side by side, one core and thread each
    jobs = [(name, args.root, nv, n_train, n_test, epochs, dist)
            for name in MODELS]
    with multiprocessing.get_context('fork').Pool(len(jobs)) as pool:
        results['runs'] = pool.map(run, jobs)
    # seconds per epoch, one model after the other on an otherwise idle
    # process (one thread): the side-by-side epochs share the cores
    torch.set_num_threads(1)
    for kind, entry in zip(MODELS, results['runs']):
        entry['seconds_per_epoch'] = epoch_seconds(build(kind, nv)[1],
                                                   train_set)
    atomic_write_json(path, results)
    plot(results, args.out)


MODELS = ('hsn', 'baseline')


def epoch_seconds(model, train_set):
    """Wall time of one training epoch (forward, backward, Adam step)."""
    opt = torch.optim.Adam(model.parameters(), lr=1e-2)
    model.train()
    start = time.perf_counter()
    for data in train_set:
        opt.zero_grad()
        F.cross_entropy(model(data), data.y).backward()
        opt.step()
    return time.perf_counter() - start


def nearest_descriptor(template, test_set, dist):
    """Accuracy curve of matching every vertex to the template vertex
    with the nearest heat kernel signature (no learning)."""
    ref = heat_kernel_signature(template.pos, template.face)
    pred = torch.cat([torch.cdist(d.x, ref).argmin(1) for d in test_set])
    target = torch.cat([d.y for d in test_set])
    return correspondence_accuracy(pred, target, dist, THRESHOLDS).tolist()


def datasets(root, nv, n_train, n_test):
    pre = Compose([AddHKS(), LogMap(RADII[0]),
                   MultiscaleSupports([0.25], [RADII[1]]),
                   HarmonicPrecompute(RINGS, 1)])
    kwargs = dict(num_train=n_train, num_test=n_test, num_vertices=nv,
                  pre_transform=pre, log=False)
    return (SyntheticCorrespondence(root, 'train', **kwargs),
            SyntheticCorrespondence(root, 'test', **kwargs))


def build(kind, nv):
    torch.manual_seed(0)
    hsn = HSNCorrespondence(HKS_TIMES, nv, channels=(16, 32), max_order=1,
                            rings=RINGS)
    if kind == 'hsn':
        return 'HSN U-ResNet (M = 0, 1)', hsn
    width = matched_width(count(hsn.backbone), HKS_TIMES)
    torch.manual_seed(0)
    return (f'PointNet++-style, global xyz (width {width})',
            Correspondence(PointNetBackbone(HKS_TIMES, width), width, nv))


def run(job):
    kind, root, nv, n_train, n_test, epochs, dist = job
    torch.set_num_threads(1)
    train_set, test_set = datasets(root, nv, n_train, n_test)
    name, model = build(kind, nv)

    def log(text):
        print(f'[{kind}] {text}', flush=True)

    history, curve, sec = train_and_test(model, train_set, test_set, dist,
                                         epochs, log)
    return {'model': name, 'parameters': count(model),
            'backbone_parameters': count(model.backbone),
            'seconds_per_epoch_side_by_side': sec, 'curve': curve,
            'exact': curve[0], 'within_0.05': curve[5],
            'within_0.1': curve[10], 'history': history}


def plot(results, out):
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for run in results['runs']:
        label = f"{run['model']} ({run['parameters']} params)"
        axes[0].plot(results['thresholds'], run['curve'], 'o-', label=label)
        axes[1].plot([h['epoch'] for h in run['history']],
                     [h['within_0.05'] for h in run['history']], 'o-',
                     label=label)
    axes[0].plot(results['thresholds'],
                 results['hks_nearest_neighbour']['curve'], 'k--',
                 label='nearest HKS (no learning)')
    axes[0].set_xlabel('geodesic error / geodesic diameter')
    axes[0].set_ylabel('fraction of correspondences')
    axes[0].set_title(f"SyntheticCorrespondence, {results['num_vertices']} "
                      f"vertices, {results['num_test']} test poses")
    axes[1].set_xlabel('epoch')
    axes[1].set_ylabel('fraction within 0.05 of the diameter')
    for ax in axes:
        ax.set_ylim(0, 1)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(out, 'hsn_correspondence.png'), dpi=120)


if __name__ == '__main__':
    main()
