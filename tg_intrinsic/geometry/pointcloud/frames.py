r"""Point-cloud normals and tangent frames."""
from typing import Optional

import numpy as np
import scipy.sparse as sp
import torch
from numba import prange
from torch import Tensor

from ..checks import check_batch, check_points, check_positive_int
from ..jit import jit
from .neighbors import knn


def estimate_normals(pos: Tensor, k: int = 10,
                     batch: Optional[Tensor] = None,
                     orient: bool = True) -> Tensor:
    r"""Estimates unit normals of a point cloud by local PCA. As in Hoppe
    et al. (1992), the normal of point :math:`i` is the eigenvector of the
    smallest eigenvalue of the covariance of :math:`i` and its :math:`k`
    nearest neighbours :math:`\mathcal{N}(i)`,

    .. math::
        C_i = \frac{1}{k + 1} \sum_{j \in \{i\} \cup \mathcal{N}(i)}
        (p_j - \bar{p}_i)(p_j - \bar{p}_i)^\top .

    With :obj:`orient=True` every normal is then flipped to point outwards,
    consistently within each example. Each example, moved into the unit
    ball, first collects evidence :math:`u_i` for the sign of :math:`n_i`:

    - *visibility*: the points are drawn as discs (centre :math:`p_i`,
      normal :math:`n_i`, radius 0.7 times the distance to the
      :math:`k`-th neighbour) into orthographic depth buffers from 32
      directions :math:`d` spread over the sphere. A disc at the front of a
      pixel (within 0.15 of its radius) is seen from outside, where an
      outward normal faces the viewer, so it votes :math:`n_i^\top d`.
      With :math:`f_i` and :math:`b_i` the sums of its positive and of its
      negative votes (per view and disc area), the cue is

      .. math::
          v_i = \operatorname{clip}\Big(\frac{f_i - b_i}{0.05}\Big)
          \Big(1 - \frac{\min(f_i, b_i)}{\max(f_i, b_i)}\Big)^{8},

      damped where a disc is seen from both sides (an open sheet, or a
      part thinner than the discs), so that its neighbours decide there;
    - *extreme points*: the farthest point along each of 256 directions
      :math:`d` lies on the convex hull, where :math:`n^\top d \geq 0`, so
      it votes :math:`e_i = n_i^\top d`.

    The votes are then spread over the signed k-nn graph,

    .. math::
        \mathbf{x} = \operatorname{arg\,min}_{\mathbf{x}}
        \sum_{(i, j)} w_{ij} \big(x_i - \operatorname{sign}(n_i^\top n_j)
        \, x_j\big)^2 + \sum_i \mu_i (x_i - u_i)^2,
        \qquad w_{ij} = (n_i^\top n_j)^2 \,
        e^{-(s_{ij} / 0.45)^2 - a_{ij} / 0.1 - c_{ij} / 0.1},

    where :math:`s_{ij}` is the slope of the edge out of the two tangent
    planes (large across thin parts), :math:`a_{ij} \geq 0` how strongly
    the offsets :math:`(p_i - \bar{p}_i)^\top n_i` and
    :math:`(p_j - \bar{p}_j)^\top n_j` from the neighbourhoods' centroids
    put the two points on opposite sides of a thin sheet,
    :math:`c_{ij} \geq 0` how strongly their visibility contradicts the
    coupling, :math:`u_i = v_i + e_i` and
    :math:`\mu_i` larger on thin parts (a sparse SPD system, solved by
    conjugate gradients). Finally a maximum spanning forest of the reliable
    edges (large :math:`w_{ij}`, :math:`x` not contradicting) cuts the
    example into rigid patches: signs inside a patch follow the tree, and a
    patch takes the sign of :math:`\sum_i \operatorname{sign}_i x_i` (points
    on thin parts decide alone). Closed shapes thus get outward normals
    whatever their position, genus or number of components, though not
    everywhere on parts thinner than the neighbourhoods (there PCA mixes
    the two sides) or in cavities seen from few directions. An open
    surface takes the side from which its one-sided parts are seen (a
    relief: the side it faces), and where it is seen from both sides
    everywhere, the side seen more (the convex side of a spherical cap); a
    flat cloud has no outside and gets a consistent, deterministic
    but arbitrary side. Examples of a batch are
    oriented independently (as if passed alone). Orientation runs on the
    CPU (numba), whatever the device of :obj:`pos`.

    Args:
        pos (torch.Tensor): Point positions.
        k (int, optional): Number of neighbours (at least 2).
            (default: :obj:`10`)
        batch (torch.Tensor, optional): Example index of every point; the
            neighbourhoods never cross examples. (default: :obj:`None`)
        orient (bool, optional): Orient the normals consistently.
            (default: :obj:`True`)

    Shapes:
        - **input:** pos :math:`(N, 3)`, batch :math:`(N)`
        - **output:** :math:`(N, 3)`, unit length

    Raises:
        ValueError: if a neighbourhood is degenerate (its points coincide or
            lie on a line), so that no plane can be fitted; remove duplicate
            points or increase :obj:`k`.
    """
    pos = check_points(pos, min_points=1)
    k = check_positive_int(k, 'k', minimum=2)
    batch = check_batch(batch, pos.size(0), pos)
    edge_index = knn(pos, k, batch, loop=False)
    # knn returns exactly k neighbours per centre, grouped by centre.
    neighbours = edge_index[0].view(-1, k)
    pos64 = pos.double()
    if pos.device.type == 'cpu':
        evals, normal = _pca_numba(pos64.contiguous().numpy(),
                                   neighbours.contiguous().numpy())
        evals, normal = torch.from_numpy(evals), torch.from_numpy(normal)
    else:
        evals, normal = _pca_torch(pos64, neighbours)
    tol = 1e3 * torch.finfo(torch.float64).eps
    degenerate = evals[:, 1] <= tol * evals[:, 2].clamp_min(
        torch.finfo(torch.float64).tiny)
    if bool(degenerate.any()):
        bad = degenerate.nonzero().flatten()
        raise ValueError(f"the neighbourhoods of {bad.numel()} point(s) "
                         f"(first: {bad[:5].tolist()}) are degenerate: their "
                         f"{k + 1} points coincide or lie on a line, so no "
                         f"tangent plane can be fitted; remove duplicate "
                         f"points or increase k")
    if orient:
        normal = _orient(pos64, normal, neighbours, batch)
    return normal.to(pos.dtype)


