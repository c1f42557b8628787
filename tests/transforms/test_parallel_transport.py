import pytest
import torch
from torch_geometric.data import Data

from tg_intrinsic.transforms import LogMap, ParallelTransport
from tests.conftest import grid_mesh, icosphere
from tests.symmetry import gauge_change, rotate_frames
from tests.transforms.conftest import angle_gap, sphere_data


def edge_lookup(edge_index, n):
    """Index of the edge (j -> i) for given j and i."""
    j, i = edge_index
    table = torch.full((n * n, ), -1, dtype=torch.long)
    table[j * n + i] = torch.arange(j.numel())
    return lambda a, b: table[a * n + b]


def unit_sphere_discs(method='fast'):
    pos, face = icosphere(2)
    pos = pos / pos.norm(dim=1, keepdim=True)
    data = LogMap(0.5, transport=False)(Data(pos=pos, face=face,
                                             normal=pos.clone()))
    return ParallelTransport(method)(data), face


def test_bad_input():
    with pytest.raises(ValueError, match='apply LogMap'):
        ParallelTransport()(sphere_data(1))


@pytest.mark.parametrize('method', ['fast', 'vector_heat'])
def test_a_plane_does_not_turn_vectors(method):
    pos, face = grid_mesh(6, jitter=0.3)
    n = pos.size(0)
    frame = torch.eye(3, dtype=pos.dtype).repeat(n, 1, 1)
    data = LogMap(0.45, transport=False)(Data(pos=pos, face=face,
                                              frame=frame))
    out = ParallelTransport(method)(data)
    assert out.transport.shape == (data.edge_index.size(1), )
    assert out.transport.abs().max() < 1e-9
    # with turned frames only the frames' difference remains
    angle = torch.linspace(-3, 3, n, dtype=pos.dtype)
    data.frame = rotate_frames(frame, angle)
    out = ParallelTransport(method)(data)
    _, want = gauge_change(data.edge_index, data.logmap,
                           torch.zeros_like(out.transport), angle)
    assert angle_gap(out.transport, want) < 1e-9


@pytest.mark.parametrize('method,tolerance', [('fast', 1e-9),
                                              ('vector_heat', 0.008)])
def test_holonomy_of_a_sphere_triangle_is_its_area(method, tolerance):
    """Around a geodesic triangle of the unit sphere a vector turns by the
    enclosed area (the spherical excess), counter-clockwise seen from
    outside; the frames drop out of the sum."""
    out, face = unit_sphere_discs(method)
    edge = edge_lookup(out.edge_index, out.num_nodes)
    a, b, c = face
    phi = out.transport
    turn = phi[edge(a, b)] + phi[edge(b, c)] + phi[edge(c, a)]
    pa, pb, pc = out.pos[a], out.pos[b], out.pos[c]
    triple = (pa * torch.linalg.cross(pb, pc)).sum(1)
    excess = 2 * torch.atan2(triple.abs(), 1 + (pa * pb).sum(1)
                             + (pb * pc).sum(1) + (pc * pa).sum(1))
    assert excess.min() > 0.03  # measurable against the tolerance
    assert angle_gap(turn, torch.sign(triple) * excess) < tolerance


def test_transport_back_is_the_inverse_and_frames_change_it_by_gauge():
    out, _ = unit_sphere_discs()
    edge = edge_lookup(out.edge_index, out.num_nodes)
    j, i = out.edge_index
    back = edge(i, j)
    assert (back >= 0).all()
    assert angle_gap(out.transport[back], -out.transport) < 1e-12
    angle = torch.rand(out.num_nodes, dtype=torch.float64,
                       generator=torch.Generator().manual_seed(0)) * 6
    turned = out.clone()
    turned.frame = rotate_frames(out.frame, angle)
    moved = ParallelTransport()(turned)
    _, want = gauge_change(out.edge_index, out.logmap, out.transport, angle)
    assert angle_gap(moved.transport, want) < 1e-9


def test_overwrites_the_transport_of_log_map_and_nothing_else():
    data = LogMap(0.3)(sphere_data(2))
    stale = data.clone()
    stale.transport = torch.zeros_like(data.transport)
    out = ParallelTransport()(stale)
    assert torch.allclose(out.transport, data.transport, atol=1e-12)
    assert out.transport.abs().max() > 0.01
    assert torch.equal(stale.transport, torch.zeros_like(data.transport))
    for key in ('edge_index', 'logmap', 'area', 'frame', 'pos'):
        assert torch.equal(out[key], data[key]), key
    assert set(out.keys()) == set(data.keys())


def test_bad_values_are_named():
    with pytest.raises(ValueError, match="'method' must be one of"):
        ParallelTransport('exact')
    data = LogMap(0.3)(sphere_data(2))
    data.frame = 2 * data.frame
    with pytest.raises(ValueError, match='orthonormal'):
        ParallelTransport()(data)
    assert repr(ParallelTransport()) == "ParallelTransport(method='fast')"
    assert repr(ParallelTransport('vector_heat')) == \
        "ParallelTransport(method='vector_heat')"
