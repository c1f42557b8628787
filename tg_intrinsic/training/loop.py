"""The training loop: one process or every process of a ``torchrun``
run, evaluation and checkpoints every ``--eval-every`` epochs."""
import argparse
import os
import random
import time
from contextlib import ExitStack
from typing import Callable, Dict, Optional

import numpy as np
import torch
import torch.nn.functional as F
from torch_geometric.loader import DataLoader
from tqdm import tqdm

from tg_intrinsic import distributed
from tg_intrinsic.devices import autocast, check_precision, default_threads
from tg_intrinsic.errors import UsageError, one_line
from tg_intrinsic.io.results import (check_output_path, output_lock,
                                     recorded_files, write_record)
from tg_intrinsic.nn.recalibrate_batch_norm import (batch_norms,
                                                    recalibrate_batch_norm)
from tg_intrinsic.training.checkpoints import CHECKPOINT
from tg_intrinsic.training.evaluation import (RECALIBRATION_BATCHES, evaluate,
                                              statistics_gap, whole_batches)
from tg_intrinsic.training.models import build_model
from tg_intrinsic.training.outputs import (claim_output, plot_history,
                                           write_metrics_csv)
from tg_intrinsic.training.prepare import (augmentation, build_mesh_datasets,
                                           build_point_sets)
from tg_intrinsic.training.sources import select_per_class
from tg_intrinsic.utils import atomic_torch_save, atomic_write_json


def seed_everything(seed: int) -> None:
    """Seeds the generators training draws from: torch's (model
    initialisation, dropout, this package's random transforms), NumPy's and
    Python's ``random`` (PyG's ``RandomScale`` and other transforms)."""
    torch.manual_seed(seed)
    np.random.seed(seed % 2 ** 32)
    random.seed(seed)


def _from_rank_zero(fn: Callable):
    """``fn()`` on rank 0 and its result on every process; a failure there
    fails every process (a user mistake as a :class:`UsageError`)."""
    if distributed.world_size() == 1:
        return fn()
    if distributed.rank() == 0:
        try:
            result = fn()
        except BaseException as error:
            distributed.broadcast_object(
                (False, f'{type(error).__name__}: {error}',
                 isinstance(error, ValueError), str(error)))
            raise
        distributed.broadcast_object((True, result))
        return result
    reply = distributed.broadcast_object(None)
    if reply[0]:
        return reply[1]
    if reply[2]:
        raise UsageError(reply[3])
    raise RuntimeError(f"rank 0 failed while checking --out: {reply[1]}")


def lone_shape_batches(model: str, batch_size: int, world: int = 1,
                       length: Optional[int] = None) -> Optional[str]:
    """Why ``model``'s batch norm over shapes (DeltaNet's head) cannot
    train on batches of ``batch_size`` (the global batch over ``world``
    processes) of a training set of ``length`` shapes, or :obj:`None`."""
    if model != 'deltanet':
        return None  # HSN normalises over vertices
    per_process = f" per process (the batch is split over {world})" \
        if world > 1 else ''
    need = ("DeltaNet's batch norm normalises over the shapes of a batch "
            f"and needs at least 2 shapes in every batch{per_process}")
    if batch_size // world < 2:
        return (f"--batch-size {batch_size}: {need}; use --batch-size "
                f"{2 * world} or more")
    # The epochs drop the remainder of the training set (see
    # distributed.global_batches), so no batch is smaller than the others
    # unless the whole set is smaller than one batch.
    if length is not None and 0 < length < batch_size and \
            length // world < 2:
        return (f"the training set has {length} shape(s), fewer than "
                f"--batch-size {batch_size}, so they make one batch; {need}:"
                f" add training shapes" +
                (" or use fewer processes" if world > 1 else ''))
    return None


def train(args) -> Dict:
    """Trains as :obj:`args` say (see the module docstring), on one
    process or, under ``torchrun``, on every process of the run."""
    device, started = distributed.start(args.backend, args.device)
    try:
        try:
            check_precision(args.precision, device)
        except ValueError as error:
            raise UsageError(str(error)) from None
        with ExitStack() as held:
            def claim():
                # rank 0 writes --out, so it alone holds its lock, for the
                # whole run: a second run into it stops at once
                check_output_path(args.out)
                held.enter_context(output_lock(args.out, '--out'))
                return claim_output(args)
            # before the data are prepared (minutes): rank 0 checks --out
            # and reads the checkpoint, which every process then gets (no
            # shared file system needed)
            state = _from_rank_zero(claim)
            return _train(args, device, state)
    finally:
        if started:
            distributed.stop()


