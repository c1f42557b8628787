"""The shape pipelines: a shape's points depend on the data seed and the
shape only, whenever it is prepared."""
import torch

from tg_intrinsic.training.options import parse_args
from tg_intrinsic.training.prepare import build_point_sets


def test_test_points_are_the_same_on_every_preparation(tmp_path):
    # A checkpoint must score the same every time: the sampling of a
    # shape depends on the data seed and the shape only.
    argv = ['--dataset', 'synthetic_shrec', '--root', str(tmp_path),
            '--num-points', '64', '--shapes-per-class', '2',
            '--num-vertices', '120', '160', '--k', '8']
    first = build_point_sets(parse_args(argv))[1]
    for folder in tmp_path.glob('deltanet_cache'):
        for f in folder.iterdir():
            f.unlink()
    again = build_point_sets(parse_args(argv))[1]
    other = build_point_sets(parse_args(argv + ['--data-seed', '1']))[1]
    for a, b in zip(first, again):
        torch.testing.assert_close(a.pos, b.pos)
        torch.testing.assert_close(a.grad_weight, b.grad_weight)
    assert not torch.allclose(first[0].pos, other[0].pos)
