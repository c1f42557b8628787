"""TangentVectorPool: a constant vector field pooled on a plane and a
sphere equals the field transported independently (3-D rotations), the
weighted mean, and bad input."""
import math

import pytest
import torch

from tg_intrinsic.geometry import tangent_frames
from tg_intrinsic.pool import TangentVectorPool
from tg_intrinsic.transforms import PoolingLevels
from tg_intrinsic.data import IntrinsicData
from tests.conftest import fibonacci_sphere
from tests.symmetry import rotate_frames


def _in_frame(vec3, frame):
    """Coordinates (a, b) of 3-D tangent vectors in frames (e_u, e_v)."""
    return torch.stack([(vec3 * frame[:, 0]).sum(-1),
                        (vec3 * frame[:, 1]).sum(-1)], -1)


def _rodrigues(vec, n_from, n_to):
    """Rotates vec by the smallest rotation taking n_from to n_to (the
    Levi-Civita transport along the great circle on a sphere)."""
    axis = torch.cross(n_from, n_to, dim=-1)
    s = axis.norm(dim=-1, keepdim=True)
    c = (n_from * n_to).sum(-1, keepdim=True)
    k = axis / s.clamp_min(1e-300)
    return (vec * c + torch.cross(k, vec, dim=-1) * s
            + k * (k * vec).sum(-1, keepdim=True) * (1 - c))


def _levels(pos, normal, seed, method='fps'):
    """Levels whose frames are turned by random angles (any gauge)."""
    g = torch.Generator().manual_seed(seed)
    angle = 2 * math.pi * torch.rand(pos.size(0), generator=g,
                                     dtype=pos.dtype)
    frame = rotate_frames(tangent_frames(normal), angle)
    return PoolingLevels(num_levels=2, method=method)(
        IntrinsicData(pos=pos, frame=frame))


@pytest.mark.parametrize('method', ['fps', 'gravo'])
def test_constant_field_on_a_plane_is_kept(method):
    g = torch.Generator().manual_seed(0)
    pos = torch.rand(600, 3, generator=g, dtype=torch.float64)
    pos[:, 2] = 0
    normal = torch.zeros_like(pos)
    normal[:, 2] = 1
    data = _levels(pos, normal, 1, method)
    field = torch.tensor([0.6, -0.8, 0.0], dtype=torch.float64)
    frames = [data.frame, data.frame_1, data.frame_2]
    v = _in_frame(field.expand(600, 3), frames[0]).unsqueeze(1)
    for level in (1, 2):
        v = TangentVectorPool()(v, data[f'pool_edge_index_{level}'],
                                data[f'pool_weight_{level}'],
                                data[f'pool_transport_{level}'],
                                data[f'pos_{level}'].size(0))
        want = _in_frame(field.expand(v.size(0), 3), frames[level])
        assert torch.allclose(v[:, 0], want, atol=1e-9)


def test_tangent_field_on_a_sphere_matches_rodrigues_transport():
    pos = fibonacci_sphere(800)
    data = _levels(pos, pos, 2)
    # A tangent field: the projection of a fixed direction (not constant
    # along the surface, so transport matters).
    direction = torch.tensor([0.3, -0.5, 0.8], dtype=torch.float64)
    field = direction - (pos @ direction)[:, None] * pos
    v = torch.stack([_in_frame(field, data.frame),
                     _in_frame(2 * field, data.frame)], 1)
    fine, coarse = data.pool_edge_index_1
    n1 = data.pos_1.size(0)
    pooled = TangentVectorPool()(v, data.pool_edge_index_1,
                                 data.pool_weight_1, data.pool_transport_1,
                                 n1)
    # Oracle: rotate every 3-D vector onto its coarse point's tangent plane
    # and average there, in 3-D.
    moved = _rodrigues(field[fine], pos[fine], data.pos_1[coarse])
    mean = torch.zeros(n1, 3, dtype=torch.float64).index_add_(0, coarse,
                                                                moved)
    mean = mean / torch.bincount(coarse, minlength=n1)[:, None]
    want = _in_frame(mean, data.frame_1)
    assert torch.allclose(pooled[:, 0], want, atol=1e-9)
    assert torch.allclose(pooled[:, 1], 2 * want, atol=1e-9)
    # Without the transport the result would differ clearly.
    plain = torch.zeros(n1, 2, dtype=torch.float64).index_add_(
        0, coarse, v[fine, 0]) / torch.bincount(coarse)[:, None]
    assert (plain - want).abs().max() > 0.05


def test_weighted_mean_and_gradients():
    v = torch.tensor([[[1.0, 0.0]], [[0.0, 2.0]], [[3.0, 3.0]]],
                     dtype=torch.float64, requires_grad=True)
    index = torch.tensor([[0, 1, 2], [0, 0, 1]])
    weight = torch.tensor([1.0, 3.0, 2.0], dtype=torch.float64)
    angle = torch.tensor([math.pi / 2, 0.0, math.pi], dtype=torch.float64)
    out = TangentVectorPool()(v, index, weight, angle, 2)
    assert torch.allclose(out[0, 0], torch.tensor(
        [0.0, (1.0 + 6.0) / 4], dtype=torch.float64))
    assert torch.allclose(out[1, 0], torch.tensor([-3.0, -3.0],
                                                  dtype=torch.float64))
    assert torch.autograd.gradcheck(
        lambda x: TangentVectorPool()(x, index, weight, angle, 2), (v, ))
    assert repr(TangentVectorPool()) == 'TangentVectorPool()'


def test_bad_input_is_explained():
    v = torch.zeros(3, 2, 2)
    index = torch.tensor([[0, 1, 2], [0, 0, 1]])
    weight, angle = torch.ones(3), torch.zeros(3)
    with pytest.raises(ValueError, match='tangent vector features'):
        TangentVectorPool()(torch.zeros(3, 2), index, weight, angle, 2)
    with pytest.raises(ValueError, match='pool_transport'):
        TangentVectorPool()(v, index, weight, torch.zeros(2), 2)
    with pytest.raises(ValueError, match='no weight'):
        TangentVectorPool()(v, index, weight, angle, 3)
