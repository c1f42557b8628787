"""
DeltaConv: surface operators and a DeltaNet
===========================================

DeltaConv in under a minute (Wiersma et al., "DeltaConv: anisotropic
operators for geometric deep learning on point clouds", SIGGRAPH 2022).

1. The operators: gradient and divergence of a point cloud by moving least
   squares (``build_mls_operators`` + ``SurfaceOperators``), checked on the
   unit sphere against the analytic answers: the surface gradient of
   f = z is the tangential part of e_z, and the Laplace-Beltrami operator
   maps z to 2 z (z is a degree-1 spherical harmonic, eigenvalue l(l+1)).
2. A small ``DeltaNetClassification`` trained for a few epochs on six
   classes of a shrunken ``SyntheticModelNet`` (generated here, no
   download), with its test accuracy.

    python examples/deltaconv.py [--out DIR] [--quick] [--epochs N]

``--quick`` (used by the smoke test) trains on 2 classes instead of 6,
3 instead of 10 training shapes per class, 128 instead of 256 points,
for 2 instead of 8 epochs, and uses 2000 instead of 8000 sphere points.
Everything is written under ``--out`` (default ``runs/examples/deltaconv``):
the generated data set cache, ``figure.png`` (the training loss per epoch
and the test accuracy) and ``results.json``.
"""
import argparse
import json
import os
import time

import torch
import torch.nn.functional as F
from torch_geometric.loader import DataLoader
from torch_geometric.transforms import Compose, RandomScale

from tg_intrinsic.datasets import SyntheticModelNet
from tg_intrinsic.geometry import SurfaceOperators, build_mls_operators
from tg_intrinsic.geometry.appearance.sh import fibonacci_sphere
from tg_intrinsic.nn import recalibrate_batch_norm
from tg_intrinsic.nn.models import DeltaNetClassification
from tg_intrinsic.transforms import RandomRotation

CLASSES = ('airplane', 'bottle', 'chair', 'guitar', 'lamp', 'table')


def parse_args():
    parser = argparse.ArgumentParser(description=__doc__.strip().split(
        '\n')[0])
    parser.add_argument('--out', default=os.path.join('runs', 'examples',
                                                      'deltaconv'))
    parser.add_argument('--quick', action='store_true',
                        help='smaller data and fewer epochs (smoke test)')
    parser.add_argument('--epochs', type=int, default=None)
    parser.add_argument('--seed', type=int, default=0)
    return parser.parse_args()


def operators_on_the_sphere(num_points):
    """Part 1: the MLS operators against analytic answers on S^2."""
    pos = fibonacci_sphere(num_points)          # [N, 3] float64, unit sphere
    # The exact normals give the frames (rows e_u, e_v, n); without
    # `normal=` the normals would be estimated by PCA of 10 neighbours.
    # normalized=False keeps the operators in the units of the shape (the
    # networks use normalized=True, which makes them scale-invariant).
    edge_index, frame, grad_w, div_w = build_mls_operators(
        pos, k=20, normal=pos, normalized=False, regularizer=1e-6)
    ops = SurfaceOperators(edge_index, grad_w, div_w, pos.size(0))

    z = pos[:, 2:]                              # [N, 1] scalar field
    grad_z = ops.grad(z)[:, 0]                  # [N, 2]: in every frame
    # Analytic: the tangential part of e_z, in the same frames.
    e_z = torch.tensor([0.0, 0.0, 1.0], dtype=pos.dtype)
    exact = torch.stack([frame[:, 0] @ e_z, frame[:, 1] @ e_z], -1)
    grad_error = (grad_z - exact).norm(dim=-1).max().item()

    # -div grad z = 2 z on the unit sphere (the library's sign: PSD).
    lap_z = ops.laplacian(z)
    lap_error = ((lap_z - 2 * z).abs().max() / 2).item()
    # curl grad = 0: a check that D and G fit together.
    curl = ops.curl(ops.grad(z)).abs().max().item()
    print(f"sphere, {num_points} points, k = 20: "
          f"max |grad z - tangential e_z| = {grad_error:.2e}, "
          f"max |Laplacian z - 2 z| / 2 = {lap_error:.2e}, "
          f"max |curl grad z| = {curl:.2e}")
    return {'points': num_points, 'grad_max_error': grad_error,
            'laplacian_max_rel_error': lap_error, 'curl_grad_max': curl}


@torch.no_grad()
def accuracy(model, loader):
    model.eval()
    correct = total = 0
    for batch in loader:
        correct += int((model(batch).argmax(-1) == batch.y.view(-1)).sum())
        total += batch.y.numel()
    return correct / total