def _pca_torch(pos: Tensor, neighbours: Tensor):
    """Ascending covariance eigenvalues and the normal (eigenvector of the
    smallest one) of every patch; the reference for :func:`_pca_numba`."""
    patch = torch.cat([pos.unsqueeze(1), pos[neighbours]], dim=1)
    centred = patch - patch.mean(dim=1, keepdim=True)
    cov = centred.transpose(1, 2) @ centred / patch.size(1)
    evals, evecs = torch.linalg.eigh(cov)
    return evals, evecs[:, :, 0]


@jit(parallel=True)
def _pca_numba(pos, neighbours):  # pragma: no cover (numba)
    """Covariance of every patch and its eigen-decomposition by cyclic
    Jacobi rotations (exact to rounding for 3 x 3), parallel over points."""
    num, k = neighbours.shape
    evals = np.empty((num, 3))
    normal = np.empty((num, 3))
    for i in prange(num):
        mean = pos[i].copy()
        for a in range(k):
            mean += pos[neighbours[i, a]]
        mean /= k + 1
        d = pos[i] - mean
        c = np.outer(d, d)
        for a in range(k):
            d = pos[neighbours[i, a]] - mean
            for r in range(3):
                for s in range(3):
                    c[r, s] += d[r] * d[s]
        c /= k + 1
        v = np.eye(3)
        for _ in range(50):
            off = c[0, 1] ** 2 + c[0, 2] ** 2 + c[1, 2] ** 2
            if off <= 1e-30 * (c[0, 0] ** 2 + c[1, 1] ** 2 + c[2, 2] ** 2) \
                    or off == 0.0:
                break
            for p in range(2):
                for q in range(p + 1, 3):
                    if c[p, q] == 0.0:
                        continue
                    theta = (c[q, q] - c[p, p]) / (2.0 * c[p, q])
                    t = np.sign(theta) / (abs(theta)
                                          + np.sqrt(theta * theta + 1.0))
                    if theta == 0.0:
                        t = 1.0
                    cs = 1.0 / np.sqrt(t * t + 1.0)
                    sn = t * cs
                    for r in range(3):  # c <- c G
                        a_rp, a_rq = c[r, p], c[r, q]
                        c[r, p] = cs * a_rp - sn * a_rq
                        c[r, q] = sn * a_rp + cs * a_rq
                    for r in range(3):  # c <- G^T c
                        a_pr, a_qr = c[p, r], c[q, r]
                        c[p, r] = cs * a_pr - sn * a_qr
                        c[q, r] = sn * a_pr + cs * a_qr
                    for r in range(3):  # v <- v G
                        v_rp, v_rq = v[r, p], v[r, q]
                        v[r, p] = cs * v_rp - sn * v_rq
                        v[r, q] = sn * v_rp + cs * v_rq
        order = np.argsort(np.array([c[0, 0], c[1, 1], c[2, 2]]))
        for r in range(3):
            evals[i, r] = c[order[r], order[r]]
        lo = order[0]
        for r in range(3):
            normal[i, r] = v[r, lo]
    return evals, normal


