"""Log maps and parallel transport (HSN precomputation) against analytic
answers on spheres and planes, the gauge symmetry, transport round trips,
bad input and the disc-graph size estimate. The vector heat back end's own
tests are in test_vector_heat.py."""
import math

import pytest
import torch
import trimesh
from hypothesis import given
from hypothesis import strategies as st

from tg_intrinsic.geometry import (estimate_normals, geodesic_neighbourhoods,
                                   log_map, lumped_mass, tangent_frames,
                                   vertex_area_weights, vertex_normals)

from tests.conftest import fibonacci_sphere, grid_mesh, icosphere
from tests.geometry.geodesics.surfaces import (angle_errors, arc,
                                               bumpy_sphere, some_centres,
                                               sphere_truth, wrap)
from tests.geometry.test_bad_input import (SETTINGS, assert_valid, call,
                                           face_arrays, point_arrays)
from tests.symmetry import rotate_frames

METHODS = ['fast', 'vector_heat']


# ----------------------------------------------------------------------------
# neighbourhoods and weights
# ----------------------------------------------------------------------------
def test_mesh_neighbourhoods_match_sphere_geodesics():
    pos, face = icosphere(4)
    eps = 0.4
    edge_index, dist = geodesic_neighbourhoods(pos, eps, face=face)
    j, i = edge_index
    true = arc(pos[i], pos[j])
    far = true > 0.1
    assert ((dist - true).abs()[far] / true[far]).max() < 3e-3
    assert (dist < eps).all()
    # Complete: every vertex within eps (minus the fast-marching error) is in.
    every = torch.acos((pos @ pos.t()).clamp(-1, 1))
    inside = (every < eps * 0.99).sum()
    assert edge_index.size(1) >= inside
    # Sorted by centre, then by distance, self-loop first.
    assert (i[1:] >= i[:-1]).all()
    same = i[1:] == i[:-1]
    assert (dist[1:][same] >= dist[:-1][same]).all()
    first = torch.ones_like(i, dtype=torch.bool)
    first[1:] = ~same
    assert torch.equal(j[first], i[first]) and (dist[first] == 0).all()


def test_neighbourhood_cap_centres_and_dtype():
    pos, face = icosphere(3, dtype=torch.float32)
    full, dist = geodesic_neighbourhoods(pos, 0.6, face=face)
    capped, cdist = geodesic_neighbourhoods(pos, 0.6, face=face,
                                            max_neighbors=5)
    assert cdist.dtype == torch.float32
    assert torch.equal(torch.bincount(capped[1]), torch.full((642, ), 5))
    # The cap keeps the nearest ones.
    kth = torch.stack([dist[full[1] == c][4] for c in range(0, 642, 50)])
    assert (cdist.view(642, 5)[::50].max(1).values <= kth + 1e-6).all()
    centers = torch.tensor([3, 100, 7])
    sub, sdist = geodesic_neighbourhoods(pos, 0.6, face=face,
                                         centers=centers)
    assert set(sub[1].tolist()) == {3, 7, 100}
    for c in centers.tolist():
        assert torch.equal(sub[0, sub[1] == c].sort().values,
                           full[0, full[1] == c].sort().values)


def test_mesh_neighbourhoods_do_not_jump_between_sheets():
    # Two parallel squares 0.02 apart: Euclidean balls would merge them.
    pos, face = grid_mesh(11)
    top = pos + torch.tensor([0, 0, 0.02], dtype=pos.dtype)
    pos2 = torch.cat([pos, top])
    face2 = torch.cat([face, face + pos.size(0)], 1)
    edge_index, _ = geodesic_neighbourhoods(pos2, 0.25, face=face2)
    sheet = (torch.arange(pos2.size(0)) >= pos.size(0)).long()
    assert torch.equal(sheet[edge_index[0]], sheet[edge_index[1]])
    euclid, _ = geodesic_neighbourhoods(pos2, 0.25)
    assert not torch.equal(sheet[euclid[0]], sheet[euclid[1]])


def test_cloud_neighbourhoods_use_arc_length():
    pos = fibonacci_sphere(1500)
    edge_index, dist = geodesic_neighbourhoods(pos, 0.3, normal=pos)
    j, i = edge_index
    true = arc(pos[i], pos[j])
    assert (dist - true).abs().max() < 1e-12  # exact on a sphere
    assert (dist < 0.3).all()
    chord, cdist = geodesic_neighbourhoods(pos, 0.3)  # no normals
    assert chord.size(1) > edge_index.size(1)  # chord < arc
    assert torch.allclose(cdist, (pos[chord[0]] - pos[chord[1]]).norm(dim=-1))


