import pytest
import torch
from torch_geometric.data import Data

from tg_intrinsic.transforms import TangentFrames
from tests.conftest import fibonacci_sphere, icosphere
from tests.symmetry import rotate_frames


def assert_orthonormal_right_handed(frame):
    eye = torch.eye(3, dtype=frame.dtype).expand_as(frame)
    assert torch.allclose(frame @ frame.transpose(1, 2), eye, atol=1e-12)
    # e_u x e_v = n, not -n
    assert torch.allclose(torch.linalg.cross(frame[:, 0], frame[:, 1]),
                          frame[:, 2], atol=1e-12)


def test_mesh_normals_and_frames_without_mutating_input():
    pos, face = icosphere(2)
    data = Data(pos=pos, face=face)
    out = TangentFrames()(data)
    assert 'frame' not in data and 'normal' not in data
    assert out.frame.shape == (pos.size(0), 3, 3)
    radial = pos / pos.norm(dim=-1, keepdim=True)
    assert ((out.frame[:, 2] * radial).sum(-1) > 0.99).all()
    assert repr(TangentFrames(k=7)) == 'TangentFrames(k=7)'


def test_frames_are_built_on_the_given_normals_which_stay_as_they_are():
    g = torch.Generator().manual_seed(0)
    pos = torch.randn(50, 3, generator=g, dtype=torch.float64)
    normal = torch.randn(50, 3, generator=g, dtype=torch.float64)
    normal = normal / normal.norm(dim=1, keepdim=True)
    out = TangentFrames()(Data(pos=pos, normal=normal))
    assert out.frame.shape == (50, 3, 3) and out.frame.dtype == pos.dtype
    assert_orthonormal_right_handed(out.frame)
    assert torch.allclose(out.frame[:, 2], normal, atol=1e-12)
    assert torch.equal(out.normal, normal)
    # the older PyG name is read as well
    old = TangentFrames()(Data(pos=pos, norm=normal))
    assert torch.allclose(old.frame[:, 2], normal, atol=1e-12)


def test_sphere_frames_and_the_normals_they_write():
    # the icosahedron: by symmetry the vertex normals are exactly radial
    pos, face = icosphere(0)
    radial = pos / pos.norm(dim=1, keepdim=True)
    out = TangentFrames()(Data(pos=pos, face=face))
    assert_orthonormal_right_handed(out.frame)
    assert torch.allclose(out.frame[:, 2], radial, atol=1e-12)
    assert torch.equal(out.normal, out.frame[:, 2])
    # a cloud: estimated normals, outward, close to radial
    pos = fibonacci_sphere(1000)
    out = TangentFrames()(Data(pos=pos))
    assert_orthonormal_right_handed(out.frame)
    assert ((out.frame[:, 2] - pos).norm(dim=1) < 0.1).all()
    assert torch.equal(out.normal, out.frame[:, 2])


def test_given_frames_are_kept_in_any_gauge():
    pos, face = icosphere(1)
    base = TangentFrames()(Data(pos=pos, face=face)).frame
    angle = torch.linspace(0, 6, pos.size(0), dtype=pos.dtype)
    turned = rotate_frames(base, angle)
    out = TangentFrames()(Data(pos=pos, face=face, frame=turned))
    assert torch.equal(out.frame, turned)
    assert 'normal' not in out  # only normals it found itself are written
    assert not torch.allclose(out.frame[:, 0], base[:, 0])


def test_float32_stays_float32():
    pos = fibonacci_sphere(200, dtype=torch.float32)
    out = TangentFrames()(Data(pos=pos, normal=pos.clone()))
    assert out.frame.dtype == torch.float32
    assert torch.allclose(out.frame[:, 2], pos, atol=1e-6)


def test_bad_input():
    pos = torch.randn(5, 3, dtype=torch.float64)
    frame = torch.eye(3, dtype=torch.float64).repeat(5, 1, 1)
    with pytest.raises(ValueError, match='orthonormal'):
        TangentFrames()(Data(pos=pos, frame=2 * frame))
    left = frame.clone()
    left[:, 2] *= -1
    with pytest.raises(ValueError, match='right-handed'):
        TangentFrames()(Data(pos=pos, frame=left))
    with pytest.raises(ValueError, match=r'\[N, 3, 3\]'):
        TangentFrames()(Data(pos=pos, frame=frame[:, :2]))
    with pytest.raises(ValueError, match="'data.normal' has 4 rows"):
        TangentFrames()(Data(pos=pos, normal=pos[:4]))
    with pytest.raises(ValueError, match='zero length'):
        TangentFrames()(Data(pos=pos, normal=torch.zeros_like(pos)))
    with pytest.raises(ValueError, match="'data.pos'"):
        TangentFrames()(Data(x=pos))
    with pytest.raises(ValueError, match="'k' must be at least 2"):
        TangentFrames(k=1)
    assert repr(TangentFrames()) == 'TangentFrames(k=10)'
