import os

import numpy as np
import pytest
import scipy.sparse as sp
import torch
from scipy.sparse.csgraph import connected_components
from torch_geometric.loader import DataLoader

from tg_intrinsic import IntrinsicData
from tg_intrinsic.datasets import SyntheticSHREC
from tg_intrinsic.datasets import implicit_surfaces as imp
from tg_intrinsic.datasets import shrec_shapes as shapes
from tg_intrinsic.datasets.quadric_decimation import (decimate,
                                                      self_intersections)

SMALL = dict(num_per_class=3, num_train_per_class=2, log=False)


@pytest.fixture(scope='module')
def root(tmp_path_factory):
    return str(tmp_path_factory.mktemp('shrec'))


@pytest.fixture(scope='module')
def small(root):
    train = SyntheticSHREC(root, split='train', **SMALL)
    test = SyntheticSHREC(root, split='test', **SMALL)
    seg = SyntheticSHREC(root, split='train', task='segmentation', **SMALL)
    return train, test, seg


# ------------------------------------------------------------ mesh checks


def manifold_report(pos, face):
    """Independent checks of a closed, oriented 2-manifold (numpy/scipy)."""
    pos = pos.double().numpy()
    F = face.t().numpy()
    n = len(pos)
    out = {}
    # every directed edge once, and its twin once: each undirected edge in
    # exactly two faces with opposite directions (consistent orientation)
    he = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    key = he[:, 0] * n + he[:, 1]
    twin = he[:, 1] * n + he[:, 0]
    out['directed_unique'] = len(np.unique(key)) == len(key)
    out['every_edge_has_twin'] = bool(np.isin(twin, key).all())
    und = np.sort(he, 1)
    _, counts = np.unique(und[:, 0] * n + und[:, 1], return_counts=True)
    out['edges_in_two_faces'] = bool((counts == 2).all())
    # vertex manifold: the faces around every vertex form one fan. Corner
    # id = face * 3 + slot; corners of one vertex in two faces that share an
    # edge incident to it are connected; every vertex needs one component.
    out['vertex_manifold'] = False
    if not (out['directed_unique'] and out['every_edge_has_twin']):
        return out
    order = np.argsort(key)
    j = order[np.searchsorted(key[order], twin)]
    fa, fb = np.arange(len(he)) % len(F), j % len(F)
    slot = np.arange(len(he)) // len(F)
    nxt_slot = (slot + 1) % 3
    # half-edge (a -> b) in face fa at slot s: a is corner s, b corner s+1
    # its twin (b -> a) in face fb at slot t: b is corner t, a corner t+1
    tslot = slot[j]
    ca = fa * 3 + slot
    cb = fa * 3 + nxt_slot
    ta = fb * 3 + (tslot + 1) % 3
    tb = fb * 3 + tslot
    A = sp.coo_matrix((np.ones(2 * len(he)), (np.r_[ca, cb], np.r_[ta, tb])),
                      shape=(3 * len(F), 3 * len(F)))
    nfans, _ = connected_components(A, directed=False)
    out['vertex_manifold'] = nfans == n
    # one connected component, genus 0, no unreferenced vertices
    E = sp.coo_matrix((np.ones(len(he)), (he[:, 0], he[:, 1])), shape=(n, n))
    out['components'] = connected_components(E, directed=False)[0]
    out['euler'] = n - len(und) // 2 + len(F)
    out['all_referenced'] = len(np.unique(F)) == n
    # outward orientation: positive enclosed volume
    a, b, c = pos[F[:, 0]], pos[F[:, 1]], pos[F[:, 2]]
    out['volume'] = float(np.einsum('ij,ij->i', a, np.cross(b, c)).sum() / 6)
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    out['area'] = float(area.sum())
    out['min_area'] = float(area.min())
    return out


def self_intersecting_pairs(pos, face):
    """Brute force: pairs of triangles without a common vertex where an
    edge of one crosses the other (candidates by bounding spheres)."""
    from scipy.spatial import cKDTree
    V = pos.double().numpy()
    F = face.t().numpy()
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    cen = (a + b + c) / 3
    rad = np.max([np.linalg.norm(x - cen, axis=1) for x in (a, b, c)], 0)
    i, j = cKDTree(cen).query_pairs(2 * rad.max(), output_type='ndarray').T
    disjoint = ~(F[i][:, :, None] == F[j][:, None, :]).any((1, 2))
    i, j = i[disjoint], j[disjoint]
    hit = np.zeros(len(i), dtype=bool)
    for s, t in ((i, j), (j, i)):
        A, B, C = V[F[t, 0]], V[F[t, 1]], V[F[t, 2]]
        e1, e2 = B - A, C - A
        for p, q in ((0, 1), (1, 2), (2, 0)):
            o = V[F[s, p]]
            d = V[F[s, q]] - o
            h = np.cross(d, e2)
            det = (e1 * h).sum(1)
            ok = np.abs(det) > 1e-14
            inv = np.where(ok, 1 / np.where(ok, det, 1), 0)
            sv = o - A
            u = (sv * h).sum(1) * inv
            qv = np.cross(sv, e1)
            v = (d * qv).sum(1) * inv
            tt = (e2 * qv).sum(1) * inv
            hit |= ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (tt >= 0) \
                & (tt <= 1)
    return int(hit.sum())