def test_area_weights():
    pos, face = icosphere(3)
    assert torch.equal(vertex_area_weights(pos, face), lumped_mass(pos, face))
    cloud = fibonacci_sphere(3000)
    w = vertex_area_weights(cloud, normal=cloud)
    assert abs(float(w.sum()) - 4 * math.pi) < 0.01 * 4 * math.pi
    assert w.min() > 0.5 * w.mean()
    grid, _ = grid_mesh(12)  # spacing 1/11
    w = vertex_area_weights(grid.float(),
                            normal=torch.tensor([[0., 0, 1]]).expand(144, 3))
    interior = (grid[:, :2] > 0.01).all(1) & (grid[:, :2] < 0.99).all(1)
    assert torch.allclose(w[interior], torch.full_like(w[interior],
                                                      1 / 121), rtol=1e-5)
    # Open-boundary cells are bounded (at most about twice the interior).
    rim = w[~interior] * 121
    assert (rim > 0.5).all() and (rim < 2.5).all()


# ----------------------------------------------------------------------------
# accuracy against analytic answers
# ----------------------------------------------------------------------------
@pytest.mark.parametrize('dtype', [torch.float32, torch.float64])
def test_fast_on_sphere(dtype):
    pos, face = icosphere(4, dtype=dtype)
    edge_index, _ = geodesic_neighbourhoods(pos, 0.4, face=face)
    frame = tangent_frames(pos)  # exact normals: the method is exact
    out = log_map(pos, edge_index, frame)
    assert all(t.dtype == dtype for t in out)
    tol = 1e-5 if dtype == torch.float32 else 1e-10
    truth = sphere_truth(pos.double(), frame.double(), edge_index)
    for err in angle_errors(*[t.double() for t in out], truth, edge_index):
        assert err < tol
    # With the mesh's vertex normals (the default frames) it is approximate.
    pos = pos.double()
    frame = tangent_frames(vertex_normals(pos, face))
    out = log_map(pos, edge_index, frame)
    r_err, t_err, p_err = angle_errors(
        *out, sphere_truth(pos, frame, edge_index), edge_index)
    assert r_err < 0.01 * 0.4 and t_err < 2e-2 and p_err < 2e-2


def test_fast_kernel_matches_torch_reference():
    # The CPU path is a numba kernel; other devices use the torch version.
    from tg_intrinsic.geometry.geodesics.logmap import _fast_numba, _fast_torch
    pos, face = bumpy_sphere(2)
    frame = tangent_frames(vertex_normals(pos, face))
    edge_index, _ = geodesic_neighbourhoods(pos, 0.8, face=face)
    # Point 7's normal opposite to point 5's (a fold): no smallest rotation.
    frame[7] = torch.stack([frame[5, 0], -frame[5, 1], -frame[5, 2]])
    edge_index = torch.cat([edge_index, torch.tensor([[7], [5]])], 1)
    for a, b in zip(_fast_numba(pos, frame, edge_index),
                    _fast_torch(pos, frame, edge_index)):
        assert torch.isfinite(a).all()
        assert torch.allclose(a, b, atol=1e-12)


def test_fast_and_vector_heat_agree_on_a_smooth_surface():
    # On an ellipsoid neither method is exact, but both approximate the
    # same quantities in the same conventions: they converge as the discs
    # shrink, the angles about quadratically (the radii sooner meet the
    # first-order discretisation error of the heat method).
    mesh = trimesh.creation.icosphere(subdivisions=4)
    pos = torch.tensor(mesh.vertices) * torch.tensor([1.0, 0.7, 0.4],
                                                     dtype=torch.float64)
    face = torch.tensor(mesh.faces).t().contiguous()
    centers = torch.arange(0, pos.size(0), 29)
    gaps = []
    for eps in (0.4, 0.2):
        edge_index, _ = geodesic_neighbourhoods(pos, eps, face=face,
                                                centers=centers)
        fast = log_map(pos, edge_index, face=face)
        heat = log_map(pos, edge_index, face=face, method='vector_heat',
                       workers=1)
        gaps.append([((fast[0] - heat[0]).abs() / eps).quantile(0.95),
                     wrap(fast[1] - heat[1]).abs().quantile(0.95),
                     wrap(fast[2] - heat[2]).abs().quantile(0.95)])
    gaps = torch.tensor(gaps)
    assert (gaps[0] < torch.tensor([0.02, 0.15, 0.05])).all()
    assert (gaps[1] < gaps[0] / torch.tensor([1.8, 3.0, 3.0])).all()


