import math
import time

import pytest
import torch
from torch_geometric.data import Data

from tg_intrinsic.datasets import bumpy_torus
from tg_intrinsic.geometry import tangent_frames, vertex_normals
from tg_intrinsic.train import hsn_pipeline
from tg_intrinsic.transforms import CleanMesh, EstimateNormals, LogMap
from tests.transforms.conftest import (RADIUS, assert_hsn_inputs,
                                       assert_point_cloud_operators, hsn,
                                       sphere_data, sphere_pos_face)


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
        "LogMap(radius=0.2, method='fast', max_neighbors=None)"


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
