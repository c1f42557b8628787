import math

import pytest
import torch

from tg_intrinsic.datasets import SphereDigits
from tg_intrinsic.datasets.sphere_digits import (load_digit_images,
                                                 rotation_about_z)
from tg_intrinsic.geometry.sphere_images import sample_image_on_sphere

pytest.importorskip('sklearn')


@pytest.fixture(scope='module')
def upright():
    return SphereDigits('test', limit=6, dtype=torch.float64)


def test_examples_are_the_digits_on_the_icosphere(upright):
    images, labels = load_digit_images()
    assert len(upright) == 6
    data = upright[1]
    assert data.pos.shape == (642, 3) and data.x.shape == (642, 1)
    assert data.level_size(1) == 162 and data.level_size(2) == 42
    # the levels are the coarser icospheres, nested
    assert torch.equal(data.pos_1, data.pos[:162])
    assert torch.equal(data.pos_2, data.pos[:42])
    # the test split holds every fourth image
    assert data.y.item() == labels[4].item()
    assert torch.allclose(data.x[:, 0],
                          sample_image_on_sphere(images[4], data.pos))
    # the digit is on the upper hemisphere, nothing on the lower one
    assert data.x[data.pos[:, 2] < -1e-9].abs().max() < 1e-12
    assert data.x.max() > 0.5
    # radii of the levels as asked
    radii = [data[k].item() for k in ('logmap_radius', 'logmap_radius_1',
                                      'logmap_radius_2')]
    assert radii == pytest.approx([0.3, 0.45, 0.8])
    assert data.logmap[:, 0].max() < 0.3
    # vertex 0 is the pole (the centre of the image)
    assert torch.allclose(data.pos[0], torch.tensor([0., 0., 1.],
                                                    dtype=torch.float64))


def test_split_sizes():
    assert len(SphereDigits('test', limit=None).labels) == 450


def test_rotation_about_the_axis_turns_the_digit_in_place(upright):
    rotated = SphereDigits('test', rotate='axis', limit=6, seed=3,
                           dtype=torch.float64)
    for i in (0, 4):
        rot = rotated.rotation(i)
        assert torch.allclose(rot @ rot.t(), torch.eye(3, dtype=rot.dtype))
        assert torch.allclose(rot[:, 2], torch.tensor([0., 0., 1.],
                                                      dtype=rot.dtype))
        expected = sample_image_on_sphere(upright.images[i],
                                          upright.mesh.pos @ rot)
        assert torch.allclose(rotated[i].x[:, 0], expected)
        assert (rotated[i].x - upright[i].x).norm() > \
            0.2 * upright[i].x.norm()
        # the pole keeps its value; the turn is in place
        assert rotated[i].x[0] == pytest.approx(upright[i].x[0].item())
    # a turn by a fifth of a circle permutes the vertices (icosphere)
    turn = rotation_about_z(2 * math.pi / 5)
    pos = upright.mesh.pos
    nearest = torch.cdist(pos @ turn, pos).min(1)
    assert nearest.values.max() < 1e-6
    assert torch.allclose(upright.signal(2, turn)[:, 0],
                          upright[2].x[nearest.indices, 0], atol=1e-12)


def test_pooling_cells_permute_with_a_fifth_turn(upright):
    """A turn by 72 degrees maps the nested icospheres onto themselves;
    every pooling cell must map onto the cell of the turned points, and
    its nearest coarse vertex must be a nearest one (on the sphere)."""
    turn = rotation_about_z(2 * math.pi / 5)
    mesh = upright.mesh
    ids = torch.arange(mesh.num_nodes)
    for level in (1, 2):
        coarse = ids[mesh[f'sample_index_{level}']]
        fine_pos, coarse_pos = mesh.pos[ids], mesh.pos[coarse]
        fine_map = torch.cdist(fine_pos @ turn.t(), fine_pos).argmin(1)
        coarse_map = torch.cdist(coarse_pos @ turn.t(), coarse_pos).argmin(1)
        cell = mesh[f'cluster_{level}']
        assert torch.equal(cell[fine_map], coarse_map[cell])
        angle = torch.arccos((fine_pos @ coarse_pos.t()).clamp(-1, 1))
        chosen = angle.gather(1, cell[:, None])[:, 0]
        assert torch.allclose(chosen, angle.min(1).values, atol=1e-9)
        # ties are common: a rule by index would break the symmetry
        ties = (angle <= angle.min(1, keepdim=True).values + 1e-9).sum(1)
        assert int((ties > 1).sum()) > coarse.numel()
        assert torch.allclose(mesh[f'area_{level}'].sum(), mesh.area.sum())
        ids = coarse


def test_so3_rotations_move_the_digit():
    data = SphereDigits('test', rotate='so3', limit=3)
    rot = data.rotation(1)
    assert torch.allclose(torch.linalg.det(rot), torch.tensor(
        1.0, dtype=rot.dtype))
    assert not torch.allclose(rot[:, 2], torch.tensor([0., 0., 1.],
                                                      dtype=rot.dtype))
    assert data[1].x.dtype == torch.float32


def test_deterministic():
    a = SphereDigits('test', rotate='axis', limit=3)
    b = SphereDigits('test', rotate='axis', limit=3)
    c = SphereDigits('test', rotate='axis', limit=3, seed=1)
    for i in range(3):
        assert torch.equal(a[i].x, b[i].x)
    assert not torch.equal(a[0].x, c[0].x)
    assert repr(a) == "SphereDigits(3, split='test', rotate='axis')"


def test_bad_input_is_explained():
    with pytest.raises(ValueError, match="'rotate' must be one of"):
        SphereDigits('test', rotate='z')
    with pytest.raises(ValueError, match="split"):
        SphereDigits('val')
    with pytest.raises(ValueError, match="one entry per level"):
        SphereDigits('test', radii=(0.3, ))
    with pytest.raises(ValueError, match="'dtype' must be"):
        SphereDigits('test', dtype=torch.int64)
    with pytest.raises(ValueError, match="'limit' must be at least 1"):
        SphereDigits('test', limit=0)
