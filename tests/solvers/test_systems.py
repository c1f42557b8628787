"""smooth / poisson against scipy's direct solves, on a mesh (cotan), a
non-manifold mesh and a point cloud (robust Laplacian); the conformal flow
against the recurrence solved directly and against its analytic limits (a
sphere stays one, an ellipsoid becomes one); bad input."""
import re

import numpy as np
import pytest
import scipy.sparse as sp
import torch
from scipy.sparse.linalg import spsolve
from torch_geometric.data import Data

from tg_intrinsic.geometry import lumped_mass
from tg_intrinsic.solvers import (ConvergenceWarning, GravoMG, conformal_flow,
                                  diffuse, poisson, smooth,
                                  stiffness_and_mass)

from tests.conftest import icosphere


def direct(matrix, m, y):
    y = y.numpy().reshape(m.size, -1)
    return np.stack([spsolve(matrix.tocsc(), m * c) for c in y.T], 1)


def sphere_data():
    pos, face = icosphere(5)
    g = torch.Generator().manual_seed(0)
    return Data(pos=pos, face=face,
                x=torch.randn(pos.size(0), 3, generator=g,
                              dtype=torch.float64))


def test_smooth_and_poisson_match_direct_solves():
    data = sphere_data()
    S, m = stiffness_and_mass(data)
    assert np.abs(S @ np.ones(m.size)).max() < 1e-10
    assert abs(m.sum() - 4 * np.pi) < 0.05
    out = smooth(data, 1e-2)
    assert out.shape == data.x.shape and out.dtype == data.x.dtype
    exact = direct(sp.diags(m) + 1e-2 * S, m, data.x)
    assert np.abs(out.numpy() - exact).max() < 1e-6 * np.abs(exact).max()
    # Smoothing damps the signal.
    assert out.norm() < data.x.norm()
    out = poisson(data, 1.0, y=data.x[:, 0])
    exact = direct(S + sp.diags(m), m, data.x[:, 0])[:, 0]
    assert out.shape == (data.x.size(0), )
    assert np.abs(out.numpy() - exact).max() < 1e-6 * np.abs(exact).max()


def test_robust_laplacian_for_clouds_and_non_manifold_meshes():
    data = sphere_data()
    cloud = Data(pos=data.pos, x=data.x)
    S, m = stiffness_and_mass(cloud)
    assert abs(m.sum() - 4 * np.pi) < 0.2
    out = smooth(cloud, 1e-2)
    exact = direct(sp.diags(m) + 1e-2 * S, m, cloud.x)
    assert np.abs(out.numpy() - exact).max() < 1e-6 * np.abs(exact).max()
    # A fin: one edge shared by three triangles.
    pos = torch.cat([data.pos, torch.tensor([[0.0, 0.0, 2.0]],
                                            dtype=torch.float64)])
    e = data.face[:, 0]
    face = torch.cat([data.face, torch.tensor([[e[0]], [e[1]],
                                               [pos.size(0) - 1]])], 1)
    fin = Data(pos=pos, face=face,
               x=torch.ones(pos.size(0), dtype=torch.float64))
    S, m = stiffness_and_mass(fin)  # robust, chosen automatically
    assert np.abs(S @ np.ones(m.size)).max() < 1e-10
    out = smooth(fin, 1e-2)
    assert torch.allclose(out, fin.x, atol=1e-6)  # constants are kept


def test_bad_input():
    data = sphere_data()
    with pytest.raises(ValueError, match='alpha'):
        smooth(data, 0.0)
    with pytest.raises(ValueError, match='singular'):
        poisson(data, 0.0)
    with pytest.raises(ValueError, match='rows'):
        smooth(data, 1e-2, y=data.x[:5])
    with pytest.raises(ValueError, match='nothing'):
        smooth(Data(pos=data.pos, face=data.face), 1e-2)


def small_data(subdivisions=3, channels=3):
    pos, face = icosphere(subdivisions)
    g = torch.Generator().manual_seed(1)
    return Data(pos=pos, face=face,
                x=torch.randn(pos.size(0), channels, generator=g,
                              dtype=torch.float64))


