import pytest
import torch
from torch_geometric.data import Data

from tg_intrinsic.transforms import MLSOperators
from tests.symmetry import rotate_frames, rotate_vectors


def plane_cloud(n=60, seed=0):
    """Random points of the z = 0 plane with the frames (x, y, z)."""
    g = torch.Generator().manual_seed(seed)
    xy = torch.rand(n, 2, generator=g, dtype=torch.float64)
    pos = torch.cat([xy, torch.zeros(n, 1, dtype=torch.float64)], 1)
    frame = torch.eye(3, dtype=torch.float64).repeat(n, 1, 1)
    return Data(pos=pos, frame=frame)


def per_centre(values, centre, n):
    return torch.zeros((n, ) + values.shape[1:],
                       dtype=values.dtype).index_add_(0, centre, values)


def test_mls_operators_refuse_neighbourhoods_too_small_to_fit():
    # k = 1 (the point alone) used to give all-zero weights silently
    from tg_intrinsic.geometry import build_mls_operators
    for k in (1, 2):
        with pytest.raises(ValueError, match="'k' must be at least 3"):
            MLSOperators(k=k)
        with pytest.raises(ValueError, match="'k' must be at least 3"):
            build_mls_operators(torch.randn(20, 3), k)
    with pytest.raises(ValueError, match="'regularizer' must be positive"):
        MLSOperators(regularizer=0)
    with pytest.raises(ValueError, match="'kernel_width' must be finite"):
        MLSOperators(kernel_width=float('nan'))
    out = MLSOperators(k=3)(Data(pos=torch.randn(20, 3,
                                                 dtype=torch.float64)))
    assert bool((out.grad_weight.abs().sum(1) > 0).any())


def test_gradient_and_divergence_are_exact_for_quadratics_on_a_plane():
    # the fit is quadratic: with a vanishing regulariser and no
    # normalisation, the gradient of a quadratic and the divergence of a
    # linear field are reproduced at every point
    data = plane_cloud()
    out = MLSOperators(k=10, regularizer=1e-12, normalized=False)(data)
    j, i = out.edge_index
    x, y = data.pos[:, 0], data.pos[:, 1]
    f = x * x + 3 * x * y - y
    grad = per_centre(f[j, None] * out.grad_weight, i, 60)
    assert torch.allclose(grad, torch.stack([2 * x + 3 * y, 3 * x - 1], 1),
                          atol=1e-6)
    field = torch.stack([x - 2 * y, 3 * x + y], 1)  # divergence 1 + 1
    div = per_centre((out.div_weight * field[j]).sum(1), i, 60)
    assert torch.allclose(div, torch.full_like(div, 2.0), atol=1e-6)


def test_constants_have_no_gradient_and_normalisation_is_one_scale():
    data = plane_cloud(seed=1)
    out = MLSOperators(k=10)(data)
    j, i = out.edge_index
    # G 1 = 0 exactly: the constant is not regularised
    assert per_centre(out.grad_weight, i, 60).abs().max() < 1e-12
    # the l-infinity norm max_i sum_j |G_ij| is 1 ...
    norm = per_centre(out.grad_weight.norm(dim=1), i, 60).max()
    assert torch.isclose(norm, torch.tensor(1.0, dtype=torch.float64))
    # ... reached by dividing G and D of the unnormalised operators by
    # one number
    raw = MLSOperators(k=10, normalized=False)(data)
    ratio = raw.grad_weight.norm(dim=1).sum() / out.grad_weight.norm(
        dim=1).sum()
    assert torch.allclose(raw.grad_weight, ratio * out.grad_weight)
    assert torch.allclose(raw.div_weight, ratio * out.div_weight)
    assert not torch.isclose(ratio, torch.tensor(1.0, dtype=torch.float64))