# Orientation constants. Lengths are relative to each example scaled into the
# unit ball. They were chosen on the training splits of SyntheticModelNet and
# SyntheticSHREC and on point samples of the scanned meshes beside the
# project other than the benchmark's (benchmarks/normals.py measures the
# test splits and its own samples).
_VIEWS = 32            # orthographic view directions of the visibility test
_EXTREME_DIRS = 256    # directions of the extreme-point rule
_SPLAT = 0.7           # disc radius / distance to the k-th neighbour
_PIXEL = 0.5           # pixel size / median disc radius
_MAX_RES = 1024        # at most this many pixels across an image
_TOLERANCE = 0.15      # a disc this far (per radius) behind the front is seen
_VOTE_SCALE = 0.05     # visibility vote (per view, per disc area) that is sure
_TWO_SIDED = 8.0       # power of (1 - two-sidedness) damping the visibility
_SIDE_SCALE = 0.2      # offset (per neighbourhood radius) that is sure
_EXTREME_WEIGHT = 1.0  # weight of the extreme-point rule
_ANCHOR = 0.03         # data weight mu_i on smooth, one-sided surfaces
_THIN_ANCHOR = 3.0     # extra data weight on thin parts
_THIN_SLOPE = 0.4      # an edge this steep out of the tangent plane is thin
_SLOPE_SCALE = 0.45    # sigma of the edge weight's slope factor
_CONFLICT_SCALE = 0.1  # tau of the edge weight's conflict factor
_PATCH_WEIGHT = 0.5    # edges at least this reliable form rigid patches
_PATCH_CONFLICT = 1.0  # conflict scale of the patch edges (relaxed signs)
_PATCH_THIN = 0.3      # points with more thin edges than this stay single
_ACROSS_SCALE = 0.1    # scale of the edge weight's opposite-sides factor

_CG_TOL = 1e-6         # relative residual of the conjugate gradients


def _directions(num: int) -> np.ndarray:
    """``num`` unit vectors on a Fibonacci spiral (deterministic)."""
    i = np.arange(num, dtype=np.float64) + 0.5
    polar = np.arccos(1.0 - 2.0 * i / num)
    azimuth = np.pi * (1.0 + 5.0 ** 0.5) * i
    return np.stack([np.cos(azimuth) * np.sin(polar),
                     np.sin(azimuth) * np.sin(polar), np.cos(polar)], 1)


