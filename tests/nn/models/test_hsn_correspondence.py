import pytest
import torch

from tg_intrinsic.nn.models import HSNCorrespondence
from tests.conftest import rel
from tests.nn.conftest import RINGS, two_level_data
from tests.nn.models.hsn_checks import (check_compile_and_precision,
                                        check_norm_is_validated,
                                        check_training_equals_evaluation)


def test_logits_over_the_template_and_gauge_invariance():
    torch.manual_seed(0)
    model = HSNCorrespondence(3, 40, channels=(4, 6), rings=RINGS,
                              hidden=16).double().eval()
    out = model(two_level_data(1, max_order=1))
    assert out.shape == (50, 40)
    gen = torch.Generator().manual_seed(9)
    angle0 = torch.rand(50, dtype=torch.float64, generator=gen) * 6
    angle1 = torch.rand(12, dtype=torch.float64, generator=gen) * 6
    out2 = model(two_level_data(1, angle0=angle0, angle1=angle1,
                                max_order=1))
    assert rel(out2, out) < 1e-8
    # different points get different predictions: not a constant head
    assert rel(out[1:], out[:1].expand(49, -1)) > 1e-3


def test_dropout_only_in_training():
    torch.manual_seed(0)
    model = HSNCorrespondence(3, 40, channels=(4, 6), rings=RINGS,
                              hidden=16, dropout=0.5).double()
    data = two_level_data(1, max_order=1)
    model.eval()
    assert rel(model(data), model(data)) == 0
    model.train()
    torch.manual_seed(1)
    a = model(data)
    torch.manual_seed(2)
    assert rel(model(data), a) > 1e-3


def test_cross_entropy_training_fits_a_template():
    # one shape against itself: the labels are the vertex indices, and a
    # few Adam steps must fit them better than chance
    torch.manual_seed(0)
    data = two_level_data(1, max_order=1)
    model = HSNCorrespondence(3, 50, channels=(8, 8), rings=RINGS,
                              hidden=32, dropout=0.0).double()
    opt = torch.optim.Adam(model.parameters(), lr=1e-2)
    target = torch.arange(50)
    for _ in range(40):
        opt.zero_grad()
        loss = torch.nn.functional.cross_entropy(model(data), target)
        loss.backward()
        opt.step()
    model.eval()
    accuracy = (model(data).argmax(1) == target).double().mean()
    assert accuracy > 0.5


def test_bad_input_is_explained():
    with pytest.raises(ValueError, match="'num_template_vertices' must be"):
        HSNCorrespondence(3, 0)
    with pytest.raises(ValueError, match="'hidden' must be at least 1"):
        HSNCorrespondence(3, 10, hidden=0)
    with pytest.raises(ValueError, match=r"'dropout' must be in \[0, 1\)"):
        HSNCorrespondence(3, 10, dropout=1.0)


def test_repr():
    model = HSNCorrespondence(3, 40, channels=(4, 6), rings=RINGS)
    assert repr(model) == ('HSNCorrespondence(3, 40, channels=(4, 6), '
                           'max_order=1, rings=4, hidden=256, '
                           'dropout=0.5)')


def make(norm='default'):
    norm = {} if norm == 'default' else {'norm': norm}
    return HSNCorrespondence(3, 7, channels=(4, 6), rings=RINGS, hidden=8,
                             **norm)


def test_training_and_evaluation_compute_the_same_function():
    check_training_equals_evaluation(
        make, [two_level_data(s, max_order=1) for s in (1, 2, 3)])


def test_norm_is_validated_and_per_mesh_by_default():
    check_norm_is_validated(make)
    assert make().backbone.norm == 'instance'
    assert make(None).backbone.norm is None


def test_compile_and_mixed_precision():
    check_compile_and_precision(HSNCorrespondence)
