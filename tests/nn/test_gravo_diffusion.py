"""GravoDiffusion: gradchecks in the times and the features (float64, the
solves at tol=1e-12), Gravo MG against the direct peer and a dense
oracle on meshes and point clouds, batches, learning a time from 0, the
cached operators, bad input."""
import copy
import pickle

import numpy as np
import pytest
import torch
from torch.func import functional_call
from torch_geometric.data import Batch, Data

from tg_intrinsic.nn import GravoDiffusion
from tg_intrinsic.solvers import GravoMG, stiffness_and_mass

from tests.conftest import fibonacci_sphere, icosphere

# gradcheck differentiates by finite differences (eps=1e-6): the solves
# must be far more accurate than that
GRADCHECK_TOL = 1e-12


def features(n, channels, seed=0, dtype=torch.float64):
    g = torch.Generator().manual_seed(seed)
    return torch.randn(n, channels, generator=g, dtype=dtype)


def dense_diffusion(data, x, times):
    """(M + t_c S)^-1 M x_c with dense numpy solves."""
    S, m = stiffness_and_mass(data)
    return torch.from_numpy(np.stack([
        np.linalg.solve(np.diag(m) + t * S.toarray(), m * c)
        for c, t in zip(x.detach().double().numpy().T, times)], 1))


def cloud(n=200, seed=0):
    g = torch.Generator().manual_seed(seed)
    pos = fibonacci_sphere(n) * (1 + 0.1 * torch.rand(n, 1, generator=g,
                                                      dtype=torch.float64))
    return Data(pos=pos)


@pytest.mark.parametrize('solver', ['gravo', 'direct'])
def test_gradcheck_in_times_and_features(solver):
    pos, face = icosphere(1)  # 42 vertices, one coarse level of 4
    data = Data(pos=pos, face=face)
    layer = GravoDiffusion(3, solver=solver, tol=GRADCHECK_TOL,
                           lower_bound=4)
    if solver == 'gravo':
        assert len(layer.operators(data)[2].prolongations) == 1
    x = features(pos.size(0), 3).requires_grad_()
    # away from theta = 0, where |theta| has a kink; two equal times share
    # a solve and still get their own gradients
    theta = torch.tensor([0.05, -0.2, 0.05], dtype=torch.float64,
                         requires_grad=True)
    assert torch.autograd.gradcheck(
        lambda x, theta: functional_call(
            layer, {'diffusion_time': theta}, (x, data)), (x, theta))


@pytest.mark.parametrize('surface', ['mesh', 'cloud'])
def test_gravo_equals_direct_and_a_dense_solve(surface):
    if surface == 'mesh':
        pos, face = icosphere(3)  # 642 vertices
        data = Data(pos=pos, face=face)
    else:
        data = cloud(600)  # the robust point-cloud Laplacian
    times = [0.0, 1e-3, 1e-2, 5e-2]
    x = features(data.pos.size(0), 4, seed=1)
    exact = dense_diffusion(data, x, times)
    out, grads = {}, {}
    for solver in ('gravo', 'direct'):
        layer = GravoDiffusion(4, solver=solver, tol=1e-10, lower_bound=50)
        with torch.no_grad():
            layer.diffusion_time.copy_(torch.tensor(times))
        inputs = x.clone().requires_grad_()
        out[solver] = layer(inputs, data)
        out[solver].square().sum().backward()
        grads[solver] = (inputs.grad, layer.diffusion_time.grad)
        assert (out[solver] - exact).abs().max() < 1e-8 * exact.abs().max()
    gravo = layer.operators(data)  # (the direct layer builds none)
    assert gravo[2] is None
    assert len(GravoDiffusion(4, lower_bound=50).operators(data)[2]
               .prolongations) >= 1  # cycles, not a direct solve
    for g, d in zip(grads['gravo'], grads['direct']):
        assert (g - d).abs().max() < 1e-7 * d.abs().max()


def test_learns_a_time_from_zero():
    # |theta| with derivative +1 at 0: a time initialised at 0 grows (with
    # the derivative 0 of torch.abs it would stay 0 for ever)
    pos, face = icosphere(2)
    data = Data(pos=pos, face=face)
    x = features(pos.size(0), 2, seed=2)
    true_times = [0.02, 0.1]
    target = dense_diffusion(data, x, true_times)
    layer = GravoDiffusion(2, lower_bound=10)
    assert torch.equal(layer.time, torch.zeros(2))
    optimizer = torch.optim.Adam(layer.parameters(), lr=0.01)
    for _ in range(40):
        optimizer.zero_grad()
        loss = (layer(x.float(), data) - target.float()).square().mean()
        loss.backward()
        optimizer.step()
    learned = layer.time.detach().double()
    assert (learned - torch.tensor(true_times)).abs().max() < \
        0.2 * max(true_times)
    assert learned[1] > learned[0] > 0.005


def test_batches_equal_examples_alone():
    for first, second in (
            (cloud(150, seed=3), cloud(180, seed=4)),
            (Data(pos=icosphere(2)[0], face=icosphere(2)[1]),
             Data(pos=icosphere(1)[0] + 0.1, face=icosphere(1)[1]))):
        batch = Batch.from_data_list([first, second])
        layer = GravoDiffusion(2, tol=1e-10, lower_bound=10)
        with torch.no_grad():
            layer.diffusion_time.copy_(torch.tensor([0.01, 0.05]))
        x = features(batch.num_nodes, 2, seed=5)
        together = layer(x, batch)
        n = first.num_nodes
        alone = torch.cat([layer(x[:n], first), layer(x[n:], second)])
        assert (together - alone).abs().max() < 1e-8 * alone.abs().max()