def _image_bases(dirs: np.ndarray):
    """Two unit vectors spanning the image plane of every view direction."""
    helper = np.where(np.abs(dirs[:, :1]) < 0.9, [[1.0, 0.0, 0.0]],
                      [[0.0, 1.0, 0.0]])
    e1 = helper - (helper * dirs).sum(1, keepdims=True) * dirs
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    return e1, np.cross(dirs, e1)


_VIEW_DIRS = _directions(_VIEWS)
_VIEW_E1, _VIEW_E2 = _image_bases(_VIEW_DIRS)
_EXTREME = _directions(_EXTREME_DIRS)


def _orient(pos: Tensor, normal: Tensor, neighbours: Tensor,
            batch: Optional[Tensor]) -> Tensor:
    """Flips PCA normals to a consistent, outward orientation (see the
    docstring of :func:`estimate_normals`); CPU, numba."""
    device = normal.device
    p = pos.detach().cpu().numpy()
    n = normal.detach().cpu().numpy().copy()
    nb = neighbours.detach().cpu().numpy().astype(np.int64)
    num, k = nb.shape
    if batch is None:
        ptr = np.array([0, num], dtype=np.int64)
    else:
        counts = np.bincount(batch.cpu().numpy(), minlength=1)
        ptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    q = _unit_ball(p, ptr)
    tiny = np.finfo(np.float64).tiny
    reach = np.maximum(np.linalg.norm(q[nb[:, -1]] - q, axis=1), 1e-12)

    # Evidence u_i for the outward sign of n_i.
    radius = _SPLAT * reach
    med = _segment_median(radius, ptr)
    radius = np.minimum(radius, 4.0 * np.repeat(med, np.diff(ptr)))
    pixel = np.maximum(_PIXEL * med, 2.0 / _MAX_RES)
    votes = _visibility_votes(q, n, radius, ptr, pixel, _VIEW_DIRS,
                              _VIEW_E1, _VIEW_E2, _TOLERANCE)
    votes /= _VIEWS * np.pi / _PIXEL ** 2  # at most about one per view
    # A disc seen from both sides lies on an open sheet (or a thin part):
    # its visibility says little about its side, so it is damped by the
    # two-sidedness and the neighbours decide.
    front = np.maximum(votes, 0.0).sum(0)
    back = np.maximum(-votes, 0.0).sum(0)
    two = np.minimum(front, back) / np.maximum(np.maximum(front, back), tiny)
    seen = np.clip((front - back) / _VOTE_SCALE, -1.0, 1.0) \
        * (1.0 - two) ** _TWO_SIDED
    extreme = _extreme_votes(q, n, ptr, _EXTREME)
    evidence = seen + _EXTREME_WEIGHT * extreme
    # The side of the neighbourhood's centroid: opposite signs of two
    # neighbours put them on the two sides of a thin sheet.
    centroid = (q + q[nb].sum(1)) / (k + 1)
    side = ((q - centroid) * n).sum(1) / reach

    # Signed k-nn graph: w_ij sign(n_i . n_j), weakened for steep edges
    # (thin parts), for neighbours whose side cues put them on the two
    # sides of a sheet and for neighbours whose visibility contradicts the
    # coupling.
    src = np.repeat(np.arange(num, dtype=np.int64), k)
    dst = nb.ravel()
    dot = (n[src] * n[dst]).sum(1)
    coupling = np.where(dot >= 0, 1.0, -1.0)
    edge = q[dst] - q[src]
    length = np.maximum(np.linalg.norm(edge, axis=1), tiny)
    slope = np.maximum(np.abs((edge * n[src]).sum(1)),
                       np.abs((edge * n[dst]).sum(1))) / length
    thin = (slope.reshape(num, k) > _THIN_SLOPE).mean(1)
    conflict = np.maximum(0.0, -coupling * seen[src] * seen[dst])
    sided = np.clip(side / _SIDE_SCALE, -1.0, 1.0)
    across = np.maximum(0.0, -coupling * sided[src] * sided[dst])
    smooth = dot ** 2 * np.exp(-(slope / _SLOPE_SCALE) ** 2
                               - across / _ACROSS_SCALE)
    weight = smooth * np.exp(-conflict / _CONFLICT_SCALE)
    graph = sp.coo_matrix((0.5 * weight * coupling, (src, dst)),
                          shape=(num, num)).tocsr()
    graph = (graph + graph.T).tocsr()
    graph.sort_indices()
    anchor = _ANCHOR + _THIN_ANCHOR * thin
    diag = np.asarray(abs(graph).sum(1)).ravel() + anchor
    relaxed = _solve_blocks(graph.indptr.astype(np.int64),
                            graph.indices.astype(np.int64), graph.data,
                            diag, anchor * evidence, ptr, _CG_TOL)

    # Rigid patches: a maximum spanning forest of the reliable edges fixes
    # the relative signs inside a patch; each patch takes the sign of its
    # summed relaxed values.
    scale = np.repeat(np.maximum(_segment_median(np.abs(relaxed), ptr), tiny),
                      np.diff(ptr))
    xn = relaxed / scale
    reliable = smooth * np.exp(
        -np.maximum(0.0, -coupling * xn[src] * xn[dst]) / _PATCH_CONFLICT)
    keep = ((reliable >= _PATCH_WEIGHT) & (thin[src] <= _PATCH_THIN)
            & (thin[dst] <= _PATCH_THIN))
    order = np.argsort(-reliable[keep], kind='stable')
    root, parity = _signed_forest(num, src[keep][order], dst[keep][order],
                                  coupling[keep][order])
    total = np.bincount(root, parity * relaxed, minlength=num)
    flip = parity * np.where(total[root] >= 0, 1.0, -1.0)
    return torch.from_numpy(n * flip[:, None]).to(device)


