"""Trains DeltaNet (on points sampled from each shape) or a Harmonic
Surface Network (on the mesh vertices) on a synthetic data set or on a
folder of your own meshes, with a progress bar, evaluation every few
epochs, an atomic checkpoint that --resume continues from, metrics.json,
metrics.csv (one row per epoch) and learning_curve.png in --out."""
import os

HELP = 'train DeltaNet or HSN on a synthetic data set or your own folder'
EXAMPLE = """examples:
  tg-intrinsic train deltanet --dataset synthetic-modelnet --epochs 30
  tg-intrinsic train hsn --dataset synthetic-shrec --num-vertices 300 500 \\
      --rotate --lr 1e-2 --out runs/hsn
  tg-intrinsic train deltanet --dataset path/to/ModelNet10 --epochs 50
      # a FOLDER laid out as FOLDER/<class>/<train|test>/*.off|obj|ply
  tg-intrinsic train hsn --task segmentation --dataset synthetic-shrec
  tg-intrinsic train deltanet --dataset synthetic-shrec --resume --out runs/x

Also available as "python -m tg_intrinsic.train --model deltanet ..."."""

SYNTHETIC = {'synthetic-modelnet': 'synthetic_modelnet',
             'synthetic-shrec': 'synthetic_shrec'}


def add_arguments(parser):
    from tg_intrinsic.train import MODELS, add_arguments as training
    parser.add_argument('model', choices=MODELS,
                        help='deltanet (point clouds) or hsn (meshes)')
    parser.add_argument('--dataset', default='synthetic-modelnet',
                        metavar='{synthetic-modelnet,synthetic-shrec,FOLDER}',
                        help='a generated data set, or a folder of meshes '
                        'laid out as FOLDER/<class>/<train|test>/*.off|obj|ply'
                        ' (default: synthetic-modelnet)')
    training(parser, model_and_dataset=False)
    parser.set_defaults(check=parser)


def run(args):
    from tg_intrinsic.train import check_arguments, train
    from .common import UsageError
    name = args.dataset.replace('_', '-')
    if name in SYNTHETIC:
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
