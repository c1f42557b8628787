import pytest
import torch
from torch_geometric.data import Data

from tg_intrinsic.transforms import NormalizeArea
from tests.conftest import grid_mesh, icosphere
from tests.symmetry import random_rotation


def surface_area(pos, face):
    a, b, c = pos[face[0]], pos[face[1]], pos[face[2]]
    return 0.5 * torch.linalg.cross(b - a, c - a).norm(dim=-1)


def test_bad_input():
    with pytest.raises(ValueError, match='NormalizeArea needs a mesh'):
        NormalizeArea()(Data(pos=torch.rand(5, 3)))


@pytest.mark.parametrize('target', [1.0, 2.5])
def test_area_becomes_the_target_and_the_shape_is_only_scaled(target):
    pos, face = icosphere(2)
    pos = 3.0 * pos * torch.tensor([1.0, 0.5, 2.0], dtype=pos.dtype) + 7.0
    data = Data(pos=pos, face=face)
    out = NormalizeArea(target)(data)
    assert torch.isclose(surface_area(out.pos, face).sum(),
                         torch.tensor(target, dtype=pos.dtype))
    # area-weighted centroid of the triangles at the origin
    area = surface_area(out.pos, face)
    centroid = (area[:, None] * out.pos[face].mean(0)).sum(0) / area.sum()
    assert centroid.abs().max() < 1e-12
    # one scale factor, no rotation: offsets between points scale evenly
    scale = (target / surface_area(pos, face).sum()) ** 0.5
    assert torch.allclose(out.pos - out.pos[0], scale * (pos - pos[0]),
                          atol=1e-12)
    assert torch.equal(data.pos, pos) and out.pos.dtype == pos.dtype


def test_normals_frames_and_other_keys_are_kept():
    pos, face = grid_mesh(4)
    frame = torch.eye(3, dtype=pos.dtype).repeat(pos.size(0), 1, 1)
    data = Data(pos=pos * 4, face=face, normal=frame[:, 2].clone(),
                frame=frame, y=torch.arange(pos.size(0)))
    out = NormalizeArea()(data)
    for key in ('face', 'normal', 'frame', 'y'):
        assert torch.equal(out[key], data[key]), key
    # the unit square scaled to area 16 comes back as the unit square,
    # centred at the origin
    centre = torch.tensor([0.5, 0.5, 0.0], dtype=pos.dtype)
    assert torch.allclose(out.pos, pos - centre, atol=1e-12)


def test_rigid_motions_commute_with_normalisation():
    pos, face = icosphere(1)
    pos = pos * torch.tensor([1.0, 2.0, 0.5], dtype=pos.dtype)
    r = random_rotation(seed=3)
    moved = pos @ r.T + torch.tensor([5.0, -2.0, 1.0], dtype=pos.dtype)
    a = NormalizeArea()(Data(pos=pos, face=face)).pos
    b = NormalizeArea()(Data(pos=moved, face=face)).pos
    assert torch.allclose(b, a @ r.T, atol=1e-12)


def test_bad_values_are_named():
    pos, face = icosphere(1)
    for area in (0.0, -1.0):
        with pytest.raises(ValueError, match="'area' must be positive"):
            NormalizeArea(area)(Data(pos=pos, face=face))
    with pytest.raises(ValueError, match="'area' must be finite"):
        NormalizeArea(float('inf'))(Data(pos=pos, face=face))
    with pytest.raises(ValueError, match='zero-area'):
        NormalizeArea()(Data(pos=torch.zeros_like(pos), face=face))
    with pytest.raises(ValueError, match="'face' indexes vertices"):
        NormalizeArea()(Data(pos=pos[:10], face=face))
    assert repr(NormalizeArea()) == 'NormalizeArea(area=1.0)'
    assert repr(NormalizeArea(4.0)) == 'NormalizeArea(area=4.0)'