def assert_closed_manifold(pos, face):
    r = manifold_report(pos, face)
    assert r['directed_unique'] and r['every_edge_has_twin'], r
    assert r['edges_in_two_faces'], r
    assert r['vertex_manifold'], r
    assert r['components'] == 1, r
    assert r['euler'] == 2, r
    assert r['all_referenced'], r
    assert r['volume'] > 0, r
    assert r['min_area'] > 0, r
    return r


def test_manifold_checker_catches_defects():
    pos = torch.tensor(np.random.default_rng(0).normal(size=(4, 3)))
    face = torch.tensor([[0, 1, 2], [0, 3, 1], [1, 3, 2], [0, 2, 3]]).t()
    r = manifold_report(pos, face)
    assert r['edges_in_two_faces'] and r['vertex_manifold']
    assert r['euler'] == 2
    flipped = face.clone()
    flipped[[1, 2], 0] = flipped[[2, 1], 0]
    assert not manifold_report(pos, flipped)['every_edge_has_twin']
    # two tetrahedra glued at one vertex: edges fine, vertex not manifold
    pos2 = torch.cat([pos, pos[1:] + 5])
    face2 = torch.cat([face, torch.where(face == 0, 0, face + 3)], 1)
    r2 = manifold_report(pos2, face2)
    assert r2['edges_in_two_faces'] and not r2['vertex_manifold']


# ----------------------------------------------------------- the helpers


def test_marching_tetrahedra_sphere_matches_analytic():
    h, n = 0.05, 50
    lo = np.full(3, -1.25)
    x = lo[0] + h * np.arange(n)
    X, Y, Z = np.meshgrid(x, x, x, indexing='ij')
    f = np.sqrt(X ** 2 + Y ** 2 + Z ** 2) - 0.8
    V, F = imp.marching_tetrahedra(f, lo, h)
    r = assert_closed_manifold(torch.tensor(V), torch.tensor(F).t())
    assert r['volume'] == pytest.approx(4 / 3 * np.pi * 0.8 ** 3, rel=1e-2)
    assert np.abs(np.linalg.norm(V, axis=1) - 0.8).max() < 0.01


def test_decimate_keeps_manifold_and_reaches_target():
    rng = np.random.default_rng(0)
    P = shapes.CLASSES['human'](rng, 0.0)  # rest pose: contact free
    V, F = shapes.extract_surface(P)
    assert shapes.mesh_topology(V, F) == (1, 2) and len(V) > 3000
    for target in (500, 1234):
        V2, F2 = decimate(V, F, target, 3)
        assert len(V2) == target and len(F2) == 2 * target - 4
        assert_closed_manifold(torch.tensor(V2), torch.tensor(F2).t())
        again = decimate(V, F, target, 3)
        assert np.array_equal(again[0], V2) and np.array_equal(again[1], F2)


def test_self_intersection_checks():
    import trimesh
    m = trimesh.creation.icosphere(2)
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    assert self_intersections(V, F) == 0
    assert self_intersecting_pairs(torch.tensor(V), torch.tensor(F).t()) == 0
    # slide a vertex past its neighbour: its fan folds over the neighbour's
    n1 = F[(F == 0).any(1)][0]
    n1 = n1[n1 != 0][0]
    W = V.copy()
    W[0] = V[n1] + 0.8 * (V[n1] - V[0])
    assert self_intersections(W, F) > 0
    assert self_intersecting_pairs(torch.tensor(W), torch.tensor(F).t()) > 0
    # and push a vertex through the far side of the sphere
    W = V.copy()
    W[0] = -1.3 * V[0]
    assert self_intersections(W, F) > 0
    assert self_intersecting_pairs(torch.tensor(W), torch.tensor(F).t()) > 0


def test_banded_grid_has_the_signs_of_the_full_grid():
    rng = np.random.default_rng(4)
    P = shapes.CLASSES['octopus'](rng, 1.0)
    lo = (P[:, 3:6] - P[:, 6:7]).min(0) - 0.1
    full = imp.eval_grid(P, lo, 0.04, 40, 41, 30)
    band = imp.eval_grid_banded(P, lo, 0.04, 40, 41, 30, 3, 1.1)
    assert np.array_equal(full < 0, band < 0)
    near = np.abs(full) < 0.1
    assert np.array_equal(full[near], band[near])


def test_field_is_negative_inside_parts():
    P = np.stack([imp.cone([0, 0, 0], [1, 0, 0], 0.2, 0.1, 2, 0.05),
                  imp.ellipsoid(np.array([0, 0, 0.0]), [0.3, 0.3, 0.3],
                                np.eye(3), 0, 0.1)])
    pts = np.array([[0.5, 0, 0], [0, 0, 0.0], [0.5, 0.5, 0], [2.0, 0, 0]])
    val = imp.eval_points(P, pts)
    assert val[0] < 0 and val[1] < 0 and val[2] > 0 and val[3] > 0
    # exact distance to the round cone's tip sphere
    assert val[3] == pytest.approx(0.9, abs=1e-9)
    assert imp.part_labels(P, pts[[0, 1]]).tolist() == [2, 0]


