"""SyntheticShapeParts: layout as ShapeNetPartNormal, determinism, labels
checked geometrically against the primitives, parts per category, points
on the surface, unit normals, batching."""
import numpy as np
import pytest
import torch
from torch_geometric.loader import DataLoader

from tg_intrinsic.data import IntrinsicData
from tg_intrinsic.datasets import SyntheticShapeParts
from tg_intrinsic.datasets.synthetic_parts import CATEGORY_PARTS, NUM_PARTS

SMALL = dict(num_points=256, num_per_category=(2, 1), log=False)


@pytest.fixture(scope='module')
def small(tmp_path_factory):
    root = str(tmp_path_factory.mktemp('parts'))
    return (SyntheticShapeParts(root, 'train', **SMALL),
            SyntheticShapeParts(root, 'test', **SMALL))


def _on_triangles(points, V, F, tol=1e-5):
    """Brute force: whether every point lies on one of the triangles
    (distance to the triangle's plane and barycentric coordinates)."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    d = points[:, None] - a[None]                              # [P, F, 3]
    off_plane = np.abs((d * n[None]).sum(-1)) < tol
    e0, e1 = b - a, c - a
    d00, d01, d11 = (e0 * e0).sum(1), (e0 * e1).sum(1), (e1 * e1).sum(1)
    d20, d21 = (d * e0[None]).sum(-1), (d * e1[None]).sum(-1)
    den = d00 * d11 - d01 * d01
    v = (d11 * d20 - d01 * d21) / den
    w = (d00 * d21 - d01 * d20) / den
    inside = (v > -1e-4) & (w > -1e-4) & (v + w < 1 + 1e-4)
    return (off_plane & inside).any(1)


def test_layout_matches_shapenet_part(small):
    train, test = small
    assert len(train) == 5 * 2 and len(test) == 5
    assert train.num_classes == NUM_PARTS == 16
    assert train.categories == ('Airplane', 'Chair', 'Lamp', 'Mug',
                                'Table')
    assert train.part_mask.shape == (5, 16)
    assert train.part_mask.sum(0).tolist() == [1] * 16  # a partition
    for data in list(train) + list(test):
        assert isinstance(data, IntrinsicData)
        assert set(data.keys()) == {'pos', 'normal', 'y', 'category'}
        assert data.pos.shape == (256, 3) and data.y.shape == (256, )
        assert data.pos.dtype == torch.float32 and data.y.dtype == \
            torch.int64 and data.category.shape == (1, )
        assert float(data.pos.norm(dim=1).max()) == pytest.approx(1.0,
                                                                  abs=1e-5)
        assert torch.allclose(data.normal.norm(dim=1), torch.ones(256),
                              atol=1e-5)
        # every point carries a part of its own category only
        assert train.part_mask[int(data.category)][data.y].all()
    batch = next(iter(DataLoader(train, batch_size=4)))
    assert batch.category.shape == (4, ) and batch.y.shape == (1024, )
    assert 'SyntheticShapeParts(10' in repr(train)


def test_same_seed_same_tensors(small, tmp_path):
    train, _ = small
    again = SyntheticShapeParts(str(tmp_path), 'train', **SMALL)
    for a, b in zip(train, again):
        for key in ('pos', 'normal', 'y', 'category'):
            assert torch.equal(a[key], b[key])
    other = SyntheticShapeParts(str(tmp_path / 'other'), 'train', seed=1,
                                **SMALL)
    assert not torch.equal(train[0].pos, other[0].pos)


@pytest.mark.parametrize('category', range(5))
def test_labels_are_the_parts_the_points_lie_on(small, category):
    train, _ = small
    data, parts, labels = train.generate(category, 0, return_parts=True)
    assert torch.equal(data.pos, train[2 * category].pos)
    pts = data.pos.double().numpy()
    y = data.y.numpy()
    on = np.stack([_on_triangles(pts, *part.mesh()) for part in parts], 1)
    # every point lies on the surface of some primitive ...
    assert on.any(1).all()
    # ... and its label is the part of a primitive it lies on
    allowed = np.zeros((len(pts), NUM_PARTS), bool)
    for p, label in enumerate(labels):
        allowed[on[:, p], label] = True
    assert allowed[np.arange(len(pts)), y].all()
    name = train.categories[category]
    assert set(labels.tolist()) <= set(CATEGORY_PARTS[name])


def test_bad_arguments_are_explained(tmp_path):
    with pytest.raises(ValueError, match="'num_per_category' must be a pair"):
        SyntheticShapeParts(str(tmp_path), num_per_category=3, log=False)
    with pytest.raises(ValueError, match="'split' must be one of"):
        SyntheticShapeParts(str(tmp_path), split='val', log=False)
    with pytest.raises(ValueError, match="'scale_jitter' must be in"):
        SyntheticShapeParts(str(tmp_path), scale_jitter=2.0, log=False)