def _train(args, device, state: Optional[Dict]) -> Dict:
    run = _Run(args, device)
    args = run.args
    train_items, test_items, source = run.prepare(state)
    num_classes = source.num_classes
    part_mask = getattr(source, 'part_mask', None)
    train_set = run.training_set(train_items, part_mask)
    # Seeded again: whether the inputs were prepared now or read from the
    # cache must not change what follows.
    seed_everything(args.seed)
    model, optimizer, schedule = run.model(num_classes, part_mask)
    checkpoint_path = os.path.join(args.out, CHECKPOINT)
    history, start_epoch = _resume(state, model, optimizer, schedule,
                                   checkpoint_path, run.say)
    net = run.network(model)
    # float16 gradients underflow without scaling; a no-op otherwise
    scaler = torch.amp.GradScaler(device.type,
                                  enabled=args.precision == '16-mixed')
    loaders = run.evaluation_loaders(train_set, test_items)
    has_batch_norm = bool(batch_norms(model))
    num_params = sum(p.numel() for p in model.parameters())
    run.say(f"{args.model} ({num_params / 1e6:.2f}M parameters), protocol "
            f"{args.protocol}, on {args.dataset}: {len(train_set)} train / "
            f"{len(test_items)} test, {num_classes} classes, {device}"
            + (f", {run.world} processes" if run.world > 1 else ''))
    started = time.perf_counter()
    for epoch in range(start_epoch, args.epochs + 1):
        totals = run.epoch(net, train_set, optimizer, scaler, epoch)
        schedule.step()
        seen = max(float(totals[0]), 1.0)
        record = {'epoch': epoch, 'train_loss': float(totals[1]) / seen,
                  'train_accuracy': float(totals[2]) / seen,
                  'test_accuracy': None,
                  'seconds': time.perf_counter() - started}
        if epoch % args.eval_every == 0 or epoch == args.epochs:
            record.update(run.scores(model, train_set, loaders, part_mask,
                                     has_batch_norm))
        history.append(record)
        if run.main_process:
            run.write_epoch(history, {
                'model': model.state_dict(),
                'optimizer': optimizer.state_dict(),
                'schedule': schedule.state_dict(), 'history': history,
                'epoch': epoch, 'world_size': run.world,
                'num_classes': num_classes, 'args': vars(args)})
    metrics = _metrics(args, history, num_params, len(train_set),
                       len(test_items), run.world)
    if run.main_process:
        run.mark_written('metrics.json')
        atomic_write_json(os.path.join(args.out, 'metrics.json'), metrics)
        run.say(f"final test accuracy: {metrics['final_test_accuracy']:.3f}"
                f" (written to {args.out})")
    return metrics


