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
                                     HarmonicPrecompute, LogMap,
                                     MultiscaleSupports)
from tests.symmetry import gauge_change, rotate_streams
from tests.transforms.conftest import apply, pipeline, sphere_data


def expected_terms(edge_index, logmap, area, radius, rings, max_order):
    """h[e, q, m] = w_j / sum_k w_k * hat_q(r) * e^{i m theta}, computed
    edge by edge: hat_q the tent around q * radius / rings reaching the
    neighbouring rings, zero from the radius on; no m != 0 term at r = 0."""
    j, i = edge_index.tolist()
    total = {}
    for a, b in zip(j, i):
        total[b] = total.get(b, 0.0) + float(area[a])
    out = torch.zeros(len(j), rings, max_order + 1, dtype=torch.complex128)
    for e, (a, b) in enumerate(zip(j, i)):
        r, theta = float(logmap[e, 0]), float(logmap[e, 1])
        w = float(area[a]) / total[b]
        for q in range(rings):
            hat = max(0.0, 1.0 - abs(r * rings / radius - q)) \
                if r < radius else 0.0
            for m in range(max_order + 1):
                if m > 0 and r == 0:
                    continue
                out[e, q, m] = w * hat * complex(np.cos(m * theta),
                                                 np.sin(m * theta))
    return out


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


def test_terms_are_the_weighted_rings_and_phases_of_every_edge():
    data = LogMap(0.3)(sphere_data(2))
    out = HarmonicPrecompute(rings=5, max_order=2)(data)
    e = data.edge_index.size(1)
    assert out.harmonic.shape == (e, 5, 3)
    assert out.harmonic.dtype == torch.complex128
    want = expected_terms(data.edge_index, data.logmap, data.area, 0.3, 5, 2)
    assert torch.allclose(out.harmonic, want, atol=1e-12)
    assert 'harmonic' not in data  # the input is not mutated


def test_turning_the_frames_turns_order_m_by_m_times_the_angle():
    data = LogMap(0.3)(sphere_data(2))
    angle = torch.rand(data.num_nodes, dtype=torch.float64,
                       generator=torch.Generator().manual_seed(0)) * 6
    turned = data.clone()
    turned.logmap, turned.transport = gauge_change(
        data.edge_index, data.logmap, data.transport, angle)
    a = HarmonicPrecompute(rings=3, max_order=2)(data).harmonic
    b = HarmonicPrecompute(rings=3, max_order=2)(turned).harmonic
    # the term of edge (j -> i) lives in the frame of the centre i
    i = data.edge_index[1]
    want = rotate_streams(a.transpose(1, 2), angle[i]).transpose(1, 2)
    assert torch.allclose(b, want, atol=1e-12)
    assert not torch.allclose(a[:, :, 1], b[:, :, 1], atol=1e-3)


def test_levels_are_precomputed_as_asked():
    data = MultiscaleSupports([0.25, 0.0625], [0.4, 0.8],
                              level0_radius=0.2)(sphere_data(3))
    every = HarmonicPrecompute(rings=4)(data)
    for level in (1, 2):
        suffix = f'_{level}'
        want = expected_terms(data['edge_index' + suffix],
                              data['logmap' + suffix],
                              data['area' + suffix],
                              float(data['logmap_radius' + suffix]), 4, 1)
        assert torch.allclose(every['harmonic' + suffix], want, atol=1e-12)
    one = HarmonicPrecompute(rings=4, levels=1)(data)
    assert 'harmonic_1' in one and 'harmonic_2' not in one
    none = HarmonicPrecompute(rings=4, levels=0)(data)
    assert 'harmonic' in none and 'harmonic_1' not in none
    assert torch.equal(none.harmonic, every.harmonic)


def test_float32_gives_complex64():
    data = LogMap(0.3)(sphere_data(2))
    single = data.clone()
    for key in ('pos', 'logmap', 'area', 'logmap_radius', 'transport'):
        single[key] = data[key].float()
    out = HarmonicPrecompute(rings=3)(single)
    assert out.harmonic.dtype == torch.complex64
    ref = HarmonicPrecompute(rings=3)(data).harmonic
    assert torch.allclose(out.harmonic.to(torch.complex128), ref, atol=1e-6)


def test_bad_values_are_named():
    data = LogMap(0.3)(sphere_data(2))
    # checked when the transform is built
    with pytest.raises(ValueError, match="'rings' must be at least 1"):
        HarmonicPrecompute(rings=0)
    with pytest.raises(ValueError, match="'max_order' must be at least 0"):
        HarmonicPrecompute(max_order=-1)
    with pytest.raises(ValueError, match="'levels' must be an integer"):
        HarmonicPrecompute(levels=1.5)
    broken = data.clone()
    broken.area = -broken.area
    with pytest.raises(ValueError, match='non-negative'):
        HarmonicPrecompute()(broken)
    levels = MultiscaleSupports([0.25], [0.6])(data)
    del levels.area_1
    with pytest.raises(ValueError, match="needs 'data.area_1'"):
        HarmonicPrecompute()(levels)
    assert repr(HarmonicPrecompute()) == \
        'HarmonicPrecompute(rings=6, max_order=1)'
    assert repr(HarmonicPrecompute(rings=4, max_order=3)) == \
        'HarmonicPrecompute(rings=4, max_order=3)'