def train_deltanet(root, quick, epochs, seed):
    """Part 2: a small DeltaNet on a few classes of SyntheticModelNet."""
    per_class = (3, 2) if quick else (10, 5)   # (train, test) shapes
    num_points = 128 if quick else 256
    # Generated on first use (a few seconds) and cached under root.
    kwargs = dict(num_points=num_points, num_per_class=per_class, seed=seed,
                  log=False)
    full_train = SyntheticModelNet(root, 'train', **kwargs)
    full_test = SyntheticModelNet(root, 'test', **kwargs)
    # A subset of the twelve classes keeps the run short.
    names = CLASSES[:2] if quick else CLASSES
    keep = torch.tensor([full_train.classes.index(c) for c in names])
    relabel = torch.full((len(full_train.classes), ), -1, dtype=torch.long)
    relabel[keep] = torch.arange(len(keep))

    def subset(dataset):
        items = []
        for data in dataset[torch.isin(dataset.y, keep)]:
            data.y = relabel[data.y]
            items.append(data)
        return items

    train_set, test_set = subset(full_train), subset(full_test)
    # Augmentation: DeltaNet builds its operators from the (augmented)
    # positions on every forward pass, so rotated or scaled clouds need no
    # precomputation.
    augment = Compose([RandomScale((2 / 3, 3 / 2)), RandomRotation(axis='z')])

    torch.manual_seed(seed)
    # Much narrower than the paper's (64, 64, 128, 256) / 1024 for the CPU.
    model = DeltaNetClassification(
        in_channels=3, num_classes=len(names), conv_channels=(32, 32, 64),
        embedding_size=256, k=20)
    optimizer = torch.optim.Adam(model.parameters(), lr=2e-3)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, epochs)
    generator = torch.Generator().manual_seed(seed)
    test_loader = DataLoader(test_set, batch_size=32)
    parameters = sum(p.numel() for p in model.parameters())
    print(f"DeltaNet ({parameters / 1e3:.0f}k parameters): "
          f"{len(train_set)} training / {len(test_set)} test clouds of "
          f"{num_points} points, classes {', '.join(names)}")
    losses = []
    for epoch in range(1, epochs + 1):
        model.train()
        total = 0.0
        # A fresh random rotation and scale of every shape in every epoch.
        train_loader = DataLoader([augment(d) for d in train_set],
                                  batch_size=8, shuffle=True,
                                  generator=generator)
        for batch in train_loader:
            optimizer.zero_grad()
            # x defaults to the positions (in_channels=3); the operators are
            # built inside the model, once per batch.
            loss = F.cross_entropy(model(batch), batch.y.view(-1))
            loss.backward()
            optimizer.step()
            total += float(loss.detach()) * batch.y.numel()
        schedule.step()
        losses.append(total / len(train_set))
        print(f"  epoch {epoch}: train loss {losses[-1]:.3f}")
    running = accuracy(model, test_loader)
    # The running statistics of a few dozen steps lag behind the weights
    # (evaluation can sit at chance level): recompute them under the
    # final weights over shuffled training batches, as `train` does.
    recalibrate_batch_norm(model, DataLoader(
        train_set, batch_size=8, shuffle=True,
        generator=torch.Generator().manual_seed(seed)))
    test = accuracy(model, test_loader)
    chance = 1 / len(names)
    print(f"DeltaNet test accuracy: {test:.3f} after {epochs} epochs "
          f"(chance {chance:.3f}; {running:.3f} with the BatchNorm running "
          f"statistics of training)")
    return {'classes': list(names), 'train_shapes': len(train_set),
            'test_shapes': len(test_set), 'num_points': num_points,
            'epochs': epochs, 'parameters': parameters,
            'test_accuracy': test,
            'test_accuracy_training_statistics': running, 'chance': chance,
            'train_loss': losses}


def figure(result, path):
    """The training loss per epoch, and the test accuracy against chance."""
    import matplotlib.pyplot as plt
    fig, (left, right) = plt.subplots(1, 2, figsize=(9, 3.5))
    epochs = range(1, len(result['train_loss']) + 1)
    left.plot(epochs, result['train_loss'], 'o-')
    left.set(xlabel='epoch', ylabel='training loss (cross entropy)',
             title='DeltaNet training')
    right.bar(['test accuracy', 'chance'],
              [result['test_accuracy'], result['chance']], color=['C0', '0.7'])
    right.set(ylim=(0, 1), title=f"{len(result['classes'])} classes")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    return fig


def main():
    args = parse_args()
    epochs = args.epochs or (2 if args.quick else 8)
    os.makedirs(args.out, exist_ok=True)
    start = time.perf_counter()
    results = {'operators': operators_on_the_sphere(
        2000 if args.quick else 8000)}
    results['deltanet'] = train_deltanet(
        os.path.join(args.out, 'SyntheticModelNet'), args.quick, epochs,
        args.seed)
    results['seconds'] = time.perf_counter() - start
    figure(results['deltanet'], os.path.join(args.out, 'figure.png'))
    with open(os.path.join(args.out, 'results.json'), 'w') as f:
        json.dump(results, f, indent=2)
    print(f"done in {results['seconds']:.1f} s; wrote "
          f"{os.path.join(args.out, 'results.json')}")


if __name__ == '__main__':
    main()
