import os

import numpy as np
import pytest
import torch
from scipy.spatial import cKDTree
from torch_geometric.loader import DataLoader

from tg_intrinsic import IntrinsicData
from tg_intrinsic.datasets import SyntheticModelNet
from tg_intrinsic.datasets import modelnet_shapes as shapes

SMALL = dict(num_points=512, num_per_class=(3, 2), log=False)


@pytest.fixture(scope='module')
def root(tmp_path_factory):
    return str(tmp_path_factory.mktemp('modelnet'))


@pytest.fixture(scope='module')
def small(root):
    return (SyntheticModelNet(root, split='train', **SMALL),
            SyntheticModelNet(root, split='test', **SMALL))


def test_api_and_shapes(small):
    train, test = small
    assert len(train) == 12 * 3 and len(test) == 12 * 2
    assert train.num_classes == 12 and len(train.classes) >= 10
    assert list(train.classes) == sorted(train.classes)
    for data in list(train) + list(test):
        assert isinstance(data, IntrinsicData)
        assert data.pos.shape == (512, 3) and data.normal.shape == (512, 3)
        assert data.pos.dtype == torch.float32 and data.y.shape == (1, )
        norm = data.pos.norm(dim=1)
        assert float(norm.max()) == pytest.approx(1.0, abs=1e-5)
        assert torch.allclose(data.normal.norm(dim=1), torch.ones(512),
                              atol=1e-5)
        # farthest point sampling: no duplicates
        assert torch.unique(data.pos, dim=0).size(0) == 512
    assert 'SyntheticModelNet(36' in repr(train)


def test_classes_balanced(small):
    train, test = small
    assert torch.bincount(torch.cat([d.y for d in train])).tolist() == [3] * 12
    assert torch.bincount(torch.cat([d.y for d in test])).tolist() == [2] * 12


def test_sampled_normals_are_triangle_normals():
    rng = np.random.default_rng(0)
    parts = shapes.CLASSES['chair'](rng)
    V, F, _ = shapes.shape_mesh(parts)
    pts, nrm, fid = shapes.sample_surface(parts, 2000, rng)
    a, b, c = V[F[fid, 0]], V[F[fid, 1]], V[F[fid, 2]]
    # on the plane of the triangle it came from, inside the triangle
    assert np.abs(((pts - a) * nrm).sum(1)).max() < 1e-9
    assert np.abs((nrm * (b - a)).sum(1)).max() < 1e-9
    assert np.abs((nrm * (c - a)).sum(1)).max() < 1e-9
    n = np.cross(b - a, c - a)
    for p, q in ((a, b), (b, c), (c, a)):
        assert (np.einsum('ij,ij->i', np.cross(q - p, pts - p), n)
                >= -1e-12).all()


def test_normals_of_known_primitives():
    rng = np.random.default_rng(1)
    # a sphere: outward, close to radial (facet normals of the UV sphere)
    c = np.array([0.3, -0.2, 0.5])
    pts, nrm, _ = shapes.sample_surface([shapes.ellipsoid(c, [0.7] * 3)],
                                        3000, rng)
    radial = (pts - c) / np.linalg.norm(pts - c, axis=1, keepdims=True)
    assert (np.abs(np.linalg.norm(pts - c, axis=1) - 0.7) < 0.03).all()
    assert ((radial * nrm).sum(1) > 0.97).all()
    # a rotated box: normals are +- its axes, outward
    box = shapes.box([0, 0, 1.0], [1.0, 2.0, 0.5], yaw=0.4)
    pts, nrm, _ = shapes.sample_surface([box], 3000, rng)
    local = (pts - box.t) @ np.linalg.inv(box.A).T
    lnrm = nrm @ box.A  # axes of the box frame (up to scale)
    lnrm /= np.linalg.norm(lnrm, axis=1, keepdims=True)
    axis = np.abs(lnrm).argmax(1)
    assert np.allclose(np.abs(lnrm).max(1), 1.0, atol=1e-9)
    on_face = np.abs(local[np.arange(len(pts)), axis])
    assert np.allclose(on_face, 1.0, atol=1e-9)
    assert (np.sign(local[np.arange(len(pts)), axis])
            == np.sign(lnrm[np.arange(len(pts)), axis])).all()
    # a cup's inner wall faces the axis, the outer wall away from it
    cup = shapes.tube([0, 0, 0], 1.0, 0.8, 1.0)
    pts, nrm, _ = shapes.sample_surface([cup], 3000, rng)
    rho = np.linalg.norm(pts[:, :2], axis=1)
    radial = (pts[:, :2] * nrm[:, :2]).sum(1) / rho
    side = np.abs(nrm[:, 2]) < 0.5
    assert (radial[side & (rho > 0.9)] > 0.97).all()
    assert (radial[side & (rho < 0.9)] < -0.97).all()


