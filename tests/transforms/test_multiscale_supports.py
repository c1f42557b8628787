import numpy as np
import pytest
import torch
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra
from torch_geometric.data import Data

from tg_intrinsic.data import IntrinsicData
from tg_intrinsic.transforms import LogMap, MultiscaleSupports
from tests.conftest import grid_mesh
from tests.symmetry import gauge_change, rotate_frames
from tests.transforms.conftest import angle_gap, edge_order, sphere_data


def farthest_points(pos, count):
    """Euclidean farthest point sampling from point 0, sorted."""
    chosen = [0]
    dist = (pos - pos[0]).norm(dim=1)
    for _ in range(count - 1):
        chosen.append(int(dist.argmax()))
        dist = torch.minimum(dist, (pos - pos[chosen[-1]]).norm(dim=1))
    return torch.sort(torch.tensor(chosen)).values


def nearest_sample_along(edge_index, length, sample, n):
    """The sample of the shortest path (Dijkstra) over the graph."""
    j, i = edge_index.numpy()
    graph = coo_matrix((length.numpy() + 1e-300, (j, i)), shape=(n, n))
    _, _, source = dijkstra(graph.tocsr(), directed=False,
                            indices=sample.numpy(), min_only=True,
                            return_predecessors=True)
    local = np.full(n, -1)
    local[sample.numpy()] = np.arange(sample.numel())
    return torch.from_numpy(local[source])


def test_bad_input():
    with pytest.raises(ValueError, match='apply LogMap'):
        MultiscaleSupports([0.25], [0.4])(sphere_data(1))
    with pytest.raises(ValueError, match='decrease within'):
        MultiscaleSupports([0.5, 0.7], [0.4, 0.8])


def test_samples_cells_and_areas_of_a_level():
    data = LogMap(0.2)(sphere_data(3))
    out = MultiscaleSupports([0.25], [0.4])(data)
    n = data.num_nodes
    sample = out.sample_index_1
    # farthest point sampling of the input, and their positions
    assert torch.equal(sample, farthest_points(data.pos, round(0.25 * n)))
    assert torch.equal(out.pos_1, data.pos[sample])
    # every point joins the cell of the sample nearest along the discs
    assert torch.equal(out.cluster_1, nearest_sample_along(
        data.edge_index, data.logmap[:, 0], sample, n))
    # a coarse point's area is its cell's
    want = torch.stack([data.area[out.cluster_1 == c].sum()
                        for c in range(sample.numel())])
    assert torch.allclose(out.area_1, want)
    assert float(out.logmap_radius_1) == 0.4
    assert isinstance(out, IntrinsicData) and 'logmap_1' not in data


def test_coarse_discs_on_a_plane_are_euclidean_in_every_gauge():
    pos, face = grid_mesh(8, jitter=0.3)
    n = pos.size(0)
    angle = torch.linspace(-3, 3, n, dtype=pos.dtype)
    frame = rotate_frames(torch.eye(3, dtype=pos.dtype).repeat(n, 1, 1),
                          angle)
    out = MultiscaleSupports([0.25], [0.6], level0_radius=0.3)(
        Data(pos=pos, face=face, frame=frame))
    coarse = out.sample_index_1
    p1, a1 = pos[coarse], angle[coarse]
    j, i = out.edge_index_1
    # discs of radius 0.6 among the samples
    m = coarse.numel()
    inside = torch.zeros(m, m, dtype=torch.bool)
    inside[j, i] = True
    assert torch.equal(inside, torch.cdist(p1, p1) < 0.6)
    # log map: the Euclidean offset in the (turned) frames of the samples;
    # transport: the frames' difference
    d = p1[j] - p1[i]
    flat = torch.stack([d[:, :2].norm(dim=1),
                        torch.atan2(d[:, 1], d[:, 0])], 1)
    logmap, transport = gauge_change(out.edge_index_1, flat,
                                     torch.zeros_like(flat[:, 0]), a1)
    assert torch.allclose(out.logmap_1[:, 0], logmap[:, 0], atol=1e-12)
    off = logmap[:, 0] > 0
    assert angle_gap(out.logmap_1[off, 1], logmap[off, 1]) < 1e-9
    assert angle_gap(out.transport_1, transport) < 1e-9
    # pooling brings every point into the frame of its sample
    assert angle_gap(out.pool_transport_1,
                     angle - a1[out.cluster_1]) < 1e-9


