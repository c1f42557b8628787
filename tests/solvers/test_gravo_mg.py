"""GravoMG against scipy's direct solve on closed meshes, meshes with
boundary, point clouds (robust Laplacian), several components; the cached
second solve; cycles; conjugate gradients; bad input."""
import numpy as np
import pytest
import scipy.sparse as sp
import torch
import trimesh
from scipy.sparse.linalg import cg, spsolve
from torch_geometric.data import Data

from tg_intrinsic.geometry import cotan_laplacian, lumped_mass, to_scipy
from tg_intrinsic.solvers import ConvergenceWarning, GravoMG
from tg_intrinsic.transforms import GravoHierarchy

from tests.conftest import grid_mesh


def face_edges(face):
    return np.concatenate([face[:, [0, 1]], face[:, [1, 2]],
                           face[:, [2, 0]]]).T


def mesh_system(pos, face, alpha=1e-2):
    """(M + alpha S) for a mesh: smoothing with a small diffusion."""
    p, f = torch.as_tensor(pos), torch.as_tensor(face).t().contiguous()
    S = to_scipy(cotan_laplacian(p, f))
    m = lumped_mass(p, f).numpy()
    return (sp.diags(m) + alpha * S).tocsr(), m


def sphere(subdivisions=5):
    mesh = trimesh.creation.icosphere(subdivisions=subdivisions)
    return np.asarray(mesh.vertices), np.asarray(mesh.faces, dtype=np.int64)


def relative_residual(A, x, b):
    return np.linalg.norm(b - A @ x) / np.linalg.norm(b)


def case(name):
    rng = np.random.default_rng(0)
    if name == 'closed':
        pos, face = sphere(5)
    elif name == 'boundary':
        # (A jittered grid has obtuse triangles, whose negative cotan
        # weights slow every smoother: 56 cycles instead of 10.)
        p, f = grid_mesh(90, jitter=0.05)
        pos, face = p.numpy(), f.t().numpy()
        # cut a hole
        centre = np.linalg.norm(pos[face].mean(1)[:, :2] - 0.5, axis=1)
        face = face[centre > 0.15]
        used = np.unique(face)
        remap = np.full(pos.shape[0], -1)
        remap[used] = np.arange(used.size)
        pos, face = pos[used], remap[face]
    elif name == 'components':
        pos, face = sphere(4)
        face = np.concatenate([face, face + pos.shape[0]])
        pos = np.concatenate([pos, pos + 3.0])
    if name == 'cloud':
        import robust_laplacian
        pos = rng.normal(size=(8000, 3))
        pos /= np.linalg.norm(pos, axis=1, keepdims=True)
        S, M = robust_laplacian.point_cloud_laplacian(pos)
        from scipy.spatial import cKDTree
        _, nbr = cKDTree(pos).query(pos, k=9)
        edges = np.stack([nbr[:, 1:].reshape(-1), np.repeat(
            np.arange(pos.shape[0]), 8)])
        A = (M + 1e-2 * S).tocsr()
        return A, M.diagonal(), GravoMG.from_points(pos, edges,
                                                    lower_bound=50)
    A, m = mesh_system(pos, face)
    return A, m, GravoMG.from_points(pos, face_edges(face), lower_bound=50)


@pytest.mark.parametrize('name', ['closed', 'boundary', 'cloud',
                                  'components'])
def test_matches_direct_solve(name):
    A, m, solver = case(name)
    assert len(solver.prolongations) >= 2
    b = m * np.random.default_rng(1).normal(size=A.shape[0])
    x = solver.solve(A, b, tol=1e-8, max_iter=60)
    assert solver.info.converged, solver.info.residuals[-3:]
    assert relative_residual(A, x, b) < 1e-8
    exact = spsolve(A.tocsc(), b)
    assert np.linalg.norm(x - exact) / np.linalg.norm(exact) < 1e-6
    # The residual history falls, and each cycle cuts it a lot.
    res = solver.info.residuals
    assert all(b < a for a, b in zip(res, res[1:]))
    assert solver.info.iterations < 40


