"""Train DeltaNet (point clouds sampled from the shapes) or a Harmonic
Surface Network (on the mesh vertices) on the synthetic data sets or your
own.

Examples::

    python -m tg_intrinsic.train --dataset synthetic_modelnet --epochs 30
    python -m tg_intrinsic.train --dataset synthetic_shrec --num-points 1024
    python -m tg_intrinsic.train --dataset mesh_folder --mesh-root ModelNet10
    python -m tg_intrinsic.train --model hsn --dataset synthetic_shrec \
        --num-vertices 300 500 --rotate --lr 1e-2
    python -m tg_intrinsic.train --model hsn --task segmentation \
        --dataset synthetic_shrec

Writes to ``--out``: ``checkpoint.pt`` (model, optimiser, schedule, history;
written atomically at every evaluation, so ``--resume`` continues an
interrupted run), ``metrics.json``, ``metrics.csv`` (one row per epoch) and
``learning_curve.png``.
"""
import argparse
import hashlib
import json
import os
import time
from typing import Dict, List, Optional

import torch
import torch.nn.functional as F
from torch_geometric.loader import DataLoader
from torch_geometric.transforms import (Compose, NormalizeScale, RandomScale,
                                        SamplePoints)
from tqdm import tqdm

from tg_intrinsic.io.figures import save_figure
from tg_intrinsic.utils import (atomic_torch_save, atomic_write,
                                atomic_write_json)

DATASETS = ('synthetic_modelnet', 'synthetic_shrec', 'mesh_folder')
MODELS = ('deltanet', 'hsn')


