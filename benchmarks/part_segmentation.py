"""Part segmentation on SyntheticShapeParts: DeltaNet (DeltaNetSegmentation)
against the Delta-U-ResNet of the DeltaConv thesis (appendix A.2) with
farthest-point-sampling pooling and with Gravo-hierarchy pooling.

Protocol, the same for every model: SyntheticShapeParts (5 categories, 16
parts) with 512 points per shape, 20 training and 10 test shapes per
category (100 / 50), seed 0; xyz input, the object category embedded
(one-hot), no augmentation (shapes are upright in train and test); Adam,
learning rate 1e-3, batch 8, 12 epochs, cross entropy, torch seed 0. The
DeltaConv operators (k = 20) and the pooling levels (three levels of a
quarter of the points each; Gravo: reduction 4, approximate sizes) are
precomputed once by PoolingLevels; DeltaNet reads the same level-0
operators. Test predictions are restricted to the parts of the shape's
category (as PointNet++'s evaluation does). Scores, ShapeNet-Part style:
instance mIoU (per shape, the mean IoU over its category's parts, a part
absent from both prediction and truth counting 1; averaged over shapes)
and class mIoU (the instance mIoU averaged per category, then over the
categories). Seconds per epoch are training time on this machine, 2
threads. Before every evaluation the batch norms' running statistics are
recalibrated over the training shapes (``recalibrate_batch_norm``, as
``train`` does); the test scores are eval mode's (what inference on the
weights gives), next to the same weights with batch statistics of
shuffled test batches (``_batch_statistics``).

CPU budget: about 9 minutes for the three runs on 2 cores.

Usage: python benchmarks/part_segmentation.py [--epochs 12] [--quick]
Writes benchmarks/results/part_segmentation.json and .png.
"""
import argparse
import os
import time

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
import torch  # noqa: E402
from torch_geometric.loader import DataLoader  # noqa: E402

from tg_intrinsic.datasets import SyntheticShapeParts  # noqa: E402
from tg_intrinsic.nn import recalibrate_batch_norm  # noqa: E402
from tg_intrinsic.nn.models import (DeltaNetSegmentation,  # noqa: E402
                                    DeltaUResNet)
from tg_intrinsic.nn.recalibrate_batch_norm import \
    batch_statistics_copy  # noqa: E402
from tg_intrinsic.train import instance_miou  # noqa: E402
from tg_intrinsic.transforms import PoolingLevels  # noqa: E402
from tg_intrinsic.utils import atomic_write_json, machine_info  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
MODELS = ('deltanet', 'uresnet_fps', 'uresnet_gravo')
LABELS = {'deltanet': 'DeltaNet', 'uresnet_fps': 'Delta-U-ResNet (FPS)',
          'uresnet_gravo': 'Delta-U-ResNet (Gravo)'}


def count(model):
    return sum(p.numel() for p in model.parameters())


def build(name, num_classes, num_categories):
    if name == 'deltanet':
        return DeltaNetSegmentation(3, num_classes,
                                    num_categories=num_categories)
    return DeltaUResNet(3, num_classes, pooling=name.split('_')[1],
                        num_categories=num_categories)


@torch.no_grad()
def evaluate(model, loader, part_mask, num_categories, statistics='running'):
    """Scores in eval mode, or (``statistics='batch'``) with every test
    batch's own batch-norm statistics."""
    model = batch_statistics_copy(model) if statistics == 'batch' \
        else model.eval()
    ious, categories, correct, total = [], [], 0, 0
    for batch in loader:
        logits = model(batch)
        mask = part_mask[batch.category][batch.batch]
        pred = logits.masked_fill(~mask, float('-inf')).argmax(1)
        correct += int((pred == batch.y).sum())
        total += pred.numel()
        for b in range(batch.num_graphs):
            at = batch.batch == b
            c = int(batch.category[b])
            ious.append(instance_miou(pred[at], batch.y[at], part_mask[c]))
            categories.append(c)
    per_category = {}
    for c in range(num_categories):
        values = [i for i, k in zip(ious, categories) if k == c]
        if values:
            per_category[c] = sum(values) / len(values)
    return {'instance_miou': sum(ious) / len(ious),
            'class_miou': sum(per_category.values()) / len(per_category),
            'category_miou': per_category,
            'accuracy': correct / total}


