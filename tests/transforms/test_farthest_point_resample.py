"""FarthestPointResample: the samples are Euclidean farthest points, the
rebuilt mesh is a valid surface on them, labels follow, and meshes with
fewer vertices than asked for are sampled further on their faces."""
import numpy as np
import pytest
import torch
from torch_geometric.data import Data
from torch_geometric.transforms import Compose

from tg_intrinsic.geometry import (edge_face_counts, face_areas, fps,
                                   is_closed_manifold)
from tg_intrinsic.io.mesh import read_mesh
from tg_intrinsic.transforms import CleanMesh, FarthestPointResample
from tests.conftest import icosphere
from tests.transforms.conftest import (assert_hsn_inputs,
                                       assert_point_cloud_operators, hsn,
                                       sphere_pos_face)


def sphere(subdivisions=5):
    pos, face = icosphere(subdivisions)
    return Data(pos=pos, face=face, y=torch.arange(pos.size(0)),
                x=2 * pos)


def test_samples_are_the_farthest_points_and_the_mesh_is_a_closed_surface():
    data = sphere()  # 10242 vertices: no subdivision needed for 1024
    out = FarthestPointResample(1024)(data)
    assert out.num_nodes == 1024
    # the samples are input vertices, the ones fps picks from vertex 0
    expected = fps(data.pos, ratio=1024 / data.num_nodes,
                   random_start=False)
    assert set(out.y.tolist()) == set(expected.tolist())
    assert torch.equal(out.pos, data.pos[out.y])
    assert torch.equal(out.x, data.x[out.y])  # attributes follow
    assert is_closed_manifold(out.face, out.num_nodes)
    assert abs(float(face_areas(out.pos, out.face).sum()) / (4 * np.pi)
               - 1) < 0.02
    # evenly spread: nearest-sample distances vary little
    d = torch.cdist(out.pos, out.pos) + 10 * torch.eye(1024)
    nearest = d.min(1).values
    assert nearest.max() / nearest.min() < 2.5


def test_fewer_vertices_than_asked_for_samples_the_faces():
    pos, face = icosphere(1)  # 42 vertices
    data = Data(pos=pos, face=face, y=torch.arange(42))
    out = FarthestPointResample(500)(data)
    assert out.num_nodes == 500
    assert is_closed_manifold(out.face, 500)
    # new points lie on the icosahedron's flat faces (inside the sphere);
    # the original vertices that were picked stay exactly where they were
    radius = out.pos.norm(dim=1)
    assert (radius <= 1 + 1e-9).all() and (radius > 0.75).all()
    on_vertex = (out.pos - pos[out.y]).norm(dim=1) < 1e-12
    assert 0 < int(on_vertex.sum()) <= 42
    # every label is the one of a nearest input vertex (edge midpoints
    # are as near to both ends)
    nearest = (out.pos[:, None] - pos[None]).norm(dim=-1).min(1).values
    assert torch.allclose((out.pos - pos[out.y]).norm(dim=1), nearest,
                          rtol=0, atol=1e-12)


def test_several_components_all_get_samples():
    a, b = sphere(4), sphere(3)
    pos = torch.cat([a.pos, 0.5 * b.pos + 3.0])
    face = torch.cat([a.face, b.face + a.num_nodes], 1)
    side = (torch.arange(pos.size(0)) >= a.num_nodes).long()
    out = FarthestPointResample(400)(Data(pos=pos, face=face, y=side))
    assert out.num_nodes == 400
    assert 0 < int(out.y.sum()) < 400  # both components are sampled
    # no triangle joins the two components
    assert torch.equal(out.y[out.face[0]], out.y[out.face[1]])
    _, count = edge_face_counts(out.face, out.num_nodes)
    assert (count <= 2).all()


def test_open_meshes_stay_edge_manifold_and_oriented():
    from tests.conftest import grid_mesh
    pos, face = grid_mesh(60, jitter=0.3)
    out = FarthestPointResample(300)(Data(pos=pos, face=face))
    assert out.num_nodes == 300
    _, count = edge_face_counts(out.face, out.num_nodes)
    assert (count <= 2).all()
    a = torch.cat([out.face[0], out.face[1], out.face[2]])
    b = torch.cat([out.face[1], out.face[2], out.face[0]])
    assert torch.unique(a * 300 + b).numel() == a.numel()  # oriented
    normal = torch.linalg.cross(out.pos[out.face[1]] - out.pos[out.face[0]],
                                out.pos[out.face[2]] - out.pos[out.face[0]])
    assert (normal[:, 2] > 0).all()  # as the input: facing +z
    assert abs(float(face_areas(out.pos, out.face).sum()) - 1) < 0.05


def test_point_clouds_keep_their_farthest_points():
    pos = torch.rand(2000, 3, dtype=torch.float64)
    data = Data(pos=pos, y=torch.arange(2000), normal=pos.clone())
    out = FarthestPointResample(256)(data)
    assert out.num_nodes == 256 and getattr(out, 'face', None) is None
    assert torch.equal(out.pos, pos[out.y])
    assert torch.equal(out.normal, pos[out.y])
    with pytest.raises(ValueError, match='no\\s+surface'):
        FarthestPointResample(4000)(data)


def test_exact_count_is_a_no_op_and_bad_input_says_what_to_do():
    data = sphere(2)
    same = FarthestPointResample(data.num_nodes)(data)
    assert torch.equal(same.pos, data.pos)
    with pytest.raises(ValueError, match='at least 4'):
        FarthestPointResample(3)
    with pytest.raises(ValueError, match='refine'):
        FarthestPointResample(100, refine=0.5)
    bad = sphere(2)
    bad.pos[0, 0] = float('inf')
    with pytest.raises(ValueError, match='CleanMesh'):
        FarthestPointResample(50)(bad)
    with pytest.raises(ValueError, match='before transforms that build'):
        FarthestPointResample(50)(Data(
            pos=data.pos, face=data.face,
            edge_index=torch.zeros(2, 1, dtype=torch.long)))


def test_repr():
    assert repr(FarthestPointResample(1024)) == \
        'FarthestPointResample(num_vertices=1024, refine=4.0)'


# Real meshes with too few vertices for the HSN precomputation: resampled,
# they run through it (and, as point clouds, through DeltaNet's operators).
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
    pos, face = sphere_pos_face(1)  # 42 vertices
    data = Data(pos=pos, face=face, y=(pos[:, 2] > 0).long())
    resampled = FarthestPointResample(1024)(data)
    assert resampled.y.shape == (1024,)
    assert_hsn_inputs(hsn(resampled), 1024)
    assert_point_cloud_operators(data, num_points=1024)
