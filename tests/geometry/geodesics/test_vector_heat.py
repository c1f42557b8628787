"""The vector heat back end of ``log_map(method='vector_heat')``: analytic
answers on spheres and planes, patches against the original global solve,
threads and worker processes, several components and the fallback to the
whole component."""
import math

import torch
import trimesh

from tg_intrinsic.geometry import (geodesic_neighbourhoods, log_map,
                                   tangent_frames)
from tg_intrinsic.geometry.geodesics import affine_heat as _affine_heat
from tg_intrinsic.geometry.geodesics import vector_heat as _vector_heat

from tests.conftest import fibonacci_sphere, grid_mesh, icosphere
from tests.geometry.geodesics.surfaces import (angle_errors, bumpy_sphere,
                                               needs_pp3d, some_centres,
                                               sphere_truth, wrap)


def test_vector_heat_on_sphere():
    pos, face = icosphere(4)
    eps = 0.4
    edge_index, _ = geodesic_neighbourhoods(pos, eps, face=face,
                                            centers=some_centres(2562, 300))
    frame = tangent_frames(pos)
    out = log_map(pos, edge_index, frame, face=face, method='vector_heat',
                  workers=1)
    r_err, t_err, p_err = angle_errors(
        *out, sphere_truth(pos, frame, edge_index), edge_index)
    assert r_err < 0.01 * eps
    assert t_err < 5e-3 and p_err < 5e-3


@needs_pp3d
def test_vector_heat_on_point_cloud_sphere(monkeypatch):
    monkeypatch.setattr(_vector_heat, 'PLAN', 'patches')
    pos = fibonacci_sphere(3000)
    eps = 0.4
    edge_index, _ = geodesic_neighbourhoods(pos, eps, normal=pos,
                                            centers=some_centres(3000, 60))
    frame = tangent_frames(pos)
    r, theta, phi = log_map(pos, edge_index, frame, method='vector_heat',
                            workers=1)
    whole = log_map(pos, edge_index, frame, method='vector_heat',
                    margin=1e9, workers=1)
    # Patches reproduce potpourri3d's point-cloud solver on the whole cloud.
    assert ((r - whole[0]).abs() / eps).quantile(0.99) < 0.02
    assert wrap(theta - whole[1]).abs().quantile(0.99) < 0.02
    assert wrap(phi - whole[2]).abs().quantile(0.99) < 0.02
    # That solver is much less accurate than the mesh one (its angles drift
    # with the distance, and its normals are not consistently oriented);
    # these bounds document it rather than a goal.
    r0, theta0, phi0 = sphere_truth(pos, frame, edge_index)
    off = edge_index[0] != edge_index[1]
    assert (r - r0).abs().max() < 0.08 * eps
    assert wrap(theta - theta0)[off].abs().median() < 0.05
    assert wrap(phi - phi0).abs().median() < 5e-3


def test_vector_heat_at_the_boundary():
    # Boundary vertices keep their true fan of triangles: on a flat square
    # the log maps and transport from rim and corner vertices are exact (a
    # 90 degree corner is not stretched to a half plane).
    pos, face = grid_mesh(15, jitter=0.3)
    frame = torch.eye(3, dtype=pos.dtype).expand(pos.size(0), 3, 3)
    rim = torch.tensor([7, 7 * 15, 7 * 15 + 14, 14 * 15 + 7])
    corners = torch.tensor([0, 14, 14 * 15, 14 * 15 + 14])
    edge_index, _ = geodesic_neighbourhoods(pos, 0.2, face=face,
                                            centers=torch.cat([rim, corners]))
    r, theta, phi = log_map(pos, edge_index, frame, face=face,
                            method='vector_heat', workers=1)
    j, i = edge_index
    d = pos[j] - pos[i]
    off = i != j
    err = wrap(theta - torch.atan2(d[:, 1], d[:, 0]))
    assert err[off].abs().max() < 5e-4
    assert phi.abs().max() < 5e-4
    assert ((r - d.norm(dim=-1)).abs() / 0.2).max() < 5e-4