def run(name, train_items, test_items, dataset, args):
    torch.manual_seed(0)
    num_categories = len(dataset.categories)
    model = build(name, dataset.num_classes, num_categories)
    optimizer = torch.optim.Adam(model.parameters(), lr=args.lr)
    generator = torch.Generator().manual_seed(0)
    train_loader = DataLoader(train_items, batch_size=args.batch_size,
                              shuffle=True, generator=generator)
    test_loader = DataLoader(test_items, batch_size=args.batch_size)
    shuffled_test_loader = DataLoader(
        test_items, batch_size=args.batch_size, shuffle=True,
        generator=torch.Generator().manual_seed(1))
    # shuffled like the training batches: batches of one category each
    # would average within-category statistics
    recalibration_loader = DataLoader(
        train_items, batch_size=args.batch_size, shuffle=True,
        generator=torch.Generator().manual_seed(2))
    history = []
    for epoch in range(1, args.epochs + 1):
        model.train()
        start = time.perf_counter()
        losses = []
        for batch in train_loader:
            optimizer.zero_grad()
            loss = torch.nn.functional.cross_entropy(model(batch), batch.y)
            loss.backward()
            optimizer.step()
            losses.append(float(loss.detach()))
        seconds = time.perf_counter() - start
        recalibrate_batch_norm(model, recalibration_loader)
        scores = evaluate(model, test_loader, dataset.part_mask,
                          num_categories)
        batch_scores = evaluate(model, shuffled_test_loader,
                                dataset.part_mask, num_categories, 'batch')
        history.append({'epoch': epoch, 'train_loss': sum(losses)
                        / len(losses), 'seconds': seconds,
                        'test_instance_miou': scores['instance_miou'],
                        'test_class_miou': scores['class_miou'],
                        'test_accuracy': scores['accuracy'],
                        'test_instance_miou_batch_statistics':
                        batch_scores['instance_miou'],
                        'test_accuracy_batch_statistics':
                        batch_scores['accuracy']})
        print(f"{name} epoch {epoch}: loss {history[-1]['train_loss']:.3f}"
              f" instance mIoU {scores['instance_miou']:.3f} (batch "
              f"statistics {batch_scores['instance_miou']:.3f}) class mIoU "
              f"{scores['class_miou']:.3f} ({seconds:.1f} s)", flush=True)
    return {'model': name, 'label': LABELS[name], 'parameters': count(model),
            'epochs': args.epochs,
            'seconds_per_epoch': sum(h['seconds'] for h in history)
            / len(history),
            'final_instance_miou': history[-1]['test_instance_miou'],
            'final_class_miou': history[-1]['test_class_miou'],
            'final_accuracy': history[-1]['test_accuracy'],
            'final_instance_miou_batch_statistics':
            history[-1]['test_instance_miou_batch_statistics'],
            'final_accuracy_batch_statistics':
            history[-1]['test_accuracy_batch_statistics'],
            'category_miou': {dataset.categories[c]: v for c, v in
                              scores['category_miou'].items()},
            'history': history}


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument('--root', default=os.path.join('data',
                                                       'SyntheticShapeParts'))
    parser.add_argument('--num-points', type=int, default=512)
    parser.add_argument('--train-per-category', type=int, default=20)
    parser.add_argument('--test-per-category', type=int, default=10)
    parser.add_argument('--epochs', type=int, default=12)
    parser.add_argument('--batch-size', type=int, default=8)
    parser.add_argument('--lr', type=float, default=1e-3)
    parser.add_argument('--threads', type=int, default=2)
    parser.add_argument('--models', nargs='+', default=list(MODELS),
                        choices=MODELS)
    parser.add_argument('--quick', action='store_true',
                        help='smoke test: 2 + 1 shapes per category, '
                        '1 epoch, nothing written')
    parser.add_argument('--out', default=os.path.join(HERE, 'results'))
    args = parser.parse_args()
    if args.quick:
        args.train_per_category, args.test_per_category = 2, 1
        args.epochs = 1
    torch.set_num_threads(args.threads)
    sets = [SyntheticShapeParts(
        args.root, split, num_points=args.num_points,
        num_per_category=(args.train_per_category, args.test_per_category))
        for split in ('train', 'test')]
    start = time.perf_counter()
    levels = {'fps': PoolingLevels(method='fps'),
              'gravo': PoolingLevels(method='gravo')}
    prepared = {m: [[t(d) for d in s] for s in sets]
                for m, t in levels.items() if any(
                    name.endswith(m) or (m == 'fps' and name == 'deltanet')
                    for name in args.models)}
    prepare_seconds = time.perf_counter() - start
    sizes = {m: [sum(d[f'pos_{l}'].size(0) for d in items[0])
                 / len(items[0]) for l in (1, 2, 3)]
             for m, items in prepared.items()}
    results = {
        'machine': machine_info(), 'threads': args.threads,
        'protocol': {
            'dataset': 'SyntheticShapeParts', 'categories': 5, 'parts': 16,
            'num_points': args.num_points,
            'train_per_category': args.train_per_category,
            'test_per_category': args.test_per_category,
            'epochs': args.epochs, 'batch_size': args.batch_size,
            'optimizer': f'Adam lr {args.lr:g}, constant',
            'input': 'xyz + category one-hot, no augmentation',
            'evaluation': 'predictions restricted to the category parts; '
                          'instance and class mIoU (ShapeNet-Part)'},
        'dataset_version': SyntheticShapeParts.version,
        'level_sizes': sizes, 'prepare_seconds': prepare_seconds,
        'runs': []}
    for name in args.models:
        method = 'fps' if name == 'deltanet' else name.split('_')[1]
        train_items, test_items = prepared[method]
        results['runs'].append(run(name, train_items, test_items, sets[0],
                                   args))
    if args.quick:
        print('quick run: nothing written')
        return
    os.makedirs(args.out, exist_ok=True)
    atomic_write_json(os.path.join(args.out, 'part_segmentation.json'),
                      results)
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for r in results['runs']:
        epochs = [h['epoch'] for h in r['history']]
        axes[0].plot(epochs, [h['train_loss'] for h in r['history']],
                     label=r['label'])
        axes[1].plot(epochs, [h['test_instance_miou'] for h in r['history']],
                     label=f"{r['label']}, {r['parameters'] / 1e6:.2f}M "
                     f"parameters")
    axes[0].set(xlabel='epoch', ylabel='training loss')
    axes[1].set(xlabel='epoch', ylabel='test instance mIoU')
    axes[1].legend(fontsize=8)
    fig.suptitle(f"SyntheticShapeParts, {args.num_points} points, "
                 f"{5 * args.train_per_category} training shapes")
    fig.tight_layout()
    fig.savefig(os.path.join(args.out, 'part_segmentation.png'), dpi=120)


if __name__ == '__main__':
    main()