@pytest.mark.parametrize('method', METHODS)
def test_flat_plane_is_exact(method):
    pos, face = grid_mesh(30, jitter=0.3)
    eps = 0.2
    frame = torch.eye(3, dtype=pos.dtype).expand(pos.size(0), 3, 3)
    # Centres whose discs stay off the boundary of the square.
    inner = ((pos[:, :2] > eps + 0.05) & (pos[:, :2] < 0.95 - eps)).all(1)
    edge_index, dist = geodesic_neighbourhoods(
        pos, eps, face=face, centers=inner.nonzero().flatten())
    r, theta, phi = log_map(pos, edge_index, frame, face=face, method=method,
                            workers=1)
    j, i = edge_index
    d = pos[j] - pos[i]
    off = i != j
    angle = torch.atan2(d[:, 1], d[:, 0])
    # Fast marching is exact on flat meshes, but for a few pairs behind
    # several obtuse triangles of this strongly jittered grid.
    rel = (dist - d.norm(dim=-1))[off] / d.norm(dim=-1)[off]
    assert (rel >= -1e-12).all() and rel.max() < 0.03
    assert (rel.abs() < 1e-12).float().mean() > 0.99
    tol = 1e-12 if method == 'fast' else 1e-4
    assert (r - d.norm(dim=-1)).abs().max() < tol * eps
    assert wrap(theta - angle)[off].abs().max() < tol
    assert phi.abs().max() < tol


# ----------------------------------------------------------------------------
# symmetries
# ----------------------------------------------------------------------------
@pytest.mark.parametrize('method', METHODS)
def test_gauge_equivariance(method):
    pos, face = bumpy_sphere(2)
    frame = tangent_frames(vertex_normals(pos, face))
    edge_index, _ = geodesic_neighbourhoods(pos, 0.6, face=face)
    r, theta, phi = log_map(pos, edge_index, frame, face=face, method=method,
                            workers=1)
    g = torch.Generator().manual_seed(1)
    alpha = (torch.rand(pos.size(0), generator=g, dtype=pos.dtype) * 2
             - 1) * math.pi
    r2, theta2, phi2 = log_map(pos, edge_index, rotate_frames(frame, alpha),
                               face=face, method=method, workers=1)
    j, i = edge_index
    off = i != j
    assert torch.allclose(r, r2, atol=1e-12)
    assert wrap(theta2 - (theta - alpha[i]))[off].abs().max() < 1e-9
    assert wrap(phi2 - (phi - alpha[i] + alpha[j]))[off].abs().max() < 1e-9
    # A frame whose normal points the other way (left-handed w.r.t. the
    # outward normal) is a valid gauge too: angles are mirrored.
    flipped = torch.stack([frame[:, 1], frame[:, 0], -frame[:, 2]], 1)
    r3, theta3, phi3 = log_map(pos, edge_index, flipped, face=face,
                               method=method, workers=1)
    assert wrap(theta3 - (math.pi / 2 - theta))[off].abs().max() < 1e-9
    assert wrap(phi3 + phi)[off].abs().max() < 1e-9


@pytest.mark.parametrize('method', METHODS)
def test_transport_round_trip(method):
    pos, face = bumpy_sphere(3)
    edge_index, _ = geodesic_neighbourhoods(pos, 0.3, face=face)
    r, theta, phi = log_map(pos, edge_index, face=face, method=method,
                            workers=1)
    j, i = edge_index
    n = pos.size(0)
    key = i * n + j
    rev = j * n + i
    sorted_key, order = key.sort()
    pos_rev = torch.searchsorted(sorted_key, rev).clamp(max=key.numel() - 1)
    both = (sorted_key[pos_rev] == rev) & (i != j)
    back = order[pos_rev[both]]
    loop = wrap(phi[both] + phi[back]).abs()  # i -> j -> i
    if method == 'fast':
        assert loop.max() < 1e-10
    else:
        assert loop.median() < 2e-3 and loop.max() < 5e-2
    # The geodesic's tangent is parallel: it leaves i at theta_ij and
    # arrives at j pointing away from i, at theta_ji + pi.
    arrive = wrap(theta[back] + math.pi + phi[both] - theta[both]).abs()
    if method == 'vector_heat':
        assert arrive.median() < 2e-2




