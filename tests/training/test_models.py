"""The models train builds from a protocol's options: the right family,
task head and number of classes."""
import pytest

from tg_intrinsic.nn.models import (DeltaNetClassification,
                                    DeltaNetSegmentation, HSNClassification,
                                    HSNSegmentation)
from tg_intrinsic.training.models import build_model
from tg_intrinsic.training.options import parse_args


@pytest.mark.parametrize('model,task,expected', [
    ('deltanet', 'classification', DeltaNetClassification),
    ('deltanet', 'segmentation', DeltaNetSegmentation),
    ('hsn', 'classification', HSNClassification),
    ('hsn', 'segmentation', HSNSegmentation)])
def test_build_model_follows_the_protocol(model, task, expected):
    argv = ['--model', model, '--task', task]
    if model == 'deltanet' and task == 'segmentation':
        argv += ['--dataset', 'synthetic_shrec']
    args = parse_args(argv)
    built = build_model(model, 7, args)
    assert type(built) is expected
    # three input channels (positions or normals), seven classes
    assert repr(built).startswith(f'{expected.__name__}(3, 7, ')