class _Run:
    """One process's part of a training run: its rank, what it says, the
    files it records in ``--out``, and the steps of :func:`_train`."""

    def __init__(self, args, device):
        self.rank = distributed.rank()
        self.world = distributed.world_size()
        self.main_process = self.rank == 0
        self.device = device
        self.quiet = args.quiet or not self.main_process
        if not self.main_process:   # no progress bars beside rank 0's
            args = argparse.Namespace(**{**vars(args), 'quiet': True})
        self.args = args
        # the files this run wrote into --out, recorded before each is
        # written
        self.written = (recorded_files(args.out, 'train') or set()) \
            if self.main_process else set()

    def say(self, text):
        if self.main_process:
            print(text)

    def mark_written(self, name):
        if name not in self.written:
            self.written.add(name)
            write_record(self.args.out, 'train', self.written)

    def prepare(self, state):
        """The train and test items and their source (rank 0 prepares and
        caches the inputs, the others then read them)."""
        args = self.args
        seed_everything(args.seed)
        # by default the cores this process shares with the others
        # torchrun started here: concurrent runs do not each take them all
        torch.set_num_threads(args.threads or default_threads())
        build = build_mesh_datasets if args.model == 'hsn' \
            else build_point_sets
        classes = None if state is None else state.get('num_classes')
        return distributed.rank_zero_first(lambda: build(args, classes))

    def training_set(self, train_items, part_mask):
        """The training items (``--train-per-class`` of them), augmented."""
        args = self.args
        if args.train_per_class is not None and \
                args.task == 'classification':
            labels = [int(item.y) for item in train_items]
            train_items = [train_items[i] for i in select_per_class(
                labels, args.train_per_class, args.data_seed)]
        train_set = _Mapped(train_items, augmentation(args), args.seed)
        if args.task == 'classification' or part_mask is not None:
            # per-shape features (DeltaNet's head, its category embedding)
            # pass through batch norm
            problem = lone_shape_batches(args.model, args.batch_size,
                                         self.world, len(train_set))
            if problem:
                raise UsageError(problem)
        return train_set

    def model(self, num_classes, part_mask):
        """The model on the device, its optimiser and its schedule."""
        args = self.args
        model = build_model(args.model, num_classes, args, None if
                            part_mask is None else part_mask.size(0))
        if args.sync_batch_norm and self.world > 1:
            from tg_intrinsic.nn import convert_sync_batch_norm
            model = convert_sync_batch_norm(model)
        model = model.to(self.device)
        if args.optimizer == 'sgd':
            optimizer = torch.optim.SGD(model.parameters(), lr=args.lr,
                                        momentum=0.9,
                                        weight_decay=args.weight_decay)
        else:
            optimizer = torch.optim.Adam(model.parameters(), lr=args.lr,
                                         weight_decay=args.weight_decay)
        if args.schedule == 'cosine':
            schedule = torch.optim.lr_scheduler.CosineAnnealingLR(
                optimizer, T_max=args.epochs, eta_min=args.lr_min)
        else:
            schedule = torch.optim.lr_scheduler.MultiStepLR(
                optimizer, milestones=args.milestones, gamma=args.gamma)
        return model, optimizer, schedule

    def network(self, model):
        """What the steps call: the model, under DDP and compiled as
        asked."""
        net = model
        if self.world > 1:
            net = torch.nn.parallel.DistributedDataParallel(
                model, device_ids=None if self.device.type == 'cpu'
                else [self.device])
        if self.args.compile:  # shapes vary by batch: one graph for all
            net = torch.compile(net, dynamic=True)
        return net

    def evaluation_loaders(self, train_set, test_items):
        """``(test, shuffled test or None, recalibration batches)``."""
        args, rank, world = self.args, self.rank, self.world
        # the test set: a contiguous part on every process, scores summed
        test_loader = DataLoader(
            [test_items[i] for i in distributed.shard(
                range(len(test_items)), rank, world)], args.batch_size)
        # batch statistics of shuffled test batches (the test set is often
        # sorted by class); recalibration on the training items without
        # augmentation, in training batches (the same count on every
        # process)
        shuffled = distributed.shard(np.random.default_rng(
            distributed.derived_seed(args.seed, 0, 1)).permutation(
                len(test_items)), rank, world)
        shuffled_test_loader = None if len(test_items) // world < 2 else \
            DataLoader([test_items[i] for i in shuffled],
                       batch_sampler=whole_batches(len(shuffled),
                                                   args.batch_size))
        recalibration = distributed.epoch_batches(
            len(train_set), args.batch_size, args.seed, 0, rank,
            world)[:RECALIBRATION_BATCHES]
        return test_loader, shuffled_test_loader, recalibration

    def epoch(self, net, train_set, optimizer, scaler, epoch):
        """One epoch of training: ``[count, loss sum, correct]`` over the
        global batches."""
        args, device, world = self.args, self.device, self.world
        # Everything random in an epoch derives from (seed, epoch): the
        # batches, each item's augmentation (seeded by its index too) and
        # dropout (seeded by the rank too).
        seed_everything(distributed.derived_seed(args.seed, epoch,
                                                 self.rank))
        train_set.epoch = epoch
        train_loader = DataLoader(train_set, batch_sampler=(
            distributed.epoch_batches(len(train_set), args.batch_size,
                                      args.seed, epoch, self.rank, world)))
        net.train()
        totals = torch.zeros(3, dtype=torch.float64, device=device)
        # closed (and cleared) before an error propagates, so that the
        # error is printed on a line of its own
        with tqdm(train_loader, desc=f'epoch {epoch}/{args.epochs}',
                  leave=False, disable=self.quiet) as bar:
            for batch in bar:
                totals += self.step(net, batch.to(device), optimizer,
                                    scaler, epoch)
                bar.set_postfix(loss=f'{float(totals[1] / totals[0]):.3f}')
        return totals

    def step(self, net, batch, optimizer, scaler, epoch):
        """One optimiser step: ``[count, loss sum, correct]`` of the
        global batch."""
        args, device = self.args, self.device
        optimizer.zero_grad()
        with autocast(args.precision, device):
            out = net(batch)
        target = batch.y.view(-1)
        loss_sum = F.cross_entropy(out.float(), target, reduction='sum',
                                   label_smoothing=args.label_smoothing)
        step = distributed.all_reduce_sum(torch.stack([
            torch.tensor(float(target.numel()), dtype=torch.float64,
                         device=device),
            loss_sum.detach().double(),
            (out.argmax(-1) == target).sum().double()]))
        if not torch.isfinite(step[1]):
            # the settings diverge: the user's to change
            raise UsageError(f"the training loss became {float(step[1])} "
                             f"in epoch {epoch}; lower --lr (the "
                             f"checkpoint of the last evaluation is kept)")
        # the mean over the global batch: DDP averages the gradients over
        # the processes, so each one scales its sum by world / n
        scaler.scale(loss_sum * (self.world / float(step[0]))).backward()
        scaler.step(optimizer)
        scaler.update()
        return step

    def scores(self, model, train_set, loaders, part_mask,
               has_batch_norm) -> Dict:
        """The test scores of an evaluation epoch, for its record."""
        test_loader, shuffled_test_loader, recalibration = loaders
        args, device = self.args, self.device
        if has_batch_norm:
            # the running statistics of the current weights, so that
            # eval-mode inference scores what training does
            recalibrate_batch_norm(model, DataLoader(
                train_set.items, batch_sampler=recalibration), device)
        # equal on every process after the recalibration; rank 0's
        # otherwise (per-process batch norm), as saved
        distributed.broadcast_buffers(model)
        scores = evaluate(model, test_loader, device, part_mask,
                          precision=args.precision)
        record = {'test_accuracy': scores['accuracy']}
        if 'miou' in scores:
            record['test_miou'] = scores['miou']
        # with batch statistics (per shape at batch size 1): the same by
        # construction without batch norms
        if not has_batch_norm:
            record['test_accuracy_batch_statistics'] = scores['accuracy']
        elif shuffled_test_loader is not None:
            record['test_accuracy_batch_statistics'] = evaluate(
                model, shuffled_test_loader, device, part_mask,
                statistics='batch', precision=args.precision)['accuracy']
        return record

    def write_epoch(self, history, checkpoint):
        """Rank 0's files after an epoch: the metrics CSV, and after an
        evaluation the checkpoint and the learning curve."""
        args, record = self.args, history[-1]
        self.mark_written('metrics.csv')
        write_metrics_csv(history, os.path.join(args.out, 'metrics.csv'))
        if record['test_accuracy'] is None:
            return
        self.say(f"epoch {record['epoch']}: loss "
                 f"{record['train_loss']:.3f}, train "
                 f"{record['train_accuracy']:.3f}, test "
                 f"{record['test_accuracy']:.3f}" + statistics_gap(record))
        self.mark_written(CHECKPOINT)
        atomic_torch_save(checkpoint, os.path.join(args.out, CHECKPOINT))
        self.mark_written('learning_curve.png')
        plot_history(history, os.path.join(args.out, 'learning_curve.png'),
                     f'{args.model} on {args.dataset}')


