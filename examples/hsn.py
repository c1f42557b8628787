"""
Harmonic Surface Networks: precomputation, training, gauge equivariance
=======================================================================

Harmonic Surface Networks in under a minute (Wiersma et al., "CNNs on
surfaces using rotation-equivariant features", SIGGRAPH 2020).

1. The precomputation on small SyntheticSHREC meshes (generated here, no
   download): unit area (``NormalizeArea``), geodesic discs with log map and
   parallel transport (``LogMap``), a coarser pooling level with its own
   discs (``MultiscaleSupports``) and the circular-harmonic filter terms per
   edge (``HarmonicPrecompute``).
2. An ``HSNClassification`` trained for a few epochs with random rotations
   as augmentation (rotations keep the precomputation valid: it is
   intrinsic, and ``RandomRotation`` turns the frames with the points), and
   its test accuracy.
3. Gauge equivariance: the same mesh with every tangent frame turned by its
   own random angle, precomputed again, gives the same predictions up to
   rounding (the network's features rotate with the frames, its outputs are
   invariant).

    python examples/hsn.py [--out DIR] [--quick] [--epochs N]

``--quick`` (used by the smoke test) uses 3 instead of 4 classes, 2 instead
of 6 training shapes per class and 1 instead of 10 epochs. ``--out``
(default ``runs/examples/hsn``) receives the generated data set cache,
``figure.png`` (the training loss per epoch, and the logits of a mesh with
its frames as given and turned) and ``results.json``.
"""
import argparse
import json
import math
import os
import time

import torch
import torch.nn.functional as F
from torch_geometric.data import Data
from torch_geometric.loader import DataLoader
from torch_geometric.transforms import Compose

from tg_intrinsic.datasets import SyntheticSHREC
from tg_intrinsic.nn.models import HSNClassification
from tg_intrinsic.transforms import (HarmonicPrecompute, LogMap,
                                     MultiscaleSupports, NormalizeArea,
                                     RandomRotation)

# Shape classes to learn (of SyntheticSHREC's twelve), to keep it short.
CLASSES = ('ant', 'hand', 'snake', 'vase')


def parse_args():
    parser = argparse.ArgumentParser(description=__doc__.strip().split(
        '\n')[0])
    parser.add_argument('--out', default=os.path.join('runs', 'examples',
                                                      'hsn'))
    parser.add_argument('--quick', action='store_true',
                        help='fewer shapes and epochs (smoke test)')
    parser.add_argument('--epochs', type=int, default=None)
    parser.add_argument('--seed', type=int, default=0)
    return parser.parse_args()


def precompute():
    """The HSN precomputation of the paper's setting (radii 0.2 and 0.4 on
    unit-area meshes, a quarter of the points on level 1, 6 rings,
    rotation orders 0 and 1)."""
    return Compose([
        NormalizeArea(),                 # radii mean the same on every shape
        LogMap(0.2, method='fast'),      # discs: edge_index, logmap (r,
                                         # theta), transport, area, frame
        MultiscaleSupports([0.25], [0.4]),  # level 1: pos_1, cluster_1,
                                            # pool_transport_1, its discs
        HarmonicPrecompute(rings=6, max_order=1),  # harmonic, harmonic_1
    ])


def load(root, quick, seed):
    per_class, train_per_class = (2, 1) if quick else (5, 3)
    names = CLASSES[:3] if quick else CLASSES
    sets = [SyntheticSHREC(root, split, num_vertices=(300, 400),
                           num_per_class=per_class,
                           num_train_per_class=train_per_class, seed=seed,
                           log=False) for split in ('train', 'test')]
    keep = {sets[0].classes.index(c): k for k, c in enumerate(names)}
    transform = precompute()
    out = []
    for dataset in sets:
        items = []
        for data in dataset:
            if int(data.y) in keep:
                data = transform(data)
                data.y = torch.tensor([keep[int(data.y)]])
                items.append(data)
        out.append(items)
    return out[0], out[1], names


@torch.no_grad()
def accuracy(model, items):
    model.eval()
    correct = 0
    for batch in DataLoader(items, batch_size=16):
        correct += int((model(batch).argmax(-1) == batch.y).sum())
    return correct / len(items)


def turn_frames(frame, angle):
    """Every frame (rows e_u, e_v, n) turned about its normal by angle."""
    c, s = torch.cos(angle)[:, None], torch.sin(angle)[:, None]
    return torch.stack([c * frame[:, 0] + s * frame[:, 1],
                        -s * frame[:, 0] + c * frame[:, 1], frame[:, 2]], 1)