def test_two_levels_nest_and_level0_radius_runs_log_map():
    data = sphere_data(3)
    out = MultiscaleSupports([0.25, 0.0625], [0.4, 0.8],
                             level0_radius=0.2)(data)
    n = data.num_nodes
    n1, n2 = round(0.25 * n), round(0.0625 * n)
    assert out.pos_1.size(0) == n1 and out.pos_2.size(0) == n2
    # level 2 samples the points of level 1
    assert out.sample_index_2.max() < n1
    assert torch.equal(out.pos_2, out.pos_1[out.sample_index_2])
    assert out.cluster_2.shape == (n1, ) and out.cluster_2.max() == n2 - 1
    assert torch.allclose(out.area_2.sum(), out.area.sum())
    assert out.edge_index_2.max() < n2
    for key, shape in [('logmap_2', (out.edge_index_2.size(1), 2)),
                       ('transport_2', (out.edge_index_2.size(1), )),
                       ('pool_transport_2', (n1, )), ('area_2', (n2, ))]:
        assert tuple(out[key].shape) == shape, key
    # the same as LogMap first
    ref = MultiscaleSupports([0.25, 0.0625], [0.4, 0.8])(LogMap(0.2)(data))
    for key in ('edge_index', 'logmap', 'edge_index_2', 'logmap_2',
                'cluster_2'):
        assert torch.equal(out[key], ref[key]), key


def test_max_neighbors_caps_the_coarse_discs_with_the_nearest():
    data = LogMap(0.2)(sphere_data(3))
    full = MultiscaleSupports([0.25], [0.5])(data)
    capped = MultiscaleSupports([0.25], [0.5], max_neighbors=6)(data)
    m = full.pos_1.size(0)
    assert (torch.bincount(capped.edge_index_1[1], minlength=m) == 6).all()
    assert full.edge_index_1.size(1) > capped.edge_index_1.size(1)
    # the kept neighbours are the nearest (by fast marching, which the
    # log map's r matches to about 1e-3)
    for centre in range(m):
        kept = capped.edge_index_1[0, capped.edge_index_1[1] == centre]
        disc = full.edge_index_1[1] == centre
        r = full.logmap_1[disc, 0]
        chosen = torch.isin(full.edge_index_1[0, disc], kept)
        assert int(chosen.sum()) == 6
        if not chosen.all():
            assert r[chosen].max() <= r[~chosen].min() + 0.005
    a, b = edge_order(full.edge_index), edge_order(capped.edge_index)
    assert torch.equal(full.edge_index[:, a], capped.edge_index[:, b])


def test_bad_values_are_named():
    with pytest.raises(ValueError, match='equal length'):
        MultiscaleSupports([0.25], [0.4, 0.8])
    with pytest.raises(ValueError, match='non-empty'):
        MultiscaleSupports([], [])
    with pytest.raises(ValueError, match="'radii' must be positive"):
        MultiscaleSupports([0.25], [0.0])
    with pytest.raises(ValueError, match='decrease within'):
        MultiscaleSupports([1.5], [0.4])
    with pytest.raises(ValueError, match="'method' must be one of"):
        MultiscaleSupports([0.25], [0.4], method='exact')
    with pytest.raises(ValueError, match="'max_memory' must be a positive"):
        MultiscaleSupports([0.25], [0.4], max_memory=-1)
    with pytest.raises(ValueError, match='level 0 has no discs'):
        MultiscaleSupports([0.25], [0.4])(Data(pos=torch.rand(9, 3)))
    with pytest.raises(ValueError, match='above max_memory'):
        MultiscaleSupports([0.25], [2.0], max_memory=20000)(
            LogMap(0.2)(sphere_data(3)))
    assert repr(MultiscaleSupports([0.25, 0.0625], [0.4, 0.8],
                                   method='vector_heat')) == (
        "MultiscaleSupports(ratios=[0.25, 0.0625], radii=[0.4, 0.8], "
        "method='vector_heat', level0_radius=None, max_neighbors=None)")
    with pytest.raises(ValueError, match="'level0_radius' must be positive"):
        MultiscaleSupports([0.25], [0.4], level0_radius=0)
    with pytest.raises(ValueError, match="'max_neighbors' must be at least"):
        MultiscaleSupports([0.25], [0.4], max_neighbors=0)


def test_given_samples_replace_farthest_point_sampling():
    data = LogMap(0.2)(sphere_data(3))
    n = data.num_nodes
    first = torch.arange(0, n, 3)
    second = torch.arange(0, first.numel(), 4)
    out = MultiscaleSupports([0.3, 0.1], [0.4, 0.8],
                             samples=[first, second])(data)
    assert torch.equal(out.sample_index_1, first)
    assert torch.equal(out.pos_1, data.pos[first])
    assert torch.equal(out.pos_2, data.pos[first[second]])
    # cells as with sampled points: the nearest sample along the discs
    assert torch.equal(out.cluster_1, nearest_sample_along(
        data.edge_index, data.logmap[:, 0], first, n))
    assert 'samples=[' in repr(MultiscaleSupports([0.3], [0.4],
                                                  samples=[first]))
    with pytest.raises(ValueError, match="one non-empty, increasing"):
        MultiscaleSupports([0.3], [0.4], samples=[first.flip(0)])
    with pytest.raises(ValueError, match="one non-empty, increasing"):
        MultiscaleSupports([0.3], [0.4], samples=[first, second])
    with pytest.raises(ValueError, match="index past the"):
        MultiscaleSupports([0.3], [0.4],
                           samples=[torch.tensor([0, n])])(data)