def test_patches_match_global_vector_heat(monkeypatch):
    pos, face = bumpy_sphere(3)
    edge_index, _ = geodesic_neighbourhoods(pos, 0.5, face=face)
    # On a mesh this small the planner would rather solve on the whole
    # surface; force patches.
    monkeypatch.setattr(_vector_heat, 'PLAN', 'patches')
    local = log_map(pos, edge_index, face=face, method='vector_heat',
                    workers=1)
    # A huge margin makes every patch the whole surface: one factorisation
    # and one solve per vertex on the full mesh, the original approach.
    whole = log_map(pos, edge_index, face=face, method='vector_heat',
                    margin=1e9, workers=1)
    r_err = (local[0] - whole[0]).abs() / 0.5
    t_err = wrap(local[1] - whole[1]).abs()
    p_err = wrap(local[2] - whole[2]).abs()
    for err in (r_err, t_err, p_err):
        assert err.median() < 1e-3
        assert err.quantile(0.99) < 1e-2


def test_threads_give_the_same_answer(monkeypatch):
    pos, face = icosphere(2)
    edge_index, _ = geodesic_neighbourhoods(pos, 0.5, face=face)
    monkeypatch.setattr(_vector_heat, 'PLAN', 'patches')
    alone = log_map(pos, edge_index, face=face, method='vector_heat',
                    workers=1)
    # Small blocks of centres, so that both threads get some.
    monkeypatch.setattr(_affine_heat, 'CENTRE_CHUNK', 16)
    threaded = log_map(pos, edge_index, face=face, method='vector_heat',
                       workers=2)
    for a, b in zip(alone, threaded):
        assert torch.equal(a, b)


@needs_pp3d
def test_worker_processes_give_the_same_answer(monkeypatch):
    pos = fibonacci_sphere(1500)
    edge_index, _ = geodesic_neighbourhoods(pos, 0.3, normal=pos,
                                            centers=some_centres(1500, 40))
    frame = tangent_frames(pos)
    monkeypatch.setattr(_vector_heat, 'PLAN', 'patches')
    alone = log_map(pos, edge_index, frame, method='vector_heat', workers=1)
    monkeypatch.setattr(_vector_heat, 'POOL_WORK', 0)
    pooled = log_map(pos, edge_index, frame, method='vector_heat',
                     workers=2)
    for a, b in zip(alone, pooled):
        assert torch.equal(a, b)


def test_several_components():
    a = trimesh.creation.icosphere(2)
    b = trimesh.creation.icosphere(2)
    b.apply_translation([5, 0, 0])
    mesh = trimesh.util.concatenate([a, b])
    pos = torch.tensor(mesh.vertices)
    face = torch.tensor(mesh.faces).t().contiguous()
    edge_index, _ = geodesic_neighbourhoods(pos, 0.8, face=face)
    r, theta, phi = log_map(pos, edge_index, face=face, method='vector_heat',
                            workers=1)
    for t in (r, theta, phi):
        assert torch.isfinite(t).all()
    half = torch.arange(pos.size(0)) < a.vertices.shape[0]
    assert torch.equal(half[edge_index[0]], half[edge_index[1]])
    # The two parts are the same sphere: the same distances.
    m = half[edge_index[1]]
    assert torch.allclose(r[m].sort().values, r[~m].sort().values,
                          atol=1e-6)


def test_far_neighbours_fall_back_to_the_whole_component(monkeypatch):
    # A neighbour two radians from its centre: the patch around the two
    # discs falls apart into two pieces, and the centre is redone on the
    # whole surface, exactly as the global solve does it.
    monkeypatch.setattr(_vector_heat, 'PLAN', 'patches')
    redone = []
    whole_jobs = _vector_heat.whole_jobs

    def spy(label, rows, *args, **kwargs):
        redone.append(rows.size)
        return whole_jobs(label, rows, *args, **kwargs)

    pos, face = icosphere(3)
    edge_index, _ = geodesic_neighbourhoods(pos, 0.3, face=face)
    far = int(((pos @ pos[0]) - math.cos(2.0)).abs().argmin())
    extra = torch.cat([edge_index, torch.tensor([[far], [0]])], 1)
    monkeypatch.setattr(_vector_heat, 'whole_jobs', spy)
    local = log_map(pos, extra, face=face, method='vector_heat', margin=2.0,
                    workers=1)
    assert redone == [1]  # the centre of the far edge
    whole = log_map(pos, extra, face=face, method='vector_heat', margin=1e9,
                    workers=1)
    for a, b in zip(local, whole):
        assert torch.isfinite(a).all()
        assert torch.allclose(a[-1], b[-1], atol=1e-12)
    true = math.acos(float(pos[0] @ pos[far]))
    assert abs(float(local[0][-1]) - true) < 0.02 * true