# ----------------------------------------------------------------------------
# bad input
# ----------------------------------------------------------------------------
def test_bad_input_messages():
    pos, face = icosphere(2)
    edge_index, _ = geodesic_neighbourhoods(pos, 0.5, face=face)
    bad = pos.clone()
    bad[3, 1] = float('nan')
    with pytest.raises(ValueError, match='NaN'):
        geodesic_neighbourhoods(bad, 0.5, face=face)
    with pytest.raises(ValueError, match='NaN'):
        log_map(bad, edge_index, face=face)
    with pytest.raises(ValueError, match='positive'):
        geodesic_neighbourhoods(pos, 0.0, face=face)
    with pytest.raises(ValueError, match='finite'):
        geodesic_neighbourhoods(pos, float('inf'), face=face)
    with pytest.raises(ValueError, match='spacing'):
        geodesic_neighbourhoods(pos, 1e-3, face=face)
    with pytest.raises(ValueError, match=r'\[2, E\]'):
        log_map(pos, edge_index[:1], face=face)
    with pytest.raises(ValueError, match='torch.long'):
        log_map(pos, edge_index.float(), face=face)
    with pytest.raises(ValueError, match='only'):
        log_map(pos, edge_index + pos.size(0), face=face)
    with pytest.raises(ValueError, match='estimate_normals'):
        log_map(pos, edge_index)  # a point cloud without frames
    with pytest.raises(ValueError, match='estimate_normals'):
        vertex_area_weights(pos)
    with pytest.raises(ValueError, match='method'):
        log_map(pos, edge_index, face=face, method='exact')
    with pytest.raises(ValueError, match='margin'):
        log_map(pos, edge_index, face=face, method='vector_heat', margin=-1)
    with pytest.raises(ValueError, match=r'\[N, 3, 3\]'):
        log_map(pos, edge_index, frame=torch.zeros(pos.size(0), 3))
    with pytest.raises(ValueError, match='orthonormal'):
        log_map(pos, edge_index, frame=torch.ones(pos.size(0), 3, 3).double())
    with pytest.raises(ValueError, match='centers'):
        geodesic_neighbourhoods(pos, 0.5, face=face,
                                centers=torch.tensor([1, 1]))


def test_bad_meshes():
    pos, face = icosphere(2)
    flat = torch.cat([pos, pos[:1] + 1e-3], 0)  # an unreferenced vertex
    with pytest.raises(ValueError, match='not referenced'):
        geodesic_neighbourhoods(flat, 0.5, face=face)
    # A zero-area triangle: three collinear vertices.
    pos3 = torch.cat([pos, torch.tensor([[3., 0, 0], [4, 0, 0], [5, 0, 0]],
                                        dtype=pos.dtype)])
    face3 = torch.cat([face, torch.tensor([[162], [163], [164]])], 1)
    with pytest.raises(ValueError, match='zero-area'):
        geodesic_neighbourhoods(pos3, 0.5, face=face3)
    with pytest.raises(ValueError, match='shape'):
        geodesic_neighbourhoods(pos, 0.5, face=face.t())
    # An edge shared by three triangles.
    pos4 = torch.cat([pos, torch.tensor([[0., 0, 2]], dtype=pos.dtype)])
    e = face[:, 0]
    face4 = torch.cat([face, torch.tensor([[e[0]], [e[1]], [162]])], 1)
    edge_index, _ = geodesic_neighbourhoods(pos4, 0.5, face=face4)
    with pytest.raises(ValueError, match='more than two triangles'):
        log_map(pos4, edge_index, face=face4, method='vector_heat')
    # A flipped triangle.
    face5 = face.clone()
    face5[:, 0] = face5[[1, 0, 2], 0]
    edge_index, _ = geodesic_neighbourhoods(pos, 0.5, face=face5)
    with pytest.raises(ValueError, match='consistently oriented'):
        log_map(pos, edge_index, face=face5, method='vector_heat')
    # Edges between separate components have no geodesic.
    two = torch.cat([pos, pos + 5])
    face2 = torch.cat([face, face + pos.size(0)], 1)
    across = torch.tensor([[0, 200], [200, 0]])
    with pytest.raises(ValueError, match='connected components'):
        log_map(two, across, face=face2, method='vector_heat')


