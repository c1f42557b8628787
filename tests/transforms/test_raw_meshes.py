"""Real-mesh conditions, end to end: every one either runs through the
Harmonic Surface Network precomputation (and, sampled as a point cloud,
through DeltaNet's operators) after the documented transform, or fails
with a ValueError that says what to do. Also a raw scan to HSN inputs in
one Compose, and the size check on a 50k-vertex scan."""
import time

import numpy as np
import pytest
import torch
from torch_geometric.data import Data
from torch_geometric.transforms import Compose, SamplePoints

from tg_intrinsic.datasets import bumpy_torus
from tg_intrinsic.io.mesh import read_mesh
from tg_intrinsic.train import hsn_pipeline
from tg_intrinsic.transforms import (CleanMesh, Decimate,
                                     FarthestPointResample, LogMap,
                                     MLSOperators)
from tests.conftest import icosphere

RADIUS = 0.15  # smaller than the paper's 0.2: the same code, faster


def hsn(data):
    return hsn_pipeline(radius=RADIUS, rings=4)(data)


def assert_hsn_inputs(out, num_nodes):
    assert out.num_nodes == num_nodes
    for key in ('logmap', 'transport', 'harmonic', 'area', 'logmap_1',
                'transport_1', 'harmonic_1', 'pool_transport_1'):
        assert torch.isfinite(out[key]).all(), key
    e = out.edge_index.size(1)
    assert out.logmap.shape == (e, 2) and out.harmonic.shape[0] == e
    assert num_nodes < e < num_nodes ** 2  # discs, not single points
    loops = out.edge_index[0] == out.edge_index[1]
    assert int(loops.sum()) == num_nodes
    assert torch.isclose(out.area.sum().double(),
                         torch.tensor(1.0, dtype=torch.float64), atol=1e-4)
    assert (out.logmap[:, 0] < RADIUS * 1.05).all()


def assert_point_cloud_operators(mesh, num_points=512):
    torch.manual_seed(0)
    cloud = SamplePoints(num_points, include_normals=True)(
        Data(pos=mesh.pos.float(), face=mesh.face))
    out = MLSOperators(k=16)(cloud)
    assert out.num_nodes == num_points
    assert out.grad_weight.shape == (out.edge_index.size(1), 2)
    for key in ('grad_weight', 'div_weight', 'frame'):
        assert torch.isfinite(out[key]).all(), key


def sphere(subdivisions=3, scale=1.0, offset=0.0):
    pos, face = icosphere(subdivisions)
    return scale * pos + offset, face


def test_several_components():
    (p1, f1), (p2, f2) = sphere(), sphere(2, 0.5, 3.0)
    data = Data(pos=torch.cat([p1, p2]),
                face=torch.cat([f1, f2 + p1.size(0)], 1))
    out = hsn(CleanMesh()(data))  # every component kept
    assert_hsn_inputs(out, data.num_nodes)
    part = (torch.arange(data.num_nodes) >= p1.size(0)).long()
    assert torch.equal(part[out.edge_index[0]], part[out.edge_index[1]])
    assert_hsn_inputs(hsn(CleanMesh(largest_component=True)(data)),
                      p1.size(0))
    assert_point_cloud_operators(data)


def test_unreferenced_vertices():
    pos, face = sphere()
    stray = torch.tensor([[3.0, 0, 0], [0, 3.0, 0]], dtype=pos.dtype)
    data = Data(pos=torch.cat([pos, stray]), face=face)
    with pytest.raises(ValueError, match='not referenced'):
        hsn(data)
    assert_hsn_inputs(hsn(CleanMesh()(data)), pos.size(0))
    assert_point_cloud_operators(data)


def test_duplicate_vertices_of_a_triangle_soup():
    pos, face = sphere()
    corners = face.t().reshape(-1)
    soup = Data(pos=pos[corners],
                face=torch.arange(corners.numel()).view(-1, 3).t())
    with pytest.raises(ValueError, match='CleanMesh'):
        hsn(soup)
    assert_hsn_inputs(hsn(CleanMesh()(soup)), pos.size(0))
    assert_point_cloud_operators(soup)


def test_a_non_manifold_edge():
    pos, face = sphere()
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


def test_quads_and_a_pentagon_from_an_obj_file(tmp_path):
    # a pentagonal prism: two pentagons and five quads
    angle = np.linspace(0, 2 * np.pi, 6)[:-1]
    ring = np.stack([np.cos(angle), np.sin(angle), np.ones(5)], 1)
    lines = [f'v {x} {y} {z}' for x, y, z in
             np.concatenate([ring * [1, 1, -1], ring])]
    lines += ['f 5 4 3 2 1', 'f 6 7 8 9 10']
    lines += [f'f {k + 1} {(k + 1) % 5 + 1} {(k + 1) % 5 + 6} {k + 6}'
              for k in range(5)]
    path = tmp_path / 'prism.obj'
    path.write_text('\n'.join(lines) + '\n')
    pos, face = read_mesh(str(path))  # polygons come back as fans
    assert face.shape == (2 * 3 + 5 * 2, 3)
    data = Data(pos=torch.from_numpy(pos), face=torch.from_numpy(face).t())
    with pytest.raises(ValueError, match='FarthestPointResample'):
        hsn(data)  # ten vertices: every disc would hold only its centre
    out = hsn(Compose([CleanMesh(), FarthestPointResample(300)])(data))
    assert_hsn_inputs(out, 300)
    assert_point_cloud_operators(data)


def test_fewer_vertices_than_requested_points():
    pos, face = sphere(1)  # 42 vertices
    data = Data(pos=pos, face=face, y=(pos[:, 2] > 0).long())
    resampled = FarthestPointResample(1024)(data)
    assert resampled.y.shape == (1024,)
    assert_hsn_inputs(hsn(resampled), 1024)
    assert_point_cloud_operators(data, num_points=1024)


def test_raw_scan_to_hsn_inputs_in_one_compose():
    torus = bumpy_torus(20000)  # 20,000 vertices
    corners = torus.face.t().reshape(-1)
    stray = torch.randn(10, 3, dtype=torch.float64)
    raw = Data(  # a float32 triangle soup with stray points and labels
        pos=torch.cat([torus.pos[corners], stray]).float(),
        face=torch.arange(corners.numel()).view(-1, 3).t(),
        y=torch.cat([(torus.uv[corners, 0] > np.pi).long(),
                     torch.zeros(10, dtype=torch.long)]))
    pipeline = Compose([CleanMesh(), Decimate(5000),
                        FarthestPointResample(1024), hsn_pipeline()])
    start = time.perf_counter()
    out = pipeline(raw)
    print(f'raw 20k-vertex soup to HSN inputs: '
          f'{time.perf_counter() - start:.2f} s')
    assert out.pos.dtype == torch.float32
    assert out.y.shape == (1024,) and set(out.y.tolist()) == {0, 1}
    for key in ('logmap', 'transport', 'harmonic', 'harmonic_1'):
        assert torch.isfinite(out[key]).all()
    assert 1024 * 20 < out.edge_index.size(1) < 1024 * 400


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