def build_datasets(name: str, root: str, num_points: int,
                   mesh_root: Optional[str] = None, seed: int = 0,
                   shapes_per_class: Optional[int] = None):
    """The train and test splits of a data set as point clouds with normals.

    Meshes (SyntheticSHREC, MeshFolder) are turned into ``num_points``
    points sampled uniformly from the surface, with face normals (the faces
    are dropped). ``shapes_per_class`` shrinks the synthetic sets (half for
    training) for quick runs.
    """
    from tg_intrinsic.datasets import (MeshFolder, SyntheticModelNet,
                                       SyntheticSHREC)
    sample = Compose([SamplePoints(num_points, include_normals=True),
                      NormalizeScale()])
    if name == 'synthetic_modelnet':
        path = os.path.join(root, 'SyntheticModelNet')
        kwargs = dict(num_points=num_points, seed=seed)
        if shapes_per_class is not None:
            kwargs['num_per_class'] = (max(1, shapes_per_class // 2),
                                       max(1, shapes_per_class // 2))
        return (SyntheticModelNet(path, 'train', **kwargs),
                SyntheticModelNet(path, 'test', **kwargs))
    if name == 'synthetic_shrec':
        path = os.path.join(root, 'SyntheticSHREC')
        kwargs = dict(seed=seed, transform=sample)
        if shapes_per_class is not None:
            kwargs.update(num_per_class=shapes_per_class,
                          num_train_per_class=max(1, shapes_per_class // 2))
        return (SyntheticSHREC(path, 'train', **kwargs),
                SyntheticSHREC(path, 'test', **kwargs))
    if name == 'mesh_folder':
        if mesh_root is None:
            raise ValueError("--dataset mesh_folder needs --mesh-root PATH "
                             "(laid out as PATH/<class>/<split>/*.off)")
        return (MeshFolder(mesh_root, 'train', transform=sample),
                MeshFolder(mesh_root, 'test', transform=sample))
    raise ValueError(f"unknown dataset {name!r}; choose one of {DATASETS}")


def hsn_pipeline(radius: float = 0.2, rings: int = 6, max_order: int = 1,
                 method: str = 'fast'):
    """The precomputation Harmonic Surface Networks train on, shared by
    ``train`` and ``tg-intrinsic precompute hsn``: mesh -> unit area,
    frames, geodesic discs of :obj:`radius` with log map and transport on
    two levels (a quarter of the points and twice the radius on level 1),
    circular-harmonic terms with :obj:`rings` rings up to order
    :obj:`max_order`; :obj:`method` is the log map method (``'fast'`` or
    ``'vector_heat'``). The paper's setting: radius 0.2 on unit area."""
    from tg_intrinsic.transforms import (HarmonicPrecompute, LogMap,
                                         MultiscaleSupports, NormalizeArea)
    # LogMap writes the transport angles too (same solve).
    return Compose([NormalizeArea(),
                    LogMap(radius, method=method),
                    MultiscaleSupports([0.25], [2 * radius], method=method),
                    HarmonicPrecompute(rings, max_order)])


def mesh_splits(args):
    """The train and test meshes of ``args.dataset`` as they are, before
    any HSN precomputation."""
    from tg_intrinsic.datasets import MeshFolder, SyntheticSHREC
    if args.dataset == 'synthetic_shrec':
        kwargs = dict(seed=args.data_seed, task=args.task)
        if args.num_vertices is not None:
            kwargs['num_vertices'] = tuple(args.num_vertices)
        if args.shapes_per_class is not None:
            kwargs.update(num_per_class=args.shapes_per_class,
                          num_train_per_class=max(
                              1, args.shapes_per_class // 2))
        path = os.path.join(args.root, 'SyntheticSHREC')
        sets = [SyntheticSHREC(path, split, **kwargs)
                for split in ('train', 'test')]
    elif args.dataset == 'mesh_folder':
        if args.mesh_root is None:
            raise ValueError("--dataset mesh_folder needs --mesh-root PATH")
        sets = [MeshFolder(args.mesh_root, split)
                for split in ('train', 'test')]
    else:
        raise ValueError("--model hsn works on meshes: use --dataset "
                         "synthetic_shrec or mesh_folder")
    return sets


def build_mesh_datasets(args):
    """Train and test lists of precomputed meshes for HSN (the vertices are
    the points). The precomputation is cached under ``root/hsn_cache``,
    keyed by the data set and every setting it depends on."""
    sets = mesh_splits(args)
    num_classes = sets[0].num_classes
    # The precomputation is deterministic: cache it beside the data.
    key = json.dumps([args.dataset, args.task, args.mesh_root,
                      args.num_vertices, args.shapes_per_class,
                      args.data_seed, args.radius, args.rings,
                      args.max_order, args.logmap_method,
                      [len(s) for s in sets]])
    cache = os.path.join(args.root, 'hsn_cache', hashlib.sha1(
        key.encode()).hexdigest()[:16] + '.pt')
    if os.path.exists(cache):
        train_items, test_items = torch.load(cache, weights_only=False)
        return train_items, test_items, num_classes
    pipeline = hsn_pipeline(args.radius, args.rings, args.max_order,
                            args.logmap_method)
    out = []
    for split, dataset in zip(('train', 'test'), sets):
        items = [pipeline(dataset[i]) for i in tqdm(
            range(len(dataset)), desc=f'precomputing {split}',
            disable=args.quiet, leave=False)]
        out.append(items)
    os.makedirs(os.path.dirname(cache), exist_ok=True)
    atomic_torch_save(out, cache)
    return out[0], out[1], num_classes


def build_model(name: str, num_classes: int, args) -> torch.nn.Module:
    if name == 'deltanet':
        from tg_intrinsic.nn.models import DeltaNetClassification
        return DeltaNetClassification(
            3, num_classes, conv_channels=args.conv_channels, k=args.k,
            vector_stream=not args.no_vector_stream)
    if name == 'hsn':
        from tg_intrinsic.nn.models import (HSNClassification,
                                            HSNSegmentation)
        cls = HSNClassification if args.task == 'classification' \
            else HSNSegmentation
        return cls(3, num_classes, channels=args.hsn_channels,
                   max_order=args.max_order, rings=args.rings)
    raise ValueError(f"unknown model {name!r}; choose one of {MODELS}")


@torch.no_grad()
def evaluate(model, loader, device) -> float:
    model.eval()
    correct = total = 0
    for batch in loader:
        batch = batch.to(device)
        pred = model(batch).argmax(dim=-1)
        correct += int((pred == batch.y.view(-1)).sum())
        total += pred.numel()
    return correct / max(total, 1)


CSV_COLUMNS = ('epoch', 'train_loss', 'train_accuracy', 'test_accuracy',
               'seconds')


def write_metrics_csv(history: List[Dict], path: str):
    """One row per epoch (``test_accuracy`` empty between evaluations),
    rewritten atomically after every epoch."""
    import csv
    import io
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, CSV_COLUMNS, extrasaction='ignore',
                            lineterminator='\n')
    writer.writeheader()
    for record in history:
        writer.writerow({k: '' if record.get(k) is None else record[k]
                         for k in CSV_COLUMNS})
    atomic_write(path, lambda f: f.write(buffer.getvalue()), 'w')


def plot_history(history: List[Dict], path: str, title: str):
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator
    epochs = [h['epoch'] for h in history]
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
    for axis in ax:
        axis.xaxis.set_major_locator(MaxNLocator(integer=True))
        axis.grid(alpha=0.3)
    ax[0].plot(epochs, [h['train_loss'] for h in history])
    ax[0].set_xlabel('epoch')
    ax[0].set_ylabel('training loss')
    ax[1].plot(epochs, [h['train_accuracy'] for h in history], label='train')
    tested = [h for h in history if h.get('test_accuracy') is not None]
    ax[1].plot([h['epoch'] for h in tested],
               [h['test_accuracy'] for h in tested], 'o-', label='test')
    ax[1].set_xlabel('epoch')
    ax[1].set_ylabel('accuracy')
    ax[1].set_ylim(0, 1)
    ax[1].legend()
    ax[0].set_title('training loss')
    ax[1].set_title('accuracy')
    fig.suptitle(title)
    fig.tight_layout()
    save_figure(fig, path)


def train(args) -> Dict:
    torch.manual_seed(args.seed)
    if args.threads:
        torch.set_num_threads(args.threads)
    device = torch.device(args.device if args.device != 'auto' else
                          ('cuda' if torch.cuda.is_available() else 'cpu'))
    from tg_intrinsic.transforms import RandomRotation
    if args.model == 'hsn':
        # Precomputed discs are intrinsic: rotations (which turn the frames
        # too) keep them valid, a scale would not.
        train_set, test_set, num_classes = build_mesh_datasets(args)
        if args.rotate:
            rotate = RandomRotation()
            train_set = _Mapped(train_set, rotate)
    else:
        train_set, test_set = build_datasets(
            args.dataset, args.root, args.num_points, args.mesh_root,
            args.data_seed, args.shapes_per_class)
        num_classes = train_set.num_classes
        augment = [train_set.transform, RandomScale((2 / 3, 3 / 2))]
        if args.rotate:
            augment.append(RandomRotation())
        train_set.transform = Compose([t for t in augment if t is not None])
    model = build_model(args.model, num_classes, args).to(device)
    if args.optimizer == 'sgd':
        optimizer = torch.optim.SGD(model.parameters(), lr=args.lr,
                                    momentum=0.9,
                                    weight_decay=args.weight_decay)
    else:
        optimizer = torch.optim.Adam(model.parameters(), lr=args.lr,
                                     weight_decay=args.weight_decay)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(
        optimizer, T_max=args.epochs, eta_min=args.lr / 100)
    os.makedirs(args.out, exist_ok=True)
    checkpoint_path = os.path.join(args.out, 'checkpoint.pt')
    history: List[Dict] = []
    start_epoch = 1
    if args.resume and os.path.exists(checkpoint_path):
        state = torch.load(checkpoint_path, map_location=device,
                           weights_only=False)
        model.load_state_dict(state['model'])
        optimizer.load_state_dict(state['optimizer'])
        schedule.load_state_dict(state['schedule'])
        history = state['history']
        start_epoch = state['epoch'] + 1
        print(f"resuming from epoch {state['epoch']} of {checkpoint_path}")

    generator = torch.Generator().manual_seed(args.seed)
    train_loader = DataLoader(train_set, args.batch_size, shuffle=True,
                              drop_last=len(train_set) > args.batch_size,
                              generator=generator)
    test_loader = DataLoader(test_set, args.batch_size)
    num_params = sum(p.numel() for p in model.parameters())
    print(f"{args.model} ({num_params / 1e6:.2f}M parameters) on "
          f"{args.dataset}: {len(train_set)} train / {len(test_set)} test, "
          f"{num_classes} classes, {device}")
    started = time.perf_counter()
    for epoch in range(start_epoch, args.epochs + 1):
        model.train()
        loss_sum = correct = seen = 0
        bar = tqdm(train_loader, desc=f'epoch {epoch}/{args.epochs}',
                   leave=False, disable=args.quiet)
        for batch in bar:
            batch = batch.to(device)
            optimizer.zero_grad()
            out = model(batch)
            loss = F.cross_entropy(out, batch.y.view(-1),
                                   label_smoothing=args.label_smoothing)
            if not torch.isfinite(loss):
                raise RuntimeError(f"the training loss became {loss.item()} "
                                   f"in epoch {epoch}; lower --lr")
            loss.backward()
            optimizer.step()
            n = batch.y.numel()
            loss_sum += float(loss.detach()) * n
            correct += int((out.argmax(-1) == batch.y.view(-1)).sum())
            seen += n
            bar.set_postfix(loss=f'{loss_sum / seen:.3f}')
        schedule.step()
        record = {'epoch': epoch, 'train_loss': loss_sum / max(seen, 1),
                  'train_accuracy': correct / max(seen, 1),
                  'test_accuracy': None,
                  'seconds': time.perf_counter() - started}
        if epoch % args.eval_every == 0 or epoch == args.epochs:
            record['test_accuracy'] = evaluate(model, test_loader, device)
        history.append(record)
        write_metrics_csv(history, os.path.join(args.out, 'metrics.csv'))
        if record['test_accuracy'] is not None:
            print(f"epoch {epoch}: loss {record['train_loss']:.3f}, "
                  f"train {record['train_accuracy']:.3f}, "
                  f"test {record['test_accuracy']:.3f}")
            atomic_torch_save({'model': model.state_dict(),
                               'optimizer': optimizer.state_dict(),
                               'schedule': schedule.state_dict(),
                               'history': history, 'epoch': epoch,
                               'args': vars(args)}, checkpoint_path)
            plot_history(history, os.path.join(args.out,
                                               'learning_curve.png'),
                         f'{args.model} on {args.dataset}')
    final = history[-1]['test_accuracy'] if history else None
    metrics = {'model': args.model, 'dataset': args.dataset,
               'parameters': num_params, 'final_test_accuracy': final,
               'best_test_accuracy': max(
                   (h['test_accuracy'] for h in history
                    if h['test_accuracy'] is not None), default=None),
               'history': history, 'args': vars(args)}
    atomic_write_json(os.path.join(args.out, 'metrics.json'), metrics)
    print(f"final test accuracy: {final:.3f} (written to {args.out})")
    return metrics


class _Mapped(torch.utils.data.Dataset):
    """A list of examples with a transform applied on access."""
    def __init__(self, items, transform):
        self.items, self.transform = items, transform

    def __len__(self):
        return len(self.items)

    def __getitem__(self, index):
        return self.transform(self.items[index])


def add_arguments(parser, model_and_dataset: bool = True):
    """The training options, shared by ``python -m tg_intrinsic.train``
    and ``tg-intrinsic train`` (which names the model and data set its own
    way: ``model_and_dataset=False``)."""
    if model_and_dataset:
        parser.add_argument('--model', default='deltanet', choices=MODELS)
        parser.add_argument('--dataset', default='synthetic_modelnet',
                            choices=DATASETS)
        parser.add_argument('--mesh-root', default=None,
                            help='root/<class>/<split>/*.off|obj|ply for '
                            'mesh_folder')
    parser.add_argument('--task', default='classification',
                        choices=['classification', 'segmentation'],
                        help='segmentation: per-vertex parts (hsn on '
                        'synthetic_shrec)')
    parser.add_argument('--root', default='data',
                        help='cache folder of the synthetic data sets')
    parser.add_argument('--out', default=None,
                        help='output folder (default: runs/<model>_<dataset>)')
    parser.add_argument('--num-points', type=int, default=1024)
    parser.add_argument('--shapes-per-class', type=int, default=None,
                        help='shrink the synthetic sets (quick runs)')
    parser.add_argument('--epochs', type=int, default=50)
    parser.add_argument('--batch-size', type=int, default=16)
    parser.add_argument('--optimizer', default='adam',
                        choices=['adam', 'sgd'],
                        help='sgd uses momentum 0.9')
    parser.add_argument('--lr', type=float, default=1e-3)
    parser.add_argument('--weight-decay', type=float, default=1e-4)
    parser.add_argument('--label-smoothing', type=float, default=0.0)
    parser.add_argument('--eval-every', type=int, default=5)
    parser.add_argument('--conv-channels', type=int, nargs='+',
                        default=[64, 64, 128, 256])
    parser.add_argument('--k', type=int, default=20)
    parser.add_argument('--rotate', action='store_true',
                        help='augment training shapes with random rotations '
                        '(uniform on SO(3)), for data in arbitrary poses')
    parser.add_argument('--no-vector-stream', action='store_true',
                        help='ablation: drop the vector stream')
    parser.add_argument('--hsn-channels', type=int, nargs=2,
                        default=[16, 32], help='hsn features on levels 0, 1')
    parser.add_argument('--max-order', type=int, default=1,
                        help='hsn: highest rotation order (0: one stream)')
    parser.add_argument('--rings', type=int, default=6)
    parser.add_argument('--radius', type=float, default=0.2,
                        help='hsn: disc radius on unit-area meshes')
    parser.add_argument('--num-vertices', type=int, nargs=2, default=None,
                        metavar=('LOW', 'HIGH'),
                        help='hsn on synthetic_shrec: vertex range of the '
                        'generated meshes (default 500 2000)')
    parser.add_argument('--logmap-method', default='fast',
                        choices=['fast', 'vector_heat'])
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--data-seed', type=int, default=0)
    parser.add_argument('--device', default='auto')
    parser.add_argument('--threads', type=int, default=0)
    parser.add_argument('--resume', action='store_true')
    if model_and_dataset:
        parser.add_argument('--quiet', action='store_true',
                            help='no progress bar')


def check_arguments(args, parser):
    """Fills the default output folder and rejects values no run can use
    (through ``parser.error``: one line, exit code 2)."""
    if args.out is None:
        args.out = os.path.join('runs', f'{args.model}_{args.dataset}')
    for name in ('num_points', 'epochs', 'batch_size', 'eval_every', 'k',
                 'rings'):
        if getattr(args, name) < 1:
            parser.error(f"--{name.replace('_', '-')} must be at least 1, "
                         f"got {getattr(args, name)}")
    for name in ('lr', 'radius'):
        if not getattr(args, name) > 0:
            parser.error(f"--{name} must be positive, got "
                         f"{getattr(args, name)}")
    for name in ('weight_decay', 'label_smoothing', 'max_order', 'threads'):
        if getattr(args, name) < 0:
            parser.error(f"--{name.replace('_', '-')} must not be negative, "
                         f"got {getattr(args, name)}")
    if args.shapes_per_class is not None and args.shapes_per_class < 1:
        parser.error(f"--shapes-per-class must be at least 1, got "
                     f"{args.shapes_per_class}")
    if min(args.conv_channels + args.hsn_channels) < 1:
        parser.error("channel counts must be at least 1")
    if args.task == 'segmentation' and args.model != 'hsn':
        parser.error("--task segmentation is available with --model hsn")
    return args


def parse_args(argv=None):
    parser = argparse.ArgumentParser(
        description='Train a tg_intrinsic classification network.')
    add_arguments(parser)
    return check_arguments(parser.parse_args(argv), parser)


def main(argv=None):
    return train(parse_args(argv))


if __name__ == '__main__':
    main()