def _resume(state, model, optimizer, schedule, checkpoint_path, say):
    """``(history, first epoch)``: a new run's, or the checkpoint's loaded
    into the model, optimiser and schedule."""
    if state is None:
        return [], 1
    # Written by any number of processes: the batches and random draws of
    # an epoch depend on (seed, epoch) only, so the generators' states
    # that older versions saved ('rng') are not needed.
    try:
        model.load_state_dict(state['model'])
        optimizer.load_state_dict(state['optimizer'])
        schedule.load_state_dict(state['schedule'])
    except (RuntimeError, ValueError, KeyError) as error:
        # a checkpoint of an older version, which saved fewer settings
        # (and not the number of classes) than are checked now
        raise UsageError(f"'{checkpoint_path}' does not fit the model of "
                         f"these settings ({one_line(error)[:200]}); resume"
                         f" it with the settings and data it was trained "
                         f"with, or start a new run with --overwrite "
                         f"(without --resume) or in another --out"
                         ) from error
    say(f"resuming from epoch {state['epoch']} of {checkpoint_path}")
    return state['history'], state['epoch'] + 1


def _metrics(args, history, num_params, train_shapes, test_shapes,
             world) -> Dict:
    """What ``train`` returns and writes to ``metrics.json``."""
    last = history[-1] if history else {}
    return {'model': args.model, 'dataset': args.dataset,
            'final_test_accuracy_batch_statistics': last.get(
                'test_accuracy_batch_statistics'),
            'final_test_miou': last.get('test_miou'),
            'protocol': args.protocol, 'parameters': num_params,
            'train_shapes': train_shapes, 'test_shapes': test_shapes,
            'final_test_accuracy': last.get('test_accuracy'),
            'best_test_accuracy': max(
                (h['test_accuracy'] for h in history
                 if h['test_accuracy'] is not None), default=None),
            'world_size': world,
            'history': history, 'args': vars(args)}


class _Mapped(torch.utils.data.Dataset):
    """A list of examples with a random transform applied on access, its
    draws seeded by (seed, :attr:`epoch`, index): the same on any process
    and after any history. The global generators are left as they were."""
    def __init__(self, items, transform, seed: int):
        self.items, self.transform, self.seed = items, transform, seed
        self.epoch = 0

    def __len__(self):
        return len(self.items)

    def __getitem__(self, index):
        if self.transform is None:
            return self.items[index]
        saved = np.random.get_state(), random.getstate()
        with torch.random.fork_rng(devices=[]):
            seed_everything(distributed.derived_seed(self.seed, self.epoch,
                                                     index))
            try:
                return self.transform(self.items[index])
            finally:
                np.random.set_state(saved[0])
                random.setstate(saved[1])
