"""Decimate: quadric edge collapses with fast-simplification; target
counts, shape kept, attributes by nearest vertex, clear errors."""
import pytest
import torch
from torch_geometric.data import Data

from tg_intrinsic.geometry import face_areas, is_closed_manifold
from tg_intrinsic.transforms import Decimate
from tests.conftest import icosphere


def sphere(subdivisions=5, dtype=torch.float64):
    pos, face = icosphere(subdivisions, dtype=dtype)
    return Data(pos=pos, face=face, y=(pos[:, 2] > 0).long(), x=pos.clone())


@pytest.mark.parametrize('dtype', [torch.float32, torch.float64])
def test_decimates_a_sphere_to_the_target_and_keeps_its_shape(dtype):
    data = sphere(dtype=dtype)  # 10242 vertices
    out = Decimate(1000)(data)
    assert abs(out.num_nodes - 1000) <= 20
    assert out.pos.dtype == dtype and out.face.dtype == torch.long
    assert is_closed_manifold(out.face, out.num_nodes)
    radius = out.pos.double().norm(dim=1)
    assert (radius - 1).abs().max() < 0.02
    area = face_areas(out.pos.double(), out.face).sum()
    assert abs(float(area) / (4 * torch.pi) - 1) < 0.03
    # attributes by nearest input vertex: labels by hemisphere stay right
    # away from the equator, x is an input position near the new vertex
    away = out.pos[:, 2].abs() > 0.05
    assert torch.equal(out.y[away], (out.pos[away, 2] > 0).long())
    assert (out.x - out.pos).norm(dim=1).max() < 0.1
    assert data.num_nodes == 10242  # not mutated


def test_ratio_and_no_op():
    data = sphere(4)
    out = Decimate(ratio=0.25)(data)
    assert abs(out.num_nodes - 0.25 * data.num_nodes) <= 0.02 * \
        data.num_nodes
    same = Decimate(data.num_nodes)(data)
    assert torch.equal(same.pos, data.pos) and torch.equal(same.face,
                                                           data.face)


def test_errors_say_what_to_do():
    with pytest.raises(ValueError, match='FarthestPointResample'):
        Decimate(100)(Data(pos=torch.rand(500, 3)))
    with pytest.raises(ValueError, match='exactly one'):
        Decimate()
    with pytest.raises(ValueError, match='exactly one'):
        Decimate(100, ratio=0.5)
    with pytest.raises(ValueError, match='at least 4'):
        Decimate(2)
    with pytest.raises(ValueError, match='ratio'):
        Decimate(ratio=1.5)
    data = sphere(2)
    data.pos[0, 0] = float('nan')
    with pytest.raises(ValueError, match='CleanMesh'):
        Decimate(10)(data)


def test_repr():
    assert repr(Decimate(5000)) == 'Decimate(num_vertices=5000)'
    assert repr(Decimate(ratio=0.1)) == 'Decimate(ratio=0.1)'
