"""Where the data come from: the protocol fills the options left out, and
the per-class training split is seeded and balanced."""
import torch

from tg_intrinsic.training.options import parse_args
from tg_intrinsic.training.sources import select_per_class


def test_protocol_defaults_and_overrides():
    from tg_intrinsic.protocols import PROTOCOLS
    args = parse_args(['--model', 'hsn'])
    hsn = PROTOCOLS['hsn-shrec11']
    assert args.protocol == 'hsn-shrec11'
    assert (args.lr, args.optimizer, args.batch_size, args.schedule) == \
        (hsn.lr, hsn.optimizer, hsn.batch_size, hsn.schedule)
    assert args.milestones == list(hsn.milestones) and args.rotate == 'xyz'
    args = parse_args(['--model', 'hsn', '--lr', '0.5', '--rotate'])
    assert args.lr == 0.5 and args.rotate == 'so3'
    args = parse_args(['--protocol', 'deltanet-shrec11',
                       '--no-anisotropic'])
    shrec = PROTOCOLS['deltanet-shrec11']
    assert (args.num_points, args.conv_channels, args.train_per_class) == \
        (shrec.num_points, list(shrec.conv_channels), 10)
    assert args.anisotropic is False
    args = parse_args(['--model', 'hsn', '--task', 'segmentation'])
    assert args.protocol == 'hsn-human-seg'
    assert args.resample_vertices == 1024


def test_select_per_class_is_seeded_and_balanced():
    labels = [0] * 16 + [1] * 16 + [2] * 3
    first = select_per_class(labels, 10, seed=4)
    assert first == select_per_class(labels, 10, seed=4)
    assert first != select_per_class(labels, 10, seed=5)
    counts = torch.bincount(torch.tensor(labels)[first])
    assert counts.tolist() == [10, 10, 3]
