import pytest
import torch

from tg_intrinsic.nn.models import HSNSegmentation
from tests.nn.models.hsn_checks import (check_compile_and_precision,
                                        MISSING_LEVELS,
                                        check_batched_equals_per_example,
                                        check_constructors_need_positive_sizes,
                                        check_gauge_invariance,
                                        check_missing_level_is_explained,
                                        check_norm_is_validated,
                                        check_training_equals_evaluation)
from tests.conftest import rel
from tests.nn.conftest import RINGS, permute_points, two_level_data


@pytest.mark.parametrize('max_order', [1, 2])
def test_predictions_are_gauge_invariant(max_order):
    check_gauge_invariance(HSNSegmentation, max_order)


def test_batched_equals_per_example():
    check_batched_equals_per_example(HSNSegmentation, (150, 5))


def test_constructors_need_positive_sizes():
    check_constructors_need_positive_sizes(HSNSegmentation)


def test_logits_follow_the_points_when_they_are_reordered():
    # the logits of a point do not depend on where it is listed
    torch.manual_seed(0)
    model = HSNSegmentation(3, 5, channels=(4, 6), max_order=1,
                            rings=RINGS).double().eval()
    with torch.no_grad():
        for p in model.parameters():  # no trivial zero outputs
            p.add_(0.05 * torch.randn_like(p))
    data = two_level_data(1, max_order=1)
    order = torch.randperm(50, generator=torch.Generator().manual_seed(3))
    out = model(data)
    out2 = model(permute_points(data, order))
    expected = out[order]
    assert out.shape == (50, 5)
    assert rel(out2, expected) < 1e-10
    # the points get different logits: the comparison can fail
    assert rel(out2, out) > 1e-3


def test_repr():
    model = HSNSegmentation(3, 5, channels=(4, 6), max_order=2, rings=RINGS)
    assert repr(model) == ('HSNSegmentation(3, 5, channels=(4, 6), '
                           'max_order=2, rings=4)')


@pytest.mark.parametrize('key,match', MISSING_LEVELS)
def test_missing_levels_are_explained(key, match):
    check_missing_level_is_explained(HSNSegmentation, key, match)


def make(norm='default'):
    norm = {} if norm == 'default' else {'norm': norm}
    return HSNSegmentation(3, 5, channels=(4, 6), rings=RINGS, **norm)


def test_training_and_evaluation_compute_the_same_function():
    check_training_equals_evaluation(
        make, [two_level_data(s, max_order=1) for s in (1, 2, 3)])


def test_norm_is_validated_and_per_mesh_by_default():
    check_norm_is_validated(make)
    assert make().norm == 'instance'
    assert make(None).norm is None


def test_compile_and_mixed_precision():
    check_compile_and_precision(HSNSegmentation)