def test_second_solve_is_cached_and_identical():
    A, m, solver = case('closed')
    b = m * np.random.default_rng(2).normal(size=A.shape[0])
    first = solver.solve(A, b)
    assert not solver.info.cached
    levels = solver.setup(A)
    second = solver.solve(A, b.copy())
    # the same Galerkin levels object: nothing was set up again
    assert solver.info.cached and solver.setup(A) is levels
    assert np.array_equal(first, second)
    assert relative_residual(A, first, b) < 1e-4
    # A matrix that differs in one bit of one value gets its own setup.
    changed = A.copy()
    changed.data[7] = np.nextafter(changed.data[7], np.inf)
    solver.solve(changed, b)
    assert not solver.info.cached


@pytest.mark.parametrize('neighbours', [6, 40])
def test_galerkin_levels_equal_scipy_products(neighbours):
    # 40 neighbours make coarse rows longer than the compiled product's
    # first slots, so they take its second, wider pass.
    rng = np.random.default_rng(3)
    pos = rng.normal(size=(3000, 3))
    from scipy.spatial import cKDTree
    _, nbr = cKDTree(pos).query(pos, k=neighbours + 1)
    rows = np.repeat(np.arange(pos.shape[0]), neighbours)
    weights = sp.csr_matrix((rng.random(rows.size),
                             (rows, nbr[:, 1:].reshape(-1))))
    A = (weights + weights.T + sp.identity(pos.shape[0]) * neighbours)
    A = A.tocsr()
    edges = np.stack([nbr[:, 1:].reshape(-1), rows])
    solver = GravoMG.from_points(pos, edges, lower_bound=20)
    levels = solver.setup(A)
    assert len(levels.A) >= 2
    expected = A
    for P, coarse in zip(solver.prolongations, levels.A[1:]):
        expected = (P.T @ expected @ P).tocsr()
        assert coarse.has_sorted_indices
        assert np.array_equal(coarse.indptr, expected.indptr)
        assert np.array_equal(coarse.indices, expected.indices)
        np.testing.assert_allclose(coarse.data, expected.data,
                                   rtol=1e-12, atol=1e-12 * abs(
                                       expected.data).max())
    if neighbours == 40:
        assert np.diff(levels.A[1].indptr).max() > 48


@pytest.mark.parametrize('cycle', ['V', 'W', 'F'])
def test_cycles_converge(cycle):
    A, m, solver = case('closed')
    b = m * np.random.default_rng(3).normal(size=A.shape[0])
    x = solver.solve(A, b, tol=1e-10, cycle=cycle, criterion='mass', mass=m)
    assert solver.info.converged
    r = b - A @ x
    assert np.sqrt(np.sum(r * r / m) / np.sum(b * b / m)) < 1e-10


def test_preconditioned_conjugate_gradients():
    A, m, solver = case('boundary')
    b = m * np.random.default_rng(4).normal(size=A.shape[0])
    counts = {}
    for name, M in (('plain', None), ('gravo', solver.as_preconditioner(A))):
        calls = []
        x, flag = cg(A, b, rtol=1e-10, maxiter=2000, M=M,
                     callback=lambda xk: calls.append(1))
        assert flag == 0 and relative_residual(A, x, b) < 1e-9
        counts[name] = len(calls)
    assert counts['gravo'] * 5 < counts['plain']


def test_pcg_method_matches_direct_solves_in_fewer_iterations():
    A, m, solver = case('boundary')
    rng = np.random.default_rng(5)
    B = m[:, None] * rng.normal(size=(A.shape[0], 3))
    X = solver.solve(A, B, tol=1e-10, max_iter=200, method='pcg')
    info = solver.info
    assert info.converged and info.residuals[-1] < 1e-10
    for k in range(3):
        assert relative_residual(A, X[:, k], B[:, k]) < 1e-10
        exact = spsolve(A.tocsc(), B[:, k])
        assert np.linalg.norm(X[:, k] - exact) < 1e-8 * np.linalg.norm(exact)
    # each column has its own step lengths: solved alone, it is the same
    alone = solver.solve(A, B[:, 1], tol=1e-10, max_iter=200, method='pcg')
    assert np.linalg.norm(alone - X[:, 1]) < 1e-8 * np.linalg.norm(alone)
    pcg_iterations = info.iterations
    solver.solve(A, B, tol=1e-10, max_iter=200)
    assert solver.info.converged
    assert pcg_iterations < solver.info.iterations
    # a zero column stays zero and does not stall the others
    B[:, 2] = 0
    X = solver.solve(A, B, tol=1e-10, max_iter=200, method='pcg')
    assert solver.info.converged and not X[:, 2].any()
    with pytest.warns(ConvergenceWarning, match='max_iter=2 PCG iterations'):
        solver.solve(A, B, tol=1e-14, max_iter=2, method='pcg')
    with pytest.raises(ValueError, match="method='pcg' runs on the CPU"):
        solver.solve(A, torch.from_numpy(B), method='pcg')
    with pytest.raises(ValueError, match='method'):
        solver.solve(A, B, method='gmres')


