import math

import pytest
import torch
from torch_geometric.data import Batch, Data

from tg_intrinsic.data import IntrinsicData
from tg_intrinsic.geometry import tangent_frames, vertex_normals
from tg_intrinsic.nn.models import HSNClassification, HSNSegmentation
from tg_intrinsic.transforms import (EstimateNormals, HarmonicPrecompute,
                                     LogMap, MultiscaleSupports,
                                     NormalizeArea, ParallelTransport,
                                     RandomRotation)
from tests.conftest import icosphere


def angle_gap(a, b):
    return float((torch.remainder(a - b + math.pi, 2 * math.pi)
                  - math.pi).abs().max())


def sphere_data(subdivisions=3):
    """A bumpy sphere (no symmetric ties between distances)."""
    pos, face = icosphere(subdivisions)
    gen = torch.Generator().manual_seed(0)
    pos = pos * (1 + 0.05 * torch.rand(pos.size(0), 1, dtype=pos.dtype,
                                       generator=gen))
    return Data(pos=pos, face=face, x=pos.clone())


def pipeline(method='fast', max_order=1):
    return [NormalizeArea(), LogMap(0.2, method=method),
            MultiscaleSupports([0.25], [0.4], method=method),
            HarmonicPrecompute(rings=4, max_order=max_order)]


def apply(data, transforms):
    for t in transforms:
        data = t(data)
    return data


def test_pipeline_writes_every_level_key_and_batches():
    data = apply(sphere_data(), pipeline())
    assert isinstance(data, IntrinsicData)
    n, n1 = data.num_nodes, data.pos_1.size(0)
    assert n1 == round(0.25 * n)
    for key, shape in [('logmap', (data.edge_index.size(1), 2)),
                       ('transport', (data.edge_index.size(1),)),
                       ('area', (n,)), ('cluster_1', (n,)),
                       ('pool_transport_1', (n,)), ('area_1', (n1,)),
                       ('logmap_1', (data.edge_index_1.size(1), 2)),
                       ('harmonic', (data.edge_index.size(1), 4, 2))]:
        assert tuple(data[key].shape) == shape, key
    # discs: within eps (the disc test is by fast marching, r by the log
    # map, so they may differ slightly), self-loops present, areas add up
    assert (data.logmap[:, 0] < 0.2 * 1.05).all()
    assert (data.logmap_1[:, 0] < 0.4 * 1.05).all()
    assert int((data.edge_index[0] == data.edge_index[1]).sum()) == n
    assert torch.allclose(data.area.sum(), torch.tensor(1.0,
                                                        dtype=torch.float64))
    assert torch.allclose(data.area_1.sum(), data.area.sum())
    # every sample is in its own cell and pools with angle 0
    sample = data.sample_index_1
    assert (data.cluster_1[sample] == torch.arange(n1)).all()
    assert (data.pool_transport_1[sample] == 0).all()
    # batching offsets every level index
    batch = Batch.from_data_list([data, data])
    assert batch.edge_index_1.max() == 2 * n1 - 1
    assert batch.cluster_1[n:].min() == n1
    assert batch.sample_index_1[n1:].min() == n + sample.min()
    assert (batch.level_batch(1) == torch.arange(2).repeat_interleave(n1)
            ).all()


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


def test_rotation_augmentation_keeps_precomputation_valid():
    data = apply(sphere_data(2), pipeline())
    torch.manual_seed(0)
    rotated = RandomRotation()(data)
    rebuilt = apply(Data(pos=rotated.pos, face=data.face, x=data.x,
                         frame=rotated.frame), pipeline())
    # equal up to the order of equidistant neighbours
    for level in ('', '_1'):
        orders = []
        for d in (rebuilt, rotated):
            j, i = d['edge_index' + level]
            orders.append(torch.argsort(i * 10 ** 6 + j))
        a, b = orders
        assert torch.equal(rebuilt['edge_index' + level][:, a],
                           rotated['edge_index' + level][:, b])
        assert torch.allclose(rebuilt['logmap' + level][a, 0],
                              rotated['logmap' + level][b, 0], atol=1e-9)
        assert angle_gap(rebuilt['logmap' + level][a, 1],
                         rotated['logmap' + level][b, 1]) < 1e-9
        assert angle_gap(rebuilt['transport' + level][a],
                         rotated['transport' + level][b]) < 1e-9
    assert angle_gap(rebuilt.pool_transport_1, rotated.pool_transport_1
                     ) < 1e-9
    assert torch.allclose(rotated.pos_1, rotated.pos[data.sample_index_1])


@pytest.mark.parametrize('Model', [HSNClassification, HSNSegmentation])
def test_models_run_on_precomputed_meshes_and_are_gauge_invariant(Model):
    torch.manual_seed(0)
    model = Model(3, 4, channels=(4, 8), rings=4).double().eval()
    data = apply(sphere_data(2), pipeline())
    # the same mesh with every frame turned by a random angle
    gen = torch.Generator().manual_seed(1)
    angle = torch.rand(data.num_nodes, dtype=torch.float64, generator=gen) * 6
    frame = data.frame
    c, s = torch.cos(angle)[:, None], torch.sin(angle)[:, None]
    turned = torch.stack([c * frame[:, 0] + s * frame[:, 1],
                          -s * frame[:, 0] + c * frame[:, 1], frame[:, 2]], 1)
    data2 = apply(Data(pos=data.pos, face=data.face, x=data.x, frame=turned),
                  pipeline())
    out, out2 = model(data), model(data2)
    assert torch.isfinite(out).all()
    assert (out2 - out).abs().max() <= 1e-8 * out.abs().max()


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
    with pytest.raises(ValueError, match='apply LogMap'):
        ParallelTransport()(sphere_data(1))
    with pytest.raises(ValueError, match='apply LogMap'):
        MultiscaleSupports([0.25], [0.4])(sphere_data(1))
    with pytest.raises(ValueError, match='decrease within'):
        MultiscaleSupports([0.5, 0.7], [0.4, 0.8])
    with pytest.raises(ValueError, match='run LogMap'):
        HarmonicPrecompute()(sphere_data(1))
    with pytest.raises(ValueError, match='NormalizeArea needs a mesh'):
        NormalizeArea()(Data(pos=torch.rand(5, 3)))
    assert repr(LogMap(0.2)) == \
        "LogMap(radius=0.2, method='fast', max_neighbors=None)"