def test_point_cloud_log_map_needs_frames_from_estimated_normals():
    pos = fibonacci_sphere(800)
    normal = estimate_normals(pos)
    edge_index, _ = geodesic_neighbourhoods(pos, 0.3, normal=normal)
    r, theta, phi = log_map(pos, edge_index, tangent_frames(normal))
    for t in (r, theta, phi):
        assert torch.isfinite(t).all()


@SETTINGS
@given(data=st.data())
def test_malformed_input_raises_or_is_finite(data):
    pos = data.draw(point_arrays())
    n = pos.size(0) if pos.dim() > 0 else 0
    face = data.draw(st.one_of(st.none(), face_arrays(n)))
    eps = data.draw(st.sampled_from([-1.0, 0.0, 0.5, float('nan'), 3.0]))
    inputs = dict(pos=pos, face=face, n=n, eps=eps)
    out = call(geodesic_neighbourhoods, pos, eps, face=face, inputs=inputs)
    if out is None:
        return
    assert_valid(out, n)
    edge_index, dist = out
    assert (dist < eps).all() and edge_index.max() < n
    # points as normals: any valid gauge
    frame = call(tangent_frames, pos, inputs=inputs)
    for result in (call(log_map, pos, edge_index, frame, face=face,
                        inputs=inputs),
                   call(vertex_area_weights, pos, face=face, normal=pos,
                        inputs=dict(inputs, normal=pos))):
        if result is not None:
            assert_valid(result, n)


# ----------------------------------------------------------------------------
# the size of the disc graph, estimated before it is built
# ----------------------------------------------------------------------------
def unit_area(pos, face):
    from tg_intrinsic.geometry import normalize_area
    return normalize_area(pos, face), face


def estimate_cases():
    from tg_intrinsic.datasets import bumpy_torus
    sphere = unit_area(*icosphere(3))
    torus = bumpy_torus(2000)
    pos, face = icosphere(3)
    scale = torch.tensor([6.0, 0.5, 0.5], dtype=pos.dtype)
    stretched = unit_area(pos * scale, face)
    plate = unit_area(pos * torch.tensor([1.0, 1.0, 0.03],
                                         dtype=pos.dtype), face)
    return {'sphere': (sphere, 0.2), 'bumpy torus': (unit_area(
        torus.pos, torus.face), 0.15), 'stretched': (stretched, 0.2),
        'stretched, small discs': (stretched, 0.05),
        'flattened': (plate, 0.1), 'open grid': (grid_mesh(30), 0.15)}


@pytest.mark.parametrize('name', list(estimate_cases()))
def test_estimated_disc_edges_match_the_real_count(name):
    from tg_intrinsic.geometry.geodesics.logmap import estimate_disc_edges
    (pos, face), eps = estimate_cases()[name]
    real = geodesic_neighbourhoods(pos, eps, face=face)[0].size(1)
    estimate = estimate_disc_edges(pos, eps, face=face)
    # The contract is a factor 1.5; the sampled marching does ~10 %.
    assert 1 / 1.25 < estimate / real < 1.25, (estimate, real)
    # ... also with a cap and for a subset of centres
    capped = geodesic_neighbourhoods(pos, eps, face=face,
                                     max_neighbors=20)[0].size(1)
    assert 1 / 1.25 < estimate_disc_edges(
        pos, eps, face=face, max_neighbors=20) / capped < 1.25
    centers = some_centres(pos.size(0), 100)
    sub = geodesic_neighbourhoods(pos, eps, face=face,
                                  centers=centers)[0].size(1)
    assert 1 / 1.25 < estimate_disc_edges(
        pos, eps, face=face, centers=centers) / sub < 1.25


def test_estimated_disc_edges_on_point_clouds():
    from tg_intrinsic.geometry.geodesics.logmap import estimate_disc_edges
    pos = fibonacci_sphere(3000)
    for eps in (0.1, 0.4):
        real = geodesic_neighbourhoods(pos, eps, normal=pos)[0].size(1)
        estimate = estimate_disc_edges(pos, eps)
        assert 1 / 1.25 < estimate / real < 1.25
    # a stretched cloud (an ellipsoid), discs that wrap around it
    stretched = pos * torch.tensor([3.0, 0.3, 0.3], dtype=pos.dtype)
    real = geodesic_neighbourhoods(stretched, 0.5)[0].size(1)
    assert 1 / 1.25 < estimate_disc_edges(stretched, 0.5) / real < 1.25


