"""The paper protocols as data: every row is a frozen, valid, JSON-able
Protocol that the training options accept, the defaults per model and
task are rows of that model and task, the values are the documented ones
(benchmarks/replicate/PROTOCOLS.md), and an unknown name is a ValueError
that lists the known ones."""
import argparse
import dataclasses
import json

import pytest

from tg_intrinsic import train
from tg_intrinsic.protocols import (DEFAULT_PROTOCOL, PROTOCOLS, Protocol,
                                    get_protocol)

NAMES = sorted(PROTOCOLS)


def test_the_rows_of_the_papers_tables():
    assert NAMES == sorted([
        'deltanet-modelnet40', 'deltanet-scanobjectnn', 'deltanet-shrec11',
        'deltanet-shapenet-part', 'deltanet-human-seg', 'hsn-shrec11',
        'hsn-human-seg'])
    for name, protocol in PROTOCOLS.items():
        assert protocol.name == name
        assert name.startswith(protocol.model + '-')


@pytest.mark.parametrize('name', NAMES)
def test_a_protocol_is_frozen_and_round_trips_through_json(name):
    protocol = get_protocol(name)
    assert protocol is PROTOCOLS[name]
    with pytest.raises(dataclasses.FrozenInstanceError):
        protocol.lr = 1.0
    as_dict = protocol.to_dict()
    assert set(as_dict) == {f.name for f in dataclasses.fields(Protocol)}
    back = json.loads(json.dumps(as_dict))  # what runs record
    tuples = {k: tuple(v) if isinstance(v, list) else v
              for k, v in back.items()}
    assert Protocol(**tuples) == protocol


@pytest.mark.parametrize('name', NAMES)
def test_every_value_is_one_the_training_accepts(name):
    p = PROTOCOLS[name]
    assert p.model in train.MODELS and p.task in train.TASKS
    assert p.rotate in (None, ) + train.ROTATIONS[1:]
    assert p.optimizer in ('sgd', 'adam') and p.schedule in ('cosine', 'step')
    if p.schedule == 'step':  # 'multiply by gamma at every milestone'
        assert p.milestones and list(p.milestones) == sorted(p.milestones)
        assert 0 < p.milestones[-1] < p.epochs and 0 < p.gamma < 1
    else:
        assert 0 < p.lr_min < p.lr
    if p.scale is not None:
        low, high = p.scale
        assert 0 < low < 1 < high
    assert not p.anisotropic or p.scale is not None
    assert 0 < p.max_angle <= 180 and p.translate >= 0
    assert p.epochs >= 1 and p.batch_size >= 1 and p.num_points >= 1
    assert p.repeats >= 1
    assert p.train_per_class is None or (p.train_per_class >= 1
                                         and p.task == 'classification')
    assert p.reported is None or 0 < p.reported <= 100
    assert 0 <= p.label_smoothing < 1 and p.metric and p.summary
    # the options the command line fills from the protocol exist on it
    for option in train.PROTOCOL_OPTIONS:
        assert hasattr(p, option)


def test_the_training_parser_takes_every_protocol(tmp_path):
    parser = argparse.ArgumentParser()
    train.add_arguments(parser)
    for name, p in PROTOCOLS.items():
        args = parser.parse_args(['--protocol', name, '--root',
                                  str(tmp_path)])
        train.resolve_protocol(args)
        assert args.model == p.model and args.task == p.task
        assert args.conv_channels == list(p.conv_channels)
        assert args.rotate == (p.rotate or 'none')
        assert args.epochs == p.epochs and args.lr == p.lr


def test_defaults_are_rows_of_their_model_and_task():
    assert set(DEFAULT_PROTOCOL) == {(m, t) for m in train.MODELS
                                     for t in train.TASKS}
    for (model, task), name in DEFAULT_PROTOCOL.items():
        p = get_protocol(name)
        assert (p.model, p.task) == (model, task)


def test_the_documented_values():
    # benchmarks/replicate/PROTOCOLS.md, sections 1-3 and HSN's notebook
    modelnet = PROTOCOLS['deltanet-modelnet40']
    assert (modelnet.k, modelnet.regularizer, modelnet.conv_channels) == \
        (20, 1e-3, (64, 64, 128, 256))
    assert (modelnet.optimizer, modelnet.lr, modelnet.weight_decay,
            modelnet.schedule, modelnet.lr_min) == \
        ('sgd', 0.1, 1e-4, 'cosine', 1e-3)
    assert (modelnet.epochs, modelnet.batch_size, modelnet.label_smoothing,
            modelnet.num_points) == (250, 32, 0.2, 1024)
    assert modelnet.scale == (0.8, 1.25) and modelnet.anisotropic
    assert modelnet.translate == 0.1 and modelnet.rotate is None
    assert modelnet.reported == 93.8
    scan = PROTOCOLS['deltanet-scanobjectnn']
    assert (scan.regularizer, scan.conv_channels, scan.rotate) == \
        (1e-2, (64, 64, 64, 128), 'y')
    # the rest is inherited from the ModelNet40 row
    assert (scan.optimizer, scan.lr, scan.epochs, scan.batch_size,
            scan.label_smoothing, scan.scale) == \
        ('sgd', 0.1, 250, 32, 0.2, (0.8, 1.25))
    shrec = PROTOCOLS['deltanet-shrec11']
    assert (shrec.conv_channels, shrec.num_points, shrec.epochs,
            shrec.rotate, shrec.scale, shrec.train_per_class,
            shrec.repeats) == ((32, 32, 32, 32), 2048, 100, 'so3', None,
                               10, 10)
    assert shrec.reported is None  # could not be checked: not printed
    hsn = PROTOCOLS['hsn-shrec11']
    assert (hsn.optimizer, hsn.lr, hsn.schedule, hsn.milestones,
            hsn.epochs, hsn.batch_size) == ('adam', 1e-2, 'step', (20, ),
                                            50, 1)
    seg = PROTOCOLS['hsn-human-seg']
    assert (seg.task, seg.resample_vertices, seg.train_per_class,
            seg.repeats) == ('segmentation', 1024, None, 1)


def test_replace_gives_new_rows_and_leaves_the_original():
    base = PROTOCOLS['deltanet-modelnet40']
    other = dataclasses.replace(base, name='mine', lr=0.5)
    assert other.lr == 0.5 and base.lr == 0.1
    assert other.conv_channels == base.conv_channels
    assert 'mine' not in PROTOCOLS


@pytest.mark.parametrize('name', ['', 'deltanet', 'DeltaNet-ModelNet40',
                                  'hsn_shrec11'])
def test_an_unknown_protocol_names_the_known_ones(name):
    with pytest.raises(ValueError) as info:
        get_protocol(name)
    message = str(info.value)
    assert f'unknown protocol {name!r}' in message
    for known in PROTOCOLS:
        assert known in message