def test_bilaplacian_smoothing_matches_a_direct_solve():
    from tg_intrinsic.transforms import GravoHierarchy
    data = small_data()
    S, m = stiffness_and_mass(data)
    alpha, beta = 1e-2, 1e-3
    A = sp.diags(m) + alpha * S + beta * S @ sp.diags(1 / m) @ S
    exact = direct(A, m, data.x)
    # on a real hierarchy (642 points, two coarse levels), not a direct
    # solve
    solver = GravoMG.from_data(GravoHierarchy(lower_bound=20)(data))
    out = smooth(data, alpha, beta=beta, solver=solver)
    assert solver.info.direct is None and solver.info.iterations > 1
    assert solver.info.converged and solver.info.residuals[-1] < 1e-8
    assert np.abs(out.numpy() - exact).max() < 1e-6 * np.abs(exact).max()
    # the bi-Laplacian term damps more than the Laplacian one alone
    assert out.norm() < smooth(data, alpha, lower_bound=20).norm()
    # alpha may be zero when beta is positive
    exact = direct(sp.diags(m) + beta * S @ sp.diags(1 / m) @ S, m, data.x)
    out = smooth(data, 0.0, beta=beta, lower_bound=20)
    assert np.abs(out.numpy() - exact).max() < 1e-6 * np.abs(exact).max()


def test_channels_are_one_block_solve_equal_to_per_channel_solves():
    from tg_intrinsic.transforms import GravoHierarchy
    data = small_data(channels=4)
    hierarchy = GravoHierarchy(lower_bound=20)(data)
    solver = GravoMG.from_data(hierarchy)
    for problem, weight in ((smooth, 1e-2), (poisson, 1.0)):
        block = problem(data, weight, solver=solver, tol=1e-10)
        info = solver.info
        # one solve: the residual history is the worst channel's
        assert info.converged and info.iterations == len(info.residuals)
        columns = torch.stack([problem(data, weight, y=data.x[:, k],
                                       solver=solver, tol=1e-10)
                               for k in range(4)], 1)
        assert block.shape == data.x.shape
        assert torch.allclose(block, columns, rtol=0, atol=1e-8 * float(
            columns.abs().max()))


def test_hierarchy_options_are_used_when_built_inside():
    import warnings
    data = small_data(channels=1)
    # below the lower bound: one direct solve, nothing to warn about
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        smooth(data, 1e-2, lower_bound=5000, max_iter=1)
    # with coarse levels one cycle does not reach 1e-8: it warns
    with pytest.warns(ConvergenceWarning, match='max_iter=1 cycles'):
        smooth(data, 1e-2, lower_bound=20, ratio=4.0, max_iter=1)
    for cycle in ('W', 'F'):
        out = poisson(data, 1.0, lower_bound=20, cycle=cycle)
        S, m = stiffness_and_mass(data)
        exact = direct(S + sp.diags(m), m, data.x)
        assert np.abs(out.numpy() - exact).max() < 1e-6 * np.abs(exact).max()


def test_bad_weights():
    data = small_data(2)
    for kwargs, name in ((dict(alpha=-1.0), 'alpha'),
                         (dict(alpha=float('nan')), 'alpha'),
                         (dict(alpha=1e-2, beta=-1.0), 'beta'),
                         (dict(alpha=0.0, beta=0.0), 'alpha')):
        with pytest.raises(ValueError, match=name):
            smooth(data, **kwargs)
    with pytest.raises(ValueError, match='eta'):
        poisson(data, float('inf'))
    bad = data.x.clone()
    bad[3, 0] = float('nan')
    with pytest.raises(ValueError, match='NaN'):
        smooth(data, 1e-2, y=bad)