def test_hsn_bytes_per_edge_matches_the_pipeline_output():
    from torch_geometric.data import Data
    from tg_intrinsic.geometry.geodesics.logmap import hsn_bytes_per_edge
    from tg_intrinsic.train import hsn_pipeline
    for dtype in (torch.float32, torch.float64):
        pos, face = icosphere(3, dtype=dtype)
        out = hsn_pipeline()(Data(pos=pos, face=face))
        per_edge = [key for key in out.keys() if key.split('_')[0] in (
            'edge', 'logmap', 'transport', 'harmonic')
            and not key.startswith('logmap_radius')]
        assert {'edge_index', 'logmap', 'transport', 'harmonic',
                'edge_index_1', 'logmap_1', 'transport_1',
                'harmonic_1'} == set(per_edge)
        stored = sum(out[k].numel() * out[k].element_size()
                     for k in per_edge)
        measured = stored / out.edge_index.size(1)
        assert abs(hsn_bytes_per_edge(dtype) / measured - 1) < 0.1


@pytest.mark.filterwarnings('ignore:the disc graph')
def test_disc_size_check_raises_before_marching(monkeypatch):
    import re
    from tg_intrinsic.geometry.geodesics import logmap as L
    pos, face = unit_area(*icosphere(3))

    def no_marching(*args, **kwargs):
        raise AssertionError('marched before the size check')
    monkeypatch.setattr(L, 'march_from', no_marching)
    limit = 2 ** 20  # 1 MiB: the 50k edges at 155 bytes do not fit
    with pytest.raises(ValueError) as info:
        geodesic_neighbourhoods(pos, 0.2, face=face, max_memory=limit,
                                bytes_per_edge=L.hsn_bytes_per_edge())
    message = str(info.value)
    for part in ('edges', 'MiB', 'max_memory', 'smaller radius',
                 'Decimate(', 'FarthestPointResample(', 'max_neighbors=',
                 'max_memory=None'):
        assert part in message, part
    monkeypatch.undo()
    # The suggestions fit.
    eps = float(re.search(r'radius \(about ([0-9.e-]+) fits\)',
                          message).group(1))
    cap = int(re.search(r'max_neighbors=(\d+)', message).group(1))
    bytes_per_edge = L.hsn_bytes_per_edge()
    for kwargs in ({'eps': eps}, {'eps': 0.2, 'max_neighbors': cap}):
        e = kwargs.pop('eps')
        edge_index, _ = geodesic_neighbourhoods(
            pos, e, face=face, max_memory=limit,
            bytes_per_edge=bytes_per_edge, **kwargs)
        assert edge_index.size(1) * bytes_per_edge <= limit
    # Off with None; a point cloud is checked as well.
    geodesic_neighbourhoods(pos, 0.2, face=face, max_memory=None)
    with pytest.raises(ValueError, match='max_memory'):
        geodesic_neighbourhoods(pos, 0.3, normal=pos, max_memory=limit)


def test_disc_size_check_warns_below_the_limit_and_skips_small_graphs(
        monkeypatch):
    from tg_intrinsic.geometry.geodesics import logmap as L
    pos, face = unit_area(*icosphere(3))
    real = geodesic_neighbourhoods(pos, 0.2, face=face)[0].size(1)
    # 60 bytes per edge, limit at twice the graph: above a quarter, warns.
    with pytest.warns(UserWarning, match='neighbours per point'):
        geodesic_neighbourhoods(pos, 0.2, face=face,
                                max_memory=2 * real * 60.0,
                                bytes_per_edge=60.0)
    # Full discs (N^2 edges) far below the warning level: no estimate.
    monkeypatch.setattr(L, '_estimate', None)
    geodesic_neighbourhoods(pos, 0.2, face=face)
    with pytest.raises(ValueError, match='max_memory'):
        geodesic_neighbourhoods(pos, 0.2, face=face, max_memory=-1)


def test_triangle_soup_is_rejected_with_a_fix():
    pos, face = icosphere(2)
    soup = pos[face.t().reshape(-1)]
    soup_face = torch.arange(soup.size(0)).view(-1, 3).t()
    with pytest.raises(ValueError, match='CleanMesh'):
        geodesic_neighbourhoods(soup, 0.3, face=soup_face)
