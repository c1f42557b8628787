"""Learning an anisotropic filter (DeltaConv thesis Fig. 3.2): networks map
a noisy piecewise-smooth signal on a point cloud to its Perona-Malik
filtered version; DeltaConv (scalar + vector streams) against isotropic
convolutions of matched size.

Protocol: random closed surfaces as point clouds of --points points
(star-shaped bumpy spheres and bumpy tori, alternately), k = 20 neighbour
MLS operators with PCA normals. Signal: two random half-space steps (jumps
of 0.5-1) plus a smooth wave (amplitude 0.3) plus Gaussian noise (0.05).
Target: 20 explicit Perona-Malik steps, g(s) = 1 / (1 + (s / 1)^2),
dt = 1 / rho (rho: spectral radius of -DG, half the stability bound), on
the unnormalised MLS operators (tg_intrinsic.geometry.pointcloud
.perona_malik). Models predict a residual (output = input + head): a
DeltaConv ResNet (first layer on v = grad u, then residual DeltaConv
layers); a Laplacian-only ResNet (layers see [x, Laplacian x], no vector
stream: isotropic); PyG's GCNConv and EdgeConv ResNets on the k-nn graph.
Widths are chosen so that every model has about as many parameters as the
DeltaConv net; every head starts at zero (the identity). Defaults: 600
points, 40 training and 8 test surfaces, width 32, 4 layers. Adam 3e-3
with a cosine schedule, MSE loss, batches of 4 surfaces, --epochs
epochs, one seed, two CPU threads. Error: relative L2,
||prediction - target|| / ||input - target|| over the test surfaces (1 =
no better than returning the input), and the MSE.

Usage: python benchmarks/perona_malik.py [--epochs 50] [--quick]
Writes benchmarks/results/perona_malik.json and .png.
"""
import argparse
import math
import os
import time

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402
import torch.nn.functional as F  # noqa: E402
from torch_geometric.nn import EdgeConv, GCNConv  # noqa: E402

from tg_intrinsic.geometry.pointcloud import (SurfaceOperators,  # noqa: E402
                                              build_mls_operators, knn,
                                              perona_malik)
from tg_intrinsic.nn import DeltaConv  # noqa: E402
from tg_intrinsic.utils import atomic_write_json, machine_info  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
K = 20
STEPS, KAPPA = 20, 1.0


def fibonacci(n):
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    phi = np.pi * (1 + 5 ** 0.5) * i
    r = np.sqrt(1 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], 1)


def surface(n, rng, kind):
    """A random closed surface as ``n`` points."""
    if kind == 'blob':
        unit = fibonacci(n)
        radius = np.ones(n)
        for _ in range(4):
            d = rng.normal(size=3)
            d /= np.linalg.norm(d)
            radius += rng.uniform(0.05, 0.15) * np.sin(
                rng.uniform(1.5, 3.5) * unit @ d + rng.uniform(0, 6.3))
        pos = unit * radius[:, None]
    else:  # a bumpy torus on a golden-ratio lattice of (u, v)
        i = np.arange(n) + 0.5
        u, v = 2 * np.pi * i / n, 2 * np.pi * ((i * 0.618034) % 1)
        r = 0.4 + 0.05 * np.sin(rng.integers(2, 6) * u + rng.uniform(0, 6))
        pos = np.stack([(1 + r * np.cos(v)) * np.cos(u),
                        (1 + r * np.cos(v)) * np.sin(u), r * np.sin(v)], 1)
    rot, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return torch.from_numpy(pos @ rot.T)


def signal(pos, rng):
    p = pos.numpy()
    u = np.zeros(len(p))
    for _ in range(2):
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        c = rng.uniform(-0.4, 0.4)
        u += rng.choice([-1, 1]) * rng.uniform(0.5, 1.0) * (p @ d > c)
    d = rng.normal(size=3)
    u += 0.3 * np.sin(rng.uniform(2, 5) * p @ (d / np.linalg.norm(d)))
    u += 0.05 * rng.normal(size=len(p))
    return torch.from_numpy(u)


def make_example(n, seed):
    rng = np.random.default_rng(seed)
    pos = surface(n, rng, 'blob' if seed % 2 == 0 else 'torus')
    u = signal(pos, rng)
    ei, _, gw, dw = build_mls_operators(pos, K, normalized=False)
    target = perona_malik(pos, u, STEPS, kappa=KAPPA,
                          operators=SurfaceOperators(ei, gw, dw, n))
    # the networks get DeltaNet's (normalised) operators, in float32
    ei, _, gw, dw = build_mls_operators(pos, K)
    return dict(pos=pos.float(), x=u.float()[:, None],
                y=target.float()[:, None], edge_index=ei, grad=gw.float(),
                div=dw.float(), knn=knn(pos, K))


def collate(examples):
    """One graph of several surfaces (indices offset), with operators."""
    out, offset = {}, 0
    for key in ('pos', 'x', 'y', 'grad', 'div'):
        out[key] = torch.cat([e[key] for e in examples])
    for key in ('edge_index', 'knn'):
        parts = []
        offset = 0
        for e in examples:
            parts.append(e[key] + offset)
            offset += e['pos'].size(0)
        out[key] = torch.cat(parts, 1)
    out['ops'] = SurfaceOperators(out['edge_index'], out['grad'],
                                  out['div'], offset)
    return out