@pytest.mark.parametrize('scale', [1e-8, 1e8])
def test_extreme_scales_with_scaled_weights(scale):
    # alpha (area) and eta (1 / area) scale with the surface: then the
    # smoothed signal is the same at every scale, and the Poisson solution
    # (S x = M y: x scales like the area) is the same up to the area
    data = small_data(channels=1)
    scaled = data.clone()
    scaled.pos = data.pos * scale
    for solve, weight, power, out_power in ((smooth, 1e-2, 2, 0),
                                            (poisson, 1.0, -2, 2)):
        reference = solve(data, weight)
        out = solve(scaled, weight * scale ** power) / scale ** out_power
        assert torch.allclose(out, reference, rtol=1e-6, atol=1e-9)
    # unscaled weights at 1e-8 make the mass term vanish under rounding:
    # a clear error that names the scale, the usable bound and the remedy,
    # and the bound it names works
    if scale < 1:
        with pytest.raises(ValueError, match=r"'eta' = 1 is too small .*"
                           r"total area .*rescale the surface") as error:
            poisson(scaled, 1.0)
        bound = float(re.search(r"at least (\S+?),", str(error.value))[1])
        assert poisson(scaled, 2 * bound).isfinite().all()


def test_a_weight_far_too_large_names_the_bound_not_a_rescaling():
    # --smooth 1e300 on a unit-size surface: the weight is the mistake
    data = small_data(channels=1)
    with pytest.raises(ValueError, match=r"'alpha' = 1e\+300 is too large"
                       r".*use 'alpha' at most") as error:
        smooth(data, 1e300)
    assert 'rescale' not in str(error.value)
    bound = float(re.search(r"at most (\S+)$", str(error.value))[1])
    assert smooth(data, bound / 2).isfinite().all()


def test_pcg_smoothing_matches_a_direct_solve():
    data = small_data(4)
    S, m = stiffness_and_mass(data)
    alpha, beta = 1e-3, 1e-5
    exact = direct(sp.diags(m) + alpha * S + beta * S @ sp.diags(1 / m) @ S,
                   m, data.x)
    solver = GravoMG.from_points(data.pos, data.face.t().reshape(-1, 2).t(),
                                 lower_bound=50)
    for method in ('cycles', 'pcg'):
        out = smooth(data, alpha, beta=beta, solver=solver, method=method)
        assert solver.info.converged and solver.info.direct is None
        assert np.abs(out.numpy() - exact).max() < 1e-6 * np.abs(exact).max()


def test_split_bilaplacian_smoothing_is_the_full_solve():
    data = small_data(4)
    S, m = stiffness_and_mass(data)
    alpha, beta = 3e-3, 1e-6  # alpha^2 >= 4 beta: real factors
    exact = direct(sp.diags(m) + alpha * S + beta * S @ sp.diags(1 / m) @ S,
                   m, data.x)
    solver = GravoMG.from_points(data.pos, data.face.t().reshape(-1, 2).t(),
                                 lower_bound=50)
    runs = {}
    for split in (None, True, False):
        out = smooth(data, alpha, beta=beta, solver=solver, split=split)
        assert np.abs(out.numpy() - exact).max() < 1e-6 * np.abs(exact).max()
        runs[split] = solver.info
    # the default splits: two Laplace-type solves whose counts add up
    assert runs[None].iterations == runs[True].iterations
    info = runs[True]
    assert info.converged and len(info.residuals) == info.iterations
    # two solves, each down to tol from a residual of 1
    assert sum(r < 1e-8 for r in info.residuals) == 2
    assert all(a < b for a, b in zip(info.times, info.times[1:]))
    with pytest.raises(ValueError, match=r'split=True needs alpha\^2'):
        smooth(data, 1e-3, beta=1e-6, solver=solver, split=True)


def ellipsoid(subdivisions=3, axes=(1.0, 0.6, 0.3)):
    pos, face = icosphere(subdivisions)
    return Data(pos=pos * torch.tensor(axes, dtype=pos.dtype), face=face)


def roundness(pos):
    """Spread of the distances to the centroid, relative to their mean."""
    r = (pos - pos.mean(0)).norm(dim=1)
    return float(r.std() / r.mean())


