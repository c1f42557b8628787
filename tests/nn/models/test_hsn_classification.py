import pytest
import torch

from tg_intrinsic.nn.models import HSNClassification
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
    check_gauge_invariance(HSNClassification, max_order)


def test_batched_equals_per_example():
    check_batched_equals_per_example(HSNClassification, (3, 5))


def test_constructors_need_positive_sizes():
    check_constructors_need_positive_sizes(HSNClassification)


def test_missing_precomputation_is_explained():
    model = HSNClassification(3, 5, rings=RINGS)
    data = two_level_data(1)
    del data.harmonic_1
    with pytest.raises(ValueError, match='HarmonicPrecompute'):
        model.double()(data)
    with pytest.raises(ValueError, match='expects 3 input channels'):
        data = two_level_data(1)
        data.x = data.x[:, :2]
        model(data)


def test_pooling_level_mismatch_is_explained():
    model = HSNClassification(3, 5, rings=RINGS).double()
    data = two_level_data(1)
    data.cluster_1 = data.cluster_1.float()
    with pytest.raises(ValueError, match="'cluster' must hold integer"):
        model(data)


def test_logits_do_not_depend_on_the_order_of_the_points():
    torch.manual_seed(0)
    model = HSNClassification(3, 5, channels=(4, 6), max_order=1,
                              rings=RINGS).double().eval()
    with torch.no_grad():
        for p in model.parameters():  # no trivial zero outputs
            p.add_(0.05 * torch.randn_like(p))
    data = two_level_data(1, max_order=1)
    order = torch.randperm(50, generator=torch.Generator().manual_seed(3))
    out = model(data)
    out2 = model(permute_points(data, order))
    assert out.shape == (1, 5)
    assert rel(out2, out) < 1e-10
    # another shape gets other logits: the model is not constant
    assert rel(model(two_level_data(2, max_order=1)), out) > 1e-3


def test_repr():
    model = HSNClassification(3, 5, channels=(4, 6), max_order=2, rings=RINGS)
    assert repr(model) == ('HSNClassification(3, 5, channels=(4, 6), '
                           'max_order=2, rings=4)')


@pytest.mark.parametrize('key,match', MISSING_LEVELS)
def test_missing_levels_are_explained(key, match):
    check_missing_level_is_explained(HSNClassification, key, match)


def make(norm='default'):
    norm = {} if norm == 'default' else {'norm': norm}
    return HSNClassification(3, 5, channels=(4, 6), rings=RINGS, **norm)


def test_training_and_evaluation_compute_the_same_function():
    check_training_equals_evaluation(
        make, [two_level_data(s, max_order=1) for s in (1, 2, 3)])


def test_norm_is_validated_and_per_mesh_by_default():
    check_norm_is_validated(make)
    assert make().norm == 'instance'
    assert make(None).norm is None


def test_compile_and_mixed_precision():
    check_compile_and_precision(HSNClassification, backend='inductor')