def test_precomputed_operators_and_the_cache():
    pos, face = icosphere(2)
    data = Data(pos=pos, face=face)
    layer = GravoDiffusion(2, init_time=0.01, lower_bound=10)
    S, m, gravo = layer.operators(data)
    # built once per surface
    assert layer.operators(data)[2] is gravo
    moved = Data(pos=pos * 2, face=face)
    assert layer.operators(moved)[2] is not gravo
    x = features(pos.size(0), 2)
    out = layer(x, data)
    assert torch.equal(layer(x, stiffness=S, mass=m, gravo=gravo), out)
    assert torch.equal(layer(x, data, stiffness=S, mass=torch.from_numpy(m)),
                       out)
    # a prebuilt hierarchy from elsewhere gives the same within tolerance
    other = GravoMG.from_mesh(pos, face, lower_bound=20)
    assert torch.allclose(layer(x, stiffness=S, mass=m, gravo=other), out,
                          rtol=0,
                          atol=1e-6 * float(out.detach().abs().max()))
    direct = GravoDiffusion(2, solver='direct', init_time=0.01)
    assert torch.allclose(direct(x, stiffness=S, mass=m), out, rtol=0,
                          atol=1e-6 * float(out.detach().abs().max()))


def test_float32_and_the_device(device):
    pos, face = icosphere(2)
    data = Data(pos=pos.to(device), face=face.to(device))
    layer = GravoDiffusion(3, init_time=0.01, lower_bound=10).to(device)
    x = features(pos.size(0), 3, dtype=torch.float32).to(device)
    x.requires_grad_()
    out = layer(x, data)
    assert out.dtype == torch.float32 and out.device == x.device
    out.sum().backward()
    assert x.grad.device == x.device and x.grad.dtype == torch.float32
    assert layer.diffusion_time.grad.device == x.device
    reference = GravoDiffusion(3, init_time=0.01, lower_bound=10)(
        x.detach().cpu().double(), Data(pos=pos, face=face))
    assert torch.allclose(out.detach().cpu().double(), reference,
                          atol=1e-5)


def test_repr_reset_and_copies():
    layer = GravoDiffusion(4, solver='direct', init_time=0.5, tol=1e-9)
    assert repr(layer) == "GravoDiffusion(4, solver='direct', tol=1e-09)"
    assert list(layer.state_dict()) == ['diffusion_time']
    with torch.no_grad():
        layer.diffusion_time.fill_(-3.0)
    assert torch.equal(layer.time, torch.full((4, ), 3.0))
    layer.reset_parameters()
    assert torch.equal(layer.diffusion_time.detach(),
                       torch.full((4, ), 0.5))
    # the cached LU factors are not copied, and rebuilt
    pos, face = icosphere(1)
    data = Data(pos=pos, face=face)
    x = features(pos.size(0), 4)
    out = layer(x, data)
    for clone in (copy.deepcopy(layer), pickle.loads(pickle.dumps(layer))):
        assert torch.equal(clone(x, data), out)


def test_bad_input():
    pos, face = icosphere(1)
    data = Data(pos=pos, face=face)
    layer = GravoDiffusion(2, lower_bound=4)
    x = features(pos.size(0), 2)
    with pytest.raises(ValueError, match=r"shape \[N, C\] = \[N, 2\].*"
                       r"x.unsqueeze\(1\)"):
        layer(x[:, 0], data)
    with pytest.raises(ValueError, match=r"3 channels but the layer was "
                       r"built with channels=2.*GravoDiffusion\(3\)"):
        layer(features(pos.size(0), 3), data)
    with pytest.raises(ValueError, match="'x' has 10 rows but there are 42 "
                       "nodes"):
        layer(x[:10], data)
    bad = x.clone()
    bad[5, 1] = float('nan')
    with pytest.raises(ValueError, match="'x' contains NaN.*repair"):
        layer(bad, data)
    with pytest.raises(ValueError, match='float tensor'):
        layer(x.long(), data)
    moved = pos.clone()
    moved[3, 0] = float('inf')
    with pytest.raises(ValueError, match="'pos' contains NaN or infinite"):
        layer(x, Data(pos=moved, face=face))
    with pytest.raises(ValueError, match='nothing to diffuse on'):
        layer(x)
    S, m = stiffness_and_mass(data)
    with pytest.raises(ValueError, match="pass both 'stiffness' and 'mass'"):
        layer(x, stiffness=S)
    with pytest.raises(ValueError, match="solver='gravo' needs a hierarchy"):
        layer(x, stiffness=S, mass=m)
    with pytest.raises(ValueError, match="solver='direct'; build the layer "
                       "with solver='gravo'"):
        GravoDiffusion(2, solver='direct')(
            x, data, gravo=GravoMG.from_mesh(pos, face, lower_bound=4))
    with pytest.raises(ValueError, match='too small for the robust'):
        layer(features(20, 2), cloud(20))
    with torch.no_grad():
        layer.diffusion_time[0] = float('nan')
    with pytest.raises(ValueError, match='smaller learning rate'):
        layer(x, data)
    for kwargs, name in ((dict(channels=0), 'channels'),
                         (dict(channels=2, solver='cg'), 'solver'),
                         (dict(channels=2, init_time=-1.0), 'init_time'),
                         (dict(channels=2, tol=0.0), 'tol')):
        with pytest.raises(ValueError, match=name):
            GravoDiffusion(**kwargs)