def test_conformal_flow_is_the_recurrence_solved_directly():
    data = ellipsoid()
    S, m = stiffness_and_mass(data)
    area, p = m.sum(), data.pos.numpy()
    centroid = m @ p / area
    infos = []
    flow = conformal_flow(data, step=0.05, steps=4, lower_bound=50,
                          callback=lambda t, info: infos.append((t, info)))
    assert flow.shape == (5, ) + tuple(data.pos.shape)
    assert flow.dtype == data.pos.dtype
    assert torch.equal(flow[0], data.pos)
    # the oracle: each step a direct solve of (M_t + h S_0) p = M_t p_t,
    # then the centroid put back and the area rescaled
    for t in range(1, 5):
        p = np.stack([spsolve((sp.diags(m) + 0.05 * S).tocsc(), m * c)
                      for c in p.T], 1)
        m = lumped_mass(torch.from_numpy(p), data.face).numpy()
        scale = np.sqrt(area / m.sum())
        p = (p - m @ p / m.sum()) * scale + centroid
        m = m * scale ** 2
        assert np.abs(flow[t].numpy() - p).max() < 1e-6
    assert [t for t, _ in infos] == [1, 2, 3, 4]
    assert all(info.converged and info.direct is None for _, info in infos)


def test_conformal_flow_rounds_an_ellipsoid_and_keeps_a_sphere():
    data = ellipsoid()
    flow = conformal_flow(data, step=0.2, steps=12, lower_bound=50)
    assert roundness(data.pos) > 0.2 and roundness(flow[-1]) < 0.02
    area = lumped_mass(data.pos, data.face).sum()
    for p in flow:
        assert abs(float(lumped_mass(p, data.face).sum() / area) - 1) < 1e-9
    # without the normalisation the surface shrinks
    shrunk = conformal_flow(data, step=0.2, steps=2, normalize=False,
                            lower_bound=50)
    assert lumped_mass(shrunk[-1], data.face).sum() < 0.9 * area
    # a round sphere is a fixed point (up to its discretisation)
    pos, face = icosphere(3)
    flow = conformal_flow(Data(pos=pos, face=face), step=0.2, steps=3,
                          lower_bound=50)
    # (the vertices slide along it a little, by 2e-3 of its radius)
    assert roundness(flow[-1]) < 1e-3
    assert (flow[-1] - pos).norm(dim=1).max() < 5e-3


def test_conformal_flow_bad_input():
    data = ellipsoid(2)
    with pytest.raises(ValueError, match="needs a triangle mesh"):
        conformal_flow(Data(pos=data.pos), step=0.1)
    for step in (0, -1.0, float('nan'), True):
        with pytest.raises(ValueError, match="'step' must be a positive"):
            conformal_flow(data, step=step)
    with pytest.raises(ValueError, match='steps'):
        conformal_flow(data, step=0.1, steps=0)
    with pytest.raises(ValueError,
                       match=r"'step' = 0.1 is too large .*rescale"):
        conformal_flow(Data(pos=data.pos * 1e-8, face=data.face), step=0.1)


def test_a_point_cloud_too_small_for_the_robust_laplacian():
    data = Data(pos=torch.randn(30, 3, dtype=torch.float64))
    with pytest.raises(ValueError, match=r"point cloud of 30 points is too "
                                         r"small .* at least 31 points"):
        stiffness_and_mass(data)
    data.pos = torch.randn(31, 3, dtype=torch.float64)
    assert stiffness_and_mass(data)[0].shape == (31, 31)


# ---------------------------------------------------------------- gradients
# The gradchecks solve to tol=1e-12: the solver's error (tol times the
# condition number, relative) must stay well below gradcheck's finite-
# difference error (eps=1e-6, atol=1e-5, rtol=1e-3). On a 42-vertex
# icosphere with one coarse level of 4 points, so the cycles, not a direct
# solve, are differentiated.
GRADCHECK_TOL = 1e-12


def tiny_data(channels=2):
    pos, face = icosphere(1)
    g = torch.Generator().manual_seed(2)
    data = Data(pos=pos, face=face,
                x=torch.randn(pos.size(0), channels, generator=g,
                              dtype=torch.float64))
    return data, GravoMG.from_mesh(pos, face, lower_bound=4)


