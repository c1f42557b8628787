import math
import time

import pytest
import torch
from torch_geometric.data import Data

from tg_intrinsic.datasets import bumpy_torus
from tg_intrinsic.geometry import tangent_frames, vertex_normals
from tg_intrinsic.train import hsn_pipeline
from tg_intrinsic.transforms import CleanMesh, EstimateNormals, LogMap
from tests.conftest import grid_mesh, icosphere
from tests.symmetry import gauge_change, rotate_frames
from tests.transforms.conftest import (RADIUS, angle_gap, assert_hsn_inputs,
                                       assert_point_cloud_operators, hsn,
                                       sphere_data, sphere_pos_face)


def plane_frames(n, angle):
    """Frames of the z = 0 plane, e_u at ``angle`` from the x axis."""
    base = torch.eye(3, dtype=angle.dtype).repeat(n, 1, 1)
    return rotate_frames(base, angle)


def test_inputs_are_not_mutated_and_frames_are_used_as_given():
    data = sphere_data(2)
    before = data.pos.clone()
    gen = torch.Generator().manual_seed(0)
    frame = tangent_frames(vertex_normals(data.pos, data.face))
    angle = torch.rand(data.num_nodes, dtype=torch.float64, generator=gen)
    c, s = torch.cos(angle)[:, None], torch.sin(angle)[:, None]
    turned = torch.stack([c * frame[:, 0] + s * frame[:, 1],
                          -s * frame[:, 0] + c * frame[:, 1], frame[:, 2]], 1)
    data.frame = turned
    out = LogMap(0.3)(data)
    assert torch.equal(data.pos, before) and 'logmap' not in data
    assert torch.equal(out.frame, turned)
    # turning frame i by a shifts theta_ij by -a (here: against the default
    # frames)
    ref = LogMap(0.3)(Data(pos=data.pos, face=data.face))
    j, i = out.edge_index
    off = out.logmap[:, 0] > 0
    delta = torch.remainder(out.logmap[off, 1] - ref.logmap[off, 1]
                            + angle[i[off]] + math.pi, 2 * math.pi) - math.pi
    assert delta.abs().max() < 1e-9


def test_log_map_of_a_cloud_without_normals_estimates_them():
    torch.manual_seed(0)
    pos = torch.randn(200, 3, dtype=torch.float64)
    pos = pos / pos.norm(dim=1, keepdim=True)
    implicit = LogMap(0.5)(Data(pos=pos))
    explicit = LogMap(0.5)(EstimateNormals()(Data(pos=pos)))
    assert torch.equal(implicit.frame, explicit.frame)
    assert torch.equal(implicit.logmap, explicit.logmap)
    # outward normals, as estimate_normals orients them
    assert bool(((implicit.frame[:, 2] * pos).sum(1) > 0).all())


def test_bad_input():
    with pytest.raises(ValueError, match="'data.normal' has 29 rows"):
        LogMap(0.2)(Data(pos=torch.rand(30, 3), normal=torch.rand(29, 3)))
    with pytest.raises(ValueError, match="'method' must be one of"):
        LogMap(0.2, method='exact')
    assert repr(LogMap(0.2)) == \
        "LogMap(radius=0.2, method='fast', max_neighbors=None, transport=True)"


def test_a_non_manifold_edge():
    pos, face = sphere_pos_face()
    a, b = int(face[0, 0]), int(face[1, 0])
    fin = 0.65 * (pos[a] + pos[b])  # a third triangle on edge (a, b)
    data = Data(pos=torch.cat([pos, fin[None]]),
                face=torch.cat([face, torch.tensor([[a], [b],
                                                    [pos.size(0)]])], 1))
    cleaned = CleanMesh()(data)  # keeps it (documented)
    assert cleaned.face.size(1) == data.face.size(1)
    assert_hsn_inputs(hsn(cleaned), data.num_nodes)  # 'fast' copes
    with pytest.raises(ValueError, match="manifold mesh, use method='fast'"):
        LogMap(RADIUS, method='vector_heat')(cleaned)
    assert_point_cloud_operators(data)


def test_size_check_fires_quickly_on_a_50k_vertex_scan(monkeypatch):
    from tg_intrinsic.geometry.geodesics import logmap as L
    torus = bumpy_torus(50000)
    data = Data(pos=torus.pos.float(), face=torus.face)

    def no_marching(*args, **kwargs):
        raise AssertionError('marched before the size check')
    monkeypatch.setattr(L, 'march_from', no_marching)
    start = time.perf_counter()
    with pytest.raises(ValueError) as info:
        hsn_pipeline()(data)  # the README recipe: unit area, radius 0.2
    print(f'size check on {data.num_nodes} vertices: '
          f'{time.perf_counter() - start:.2f} s')
    message = str(info.value)
    assert 'GiB' in message and 'edges' in message
    assert 'Decimate(' in message and 'FarthestPointResample(' in message


@pytest.mark.parametrize('method', ['fast', 'vector_heat'])
def test_on_a_plane_it_is_the_euclidean_offset_in_the_frame(method):
    pos, face = grid_mesh(6, jitter=0.3)
    n = pos.size(0)
    angle = torch.linspace(-3, 3, n, dtype=pos.dtype)
    out = LogMap(0.45, method=method)(Data(pos=pos, face=face,
                                           frame=plane_frames(n, angle)))
    j, i = out.edge_index
    # the discs: every pair closer than the radius, itself included
    dist = torch.cdist(pos, pos)
    inside = torch.zeros(n, n, dtype=torch.bool)
    inside[j, i] = True
    assert torch.equal(inside, dist < 0.45)
    # (r, theta) of the offset in the standard frame, then every frame i
    # turned by angle[i]; transport along a plane is the identity, so
    # phi_ji = angle[j] - angle[i]
    d = pos[j] - pos[i]
    flat = torch.stack([d[:, :2].norm(dim=1),
                        torch.atan2(d[:, 1], d[:, 0])], 1)
    logmap, transport = gauge_change(out.edge_index, flat,
                                     torch.zeros_like(flat[:, 0]), angle)
    assert torch.allclose(out.logmap[:, 0], logmap[:, 0], atol=1e-12)
    off = logmap[:, 0] > 0
    assert angle_gap(out.logmap[off, 1], logmap[off, 1]) < 1e-9
    assert angle_gap(out.transport, transport) < 1e-9


