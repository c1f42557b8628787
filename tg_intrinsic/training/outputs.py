"""What a run writes: the output folder claimed before any data is read,
the metrics CSV and the learning curve."""
import os
from typing import Dict, List, Optional

from tg_intrinsic.errors import UsageError
from tg_intrinsic.io.figures import save_figure
from tg_intrinsic.io.results import (RECORD, check_output_path, claim_folder,
                                     recorded_files, write_record)
from tg_intrinsic.training.checkpoints import (CHECKPOINT, OUTPUT_FILES,
                                               check_resume, read_checkpoint)
from tg_intrinsic.utils import atomic_write, remove_temporaries


CSV_COLUMNS = ('epoch', 'train_loss', 'train_accuracy', 'test_accuracy',
               'test_accuracy_batch_statistics', 'test_miou', 'seconds')


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


def _earlier_run(out: str, files: List[str]) -> str:
    """Why a new run does not start in ``out``, which holds ``files`` of
    an earlier one."""
    if CHECKPOINT not in files:
        return (f"--out '{out}' holds an earlier run that saved no "
                f"checkpoint ({', '.join(files)}); --overwrite starts over "
                f"(deleting it), or give another --out")
    try:
        epoch = read_checkpoint(os.path.join(out, CHECKPOINT))['epoch']
    except ValueError:
        return (f"--out '{out}' holds an earlier run with an unreadable "
                f"checkpoint; --overwrite starts over (deleting it), or "
                f"give another --out")
    return (f"--out '{out}' holds an earlier run (checkpoint at epoch "
            f"{epoch}); --resume continues it, --overwrite starts over "
            f"(deleting it), or give another --out")


def claim_output(args) -> Optional[Dict]:
    """Checks the output folder ``args.out`` before any data is read and
    returns the checkpoint to resume (:obj:`None` for a new run): the rules
    of :mod:`tg_intrinsic.io.results` (no input in it, no files another
    command wrote unless ``args.overwrite``), and with ``args.resume`` a
    readable checkpoint of the same model, task and settings
    (:func:`check_resume`). A new run does not start over an earlier one
    unless ``args.overwrite``, which then deletes the earlier run's files.
    Records that ``train`` writes there (:func:`~tg_intrinsic.io.results.
    write_record`) and removes the temporary files of killed writes."""
    out = args.out
    inputs = [args.mesh_root] if getattr(args, 'mesh_root', None) else []
    check_output_path(out, inputs, '--out')
    for source in inputs:
        # a folder data set would read the run's files as data
        real = os.path.realpath(source)
        if os.path.realpath(out).startswith(real + os.sep):
            raise UsageError(f"--out '{out}' is inside the data set folder "
                             f"'{source}', which would read the run's "
                             f"files as data; give an --out outside it")
    path = os.path.join(out, CHECKPOINT)
    own = recorded_files(out, 'train')
    if own is None and os.path.isfile(path) and not os.path.exists(
            os.path.join(out, RECORD)):
        # a run of a version that kept no record: these are its files
        own = {name for name in OUTPUT_FILES
               if os.path.exists(os.path.join(out, name))}
    # left by a run killed while writing a checkpoint or metrics
    leftovers = [] if own is None else remove_temporaries(out)
    state = None
    if args.resume and os.path.exists(path):
        state = read_checkpoint(path)
        changes = check_resume(args, state, path)
        # the files beside the run's were allowed when it started
        claim_folder(out, 'train', args.overwrite or (
            own is not None and CHECKPOINT in own), inputs)
        if changes:
            print(f"resuming with changed settings: {', '.join(changes)}")
    else:
        earlier = sorted(name for name in own or ()
                         if os.path.isfile(os.path.join(out, name)))
        if earlier and not args.overwrite:
            raise UsageError(_earlier_run(out, earlier))
        claim_folder(out, 'train', args.overwrite, inputs)
        for name in earlier:  # the folder never mixes two runs
            os.remove(os.path.join(out, name))
        own = set()
        if args.resume:
            print(f"no checkpoint in {out}: starting a new run at epoch 1")
    if os.path.isdir(out):  # else made with the run's first file
        leftovers += remove_temporaries(out)
        write_record(out, 'train', own or ())
    if leftovers:
        print(f"removed {len(leftovers)} temporary file(s) of an "
              f"interrupted write from {out}: {', '.join(leftovers)}")
    return state
