"""Shared helpers of the training tests: a tiny DeltaNet run."""
from tg_intrinsic.training.options import main

TINY = ['--dataset', 'synthetic_modelnet', '--num-points', '96',
        '--shapes-per-class', '4', '--batch-size', '8', '--conv-channels',
        '8', '8', '--k', '8', '--eval-every', '1', '--quiet']


def run(tmp_path, *extra, root=None, out=None):
    """``train`` on the tiny generated set: its metrics."""
    return main(TINY + ['--root', str(root or tmp_path / 'data'), '--out',
                        str(out or tmp_path / 'run'), *extra])