def test_on_the_unit_sphere_r_is_the_great_circle_distance():
    pos, face = icosphere(2)
    normal = pos / pos.norm(dim=1, keepdim=True)
    out = LogMap(0.5)(Data(pos=normal, face=face, normal=normal))
    j, i = out.edge_index
    a, b = normal[j], normal[i]
    arc = torch.atan2(torch.linalg.cross(a, b).norm(dim=1),
                      (a * b).sum(1))
    assert torch.allclose(out.logmap[:, 0], arc, atol=1e-12)
    assert (arc < 0.5 * 1.05).all() and arc.max() > 0.4
    # theta is the direction of the neighbour seen from the centre: the
    # tangent part of b - a
    frame = out.frame[i]
    d = a - b
    theta = torch.atan2((d * frame[:, 1]).sum(1), (d * frame[:, 0]).sum(1))
    off = arc > 0
    assert angle_gap(out.logmap[off, 1], theta[off]) < 1e-9


def test_keys_shapes_dtypes_and_area():
    pos, face = icosphere(2)
    data = Data(pos=pos.float(), face=face)
    out = LogMap(0.5)(data)
    e, n = out.edge_index.size(1), pos.size(0)
    assert out.edge_index.dtype == torch.long
    for key, shape in [('logmap', (e, 2)), ('transport', (e, )),
                       ('area', (n, )), ('frame', (n, 3, 3)),
                       ('logmap_radius', (1, ))]:
        assert tuple(out[key].shape) == shape, key
        assert out[key].dtype == torch.float32, key
    assert float(out.logmap_radius) == 0.5
    loops = out.edge_index[0] == out.edge_index[1]
    assert int(loops.sum()) == n and (out.logmap[loops, 0] == 0).all()
    # a third of the incident triangle areas: they add up to the surface
    a, b, c = pos[face[0]], pos[face[1]], pos[face[2]]
    total = 0.5 * torch.linalg.cross(b - a, c - a).norm(dim=1).sum()
    assert torch.isclose(out.area.double().sum(), total, rtol=1e-6)
    assert (out.area > 0).all()
    without = LogMap(0.5, transport=False)(data)
    assert 'transport' not in without
    assert torch.equal(without.logmap, out.logmap)


def test_max_neighbors_keeps_the_nearest_of_every_disc():
    data = sphere_data(2)
    full = LogMap(0.6)(data)
    capped = LogMap(0.6, max_neighbors=5)(data)
    n = data.num_nodes
    count = torch.bincount(capped.edge_index[1], minlength=n)
    assert (count == 5).all()
    assert full.edge_index.size(1) > 2 * capped.edge_index.size(1)
    # the nearest by fast marching, which r of the log map matches to
    # about 1e-3
    for centre in range(n):
        kept = capped.edge_index[0, capped.edge_index[1] == centre]
        disc = full.edge_index[1] == centre
        r = full.logmap[disc, 0]
        chosen = torch.isin(full.edge_index[0, disc], kept)
        assert int(chosen.sum()) == 5
        if not chosen.all():
            assert r[chosen].max() <= r[~chosen].min() + 0.005


def test_memory_limit_says_what_fits_and_the_advice_works():
    pos, face = icosphere(2)
    data = Data(pos=pos, face=face)
    with pytest.raises(ValueError, match='above max_memory') as info:
        LogMap(0.5, max_memory=300000)(data)
    cap = int(str(info.value).split('max_neighbors=')[1].split(';')[0])
    out = LogMap(0.5, max_neighbors=cap, max_memory=300000)(data)
    assert (torch.bincount(out.edge_index[1]) <= cap).all()
    assert LogMap(0.5, max_memory=None)(data).edge_index.size(1) > \
        out.edge_index.size(1)


def test_bad_values_are_named():
    pos, face = icosphere(1)
    # checked when the transform is built, not when it first runs
    for radius in (0.0, -0.1):
        with pytest.raises(ValueError, match="'radius' must be positive"):
            LogMap(radius)
    with pytest.raises(ValueError, match="'radius' must be finite"):
        LogMap(float('nan'))
    with pytest.raises(ValueError, match="'max_memory' must be a positive"):
        LogMap(0.2, max_memory=0)
    with pytest.raises(ValueError, match="'max_neighbors' must be at least"):
        LogMap(0.5, max_neighbors=0)
    with pytest.raises(ValueError, match="'data.pos'"):
        LogMap(0.5)(Data(x=pos))
    with pytest.raises(ValueError, match='right-handed'):
        LogMap(0.5)(Data(pos=pos, face=face, frame=-torch.eye(
            3, dtype=pos.dtype).repeat(pos.size(0), 1, 1)))
    assert repr(LogMap(0.3, method='vector_heat', max_neighbors=8,
                       max_memory=1e6)) == (
        "LogMap(radius=0.3, method='vector_heat', max_neighbors=8, "
        "transport=True, max_memory=1000000.0)")
    assert 'transport=False' in repr(LogMap(0.3, transport=False))