def test_from_transform_and_direct_fallback():
    pos, face = sphere(4)
    # from_mesh builds the same levels as the transform
    mesh = GravoMG.from_mesh(pos, face.T, lower_bound=50)
    with pytest.raises(ValueError, match=r'\[3, F\].*looks like \[F, 3\]'):
        GravoMG.from_mesh(pos, face)
    with pytest.raises(ValueError, match='indexes vertices'):
        GravoMG.from_mesh(pos, face.T + 1)
    tensors = GravoMG.from_mesh(torch.tensor(pos),
                                torch.tensor(face.T), lower_bound=50)
    data = GravoHierarchy(lower_bound=50)(Data(
        pos=torch.tensor(pos), face=torch.tensor(face).t().contiguous()))
    solver = GravoMG.from_data(data)
    for a, b, c in zip(mesh.prolongations, solver.prolongations,
                       tensors.prolongations):
        assert abs(a - b).max() < 1e-12 and abs(a - c).max() == 0
    A, m = mesh_system(pos, face)
    b = m.copy()
    x = solver.solve(A, b, tol=1e-9)
    assert relative_residual(A, x, b) < 1e-9
    assert 'levels=[2562' in repr(solver)
    # Too few points for a level: one direct solve, and info says so.
    small = GravoMG([])
    x = small.solve(A, b)
    assert small.info.direct and 'direct' in small.info.direct
    assert relative_residual(A, x, b) < 1e-12


def test_bad_input():
    A, m, solver = case('closed')
    b = m.copy()
    with pytest.raises(ValueError, match='square'):
        solver.solve(A[:, :-1], b)
    with pytest.raises(ValueError, match='symmetric'):
        solver.solve(A + sp.random(A.shape[0], A.shape[0], density=1e-4,
                                   random_state=0, format='csr'), b)
    # A small asymmetry in every row (1e-6 relative) is found too.
    rows = sp.diags(1 + 1e-6 * np.random.default_rng(9).random(A.shape[0]))
    with pytest.raises(ValueError, match='symmetric'):
        solver.solve((rows @ A).tocsr(), b)
    bad = A.copy()
    bad.data[0] = np.nan
    with pytest.raises(ValueError, match='NaN'):
        solver.solve(bad, b)
    with pytest.raises(ValueError, match='NaN'):
        solver.solve(A, np.full_like(b, np.nan))
    with pytest.raises(ValueError, match='singular'):
        solver.solve(A - sp.diags(m), b)  # the bare Laplacian
    with pytest.raises(ValueError, match='hierarchy has'):
        solver.solve(A[:-1, :-1], b[:-1])
    with pytest.raises(ValueError, match='cycle'):
        solver.solve(A, b, cycle='X')
    with pytest.raises(ValueError, match='mass'):
        solver.solve(A, b, criterion='mass')
    zero_row = A.tolil()
    zero_row[3, :] = 0
    zero_row[:, 3] = 0
    with pytest.raises(ValueError, match='zero or negative diagonal.*\\[3\\]'):
        solver.solve(zero_row.tocsr(), b)
    for options, match in [
            (dict(tol=0), "'tol' must be positive"),
            (dict(tol=float('nan')), "'tol' must be finite"),
            (dict(max_iter=0), "'max_iter' must be at least 1"),
            (dict(pre=-1), "'pre' must be at least 0"),
            (dict(pre=0, post=0), 'both 0'),
            (dict(x0=np.zeros(5)), "'x0' must have the shape of 'b'"),
            (dict(x0=np.full_like(b, np.nan)), "'x0' holds NaN"),
            (dict(x0=torch.full((b.size, ), float('nan')).double()),
             "'x0' holds NaN")]:
        with pytest.raises(ValueError, match=match):
            solver.solve(A, b, **options)


