"""Train DeltaNet (on points sampled once from each shape) or a Harmonic
Surface Network (on the mesh vertices) on the synthetic data sets or your
own, with the papers' protocols as defaults.

Examples::

    python -m tg_intrinsic.train --dataset synthetic_modelnet --epochs 30
    python -m tg_intrinsic.train --protocol deltanet-shrec11         --dataset mesh_folder --mesh-root shrec_16
    python -m tg_intrinsic.train --model hsn --dataset synthetic_shrec         --num-vertices 300 500
    python -m tg_intrinsic.train --model hsn --task segmentation         --dataset synthetic_shrec

Every option left out takes the value of the protocol (``--protocol``, or
the model and task's default one, see :mod:`tg_intrinsic.protocols`).
Inputs are prepared once per shape and cached under ``--root``: DeltaNet's
points (sampled with a generator seeded per shape, so a checkpoint always
scores the same) with their operators, HSN's discs, log maps and
transport. Rotations, uniform scales and translations keep both valid;
a per-axis scale makes DeltaNet rebuild its operators for every batch.

Writes to ``--out``: ``checkpoint.pt`` (model, optimiser, schedule, history
and the settings; written atomically at every evaluation, so ``--resume``
continues an interrupted run), ``metrics.json``, ``metrics.csv`` (one row
per epoch) and ``learning_curve.png``, and records them there
(:mod:`tg_intrinsic.io.results`). Before any data is prepared, the output
folder is checked: it may not be, or be inside, the data set folder; it
may hold files that ``train`` did not write only with ``--overwrite``
(they are kept); and a new run does not start over an earlier one there
unless ``--overwrite``, which deletes the earlier run's files first, so
the folder never mixes two runs.

``--resume`` continues from ``checkpoint.pt`` (or, when there is none,
says so and starts a new run at epoch 1, so a job script can always pass
it). The checkpoint must be readable and of the same model and task, and
the settings must be the checkpoint's: a run resumed with other values
would not be the run the checkpoint continues (the optimiser's state even
keeps the old ``--lr``). The check names every setting that differs.
``--allow-changes epochs,eval-every`` lets the settings that change how
the run goes on, not what the checkpoint holds, differ: ``--epochs``,
``--eval-every``, ``--sync-batch-norm`` and the path of the data set
folder (``--dataset`` or ``--mesh-root``, e.g. after moving it). Settings
that do not change what is computed (``--quiet``, ``--workers``,
``--threads``, ``--device``, ``--backend``, ``--on-disk``, ``--root``)
may always differ, and so may those the model or data set does not use.
A setting an older checkpoint did not save is not checked.

Evaluation reports what inference on the checkpoint gives: the test
scores are taken in eval mode (``model.eval()``) on the weights saved
with them. HSN normalises per mesh (:class:`~tg_intrinsic.nn.
ComplexInstanceNorm`, ``--hsn-norm instance``), the same function in
training and evaluation at any batch size; batch norms (DeltaNet's, or
HSN's with ``--hsn-norm batch``) get running statistics recomputed under
the current weights before every evaluation
(:func:`~tg_intrinsic.nn.recalibrate_batch_norm` over up to
``RECALIBRATION_BATCHES`` training batches without augmentation). Every
evaluation also records ``test_accuracy_batch_statistics``, the same
weights normalised by each (shuffled) test batch's own statistics (not
with fewer than two test shapes per process), and the log says so when
the two differ by more than a point
(``benchmarks/normalisation.py`` measures why both are needed).

Runs are reproducible: ``--seed`` seeds the model's initialisation and,
with the epoch, everything random in an epoch: the shuffling, each
shape's augmentation (seeded by its index too) and dropout. So two runs
with the same arguments on the same machine and thread count give the
same weights bit for bit on the CPU, and an interrupted run resumed with
``--resume`` shuffles and augments its remaining epochs as an
uninterrupted one would, and ends with the same weights. (Older
checkpoints' generator states, ``rng``, are no longer needed and are
ignored.) A run starting or resuming in ``--out`` removes the temporary
files (``.tmp-*``) that a run killed while writing left there.

Data-parallel training: under ``torchrun`` (one process per core or GPU,
e.g. ``torchrun --standalone --nproc_per_node 2 -m tg_intrinsic.train
...``) every process joins the process group its environment describes
(backend ``gloo`` on the CPU, ``nccl`` on CUDA, ``--backend`` to choose)
and trains the model wrapped in
:class:`~torch.nn.parallel.DistributedDataParallel`. ``--batch-size`` is
the global batch, a multiple of the number of processes N: each process
takes its 1/N of every global batch (:func:`tg_intrinsic.distributed.
epoch_batches`; the remainder of an epoch is dropped as on one process),
so N processes and one see the same batches; losses and scores are summed
over the processes and equal one process's. Batch norm: by default each
process normalises with the statistics of its own part of the batch (as
DDP does; faster, but another run than one process's);
``--sync-batch-norm`` takes them over the global batch
(:func:`tg_intrinsic.nn.convert_sync_batch_norm`, on the CPU too), and
then, without dropout (``--dropout 0``), N processes train as one to
float32 rounding. Rank 0 prepares the input cache first (the others then
read it), reads a checkpoint to resume (any number of processes may have
written it) and alone prints and writes the outputs.

(The face of :mod:`tg_intrinsic.training`, whose modules hold the code;
every name of the former module is importable from here.)
"""
# flake8: noqa: F401 (the names are re-exported)
from tg_intrinsic.training.sources import (DATASETS, DEFAULT_DATASET, MODELS,
                                           PROTOCOL_OPTIONS, ROTATIONS,
                                           SUPPORTED, TASKS, resolve_protocol,
                                           select_per_class, source_splits)
from tg_intrinsic.training.prepare import (augmentation, build_mesh_datasets,
                                           build_point_sets, hsn_pipeline)
from tg_intrinsic.training.models import build_model
from tg_intrinsic.training.evaluation import (RECALIBRATION_BATCHES, evaluate,
                                              instance_miou, statistics_gap,
                                              whole_batches)
from tg_intrinsic.training.outputs import (CSV_COLUMNS, claim_output,
                                           plot_history, write_metrics_csv)
from tg_intrinsic.training.checkpoints import (CHECKPOINT, DELTANET_ONLY,
                                               HSN_ONLY, OLD_DEFAULTS,
                                               OUTPUT_FILES,
                                               RESUME_CHANGEABLE, RESUME_FREE,
                                               allowed_changes, check_resume,
                                               read_checkpoint, resume_changes)
from tg_intrinsic.training.loop import (lone_shape_batches, seed_everything,
                                        train)
from tg_intrinsic.training.options import (add_arguments, check_arguments,
                                           main, parse_args)

__all__ = [
    'train', 'evaluate', 'build_model', 'read_checkpoint',
    'resolve_protocol', 'hsn_pipeline', 'instance_miou',
    'seed_everything', 'add_arguments', 'parse_args', 'main',
]

if __name__ == '__main__':
    main()