class DeltaResNet(torch.nn.Module):
    def __init__(self, width, layers):
        super().__init__()
        self.first = DeltaConv(1, width)
        self.convs = torch.nn.ModuleList(
            [DeltaConv(width, width) for _ in range(layers - 1)])
        self.head = torch.nn.Linear(width, 1)

    def forward(self, b):
        ops = b['ops']
        x, v = self.first(b['x'], ops.grad(b['x']), b['edge_index'], ops)
        for conv in self.convs:
            dx, dv = conv(x, v, b['edge_index'], ops)
            x, v = x + dx, v + dv
        return b['x'] + self.head(x)


class LaplacianLayer(torch.nn.Module):
    """Isotropic: x' = MLP([x, Laplacian x])."""
    def __init__(self, c_in, c_out):
        super().__init__()
        self.lin = torch.nn.Linear(2 * c_in, c_out, bias=False)
        self.norm = torch.nn.BatchNorm1d(c_out)

    def forward(self, x, ops):
        h = self.lin(torch.cat([x, ops.laplacian(x)], 1))
        return F.leaky_relu(self.norm(h), 0.2)


class LaplacianResNet(torch.nn.Module):
    def __init__(self, width, layers):
        super().__init__()
        self.first = LaplacianLayer(1, width)
        self.layers = torch.nn.ModuleList(
            [LaplacianLayer(width, width) for _ in range(layers - 1)])
        self.head = torch.nn.Linear(width, 1)

    def forward(self, b):
        x = self.first(b['x'], b['ops'])
        for layer in self.layers:
            x = x + layer(x, b['ops'])
        return b['x'] + self.head(x)


class GraphResNet(torch.nn.Module):
    """GCNConv or EdgeConv layers on the k-nn graph, residual."""
    def __init__(self, width, layers, kind):
        super().__init__()
        self.lift = torch.nn.Linear(1, width)
        self.kind = kind

        def conv():
            if kind == 'gcn':
                return GCNConv(width, width)
            return EdgeConv(torch.nn.Sequential(
                torch.nn.Linear(2 * width, width), torch.nn.LeakyReLU(0.2),
                torch.nn.Linear(width, width)), aggr='max')

        self.convs = torch.nn.ModuleList([conv() for _ in range(layers)])
        self.norms = torch.nn.ModuleList(
            [torch.nn.BatchNorm1d(width) for _ in range(layers)])
        self.head = torch.nn.Linear(width, 1)

    def forward(self, b):
        x = self.lift(b['x'])
        for conv, norm in zip(self.convs, self.norms):
            x = x + F.leaky_relu(norm(conv(x, b['knn'])), 0.2)
        return b['x'] + self.head(x)


def zero_heads(model):
    """Every model starts as the identity (a zero residual)."""
    torch.nn.init.zeros_(model.head.weight)
    torch.nn.init.zeros_(model.head.bias)
    return model


def count(model):
    return sum(p.numel() for p in model.parameters())


def matched(build, target):
    """The width whose model is closest to ``target`` parameters."""
    best = min(range(4, 257), key=lambda w: abs(count(build(w)) - target))
    return best, build(best)


def evaluate(model, batches):
    model.eval()
    num = den = mse = total = 0.0
    with torch.no_grad():
        for b in batches:
            pred = model(b)
            num += float((pred - b['y']).square().sum())
            den += float((b['x'] - b['y']).square().sum())
            mse += float((pred - b['y']).square().sum())
            total += b['y'].numel()
    return math.sqrt(num / den), mse / total