def test_hidden_samples_are_removed():
    rng = np.random.default_rng(2)
    a = shapes.box([0, 0, 0], [2.0, 2.0, 2.0])
    b = shapes.box([1.0, 0, 0], [2.0, 1.0, 1.0])
    pts, _, _ = shapes.sample_surface([a, b], 4000, rng)
    inside_a = (np.abs(pts) < 1 - 1e-6).all(1)
    inside_b = (np.abs(pts - [1.0, 0, 0]) < [1 - 1e-6, 0.5 - 1e-6,
                                             0.5 - 1e-6]).all(1)
    assert not inside_a.any() and not inside_b.any()


def test_contact_faces_between_touching_parts_are_removed():
    # A box standing on another (like a mattress on a bed base): the top
    # of the lower and the bottom of the upper box coincide where they
    # touch; both faces are inside the union and must not be sampled, while
    # the uncovered rest of the lower box's top and flush side faces stay.
    rng = np.random.default_rng(3)
    base = shapes.box([0, 0, 0.5], [2.0, 2.0, 1.0])
    top = shapes.box([0.25, 0, 1.25], [1.0, 1.0, 0.5])
    flush = shapes.box([-1.5, 0, 0.5], [1.0, 2.0, 1.0])  # side to side
    pts, nrm, _ = shapes.sample_surface([base, top, flush], 6000, rng)
    on_contact = (np.abs(pts[:, 2] - 1.0) < 1e-9) \
        & (np.abs(pts[:, 0] - 0.25) < 0.5) & (np.abs(pts[:, 1]) < 0.5)
    assert not on_contact.any()
    on_wall = (np.abs(pts[:, 0] + 1.0) < 1e-9) & (pts[:, 2] < 1.0)
    assert not on_wall.any()
    # the rest of the base's top face and the top box's sides remain
    uncovered = (np.abs(pts[:, 2] - 1.0) < 1e-9) & (pts[:, 0] > 0.8)
    assert uncovered.sum() > 20 and (nrm[uncovered, 2] > 0.99).all()
    sides = (np.abs(pts[:, 1] - 0.5) < 1e-9) & (pts[:, 2] > 1.0)
    assert sides.sum() > 20
    # no two samples with opposite normals coincide anywhere
    from scipy.spatial import cKDTree
    pairs = cKDTree(pts).query_pairs(1e-3, output_type='ndarray')
    assert ((nrm[pairs[:, 0]] * nrm[pairs[:, 1]]).sum(1) > -0.5).all()


def test_dataset_normals_perpendicular_to_local_surface(small):
    """Normals agree with a PCA plane fit of the sampled points."""
    train, _ = small
    agree = []
    for data in train:
        pos, nrm = data.pos.double().numpy(), data.normal.double().numpy()
        _, idx = cKDTree(pos).query(pos, k=10)
        nb = pos[idx] - pos[idx].mean(1, keepdims=True)
        _, _, vt = np.linalg.svd(nb)
        agree.append(np.abs((vt[:, 2] * nrm).sum(1)))
    agree = np.concatenate(agree)
    # thin parts (legs, plates) mix both sides in a neighbourhood; random
    # unit vectors would give a median of 0.5
    assert np.median(agree) > 0.95
    assert (agree > 0.9).mean() > 0.7