def test_keys_shapes_and_the_recorded_parameters():
    g = torch.Generator().manual_seed(2)
    pos = torch.randn(40, 3, generator=g, dtype=torch.float64)
    data = Data(pos=pos, normal=pos / pos.norm(dim=1, keepdim=True))
    out = MLSOperators(k=8, regularizer=1e-2, kernel_width=2.0,
                       normalized=False)(data)
    j, i = out.edge_index
    assert out.edge_index.dtype == torch.long and j.numel() == 40 * 8
    # k neighbours per centre, the centre itself among them, no repeats
    assert (torch.bincount(i, minlength=40) == 8).all()
    assert int((j == i).sum()) == 40
    assert torch.unique(i * 40 + j).numel() == 40 * 8
    for key in ('grad_weight', 'div_weight'):
        assert out[key].shape == (320, 2) and out[key].dtype == pos.dtype
        assert torch.isfinite(out[key]).all() and out[key].abs().max() > 0
    assert torch.allclose(out.frame[:, 2], data.normal, atol=1e-12)
    assert torch.equal(out.mls_parameters, torch.tensor(
        [[8.0, 1e-2, 2.0, 0.0]], dtype=torch.float64))
    assert 'grad_weight' not in data  # the input is not mutated


def test_turning_the_frames_turns_the_weights():
    data = plane_cloud(seed=3)
    data.pos[:, 2] = 0.3 * data.pos[:, 0] ** 2  # curved a little
    out = MLSOperators(k=10)(Data(pos=data.pos))
    angle = torch.linspace(0, 6, 60, dtype=torch.float64)
    turned = MLSOperators(k=10)(Data(pos=data.pos,
                                     frame=rotate_frames(out.frame, angle)))
    assert torch.equal(turned.edge_index, out.edge_index)
    j, i = out.edge_index
    # G lives in the frame of the centre i, D reads vectors in the frame
    # of the neighbour j
    assert torch.allclose(turned.grad_weight,
                          rotate_vectors(out.grad_weight, angle[i]),
                          atol=1e-10)
    assert torch.allclose(turned.div_weight,
                          rotate_vectors(out.div_weight, angle[j]),
                          atol=1e-10)


def test_the_normalised_operators_do_not_depend_on_the_size():
    data = plane_cloud(seed=4)
    a = MLSOperators(k=10)(data)
    b = MLSOperators(k=10)(Data(pos=250.0 * data.pos, frame=data.frame))
    assert torch.equal(a.edge_index, b.edge_index)
    assert torch.allclose(a.grad_weight, b.grad_weight, atol=1e-10)
    assert torch.allclose(a.div_weight, b.div_weight, atol=1e-10)


def test_examples_of_a_batch_stay_apart():
    a, b = plane_cloud(30, seed=5), plane_cloud(30, seed=6)
    pos = torch.cat([a.pos, b.pos])  # the same square: they overlap
    batch = torch.arange(2).repeat_interleave(30)
    out = MLSOperators(k=6)(Data(pos=pos, frame=torch.cat([a.frame,
                                                           b.frame]),
                                 batch=batch))
    j, i = out.edge_index
    assert torch.equal(batch[j], batch[i])
    # every example gets its own scale and normalisation: as if alone
    alone = MLSOperators(k=6)(a)
    first = i < 30
    assert torch.equal(out.edge_index[:, first], alone.edge_index)
    assert torch.allclose(out.grad_weight[first], alone.grad_weight,
                          atol=1e-12)
    assert torch.allclose(out.div_weight[first], alone.div_weight,
                          atol=1e-12)


def test_bad_input():
    with pytest.raises(ValueError, match="needs point positions"):
        MLSOperators()(Data(x=torch.randn(10, 3)))
    pos = torch.randn(10, 3)
    with pytest.raises(ValueError, match="'data.normal' has 9 rows"):
        MLSOperators(k=4)(Data(pos=pos, normal=pos[:9]))
    with pytest.raises(ValueError, match="'kernel_width' must be positive"):
        MLSOperators(kernel_width=-1.0)
    with pytest.raises(ValueError, match="'k' must be an integer"):
        MLSOperators(k=4.5)
    assert repr(MLSOperators()) == ('MLSOperators(k=20, regularizer=0.001, '
                                    'kernel_width=1.0, normalized=True)')
    assert repr(MLSOperators(k=5, normalized=False)) == (
        'MLSOperators(k=5, regularizer=0.001, kernel_width=1.0, '
        'normalized=False)')