def train(model, batches, tests, epochs, lr, seed):
    gen = torch.Generator().manual_seed(seed)
    optimizer = torch.optim.Adam(model.parameters(), lr=lr)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(
        optimizer, epochs * len(batches), eta_min=lr / 100)
    history, start = [], time.time()
    for epoch in range(1, epochs + 1):
        model.train()
        total = 0.0
        for i in torch.randperm(len(batches), generator=gen).tolist():
            loss = F.mse_loss(model(batches[i]), batches[i]['y'])
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            schedule.step()
            total += loss.item()
        entry = {'epoch': epoch, 'loss': total / len(batches),
                 'seconds': time.time() - start}
        if epoch == epochs or epoch % max(1, epochs // 5) == 0:
            entry['test_rel_l2'], entry['test_mse'] = evaluate(model, tests)
            print(f"  epoch {epoch}: loss {entry['loss']:.2e}, test rel "
                  f"L2 {entry['test_rel_l2']:.3f}", flush=True)
        history.append(entry)
    return history


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument('--epochs', type=int, default=50)
    parser.add_argument('--points', type=int, default=600)
    parser.add_argument('--train', type=int, default=40)
    parser.add_argument('--test', type=int, default=8)
    parser.add_argument('--width', type=int, default=32)
    parser.add_argument('--layers', type=int, default=4)
    parser.add_argument('--lr', type=float, default=3e-3)
    parser.add_argument('--threads', type=int, default=2)
    parser.add_argument('--quick', action='store_true',
                        help='3 epochs on 8 + 4 surfaces of 500 points')
    parser.add_argument('--out', default=os.path.join(HERE, 'results'))
    args = parser.parse_args()
    if args.quick:
        args.epochs, args.train, args.test, args.points = 3, 8, 4, 500
    torch.set_num_threads(args.threads)
    start = time.time()
    examples = [make_example(args.points, s)
                for s in range(args.train + args.test)]
    train_set, test_set = examples[:args.train], examples[args.train:]
    batches = [collate(train_set[i:i + 4])
               for i in range(0, len(train_set), 4)]
    tests = [collate(test_set[i:i + 4]) for i in range(0, len(test_set), 4)]
    data_seconds = time.time() - start
    torch.manual_seed(0)
    delta = DeltaResNet(args.width, args.layers)
    size = count(delta)
    builders = [
        ('DeltaConv (scalar + vector)', lambda w: DeltaResNet(w, args.layers)),
        ('Laplacian only (isotropic)',
         lambda w: LaplacianResNet(w, args.layers)),
        ('GCNConv (isotropic)', lambda w: GraphResNet(w, args.layers, 'gcn')),
        ('EdgeConv', lambda w: GraphResNet(w, args.layers, 'edge')),
    ]
    results = {
        'machine': machine_info(), 'quick': args.quick,
        'epochs': args.epochs, 'points': args.points,
        'train_surfaces': args.train, 'test_surfaces': args.test,
        'layers': args.layers, 'data_seconds': data_seconds,
        'protocol': (f'{args.points}-point bumpy spheres and tori, k = {K} '
                     f'MLS operators; noisy piecewise-smooth signals; '
                     f'target {STEPS} Perona-Malik steps (kappa {KAPPA}, '
                     f'dt = 1 / rho); residual ResNets of {args.layers} '
                     f'layers, matched parameters; Adam {args.lr} cosine, '
                     f'MSE, 4 surfaces per batch'),
        'runs': []}
    for name, build in builders:
        torch.manual_seed(0)
        if name.startswith('DeltaConv'):
            width, model = args.width, build(args.width)
        else:
            width, model = matched(build, size)
        zero_heads(model)  # after matching: same start for every model
        print(f'{name}: width {width}, {count(model)} parameters',
              flush=True)
        history = train(model, batches, tests, args.epochs, args.lr, seed=0)
        rel_l2, mse = evaluate(model, tests)
        results['runs'].append({
            'model': name, 'width': width, 'parameters': count(model),
            'test_rel_l2': rel_l2, 'test_mse': mse,
            'seconds': history[-1]['seconds'], 'history': history})
        results['runs'][-1]['example'] = prediction(model, tests[0])
        atomic_write_json(os.path.join(args.out, 'perona_malik.json'),
                          strip(results))
    results['input_mse'] = float(np.mean([
        float((b['x'] - b['y']).square().mean()) for b in tests]))
    results['total_seconds'] = time.time() - start
    plot(results, tests[0], args.out)
    atomic_write_json(os.path.join(args.out, 'perona_malik.json'),
                      strip(results))


def prediction(model, batch):
    model.eval()
    with torch.no_grad():
        return model(batch)[:, 0]


def strip(results):
    """The results without the example predictions (tensors)."""
    out = dict(results)
    out['runs'] = [{k: v for k, v in r.items() if k != 'example'}
                   for r in results['runs']]
    return out


def plot(results, batch, out):
    n = results['points']
    pos = batch['pos'][:n].numpy()
    panels = [('input', batch['x'][:n, 0]),
              ('target (Perona-Malik)', batch['y'][:n, 0])] + [
        (r['model'], r['example'][:n]) for r in results['runs']]
    fig = plt.figure(figsize=(3.2 * (len(panels) + 1), 3.4))
    lo, hi = float(batch['y'][:n].min()), float(batch['y'][:n].max())
    for k, (title, values) in enumerate(panels):
        ax = fig.add_subplot(1, len(panels) + 1, k + 1, projection='3d')
        ax.scatter(pos[:, 0], pos[:, 1], pos[:, 2], c=values.numpy(), s=3,
                   cmap='coolwarm', vmin=lo, vmax=hi)
        ax.set_title(title, fontsize=8)
        ax.set_axis_off()
    ax = fig.add_subplot(1, len(panels) + 1, len(panels) + 1)
    names = [r['model'].split(' (')[0] for r in results['runs']]
    ax.bar(names, [r['test_rel_l2'] for r in results['runs']],
           color=['C0'] + ['C7'] * (len(names) - 1))
    ax.axhline(1.0, color='k', lw=0.8, ls='--')
    ax.set_ylabel('test relative L2 error')
    ax.tick_params(axis='x', labelrotation=45, labelsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(out, 'perona_malik.png'), dpi=110)
    plt.close(fig)


if __name__ == '__main__':
    main()
