import math
import pytest
import torch
from torch_geometric.data import Data

from tg_intrinsic.transforms import MLSOperators, RandomRotation
from tg_intrinsic.transforms.random_rotation import random_rotation_matrix
from tests.transforms.conftest import angle_gap, apply, pipeline, sphere_data


@pytest.mark.parametrize('axis', [None, 'x', 'y', 'z'])
def test_matrices_are_rotations(axis):
    gen = torch.Generator().manual_seed(0)
    for _ in range(20):
        r = random_rotation_matrix(axis, gen)
        assert torch.allclose(r @ r.T, torch.eye(3, dtype=r.dtype),
                              atol=1e-12)
        assert abs(float(torch.linalg.det(r)) - 1) < 1e-12
        if axis is not None:  # the axis itself is fixed
            e = torch.zeros(3, dtype=r.dtype)
            e['xyz'.index(axis)] = 1
            assert torch.allclose(r @ e, e)


def test_so3_rotations_are_uniform():
    # Under the Haar measure E[R] = 0 and E[R_ij^2] = 1/3; a rotation about
    # a fixed axis (or a biased sampler) violates both.
    gen = torch.Generator().manual_seed(1)
    rs = torch.stack([random_rotation_matrix(None, gen) for _ in range(4000)])
    assert rs.mean(0).abs().max() < 0.05
    assert ((rs ** 2).mean(0) - 1 / 3).abs().max() < 0.03


def test_points_normals_frames_and_operators_turn_together():
    # random points: a regular sphere has tied neighbour distances
    pos = torch.randn(300, 3, dtype=torch.float64,
                      generator=torch.Generator().manual_seed(2))
    pos = pos / pos.norm(dim=-1, keepdim=True)
    normal = pos.clone()
    data = MLSOperators(k=10)(Data(pos=pos, normal=normal))
    torch.manual_seed(3)
    out = RandomRotation()(data)
    assert torch.equal(data.pos, pos)  # input not mutated
    r = torch.linalg.lstsq(pos, out.pos).solution.T
    assert torch.allclose(r @ r.T, torch.eye(3, dtype=r.dtype), atol=1e-10)
    assert torch.allclose(out.normal, normal @ r.T, atol=1e-12)
    assert torch.allclose(out.frame, data.frame @ r.T, atol=1e-12)
    # The stored intrinsic operators equal those rebuilt on the rotated
    # cloud in the rotated frames.
    rebuilt = MLSOperators(k=10)(Data(pos=out.pos, frame=out.frame))
    assert torch.equal(rebuilt.edge_index, out.edge_index)
    assert torch.allclose(rebuilt.grad_weight, out.grad_weight, atol=1e-9)
    assert torch.allclose(rebuilt.div_weight, out.div_weight, atol=1e-9)


def test_bad_input():
    with pytest.raises(ValueError, match="axis must be"):
        RandomRotation(axis='w')
    with pytest.raises(ValueError, match=r"data.pos' must have shape "
                                          r"\[N, 3\]"):
        RandomRotation()(Data(pos=torch.zeros(4, 2)))
    # integer positions used to rotate to zeros, float16 passed silently
    with pytest.raises(ValueError, match='float32 or float64'):
        RandomRotation()(Data(pos=torch.ones(4, 3, dtype=torch.long)))
    with pytest.raises(ValueError, match='float32 or float64'):
        RandomRotation()(Data(pos=torch.ones(4, 3, dtype=torch.float16)))
    with pytest.raises(ValueError, match='NaN'):
        RandomRotation()(Data(pos=torch.full((4, 3), float('nan'))))
    pos = torch.randn(6, 3)
    with pytest.raises(ValueError, match="'data.normal' has 5 rows"):
        RandomRotation()(Data(pos=pos, normal=torch.randn(5, 3)))
    with pytest.raises(ValueError, match='frame'):
        RandomRotation()(Data(pos=pos, frame=torch.eye(3).repeat(5, 1, 1)))
    with pytest.raises(ValueError, match=r"'data.normal_1' must have shape "
                                          r"\[2, 3\]"):
        RandomRotation()(Data(pos=pos, pos_1=pos[:2],
                              normal_1=torch.randn(3, 3)))
    with pytest.raises(ValueError, match="max_angle must be in"):
        RandomRotation('x', max_angle=0)
    assert repr(RandomRotation('z')) == \
        "RandomRotation(axis='z', max_angle=180)"


def test_euler_rotations_stay_within_the_angle():
    # 'xyz' with max_angle a: R = Rz Ry Rx, each angle uniform in [-a, a].
    # The rotation angle of R is then at most 3a, and about one axis it
    # is exactly the drawn angle (trace = 1 + 2 cos(angle)).
    from tg_intrinsic.transforms.random_rotation import random_rotation_matrix
    generator = torch.Generator().manual_seed(0)
    for _ in range(50):
        matrix = random_rotation_matrix('xyz', generator, max_angle=10.0)
        assert torch.allclose(matrix @ matrix.T, torch.eye(3,
                              dtype=matrix.dtype), atol=1e-12)
        angle = torch.arccos(((matrix.trace() - 1) / 2).clamp(-1, 1))
        assert angle <= math.radians(30) + 1e-9
        single = random_rotation_matrix('z', generator, max_angle=10.0)
        assert single[2, 2] == 1 and abs(torch.atan2(
            single[1, 0], single[0, 0])) <= math.radians(10) + 1e-12


def test_rotation_augmentation_keeps_precomputation_valid():
    data = apply(sphere_data(2), pipeline())
    torch.manual_seed(0)
    rotated = RandomRotation()(data)
    rebuilt = apply(Data(pos=rotated.pos, face=data.face, x=data.x,
                         frame=rotated.frame), pipeline())
    # equal up to the order of equidistant neighbours
    for level in ('', '_1'):
        orders = []
        for d in (rebuilt, rotated):
            j, i = d['edge_index' + level]
            orders.append(torch.argsort(i * 10 ** 6 + j))
        a, b = orders
        assert torch.equal(rebuilt['edge_index' + level][:, a],
                           rotated['edge_index' + level][:, b])
        assert torch.allclose(rebuilt['logmap' + level][a, 0],
                              rotated['logmap' + level][b, 0], atol=1e-9)
        assert angle_gap(rebuilt['logmap' + level][a, 1],
                         rotated['logmap' + level][b, 1]) < 1e-9
        assert angle_gap(rebuilt['transport' + level][a],
                         rotated['transport' + level][b]) < 1e-9
    assert angle_gap(rebuilt.pool_transport_1, rotated.pool_transport_1
                     ) < 1e-9
    assert torch.allclose(rotated.pos_1, rotated.pos[data.sample_index_1])