def test_upright_and_rotate_up(small, tmp_path):
    train = small[0]
    rot = SyntheticModelNet(str(tmp_path), rotate_up=True, **SMALL)
    for a, b in zip(train, rot):
        assert torch.allclose(a.pos[:, 2], b.pos[:, 2], atol=1e-6)
        assert torch.allclose(a.pos[:, :2].norm(dim=1),
                              b.pos[:, :2].norm(dim=1), atol=1e-6)
        assert torch.allclose(a.normal[:, 2], b.normal[:, 2], atol=1e-6)
    # aligned tables: the table top is the largest horizontal surface
    table = [d for d in train if train.classes[int(d.y)] == 'table'][0]
    up = table.normal[:, 2].abs() > 0.99
    assert up.float().mean() > 0.3


def test_deterministic_and_cached(small, root, tmp_path, monkeypatch):
    train = small[0]
    same = SyntheticModelNet(str(tmp_path / 'a'), **SMALL)
    for a, b in zip(train, same):
        assert torch.equal(a.pos, b.pos) and torch.equal(a.normal, b.normal)
    other = SyntheticModelNet(str(tmp_path / 'b'), seed=3, **SMALL)
    assert not torch.equal(other[0].pos, train[0].pos)

    files = [os.path.join(train.processed_dir, f)
             for f in train.processed_file_names]
    assert all('seed0' in os.path.basename(f) for f in files)
    mtimes = [os.path.getmtime(f) for f in files]

    def fail(self):
        raise AssertionError('process() called although cached')

    monkeypatch.setattr(SyntheticModelNet, 'process', fail)
    again = SyntheticModelNet(root, split='test', **SMALL)
    assert torch.equal(again[0].pos, small[1][0].pos)
    assert [os.path.getmtime(f) for f in files] == mtimes
    with pytest.raises(AssertionError, match='process'):
        SyntheticModelNet(root, num_points=256, num_per_class=(3, 2),
                          log=False)


def test_batching(small):
    batch = next(iter(DataLoader(small[0], batch_size=6, shuffle=True)))
    assert batch.pos.shape == (6 * 512, 3) and batch.normal.shape == (6 * 512,
                                                                      3)
    assert batch.y.shape == (6, ) and batch.batch.max() == 5


def test_bad_arguments(tmp_path):
    with pytest.raises(ValueError, match='split'):
        SyntheticModelNet(str(tmp_path), split='valid')
    with pytest.raises(ValueError, match='num_per_class'):
        SyntheticModelNet(str(tmp_path), num_per_class=10)
    with pytest.raises(ValueError, match='num_points'):
        SyntheticModelNet(str(tmp_path), num_points=0)


def test_a_pre_transform_is_never_skipped_by_an_older_cache(tmp_path):
    # The README's DeltaConv example passes pre_transform=MLSOperators(...)
    # to a root the demo may already have generated without one.
    from tg_intrinsic.transforms import MLSOperators
    kwargs = dict(num_points=64, num_per_class=(1, 1), log=False)
    plain = SyntheticModelNet(str(tmp_path), 'train', **kwargs)
    assert 'grad_weight' not in plain[0]
    pre = SyntheticModelNet(str(tmp_path), 'train', **kwargs,
                            pre_transform=MLSOperators(k=8))
    assert 'grad_weight' in pre[0]
    other = SyntheticModelNet(str(tmp_path), 'train', **kwargs,
                              pre_transform=MLSOperators(k=6))
    assert other[0].edge_index.size(1) == 6 * other[0].num_nodes
    assert torch.equal(plain[0].pos, pre[0].pos)