def test_gradients_match_dense_solves():
    # before the adjoint solves the results had no gradient at all
    data = small_data(channels=3)
    S, m = stiffness_and_mass(data)
    S_dense = S.toarray()
    solver = GravoMG.from_mesh(data.pos, data.face, lower_bound=20)
    weights = torch.randn(data.x.shape, dtype=torch.float64,
                          generator=torch.Generator().manual_seed(3))
    for problem, weight, matrix in (
            (smooth, 1e-2, np.diag(m) + 1e-2 * S_dense),
            (poisson, 1.0, S_dense + np.diag(m))):
        y = data.x.clone().requires_grad_()
        out = problem(data, weight, y=y, solver=solver, tol=1e-10)
        assert solver.info.direct is None  # cycles, not an LU
        assert out.requires_grad
        # with or without grad: the same numbers
        assert torch.equal(out.detach(), problem(data, weight, y=data.x,
                                                 solver=solver, tol=1e-10))
        (out * weights).sum().backward()
        # x = A^-1 M y, so dL/dy = M A^-T w
        exact = m[:, None] * np.linalg.solve(matrix.T, weights.numpy())
        assert np.abs(y.grad.numpy() - exact).max() < \
            1e-8 * np.abs(exact).max()
    # dL/dalpha = -lambda^T S x with lambda = A^-T w
    alpha = torch.tensor(1e-2, dtype=torch.float64, requires_grad=True)
    out = smooth(data, alpha, solver=solver, tol=1e-10)
    (out * weights).sum().backward()
    A = np.diag(m) + 1e-2 * S_dense
    x = np.linalg.solve(A, m[:, None] * data.x.numpy())
    multiplier = np.linalg.solve(A.T, weights.numpy())
    exact = -(multiplier * (S_dense @ x)).sum()
    assert abs(float(alpha.grad) - exact) < 1e-8 * abs(exact)
    assert torch.equal(out.detach(), smooth(data, 1e-2, solver=solver,
                                            tol=1e-10))


def test_gradcheck_smooth_and_poisson_in_y():
    # one channel: every input and output costs a solve (several channels
    # are checked in test_gradients_match_dense_solves)
    data, solver = tiny_data(channels=1)
    y = data.x.clone().requires_grad_()
    for problem, weight in ((smooth, 1e-1), (poisson, 3.0)):
        problem(data, weight, solver=solver, tol=GRADCHECK_TOL)
        assert solver.info.direct is None and solver.info.iterations > 1
        assert torch.autograd.gradcheck(
            lambda y: problem(data, weight, y=y, solver=solver,
                              tol=GRADCHECK_TOL), (y, ))


@pytest.mark.parametrize('beta, split', [(0.0, None), (1e-4, None),
                                         (1e-4, False)])
def test_gradcheck_smooth_in_alpha(beta, split):
    # beta > 0: through both factors of the split solve, or the full
    # bi-Laplacian system (with PCG)
    data, solver = tiny_data(channels=1)
    alpha = torch.tensor(0.05, dtype=torch.float64, requires_grad=True)
    method = 'pcg' if split is False else 'cycles'
    assert torch.autograd.gradcheck(
        lambda a: smooth(data, a, beta=beta, split=split, solver=solver,
                         tol=GRADCHECK_TOL, method=method), (alpha, ))


def test_learned_alpha_on_float32_and_the_double_root():
    data, solver = tiny_data()
    y = data.x.float().requires_grad_()
    alpha = torch.tensor([0.05], requires_grad=True)
    out = smooth(data, alpha, y=y, solver=solver)
    assert out.dtype == torch.float32 and out.requires_grad
    out.square().sum().backward()
    # smoothing more shrinks the signal: the loss falls with alpha
    assert alpha.grad.dtype == torch.float32 and alpha.grad.shape == (1, )
    assert float(alpha.grad) < 0 and y.grad.dtype == torch.float32
    # at alpha^2 = 4 beta the factors' derivative is infinite: the full
    # system gives the finite gradient, equal to the one just beside it
    grads = []
    for a in (0.02, 0.02 * (1 + 1e-7)):
        alpha = torch.tensor(a, dtype=torch.float64, requires_grad=True)
        smooth(data, alpha, beta=1e-4, solver=solver,
               tol=GRADCHECK_TOL).square().sum().backward()
        grads.append(float(alpha.grad))
    assert np.isfinite(grads).all()
    assert abs(grads[0] - grads[1]) < 1e-5 * abs(grads[0])
    with pytest.raises(ValueError, match='differentiable alpha'):
        smooth(data, torch.tensor(0.02, dtype=torch.float64,
                                  requires_grad=True), beta=1e-4,
               solver=solver, split=True)
    with pytest.raises(ValueError, match='one floating-point value'):
        smooth(data, torch.tensor([0.1, 0.2]), solver=solver)


