"""Shared checks of the dataset tests: independent (numpy/scipy) oracles of
a closed, oriented 2-manifold and of self-intersections."""
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components


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