# --------------------------------------------------------------- dataset


def test_api(small):
    train, test, seg = small
    assert len(train) == 12 * 2 and len(test) == 12 * 1 and len(seg) == 24
    assert train.num_classes == 12 and seg.num_classes == 6
    assert list(train.classes) == sorted(train.classes)
    assert len(train.classes) >= 10
    assert seg.part_names == shapes.PART_NAMES
    assert isinstance(train[0], IntrinsicData)
    assert 'SyntheticSHREC(24' in repr(train)
    assert torch.bincount(torch.cat([d.y for d in train])).tolist() == [2] * 12


def test_every_mesh_is_a_closed_manifold(small):
    train, test, _ = small
    counts = []
    for data in list(train) + list(test):
        assert data.pos.dtype == torch.float32
        assert data.face.dtype == torch.long
        assert data.face.shape[0] == 3
        r = assert_closed_manifold(data.pos, data.face)
        assert r['area'] == pytest.approx(1.0, rel=1e-3)  # unit area
        assert self_intersecting_pairs(data.pos, data.face) == 0
        counts.append(data.num_nodes)
    counts = np.array(counts)
    assert counts.min() >= 500 and counts.max() <= 2000
    assert len(np.unique(counts)) > len(counts) // 2  # resolution varies


def test_labels(small):
    train, test, seg = small
    for data in list(train) + list(test):
        assert data.y.shape == (1, ) and 0 <= int(data.y) < 12
    for data, cls in zip(seg, train):
        assert data.y.shape == (data.num_nodes, )
        assert data.y.dtype == torch.long
        assert int(data.y.min()) >= 0 and int(data.y.max()) < 6
        assert len(torch.unique(data.y)) > 1
        assert torch.equal(data.category, cls.y)
        assert torch.equal(data.pos, cls.pos)


def test_deterministic_and_seed_dependent(small, tmp_path):
    train = small[0]
    same = SyntheticSHREC(str(tmp_path / 'a'), **SMALL)
    for a, b in zip(train, same):
        assert torch.equal(a.pos, b.pos) and torch.equal(a.face, b.face)
    # shape j of class c does not depend on the dataset size
    fewer = SyntheticSHREC(str(tmp_path / 'b'), num_per_class=2,
                           num_train_per_class=1, log=False)
    assert torch.equal(fewer[0].pos, train[0].pos)
    other = SyntheticSHREC(str(tmp_path / 'c'), num_per_class=2,
                           num_train_per_class=1, seed=1, log=False)
    assert not torch.equal(other[0].pos[:10], fewer[0].pos[:10])


def test_cached_not_regenerated(small, root, monkeypatch):
    train = small[0]
    files = [os.path.join(train.processed_dir, f)
             for f in train.processed_file_names]
    assert all(os.path.exists(f) for f in files)
    assert all('seed0' in f and 'n3' in f for f in files)
    mtimes = [os.path.getmtime(f) for f in files]

    def fail(self):
        raise AssertionError('process() called although cached')

    monkeypatch.setattr(SyntheticSHREC, 'process', fail)
    again = SyntheticSHREC(root, split='test', task='segmentation', **SMALL)
    assert len(again) == 12
    assert [os.path.getmtime(f) for f in files] == mtimes
    # other generation parameters -> other files -> regenerated
    with pytest.raises(AssertionError, match='process'):
        SyntheticSHREC(root, seed=5, **SMALL)


def test_batching(small):
    train, _, seg = small
    loader = DataLoader(seg, batch_size=4, shuffle=False)
    batch = next(iter(loader))
    sizes = [seg[i].num_nodes for i in range(4)]
    assert batch.num_graphs == 4 and batch.pos.size(0) == sum(sizes)
    assert batch.y.size(0) == sum(sizes) and batch.category.shape == (4, )
    nf0 = seg[0].face.size(1)
    assert torch.equal(batch.face[:, :nf0], seg[0].face)
    assert torch.equal(batch.face[:, nf0:nf0 + seg[1].face.size(1)],
                       seg[1].face + sizes[0])
    batch = next(iter(DataLoader(train, batch_size=5)))
    assert batch.y.shape == (5, )


def test_bad_arguments(tmp_path):
    with pytest.raises(ValueError, match='split'):
        SyntheticSHREC(str(tmp_path), split='val')
    with pytest.raises(ValueError, match='task'):
        SyntheticSHREC(str(tmp_path), task='regression')
    with pytest.raises(ValueError, match='num_train_per_class'):
        SyntheticSHREC(str(tmp_path), num_per_class=3, num_train_per_class=3)
    with pytest.raises(ValueError, match='num_vertices'):
        SyntheticSHREC(str(tmp_path), num_vertices=(2000, 500))
    with pytest.raises(ValueError, match='seed'):
        SyntheticSHREC(str(tmp_path), seed=-1)
