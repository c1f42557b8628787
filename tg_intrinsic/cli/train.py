"""Trains DeltaNet (on points sampled from each shape) or a Harmonic
Surface Network (on the mesh vertices) on a synthetic data set or on a
folder of your own meshes, with a progress bar, evaluation every few
epochs, an atomic checkpoint that --resume continues from, metrics.json,
metrics.csv (one row per epoch) and learning_curve.png in --out.

--resume checks, before any data is prepared, that the checkpoint in --out
is readable and was trained with the same model, task and settings, and
names each setting that differs; --allow-changes epochs,eval-every (also
sync-batch-norm, dataset: a moved folder) lets those go on with new values,
while --quiet, --workers, --threads, --device, --backend, --on-disk and
--root may always differ. Without a checkpoint in --out, --resume says so
and starts a new run at epoch 1. A new run does not start over an earlier
one in --out, nor beside files train did not write, unless --overwrite
(which deletes the earlier run's files first and keeps the others)."""
import os

HELP = ('train DeltaNet or HSN with a paper protocol on a synthetic data set '
        'or your own folder')
EXAMPLE = """examples:
  tg-intrinsic train hsn --dataset path/to/shrec_16      # HSN's SHREC11 protocol
  tg-intrinsic train deltanet --protocol deltanet-shrec11 --dataset path/to/shrec_16
  tg-intrinsic train deltanet --dataset synthetic-modelnet --epochs 30 --lr 0.05
  tg-intrinsic train hsn --task segmentation --dataset path/to/human_seg
      # MeshCNN's layout: train/, test/, seg/*.eseg
  tg-intrinsic train deltanet --dataset synthetic-shrec --resume --out runs/x
  tg-intrinsic train hsn --resume --out runs/y --allow-changes epochs \\
      --epochs 200       # continue runs/y up to epoch 200 (started with fewer)
  tg-intrinsic train deltanet --task segmentation --dataset synthetic-parts
      # generated ShapeNet-Part-style parts (5 categories, 16 parts)

Every option left out takes the value of the protocol (--protocol, else
the model and task's default: deltanet-modelnet40, deltanet-shapenet-part,
hsn-shrec11, hsn-human-seg). FOLDER may be any standard layout:
<class>/<train|test>/*.off|obj|ply, MeshCNN segmentation, point clouds
<class>/<train|test>/*.txt|xyz|npy|pts, modelnet40_normal_resampled,
ShapeNet-Part (normal), ScanObjectNN h5_files.
Also available as "python -m tg_intrinsic.train --model deltanet ...".
Data-parallel: torchrun --standalone --nproc_per_node N --no-python
tg-intrinsic train deltanet ... (--batch-size is the global batch, a
multiple of N; --sync-batch-norm for batch statistics over all of it)."""

SYNTHETIC = {'synthetic-modelnet': 'synthetic_modelnet',
             'synthetic-shrec': 'synthetic_shrec',
             'synthetic-parts': 'synthetic_parts'}


def add_arguments(parser):
    from tg_intrinsic.training.options import add_arguments as training
    from tg_intrinsic.training.sources import MODELS
    parser.add_argument('model', choices=MODELS,
                        help='deltanet (point clouds) or hsn (meshes)')
    parser.add_argument('--dataset', default=None,
                        metavar='{synthetic-modelnet,synthetic-shrec,'
                        'synthetic-parts,FOLDER}',
                        help='a generated data set, or a folder of meshes '
                        'laid out as FOLDER/<class>/<train|test>/*.off|obj|ply'
                        ' (default: synthetic-modelnet for deltanet, '
                        'synthetic-shrec for hsn)')
    training(parser, model_and_dataset=False)
    parser.set_defaults(check=parser)


def run(args):
    from tg_intrinsic.training.loop import train
    from tg_intrinsic.training.options import check_arguments
    from .common import UsageError
    name = (args.dataset or '').replace('_', '-')
    if args.dataset is None:
        args.mesh_root = None
    elif name in SYNTHETIC:
        args.dataset, args.mesh_root = SYNTHETIC[name], None
    elif os.path.isdir(args.dataset):
        args.dataset, args.mesh_root = 'mesh_folder', args.dataset
    else:
        raise UsageError(f"--dataset {args.dataset!r} is neither "
                         f"{' nor '.join(SYNTHETIC)} nor an existing folder")
    parser = args.check
    del args.check, args.run
    check_arguments(args, parser)
    train(args)
    return 0
