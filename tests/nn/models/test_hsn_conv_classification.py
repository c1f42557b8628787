import math

import pytest
import torch
from torch_geometric.data import Batch

from tg_intrinsic.nn.models import HSNConvClassification
from tests.conftest import rel
from tests.nn.conftest import RINGS, two_level_data
from tests.nn.models.hsn_checks import (check_compile_and_precision,
                                        MISSING_LEVELS,
                                        check_batched_equals_per_example,
                                        check_gauge_invariance,
                                        check_missing_level_is_explained,
                                        check_norm_is_validated,
                                        check_training_equals_evaluation)


@pytest.mark.parametrize('max_order', [0, 1, 2])
def test_predictions_are_gauge_invariant(max_order):
    check_gauge_invariance(HSNConvClassification, max_order)


def test_batched_equals_per_example():
    check_batched_equals_per_example(HSNConvClassification, (3, 5))


@pytest.mark.parametrize('key,match', MISSING_LEVELS)
def test_missing_levels_are_explained(key, match):
    check_missing_level_is_explained(HSNConvClassification, key, match)


def test_layers_follow_the_paper():
    model = HSNConvClassification(1, 10)
    widths = [(c.in_channels, c.out_channels) for c in model.convs]
    assert widths == [(1, 8), (8, 8), (8, 16), (16, 16), (16, 32), (32, 32)]
    assert (model.out.in_channels, model.out.out_channels) == (32, 10)
    one = HSNConvClassification(1, 10, max_order=0)
    count = lambda m: sum(p.numel() for p in m.parameters())  # noqa: E731
    assert count(one) < count(model)
    assert repr(model) == ('HSNConvClassification(1, 10, channels=(8, 16, '
                           '32), convs_per_level=2, max_order=1, rings=6)')


def test_prebuilt_operators_give_the_same_logits():
    torch.manual_seed(0)
    model = HSNConvClassification(3, 5, channels=(4, 6), max_order=1,
                                  rings=RINGS).double().eval()
    data = Batch.from_data_list([two_level_data(s, max_order=1)
                                 for s in (1, 2)])
    ops = model.operators(data)
    assert rel(model(data, ops), model(data)) < 1e-12
    with pytest.raises(ValueError, match='one dict per level'):
        model(data, ops[:1])


def test_constructor_refusals():
    with pytest.raises(ValueError, match="'in_channels' must be at least 1"):
        HSNConvClassification(0, 5)
    with pytest.raises(ValueError, match="'channels' must hold at least 1"):
        HSNConvClassification(3, 5, channels=())
    with pytest.raises(ValueError, match="'convs_per_level' must be at"):
        HSNConvClassification(3, 5, convs_per_level=0)
    with pytest.raises(ValueError, match="'max_order' must be at least 0"):
        HSNConvClassification(3, 5, max_order=-1)


@pytest.fixture(scope='module')
def digits():
    pytest.importorskip('sklearn')
    from tg_intrinsic.datasets import SphereDigits
    return SphereDigits('test', limit=6, dtype=torch.float64)


@pytest.mark.parametrize('max_order', [0, 1])
def test_turning_the_digit_about_the_axis_keeps_the_logits(digits,
                                                           max_order):
    """The icosphere has a vertex at the pole and is symmetric under turns
    by 72 degrees about it: the turned digit is the same signal on permuted
    vertices whose discs are the same up to a gauge change. Every harmonic
    layer and the magnitudes at the global pool see the same thing, so the
    logits of a one-level network agree to rounding, for one stream (its
    filters are isotropic) and two (equivariant order-1 stream)."""
    from tg_intrinsic.datasets.sphere_digits import rotation_about_z
    torch.manual_seed(0)
    model = HSNConvClassification(1, 10, channels=(4, ), max_order=max_order,
                                  rings=6).double().eval()
    for i in range(2):
        data, turned = digits[i], digits[i]
        turned.x = digits.signal(i, rotation_about_z(2 * math.pi / 5))
        assert rel(turned.x, data.x) > 0.3  # the input really changes
        out = model(data)
        assert rel(model(turned), out) < 1e-9
    # the logits do depend on the digit
    assert rel(model(digits[2]), model(digits[0])) > 1e-3


@pytest.mark.parametrize('max_order', [0, 1])
def test_the_three_level_network_ignores_turns(digits, max_order):
    """The paper's network on nested icosphere levels whose pooling cells
    turns about the pole permute like the vertices (covariant_clusters):
    a turn by 72 degrees keeps the logits to rounding; other angles
    resample the digit, which moves them by a small fraction of how much
    they differ between digits (0.25% measured; with the cells of
    MultiscaleSupports, which break ties by index, up to 30%)."""
    from tg_intrinsic.datasets.sphere_digits import rotation_about_z
    torch.manual_seed(0)
    model = HSNConvClassification(1, 10, max_order=max_order).double()
    model.eval()
    logits = torch.cat([model(digits[i]) for i in range(6)])
    spread = (logits - logits.mean(0)).norm(dim=1).mean()
    for angle, bound in ((2 * math.pi / 5, 1e-9), (2.5, 0.01)):
        for i in range(2):
            turned = digits[i]
            turned.x = digits.signal(i, rotation_about_z(angle))
            assert (model(turned) - logits[i]).norm() < bound * spread


def make(norm='default'):
    norm = {} if norm == 'default' else {'norm': norm}
    return HSNConvClassification(3, 5, channels=(4, 6), rings=RINGS, **norm)


def test_training_and_evaluation_compute_the_same_function():
    check_training_equals_evaluation(
        make, [two_level_data(s, max_order=1) for s in (1, 2, 3)])


def test_norm_is_validated_and_batch_norm_by_default():
    # many digits share one mesh in large batches: batch norm is the
    # default (per-digit normalisation cost 2-18 points on sphere digits)
    check_norm_is_validated(make)
    assert make().norm == 'batch'
    assert make(None).norm is None


def test_compile_and_mixed_precision():
    check_compile_and_precision(HSNConvClassification)