@jit
def _unit_ball(pos, ptr):  # pragma: no cover (numba)
    """Every example moved to its bounding-box centre and scaled so that its
    farthest point has norm 1."""
    out = np.empty_like(pos)
    for ex in range(ptr.shape[0] - 1):
        lo, hi = ptr[ex], ptr[ex + 1]
        if hi <= lo:
            continue
        centre = np.empty(3)
        for d in range(3):
            centre[d] = 0.5 * (pos[lo:hi, d].min() + pos[lo:hi, d].max())
        far = 0.0
        for i in range(lo, hi):
            r2 = 0.0
            for d in range(3):
                out[i, d] = pos[i, d] - centre[d]
                r2 += out[i, d] ** 2
            far = max(far, r2)
        far = np.sqrt(far)
        if far > 0.0:
            out[lo:hi] /= far
    return out


@jit
def _segment_median(values, ptr):  # pragma: no cover (numba)
    out = np.zeros(ptr.shape[0] - 1)
    for ex in range(ptr.shape[0] - 1):
        if ptr[ex + 1] > ptr[ex]:
            out[ex] = np.median(values[ptr[ex]:ptr[ex + 1]])
    return out


@jit(parallel=True)
def _visibility_votes(q, n, radius, ptr, pixel, dirs, e1, e2,
                      tolerance):  # pragma: no cover (numba)
    """Orthographic z-buffer of the discs (centre q_i, normal n_i, radius
    r_i) of every example from every direction d. A disc whose depth at a
    pixel is within ``tolerance`` r_i |n_i . d| of the front adds
    n_i . d to its vote. Returns the votes per view ``[V, N]``."""
    num_views = dirs.shape[0]
    num_ex = ptr.shape[0] - 1
    votes = np.zeros((num_views, q.shape[0]))
    for task in prange(num_ex * num_views):
        ex = task // num_views
        v = task - ex * num_views
        lo, hi = ptr[ex], ptr[ex + 1]
        if hi <= lo:
            continue
        h = pixel[ex]
        res = int(np.ceil(2.0 / h)) + 2
        depth = np.full(res * res, -np.inf)
        for sweep in range(2):
            for i in range(lo, hi):
                nd = n[i, 0] * dirs[v, 0] + n[i, 1] * dirs[v, 1] \
                    + n[i, 2] * dirs[v, 2]
                if abs(nd) < 1e-3:  # seen edge-on: covers no area
                    continue
                inv = -1.0 / nd
                na = (n[i, 0] * e1[v, 0] + n[i, 1] * e1[v, 1]
                      + n[i, 2] * e1[v, 2]) * inv
                nb = (n[i, 0] * e2[v, 0] + n[i, 1] * e2[v, 1]
                      + n[i, 2] * e2[v, 2]) * inv
                u = q[i, 0] * e1[v, 0] + q[i, 1] * e1[v, 1] \
                    + q[i, 2] * e1[v, 2] + 1.0
                w = q[i, 0] * e2[v, 0] + q[i, 1] * e2[v, 1] \
                    + q[i, 2] * e2[v, 2] + 1.0
                z = q[i, 0] * dirs[v, 0] + q[i, 1] * dirs[v, 1] \
                    + q[i, 2] * dirs[v, 2]
                r = radius[i]
                r2 = r * r
                slack = tolerance * r * abs(nd)
                x0 = max(int(np.floor((u - r) / h)), 0)
                x1 = min(int(np.floor((u + r) / h)), res - 1)
                y0 = max(int(np.floor((w - r) / h)), 0)
                y1 = min(int(np.floor((w + r) / h)), res - 1)
                for x in range(x0, x1 + 1):
                    du = (x + 0.5) * h - u
                    row = x * res
                    for y in range(y0, y1 + 1):
                        dw = (y + 0.5) * h - w
                        t = na * du + nb * dw  # depth offset on the disc
                        if du * du + dw * dw + t * t > r2:
                            continue
                        if sweep == 0:
                            if z + t > depth[row + y]:
                                depth[row + y] = z + t
                        elif z + t >= depth[row + y] - slack:
                            votes[v, i] += nd
    return votes


