import time

import numpy as np
import pytest
import torch
from torch_geometric.data import Batch, Data
from torch_geometric.transforms import Compose

from tg_intrinsic.data import IntrinsicData
from tg_intrinsic.datasets import bumpy_torus
from tg_intrinsic.nn.models import HSNClassification, HSNSegmentation
from tg_intrinsic.train import hsn_pipeline
from tg_intrinsic.transforms import (CleanMesh, Decimate,
                                     FarthestPointResample,
                                     HarmonicPrecompute)
from tests.transforms.conftest import apply, pipeline, sphere_data


# The whole HSN precomputation (NormalizeArea, LogMap, MultiscaleSupports,
# HarmonicPrecompute): integration tests kept with its last transform.
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


def test_bad_input():
    with pytest.raises(ValueError, match='run LogMap'):
        HarmonicPrecompute()(sphere_data(1))
