"""CleanMesh: welding, unreferenced vertices, degenerate and duplicate
triangles, polygons, components, attributes carried through."""
import pytest
import torch
from torch_geometric.data import Data

from tg_intrinsic.geometry import face_areas, is_closed_manifold
from tg_intrinsic.transforms import CleanMesh
from tests.conftest import icosphere
from tests.transforms.conftest import (assert_hsn_inputs,
                                       assert_point_cloud_operators, hsn,
                                       sphere_pos_face)


def sphere(subdivisions=2):
    pos, face = icosphere(subdivisions)
    return Data(pos=pos, face=face, y=torch.arange(pos.size(0)),
                normal=pos.clone())


def test_a_clean_mesh_comes_back_unchanged_and_the_input_is_not_mutated():
    data = sphere()
    before = data.pos.clone()
    out = CleanMesh()(data)
    assert torch.equal(out.pos, data.pos) and torch.equal(out.face, data.face)
    assert torch.equal(out.y, data.y) and torch.equal(data.pos, before)
    assert out is not data


def test_welds_a_triangle_soup_and_keeps_the_first_copy_attributes():
    data = sphere()
    corners = data.face.t().reshape(-1)
    soup = Data(pos=data.pos[corners], face=torch.arange(corners.numel())
                .view(-1, 3).t().contiguous(), y=data.y[corners],
                normal=data.normal[corners])
    out = CleanMesh()(soup)
    assert out.num_nodes == data.num_nodes
    assert out.face.size(1) == data.face.size(1)
    assert is_closed_manifold(out.face, out.num_nodes)
    # every output vertex carries the label of the input vertex it welds
    assert torch.equal(out.pos, data.pos[out.y])
    assert torch.equal(out.normal, data.normal[out.y])
    # the same surface
    assert torch.allclose(face_areas(out.pos, out.face).sum(),
                          face_areas(data.pos, data.face).sum())


def test_welds_within_a_tolerance():
    data = sphere()
    corners = data.face.t().reshape(-1)
    noisy = data.pos[corners] + 1e-9 * torch.randn(corners.numel(), 3,
                                                   dtype=torch.float64)
    soup = Data(pos=noisy, face=torch.arange(corners.numel()).view(-1, 3).t())
    assert CleanMesh()(soup).num_nodes == corners.numel()
    assert CleanMesh(weld_tolerance=1e-6)(soup).num_nodes == data.num_nodes


def test_drops_unreferenced_nan_degenerate_and_duplicate_faces():
    data = sphere()
    n, f = data.num_nodes, data.face.size(1)
    extra_pos = torch.tensor([[5.0, 5, 5], [float('nan'), 0, 0],
                              [0.5, 0.5, 0.5]], dtype=torch.float64)
    a, b = data.face[0, 0], data.face[1, 0]
    mid = (data.pos[a] + data.pos[b]) / 2
    pos = torch.cat([data.pos, extra_pos, mid[None]])
    extra_face = torch.tensor([
        [a, a, b],          # repeated corner
        [a, b, n + 3],      # zero area: n + 3 is the midpoint of a-b
        [a, n + 1, b],      # a NaN corner
    ]).t()
    face = torch.cat([data.face, extra_face, data.face[:, :4],
                      data.face[:, 4:6].flip(0)], 1)  # copies, reversed too
    out = CleanMesh()(Data(pos=pos, face=face, y=torch.arange(n + 4)))
    assert out.num_nodes == n and out.face.size(1) == f
    assert torch.equal(out.y, torch.arange(n))
    assert is_closed_manifold(out.face, out.num_nodes)


def test_polygons_become_fans_and_face_attributes_follow():
    # a unit cube of quads; one face given as a triangle padded with -1
    pos = torch.tensor([[x, y, z] for x in (0., 1.) for y in (0., 1.)
                        for z in (0., 1.)], dtype=torch.float64)
    quads = torch.tensor([[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1],
                          [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, -1],
                          [1, 7, 3, -1]]).t()
    label = torch.arange(7) * 10
    out = CleanMesh()(Data(pos=pos, face=quads, face_label=label))
    assert out.face.shape == (3, 12)
    assert is_closed_manifold(out.face, 8)
    assert torch.equal(out.face_label, torch.tensor(
        [0, 0, 10, 10, 20, 20, 30, 30, 40, 40, 50, 60]))
    assert torch.isclose(face_areas(out.pos, out.face).sum(),
                         torch.tensor(6.0, dtype=torch.float64))


def test_components_kept_or_only_the_largest():
    a, b = sphere(), sphere(1)
    b.pos = 0.3 * b.pos + 4.0
    data = Data(pos=torch.cat([a.pos, b.pos]),
                face=torch.cat([a.face, b.face + a.num_nodes], 1),
                y=torch.cat([torch.zeros(a.num_nodes), torch.ones(b.num_nodes)
                             ]).long())
    both = CleanMesh()(data)
    assert both.num_nodes == data.num_nodes
    largest = CleanMesh(largest_component=True)(data)
    assert largest.num_nodes == a.num_nodes and (largest.y == 0).all()
    # by area, not by vertex count: a big coarse sphere beats a small fine
    big = sphere(1)
    big.pos = 10 * big.pos
    data = Data(pos=torch.cat([a.pos, big.pos + 30]),
                face=torch.cat([a.face, big.face + a.num_nodes], 1))
    assert CleanMesh(largest_component=True)(data).num_nodes == big.num_nodes


def test_bad_input_says_what_to_do():
    with pytest.raises(ValueError, match='point cloud'):
        CleanMesh()(Data(pos=torch.rand(10, 3)))
    data = sphere()
    with pytest.raises(ValueError, match='before transforms that build'):
        CleanMesh()(Data(pos=data.pos, face=data.face,
                         edge_index=torch.zeros(2, 1, dtype=torch.long)))
    with pytest.raises(ValueError, match='outside'):
        CleanMesh()(Data(pos=data.pos, face=data.face + 1000))
    with pytest.raises(ValueError, match='no triangle'):
        CleanMesh()(Data(pos=torch.zeros(3, 3, dtype=torch.float64),
                         face=torch.tensor([[0], [1], [2]])))
    with pytest.raises(ValueError, match='weld_tolerance'):
        CleanMesh(weld_tolerance=-1)


def test_repr():
    assert repr(CleanMesh()) == \
        'CleanMesh(weld_tolerance=0.0, largest_component=False)'


# Real-mesh conditions, end to end: CleanMesh makes each one run through the
# Harmonic Surface Network precomputation (and, sampled as a point cloud,
# through DeltaNet's operators), or it fails with a ValueError naming it.
def test_several_components():
    (p1, f1), (p2, f2) = sphere_pos_face(), sphere_pos_face(2, 0.5, 3.0)
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
    pos, face = sphere_pos_face()
    stray = torch.tensor([[3.0, 0, 0], [0, 3.0, 0]], dtype=pos.dtype)
    data = Data(pos=torch.cat([pos, stray]), face=face)
    with pytest.raises(ValueError, match='not referenced'):
        hsn(data)
    assert_hsn_inputs(hsn(CleanMesh()(data)), pos.size(0))
    assert_point_cloud_operators(data)


def test_duplicate_vertices_of_a_triangle_soup():
    pos, face = sphere_pos_face()
    corners = face.t().reshape(-1)
    soup = Data(pos=pos[corners],
                face=torch.arange(corners.numel()).view(-1, 3).t())
    with pytest.raises(ValueError, match='CleanMesh'):
        hsn(soup)
    assert_hsn_inputs(hsn(CleanMesh()(soup)), pos.size(0))
    assert_point_cloud_operators(soup)