@jit(parallel=True)
def _extreme_votes(q, n, ptr, dirs):  # pragma: no cover (numba)
    """The farthest point of an example along d lies on its convex hull, so
    its outward normal has n . d >= 0: it gets the vote n_i . d."""
    out = np.zeros(q.shape[0])
    for ex in prange(ptr.shape[0] - 1):
        lo, hi = ptr[ex], ptr[ex + 1]
        if hi <= lo:
            continue
        for m in range(dirs.shape[0]):
            best = -np.inf
            arg = lo
            for i in range(lo, hi):
                z = q[i, 0] * dirs[m, 0] + q[i, 1] * dirs[m, 1] \
                    + q[i, 2] * dirs[m, 2]
                if z > best:
                    best = z
                    arg = i
            out[arg] += n[arg, 0] * dirs[m, 0] + n[arg, 1] * dirs[m, 1] \
                + n[arg, 2] * dirs[m, 2]
    return out


@jit(parallel=True)
def _solve_blocks(indptr, indices, data, diag, rhs, ptr,
                  tol):  # pragma: no cover (numba)
    """Solves (diag(D) - W) x = b by Jacobi-preconditioned conjugate
    gradients, one example at a time (W: CSR with zero diagonal, no entries
    between examples; D > sum_j |W_ij|, so the matrix is SPD)."""
    x = np.zeros(rhs.shape[0])
    for ex in prange(ptr.shape[0] - 1):
        lo, hi = ptr[ex], ptr[ex + 1]
        m = hi - lo
        if m == 0:
            continue
        b = rhs[lo:hi]
        bnorm = np.sqrt((b * b).sum())
        if bnorm == 0.0:
            continue
        xs = np.zeros(m)
        r = b.copy()
        z = r / diag[lo:hi]
        p = z.copy()
        rz = (r * z).sum()
        ap = np.empty(m)
        for _ in range(20 * m + 100):
            for i in range(m):
                s = diag[lo + i] * p[i]
                for e in range(indptr[lo + i], indptr[lo + i + 1]):
                    s -= data[e] * p[indices[e] - lo]
                ap[i] = s
            pap = (p * ap).sum()
            if pap <= 0.0:
                break
            alpha = rz / pap
            xs += alpha * p
            r -= alpha * ap
            if np.sqrt((r * r).sum()) <= tol * bnorm:
                break
            z = r / diag[lo:hi]
            rz_new = (r * z).sum()
            p = z + (rz_new / rz) * p
            rz = rz_new
        x[lo:hi] = xs
    return x