def test_prolongations_are_checked():
    _, _, solver = case('closed')
    broken = [P.copy() for P in solver.prolongations]
    broken[1].data[0] = np.nan
    with pytest.raises(ValueError, match='prolongation 1 holds NaN'):
        GravoMG(broken)
    with pytest.raises(ValueError, match='do not chain'):
        GravoMG(solver.prolongations[::-1])


def test_not_converging_warns_or_raises():
    A, m, solver = case('closed')
    with pytest.warns(ConvergenceWarning, match='max_iter=1 cycles'):
        x = solver.solve(A, m, tol=1e-12, max_iter=1)
    assert not solver.info.converged and solver.info.iterations == 1
    assert 'above tol=1e-12' in solver.info.reason
    assert np.isfinite(x).all()
    with pytest.raises(RuntimeError, match='did not converge'):
        solver.solve(A, m, tol=1e-12, max_iter=1, strict=True)
    solver.solve(A, m, tol=1e-6, strict=True)
    assert solver.info.converged and solver.info.reason is None


def test_the_convergence_warning_words_its_settings_for_any_interface():
    # the library names its arguments; an interface with other names for
    # them (the command line: --max-cycles, --tol, --method) rewords the
    # one text through `setting` instead of keeping a copy (issue 40)
    import pickle
    A, m, solver = case('closed')
    with pytest.warns(ConvergenceWarning) as record:
        solver.solve(A, m, tol=1e-12, max_iter=2)
    warning = record[0].message
    assert (warning.max_iter, warning.method, warning.tol) == (2, 'cycles',
                                                                1e-12)
    assert warning.residual == solver.info.residuals[-1]
    assert warning.reason() == solver.info.reason
    assert str(warning) == f'GravoMG.solve did not converge: ' \
        f'{solver.info.reason}'
    assert solver.info.reason.endswith(
        "above tol=1e-12; raise max_iter, or use method='pcg'")

    def option(name, value=None):
        flag = {'max_iter': '-n', 'tol': '-t', 'method': '-m'}[name]
        return flag if value is None else f'{flag} {value}'

    assert warning.reason(option) == (
        f'stopped at -n 2 cycles with relative residual '
        f'{warning.residual:.3g} above -t 1e-12; raise -n, or use -m pcg')
    copy = pickle.loads(pickle.dumps(warning))  # e.g. from a worker
    assert str(copy) == str(warning) and copy.reason(option) == \
        warning.reason(option)
    with pytest.warns(ConvergenceWarning, match='max_iter=1 PCG iterations'
                      r' with relative residual \S+ above tol=1e-12; raise '
                      'max_iter$') as record:
        solver.solve(A, m, tol=1e-12, max_iter=1, method='pcg')
    assert record[0].message.reason(option).endswith('raise -n')


DEVICES = ['cpu'] + (['cuda'] if torch.cuda.is_available() else [])


@pytest.mark.parametrize('device', DEVICES)
@pytest.mark.parametrize('dtype', [torch.float64, torch.float32])
@pytest.mark.parametrize('name', ['closed', 'boundary', 'cloud'])
def test_torch_backend_matches_direct_solve(name, dtype, device):
    A, m, solver = case(name)
    rng = np.random.default_rng(6)
    b = m[:, None] * rng.normal(size=(A.shape[0], 3))
    exact = spsolve(A.tocsc(), b)
    B = torch.tensor(b, dtype=dtype, device=device)
    tol = 1e-8 if dtype == torch.float64 else 1e-4
    X = solver.solve(A, B, tol=tol, max_iter=200)
    assert X.dtype == dtype and X.device.type == device
    assert X.shape == B.shape
    assert solver.info.converged, solver.info.residuals[-3:]
    x = X.cpu().double().numpy()
    for k in range(3):
        assert relative_residual(A, x[:, k], b[:, k]) < 2 * tol
    error = np.linalg.norm(x - exact) / np.linalg.norm(exact)
    assert error < (1e-6 if dtype == torch.float64 else 1e-3)


def test_torch_batch_equals_columns_one_at_a_time():
    A, m, solver = case('closed')
    b = m[:, None] * np.random.default_rng(7).normal(size=(A.shape[0], 4))
    B = torch.tensor(b)
    # a tolerance no cycle reaches: exactly max_iter cycles for the batch
    # and for each column
    with pytest.warns(ConvergenceWarning):
        batch = solver.solve(A, B, tol=1e-300, max_iter=3)
    for k in range(4):
        with pytest.warns(ConvergenceWarning):
            column = solver.solve(A, B[:, k], tol=1e-300, max_iter=3)
        assert column.shape == (A.shape[0], )
        assert torch.allclose(batch[:, k], column, rtol=0, atol=1e-14)