def figure(losses, logits, logits_turned, path):
    """The training loss per epoch, and one mesh's logits with its frames
    as given against turned by random angles (the same: equivariance)."""
    import matplotlib.pyplot as plt
    fig, (left, right) = plt.subplots(1, 2, figsize=(9, 3.5))
    left.plot(range(1, len(losses) + 1), losses, 'o-')
    left.set(xlabel='epoch', ylabel='training loss (cross entropy)',
             title='HSN training')
    right.scatter(logits.flatten().numpy(), logits_turned.flatten().numpy())
    right.set(xlabel='logits, frames as given',
              ylabel='logits, frames turned at random',
              title='gauge equivariance')
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    return fig


def main():
    args = parse_args()
    epochs = args.epochs or (1 if args.quick else 15)
    os.makedirs(args.out, exist_ok=True)
    start = time.perf_counter()

    # -- 1. data and precomputation ------------------------------------
    train_items, test_items, names = load(
        os.path.join(args.out, 'SyntheticSHREC'), args.quick, args.seed)
    example = train_items[0]
    print(f"{len(train_items)} training / {len(test_items)} test meshes "
          f"({', '.join(names)}), {example.num_nodes} vertices -> "
          f"{example.pos_1.size(0)} on level 1; discs of the first: "
          f"{example.edge_index.size(1) / example.num_nodes:.0f} / "
          f"{example.edge_index_1.size(1) / example.pos_1.size(0):.0f} "
          f"neighbours; precomputed in {time.perf_counter() - start:.1f} s")

    # -- 2. training ----------------------------------------------------
    torch.manual_seed(args.seed)
    model = HSNClassification(3, len(names), channels=(16, 32), max_order=1,
                              rings=6)
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-2)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, epochs)
    rotate = RandomRotation()        # any rotation in SO(3), frames too
    generator = torch.Generator().manual_seed(args.seed)
    losses = []
    for epoch in range(1, epochs + 1):
        model.train()
        total = 0.0
        loader = DataLoader([rotate(d) for d in train_items], batch_size=8,
                            shuffle=True, generator=generator)
        for batch in loader:
            optimizer.zero_grad()
            # x defaults to the (rotated) positions: 3 input channels
            loss = F.cross_entropy(model(batch), batch.y)
            loss.backward()
            optimizer.step()
            total += float(loss.detach()) * batch.y.numel()
        schedule.step()
        losses.append(total / len(train_items))
        print(f"  epoch {epoch}: train loss {losses[-1]:.3f}")
    # HSN normalises every mesh by its own statistics (ComplexInstanceNorm),
    # so evaluation mode computes what training did: nothing to recalibrate
    test = accuracy(model, test_items)
    print(f"HSN test accuracy: {test:.3f} after {epochs} epochs "
          f"(chance {1 / len(names):.3f})")

    # -- 3. gauge equivariance ------------------------------------------
    # Precompute a test mesh again with every tangent frame turned by its
    # own random angle (LogMap uses data.frame as given): all log-map
    # angles, transports and filter terms change, the predictions do not.
    mesh = test_items[0]
    gen = torch.Generator().manual_seed(1)
    angle = torch.rand(mesh.num_nodes, generator=gen,
                       dtype=mesh.frame.dtype) * 2 * math.pi
    turned = precompute()(Data(pos=mesh.pos, face=mesh.face, y=mesh.y,
                               frame=turn_frames(mesh.frame, angle)))
    model.eval()
    with torch.no_grad():
        out, out_turned = model(mesh), model(turned)
    gauge = float((out_turned - out).abs().max() / out.abs().max())
    theta_change = float((turned.logmap[:, 1] - mesh.logmap[:, 1]).abs().max())
    print(f"gauge equivariance: frames turned by random angles change the "
          f"log-map angles by up to {theta_change:.2f} rad; max relative "
          f"change of the logits {gauge:.1e}")

    figure(losses, out, out_turned, os.path.join(args.out, 'figure.png'))
    results = {'classes': list(names), 'train_shapes': len(train_items),
               'test_shapes': len(test_items), 'epochs': epochs,
               'test_accuracy': test,
               'gauge_relative_change': gauge,
               'seconds': time.perf_counter() - start}
    with open(os.path.join(args.out, 'results.json'), 'w') as f:
        json.dump(results, f, indent=2)
    print(f"done in {results['seconds']:.1f} s; wrote "
          f"{os.path.join(args.out, 'results.json')}")


if __name__ == '__main__':
    main()