@jit
def _find(parent, parity, i):  # pragma: no cover (numba)
    """Root of i and the sign of i relative to it, compressing the path."""
    root = i
    sign = 1
    while parent[root] != root:
        sign *= parity[root]
        root = parent[root]
    node = i
    node_sign = sign
    while node != root and parent[node] != root:
        nxt = parent[node]
        nxt_sign = node_sign * parity[node]
        parent[node] = root
        parity[node] = node_sign
        node = nxt
        node_sign = nxt_sign
    return root, sign


@jit
def _signed_forest(num, src, dst, coupling):  # pragma: no cover (numba)
    """Kruskal's spanning forest over the edges in the given order, with the
    relative sign of every point to its tree's root (s_i s_j = coupling)."""
    parent = np.arange(num)
    parity = np.ones(num, dtype=np.int64)
    size = np.ones(num, dtype=np.int64)
    for e in range(src.shape[0]):
        ri, si = _find(parent, parity, src[e])
        rj, sj = _find(parent, parity, dst[e])
        if ri == rj:
            continue
        if size[ri] < size[rj]:
            ri, rj = rj, ri
            si, sj = sj, si
        parent[rj] = ri
        parity[rj] = si * sj * (1 if coupling[e] > 0 else -1)
        size[ri] += size[rj]
    root = np.empty(num, dtype=np.int64)
    sign = np.empty(num)
    for i in range(num):
        r, s = _find(parent, parity, i)
        root[i] = r
        sign[i] = s
    return root, sign


def tangent_frames(normal: Tensor) -> Tensor:
    r"""Builds an orthonormal, right-handed tangent frame at every point.

    Row 0 is :math:`e_u`, the unit projection onto the tangent plane of the
    coordinate axis least aligned with :math:`n`; row 1 is
    :math:`e_v = n \times e_u`; row 2 is :math:`n`. Hence
    :math:`e_u \times e_v = n`. A tangent vector with coordinates
    :math:`(a, b)` is :math:`a e_u + b e_v`. The choice of :math:`e_u` is a
    gauge: intrinsic operators in this library are independent of it.

    Args:
        normal (torch.Tensor): Normals (need not be unit length, must not be
            zero).

    Shapes:
        - **input:** :math:`(N, 3)`
        - **output:** :math:`(N, 3, 3)` with rows :math:`(e_u, e_v, n)`
    """
    normal = check_points(normal, 'normal', min_points=0)
    length = normal.norm(dim=-1, keepdim=True)
    zero = length.squeeze(-1) <= torch.finfo(normal.dtype).tiny
    if bool(zero.any()):
        bad = zero.nonzero().flatten()
        raise ValueError(f"{bad.numel()} normal(s) have zero length (first: "
                         f"{bad[:5].tolist()}); estimate them first, e.g. "
                         f"with estimate_normals(pos)")
    n = normal / length
    axis = torch.zeros_like(n)
    axis.scatter_(1, n.abs().argmin(dim=1, keepdim=True), 1.0)
    e_u = axis - (axis * n).sum(-1, keepdim=True) * n
    e_u = e_u / e_u.norm(dim=-1, keepdim=True)
    e_v = torch.linalg.cross(n, e_u)
    return torch.stack([e_u, e_v, n], dim=1)
