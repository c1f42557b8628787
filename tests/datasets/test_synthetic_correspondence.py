import numpy as np
import pytest
import torch

from tg_intrinsic.datasets import (SyntheticCorrespondence,
                                   correspondence_accuracy)
from tests.datasets.conftest import manifold_report


@pytest.fixture(scope='module')
def root(tmp_path_factory):
    return str(tmp_path_factory.mktemp('corr'))


@pytest.fixture(scope='module')
def small(root):
    return SyntheticCorrespondence(root, num_train=3, num_test=2,
                                   num_vertices=400, log=False)


def edges(face):
    F = face.t().numpy()
    e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    return np.unique(np.sort(e, 1), axis=0)


def test_api(small, root):
    test = SyntheticCorrespondence(root, split='test', num_train=3,
                                   num_test=2, num_vertices=400, log=False)
    assert len(small) == 3 and len(test) == 2
    assert small.num_classes == 400
    data = small[0]
    assert data.pos.shape == (400, 3) and data.pos.dtype == torch.float32
    assert data.face.shape == small.template.face.shape
    assert torch.equal(data.y, torch.arange(400))
    assert repr(small) == ("SyntheticCorrespondence(3, split='train', "
                           "num_vertices=400, seed=0)")
    # poses differ from each other and from the template
    assert not torch.allclose(test[0].pos, small[0].pos, atol=1e-2)


def test_poses_keep_the_template_and_are_near_isometric(small):
    t = small.template
    assert all(manifold_report(t.pos, t.face).values())
    e = edges(t.face)
    before = np.linalg.norm(t.pos[e[:, 0]] - t.pos[e[:, 1]], axis=1)
    for data in small:
        # vertex i of the pose is vertex i of the template: same triangles
        assert torch.equal(data.face, t.face)
        assert torch.equal(data.part, t.part)
        after = np.linalg.norm(data.pos[e[:, 0]] - data.pos[e[:, 1]],
                               axis=1)
        stretch = np.abs(after / before - 1)
        assert np.median(stretch) < 0.02
        assert stretch.max() <= SyntheticCorrespondence.max_stretch + 1e-4
        # and it is a real pose: the limbs moved far, the body did not
        move = (data.pos - t.pos).norm(dim=1)
        assert move.max() > 0.1
        assert move[t.part == 0].median() < 0.02


def test_permuted_vertices_are_labelled_by_the_template(root, small):
    perm = SyntheticCorrespondence(root, num_train=3, num_test=2,
                                   num_vertices=400, permute=True,
                                   log=False)
    data, plain = perm[1], small[1]
    assert not torch.equal(data.y, torch.arange(400))
    # the vertex listed at k is template vertex y[k]
    assert torch.allclose(data.pos, plain.pos[data.y])
    # its triangles, mapped to template vertices, are the template's
    mapped = data.y[data.face]
    same = {tuple(sorted(f)) for f in mapped.t().tolist()}
    assert same == {tuple(sorted(f)) for f in plain.face.t().tolist()}


def test_deterministic_and_seed_dependent(small, tmp_path):
    again = SyntheticCorrespondence(str(tmp_path / 'a'), num_train=3,
                                    num_test=2, num_vertices=400, log=False)
    for a, b in zip(again, small):
        assert torch.equal(a.pos, b.pos)
    other = SyntheticCorrespondence(str(tmp_path / 'b'), num_train=3,
                                    num_test=2, num_vertices=400, seed=1,
                                    log=False)
    assert not torch.equal(other[0].pos, small[0].pos)


def test_pose_zero_repeats_the_template(tmp_path):
    rest = SyntheticCorrespondence(str(tmp_path), num_train=1, num_test=1,
                                   num_vertices=400, pose=0.0, log=False)
    assert torch.allclose(rest[0].pos, rest.template.pos, atol=1e-6)


def test_accuracy_matches_brute_force():
    gen = torch.Generator().manual_seed(0)
    points = torch.rand(30, 3, generator=gen)
    dist = (points[:, None] - points[None]).norm(dim=-1)
    pred = torch.randint(0, 30, (200, ), generator=gen)
    target = torch.randint(0, 30, (200, ), generator=gen)
    thresholds = [0.0, 0.05, 0.1, 0.3, 1.0]
    out = correspondence_accuracy(pred, target, dist, thresholds)
    diameter = max(float(dist[a, b]) for a in range(30) for b in range(30))
    for t, value in zip(thresholds, out.tolist()):
        hits = sum(float(dist[p, q]) <= t * diameter
                   for p, q in zip(pred.tolist(), target.tolist()))
        assert value == pytest.approx(hits / 200)
    assert out[0] == pytest.approx(float((pred == target).double().mean()))
    assert out[-1] == 1.0


def test_bad_arguments(tmp_path):
    root = str(tmp_path)
    with pytest.raises(ValueError, match="'num_train' must be at least 1"):
        SyntheticCorrespondence(root, num_train=0)
    with pytest.raises(ValueError, match="'num_vertices' must be at least"):
        SyntheticCorrespondence(root, num_vertices=50)
    with pytest.raises(ValueError, match="'pose' must be in"):
        SyntheticCorrespondence(root, pose=3)
    with pytest.raises(ValueError, match="'split' must be one of"):
        SyntheticCorrespondence(root, split='val')
    dist = torch.rand(5, 5)
    with pytest.raises(ValueError, match="the same length"):
        correspondence_accuracy(torch.zeros(3, dtype=torch.long),
                                torch.zeros(4, dtype=torch.long), dist, [0])
    with pytest.raises(ValueError, match="template vertices in"):
        correspondence_accuracy(torch.tensor([5]), torch.tensor([0]), dist,
                                [0])
    with pytest.raises(ValueError, match="square matrix"):
        correspondence_accuracy(torch.tensor([0]), torch.tensor([0]),
                                dist[:3], [0])