@pytest.mark.parametrize('cycle', ['W', 'F'])
def test_torch_cycles_and_mass_criterion(cycle):
    A, m, solver = case('closed')
    b = torch.tensor(m * np.random.default_rng(8).normal(size=A.shape[0]))
    x = solver.solve(A, b, tol=1e-9, cycle=cycle, criterion='mass', mass=m)
    assert solver.info.converged
    r = b.numpy() - A @ x.numpy()
    assert np.sqrt(np.sum(r * r / m) / np.sum(b.numpy() ** 2 / m)) < 1e-9


def test_torch_bad_input():
    A, m, solver = case('closed')
    with pytest.raises(ValueError, match='float32 or float64'):
        solver.solve(A, torch.ones(A.shape[0], dtype=torch.long))
    with pytest.raises(ValueError, match='NaN'):
        solver.solve(A, torch.full((A.shape[0], ), float('nan')))
    with pytest.raises(ValueError, match='shape'):
        solver.solve(A, torch.ones(A.shape[0], 2, 2))


def test_divergence_is_an_error_not_nan():
    # S + 1e-6 M in float32: rounding in the near-constant mode is
    # amplified a million-fold by the coarse solve, and the cycles diverge
    # (x80 per cycle on this sphere). float64 converges.
    pos, face = sphere(5)
    A, m = mesh_system(pos, face, alpha=1.0)
    A = (A - sp.diags(m) + 1e-6 * sp.diags(m)).tocsr()  # S + 1e-6 M
    solver = GravoMG.from_mesh(pos, face.T, lower_bound=100)
    b = m * np.random.default_rng(10).normal(size=A.shape[0])
    with pytest.raises(RuntimeError, match='diverge.*float64'):
        solver.solve(A, torch.tensor(b, dtype=torch.float32))
    x = solver.solve(A, torch.tensor(b))
    assert solver.info.converged
    assert relative_residual(A, x.numpy(), b) < 1e-4


def test_torch_solve_is_differentiable_in_b():
    # a 49-vertex grid with two coarse levels; gradcheck needs the solve
    # far below its finite-difference error: tol=1e-12
    pos, face = grid_mesh(7)
    A, m = mesh_system(pos, face.t(), alpha=0.1)
    solver = GravoMG.from_mesh(pos, face, lower_bound=3)
    assert len(solver.prolongations) == 2
    rng = np.random.default_rng(11)
    b = torch.tensor(m[:, None] * rng.normal(size=(A.shape[0], 2)),
                     requires_grad=True)
    x = solver.solve(A, b, tol=1e-12)
    assert x.requires_grad and solver.info.iterations > 1
    # the same numbers as without grad
    assert torch.equal(x.detach(), solver.solve(A, b.detach(), tol=1e-12))
    weights = torch.tensor(rng.normal(size=b.shape))
    (x * weights).sum().backward()
    # dL/db = A^-T w, against a dense solve
    exact = np.linalg.solve(A.toarray().T, weights.numpy())
    assert np.abs(b.grad.numpy() - exact).max() < 1e-9 * np.abs(exact).max()
    column = b[:, 0].detach().requires_grad_()
    assert torch.autograd.gradcheck(
        lambda b: solver.solve(A, b, tol=1e-12), (column, ))
    # a start x0 and other cycles (a random projection of the Jacobian:
    # the torch cycles are slow on a busy CPU), and the direct solve
    # without coarse levels
    assert torch.autograd.gradcheck(
        lambda b: solver.solve(A, b, x0=torch.ones_like(b), tol=1e-12,
                               cycle='W'), (b, ), fast_mode=True)
    direct = GravoMG.from_mesh(pos, face, lower_bound=1000)
    assert torch.autograd.gradcheck(lambda b: direct.solve(A, b), (b, ))
    assert direct.info.direct is not None
    # float32 stays float32
    b32 = b.detach().float().requires_grad_()
    solver.solve(A, b32, tol=1e-6).sum().backward()
    assert b32.grad.dtype == torch.float32