def dense_diffusion(S, m, y, times):
    return np.stack([np.linalg.solve(np.diag(m) + t * S.toarray(), m * c)
                     for c, t in zip(y.T, times)], 1)


def test_diffuse_matches_dense_solves_per_channel():
    data = small_data(channels=4)
    S, m = stiffness_and_mass(data)
    times = [1e-2, 0.0, 1e-3, 1e-2]
    exact = dense_diffusion(S, m, data.x.numpy(), times)
    solver = GravoMG.from_mesh(data.pos, data.face, lower_bound=20)
    solver.cache_size = 3
    for which in ('direct', solver):
        out = diffuse(S, m, data.x, torch.tensor(times, dtype=torch.float64),
                      which, tol=1e-10)
        assert out.shape == data.x.shape and out.dtype == data.x.dtype
        assert np.abs(out.numpy() - exact).max() < 1e-8 * np.abs(
            exact).max()
    assert solver.info.converged and solver.info.direct is None
    # the two equal times share a block solve: three matrices, all three
    # still set up in a cache of three
    for t in set(times):
        solver.setup((sp.diags(m) + t * S).tocsr())
        assert solver.info.cached
    # one number: every channel with it, as smooth does
    out = diffuse(S, m, data.x, 1e-2, 'direct')
    assert torch.allclose(out, smooth(data, 1e-2, tol=1e-12), rtol=0,
                          atol=1e-9)
    # (N) signals and float32
    out = diffuse(S, m, data.x[:, 0].float(), 1e-2, 'direct')
    assert out.shape == (m.size, ) and out.dtype == torch.float32


@pytest.mark.parametrize('which', ['direct', 'gravo'])
def test_gradcheck_diffuse_in_y_and_times(which):
    data, solver = tiny_data(channels=3)
    S, m = stiffness_and_mass(data)
    solver = solver if which == 'gravo' else 'direct'
    y = data.x.clone().requires_grad_()
    times = torch.tensor([0.1, 0.03, 0.1], dtype=torch.float64,
                         requires_grad=True)
    assert torch.autograd.gradcheck(
        lambda y, t: diffuse(S, m, y, t, solver, tol=GRADCHECK_TOL),
        (y, times))
    # one time shared by all channels collects their gradients
    shared = torch.tensor(0.1, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(
        lambda t: diffuse(S, m, data.x, t, solver, tol=GRADCHECK_TOL),
        (shared, ))


def test_diffuse_bad_input():
    data, solver = tiny_data()
    S, m = stiffness_and_mass(data)
    y = data.x
    with pytest.raises(ValueError, match="'time' must be finite and >= 0"):
        diffuse(S, m, y, torch.tensor([0.1, float('nan')]), solver)
    with pytest.raises(ValueError, match="'time' must be finite and >= 0"):
        diffuse(S, m, y, torch.tensor([0.1, -0.1]), solver)
    with pytest.raises(ValueError, match=r'value per channel \(2\)'):
        diffuse(S, m, y, torch.ones(3), solver)
    with pytest.raises(ValueError, match="'time' must be a finite number"):
        diffuse(S, m, y, -1.0, solver)
    with pytest.raises(ValueError, match=r"'y' must be a float tensor of "
                       r"shape \(42\)"):
        diffuse(S, m, y[:10], 0.1, solver)
    with pytest.raises(ValueError, match='NaN'):
        diffuse(S, m, torch.full_like(y, float('nan')), 0.1, solver)
    with pytest.raises(ValueError, match="'mass' must hold one finite "
                       "positive value"):
        diffuse(S, -m, y, 0.1, solver)
    with pytest.raises(ValueError, match="'stiffness' must be a square "
                       "scipy sparse matrix"):
        diffuse(S.toarray(), m, y, 0.1, solver)
    with pytest.raises(ValueError, match="'solver' must be one of"):
        diffuse(S, m, y, 0.1, 'gravo')
    with pytest.raises(ValueError, match="'solver' must be a GravoMG"):
        diffuse(S, m, y, 0.1, None)
