r"""Affine vector heat log maps and transport on triangle meshes (scipy).

Private back end of :func:`tg_intrinsic.geometry.log_map` with
``method='vector_heat'`` on meshes. It computes the quantities of
geometry-central's ``AffineLocal`` log map and its vector transport (Sharp,
Soliman and Crane, "The Vector Heat Method", 2019), but for many sources at
once. The affine heat flow acts on homogeneous tangent points
:math:`(z, w)` and its matrix is block triangular: the homogeneous part
:math:`w` is the scalar heat flow, and the tangent part :math:`z` is a
connection-Laplacian heat flow driven by :math:`w`,

.. math::
    (M + tL)\, w = \delta_s, \qquad
    (M + tL^\nabla)\, z = -t \sum_j w_{ij}\, e_{ij}\, w_j, \qquad
    (M + tL^\nabla)\, X = \delta_s,

with :math:`M` the lumped (barycentric) mass, :math:`L` the cotan
Laplacian, :math:`L^\nabla` the connection Laplacian, :math:`e_{ij}` the
edge vector from :math:`i` to :math:`j` in the tangent space of :math:`i`,
and :math:`X` the transported unit vector of the source. The log map of
vertex :math:`i` is :math:`z_i / (w_i \hat X_i)` (:math:`\hat X = X/|X|`)
and the transport from the source to :math:`i` turns vectors by
:math:`\arg X_i`. So one real and one complex factorisation serve every
source of a patch, and all sources are solved together as the columns of
one right-hand side, where geometry-central factorises a :math:`3N \times
3N` system and solves it once per source.

Tangent spaces: the corner angles around a vertex are rescaled to sum to
:math:`2\pi` (interior vertices; boundary vertices keep their true fan
angle), and the intrinsic directions are rotated onto the caller's frames
by the rotation that best aligns them with the edges projected onto the
tangent plane. Where a frame's normal points against the triangles'
orientation the angles are mirrored.
"""

from concurrent.futures import ThreadPoolExecutor

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from ..jit import jit

#: Sources solved together (right-hand side columns) at most.
CENTRE_CHUNK = 256


@jit
def _signposts(corner_ptr, corner_list, corner_next, corner_angle, signpost,
               total, is_open):  # pragma: no cover (numba)
    """The angle of every halfedge at its tail, counter-clockwise from the
    vertex's first halfedge, walking the fans of triangles around each
    vertex (open fans from their boundary edge; closed ones from their
    first triangle). Halfedge ``h = 3 f + s`` is also corner ``h``."""
    has_prev = np.zeros(corner_next.shape[0], dtype=np.bool_)
    for c in range(corner_next.shape[0]):
        if corner_next[c] >= 0:
            has_prev[corner_next[c]] = True
    seen = np.zeros(corner_next.shape[0], dtype=np.bool_)
    for v in range(corner_ptr.shape[0] - 1):
        angle = 0.0
        for phase in range(2):  # open fans first, then closed ones
            for k in range(corner_ptr[v], corner_ptr[v + 1]):
                start = corner_list[k]
                if seen[start] or (phase == 0 and has_prev[start]):
                    continue
                if phase == 0:
                    is_open[v] = True
                c = start
                while c >= 0 and not seen[c]:
                    seen[c] = True
                    signpost[c] = angle
                    angle += corner_angle[c]
                    c = corner_next[c]
        total[v] = angle


@jit
def _opposite_cot(a, b, c):  # pragma: no cover (numba)
    """Cotangent of the angle opposite side ``c`` in a triangle with sides
    a, b, c."""
    s = 0.5 * (a + b + c)
    area = np.sqrt(max((s * (s - a) * (s - b) * (s - c)), 1e-300))
    return (a * a + b * b - c * c) / (4.0 * area)


@jit
def _law_of_cosines(a, b, c):  # pragma: no cover (numba)
    """The angle between sides a and b of a triangle with sides a, b, c."""
    cos = (a * a + b * b - c * c) / (2.0 * a * b)
    return np.arccos(min(1.0, max(-1.0, cos)))


@jit
def _flip_to_delaunay(tail, nxt, twin, face_of, face_he, length, signpost,
                      total, is_open, degree):  # pragma: no cover (numba)
    """Intrinsic edge flips until every interior edge is Delaunay (its
    cotan weight is non-negative). A flip replaces the diagonal a-b of the
    quad (a, b, c) + (b, a, d) by c-d, with its length from the quad laid
    flat and its signposts at c and d from the angles inside the old
    corners; nothing else changes. Returns the number of flips."""
    stack = np.empty(tail.shape[0] + 4, dtype=np.int64)
    queued = np.zeros(tail.shape[0], dtype=np.bool_)
    top = 0
    for h in range(tail.shape[0]):
        if twin[h] > h:
            stack[top] = h
            top += 1
            queued[h] = True
    flips = 0
    while top > 0:
        top -= 1
        h = stack[top]
        queued[h] = False
        t = twin[h]
        n1 = nxt[h]
        p1 = nxt[n1]
        n2 = nxt[t]
        p2 = nxt[n2]
        a, b, c, d = tail[h], tail[t], tail[p1], tail[p2]
        l_ab, l_bc, l_ca = length[h], length[n1], length[p1]
        l_ad, l_db = length[n2], length[p2]
        weight = (_opposite_cot(l_bc, l_ca, l_ab)
                  + _opposite_cot(l_ad, l_db, l_ab))
        if weight >= -1e-12 or degree[a] < 3 or degree[b] < 3:
            continue
        # Lay the quad flat: a at the origin, b on the x axis, c above.
        cx = (l_ab * l_ab + l_ca * l_ca - l_bc * l_bc) / (2.0 * l_ab)
        cy = np.sqrt(max(l_ca * l_ca - cx * cx, 0.0))
        dx = (l_ab * l_ab + l_ad * l_ad - l_db * l_db) / (2.0 * l_ab)
        dy = -np.sqrt(max(l_ad * l_ad - dx * dx, 0.0))
        l_cd = np.sqrt((cx - dx) ** 2 + (cy - dy) ** 2)
        # New halfedges: h = d -> c in (c, a, d), t = c -> d in (d, b, c).
        at_d = signpost[p2] + _law_of_cosines(l_db, l_cd, l_bc)
        at_c = signpost[p1] + _law_of_cosines(l_ca, l_cd, l_ad)
        signpost[h] = at_d if is_open[d] else at_d % total[d]
        signpost[t] = at_c if is_open[c] else at_c % total[c]
        tail[h], tail[t] = d, c
        length[h] = length[t] = l_cd
        f1, f2 = face_of[h], face_of[t]
        nxt[p1], nxt[n2], nxt[h] = n2, h, p1
        nxt[p2], nxt[n1], nxt[t] = n1, t, p2
        face_of[n2] = f1
        face_of[n1] = f2
        face_he[f1], face_he[f2] = h, t
        degree[a] -= 1
        degree[b] -= 1
        degree[c] += 1
        degree[d] += 1
        flips += 1
        for e in (n1, p1, n2, p2):
            e = min(e, twin[e]) if twin[e] >= 0 else -1
            if e >= 0 and not queued[e]:
                stack[top] = e
                top += 1
                queued[e] = True
    return flips


class MeshTangentData:
    r"""Everything the affine heat solves need about a whole mesh, on its
    intrinsic Delaunay triangulation (as geometry-central's solvers in
    potpourri3d use by default): obtuse triangles make cotan weights
    negative, and then heat flows change sign and log maps flip.

    ``face`` holds the intrinsic triangles (the same vertices). Corner
    ``c = 3 f + s`` sits at vertex ``face[f, s]``; its first edge goes to
    ``face[f, s + 1]`` and its second to ``face[f, s + 2]``.
    ``dir_first``/``dir_second`` are those edges' unit directions in the
    tangent space of the corner's vertex (angles counter-clockwise from the
    vertex's reference edge, rescaled to sum to 2 pi around interior
    vertices), ``length_first``/``length_second`` their lengths, ``cot`` the
    cotangent of the corner angle, and ``mass`` the barycentric vertex
    areas. A direction at angle ``psi`` is at angle ``offset + sign * psi``
    in the caller's frame: ``offset`` is the rotation that best aligns the
    directions of the mesh edges with their projections onto the frame's
    tangent plane, and ``sign`` is -1 where the frame is mirrored against
    the triangles' orientation."""

    def __init__(self, pos: np.ndarray, face: np.ndarray,
                 frame: np.ndarray, delaunay: bool = True):
        num_vertices = pos.shape[0]
        num_faces = face.shape[0]
        v = face.reshape(-1)
        b = np.roll(face, -1, axis=1).reshape(-1)
        c = np.roll(face, -2, axis=1).reshape(-1)
        to_b, to_c = pos[b] - pos[v], pos[c] - pos[v]
        cross = np.cross(to_b, to_c)
        corner_angle = np.arctan2(np.linalg.norm(cross, axis=1),
                                  (to_b * to_c).sum(1))
        # The corner after c around v starts with c's second edge (v -> c);
        # the twin of halfedge v -> b is b -> v.
        key = v * num_vertices + b
        order = np.argsort(key)

        def find(query):
            at = np.minimum(np.searchsorted(key[order], query), v.size - 1)
            return np.where(key[order][at] == query, order[at], -1)

        corner_next = find(v * num_vertices + c)
        twin = find(b * num_vertices + v)
        corner_list = np.argsort(v, kind='stable')
        corner_ptr = np.zeros(num_vertices + 1, dtype=np.int64)
        np.cumsum(np.bincount(v, minlength=num_vertices), out=corner_ptr[1:])
        signpost = np.zeros(v.size)
        total = np.zeros(num_vertices)
        is_open = np.zeros(num_vertices, dtype=bool)
        _signposts(corner_ptr, corner_list, corner_next, corner_angle,
                   signpost, total, is_open)
        # Orientation: our normal against the triangles' (area weighted).
        normal_sum = np.zeros((num_vertices, 3))
        np.add.at(normal_sum, v, cross)
        self.sign = np.where((normal_sum * frame[:, 2]).sum(1) < 0, -1.0, 1.0)
        # Offset: the rotation that best aligns the intrinsic directions of
        # the mesh edges with their projections onto the frame's plane.
        scale = np.where(is_open | (total <= 0), 1.0,
                         2.0 * np.pi / np.maximum(total, 1e-300))
        projected = np.arctan2((to_b * frame[v, 1]).sum(1),
                               (to_b * frame[v, 0]).sum(1))
        turn = np.exp(1j * (projected - self.sign[v] * scale[v] * signpost))
        self.offset = np.angle(np.bincount(v, turn.real, num_vertices)
                               + 1j * np.bincount(v, turn.imag, num_vertices))
        length = np.linalg.norm(to_b, axis=1)
        nxt = (3 * (np.arange(v.size) // 3) + (np.arange(v.size) + 1) % 3)
        face_he = 3 * np.arange(num_faces)
        tail = v.copy()
        self.flips = 0
        if delaunay:
            degree = np.bincount(v, minlength=num_vertices) + np.bincount(
                b[twin < 0], minlength=num_vertices)
            self.flips = _flip_to_delaunay(
                tail, nxt, twin, np.arange(v.size) // 3, face_he, length,
                signpost, total, is_open, degree)
        # The (intrinsic) triangles and their corners.
        h0 = face_he
        h1 = nxt[h0]
        h2 = nxt[h1]
        self.face = np.stack([tail[h0], tail[h1], tail[h2]], axis=1)
        he = np.stack([h0, h1, h2], axis=1).reshape(-1)
        before = np.stack([h2, h0, h1], axis=1).reshape(-1)  # ends at tail
        after = np.stack([h1, h2, h0], axis=1).reshape(-1)  # opposite
        self.length_first = length[he]
        self.length_second = length[before]
        opposite = length[after]
        a, c2 = self.length_first, self.length_second
        cos = (a * a + c2 * c2 - opposite * opposite) / (2.0 * a * c2)
        angle = np.arccos(np.clip(cos, -1.0, 1.0))
        half = 0.5 * (a + c2 + opposite)
        area = np.sqrt(np.maximum(half * (half - a) * (half - c2)
                                  * (half - opposite), 0.0))
        self.cot = cos * a * c2 / (2.0 * np.maximum(area, 1e-300))
        corner_vertex = self.face.reshape(-1)
        self.mass = np.bincount(corner_vertex, weights=area / 3.0,
                                minlength=num_vertices)
        psi = scale[corner_vertex] * signpost[he]
        self.dir_first = np.exp(1j * psi)
        self.dir_second = np.exp(1j * (psi + scale[corner_vertex] * angle))
        # geometry-central's diffusion time uses the mean edge length of
        # the (intrinsic) triangulation it solves on.
        self.mean_edge = float(length[he].mean())

    def edge_terms(self, faces: np.ndarray):
        """Per edge (v, b) of every given triangle, both directions: the
        rows, the columns, the triangle's half of the cotan weight, the
        edge vector from row to column in the row's space, and the
        transport from the column's space to the row's (unit complex).
        Summed over the triangles, the weights are the cotan weights."""
        slot = (3 * faces[:, None] + np.arange(3)).reshape(-1)
        # Corner (f, s) owns v -> b as its first edge, the corner
        # (f, s + 1) at b owns b -> v as its second; (f, s + 2) is opposite.
        f, s = slot // 3, slot % 3
        at_b = 3 * f + (s + 1) % 3
        v = self.face[f, s]
        b = self.face[f, (s + 1) % 3]
        weight = 0.5 * self.cot[3 * f + (s + 2) % 3]
        e_vb = self.length_first[slot] * self.dir_first[slot]
        e_bv = self.length_second[at_b] * self.dir_second[at_b]
        transport = -self.dir_first[slot] / self.dir_second[at_b]
        return (np.concatenate([v, b]), np.concatenate([b, v]),
                np.concatenate([weight, weight]),
                np.concatenate([e_vb, e_bv]),
                np.concatenate([transport, np.conj(transport)]))


# ----------------------------------------------------------------------------
# sparse triangular solves with many right-hand sides
# ----------------------------------------------------------------------------
# SuperLU's own solve handles one column at a time; these sweep each factor
# once for a whole block of columns (stored row-major, so the inner loop is
# contiguous), about ten times faster for real and five for complex ones.
# They release the GIL, so blocks of sources are solved in threads.
@jit(nogil=True)
def _lower_real(indptr, indices, value, x):  # pragma: no cover (numba)
    for j in range(x.shape[0]):
        for p in range(indptr[j], indptr[j + 1]):
            i = indices[p]
            if i > j:
                a = value[p]
                for c in range(x.shape[1]):
                    x[i, c] -= a * x[j, c]


@jit(nogil=True)
def _upper_real(indptr, indices, value, inv_diag, x):  # pragma: no cover
    for j in range(x.shape[0] - 1, -1, -1):
        for c in range(x.shape[1]):
            x[j, c] *= inv_diag[j]
        for p in range(indptr[j], indptr[j + 1]):
            i = indices[p]
            if i < j:
                a = value[p]
                for c in range(x.shape[1]):
                    x[i, c] -= a * x[j, c]


@jit(nogil=True)
def _lower_complex(indptr, indices, re, im, xr, xi):  # pragma: no cover
    for j in range(xr.shape[0]):
        for p in range(indptr[j], indptr[j + 1]):
            i = indices[p]
            if i > j:
                a, b = re[p], im[p]
                for c in range(xr.shape[1]):
                    xr[i, c] -= a * xr[j, c] - b * xi[j, c]
                    xi[i, c] -= a * xi[j, c] + b * xr[j, c]


@jit(nogil=True)
def _upper_complex(indptr, indices, re, im, inv_re, inv_im, xr,
                   xi):  # pragma: no cover (numba)
    for j in range(xr.shape[0] - 1, -1, -1):
        a, b = inv_re[j], inv_im[j]
        for c in range(xr.shape[1]):
            u, v = xr[j, c], xi[j, c]
            xr[j, c] = a * u - b * v
            xi[j, c] = a * v + b * u
        for p in range(indptr[j], indptr[j + 1]):
            i = indices[p]
            if i < j:
                a, b = re[p], im[p]
                for c in range(xr.shape[1]):
                    xr[i, c] -= a * xr[j, c] - b * xi[j, c]
                    xi[i, c] -= a * xi[j, c] + b * xr[j, c]


@jit(nogil=True)
def _gather(col, row_w, row_z, w, zr, zi, k, r, psi, beta
            ):  # pragma: no cover (numba)
    """Per pair: the log map ``z / (w X/|X|)`` in polar form (r, psi) and
    the angle ``beta`` of the transported axis X. ``row_w``/``row_z`` are
    the pair's target rows in the scalar/vector solutions (-1: not in the
    patch, NaN); columns ``c`` hold z and ``k + c`` hold X."""
    for p in range(col.shape[0]):
        if row_w[p] < 0:
            r[p] = psi[p] = beta[p] = np.nan
            continue
        c = col[p]
        a = w[row_w[p], c]
        z_re, z_im = zr[row_z[p], c], zi[row_z[p], c]
        x_re, x_im = zr[row_z[p], k + c], zi[row_z[p], k + c]
        norm = a * np.sqrt(x_re * x_re + x_im * x_im)
        if norm == 0.0:  # not connected to the source inside the patch
            r[p] = psi[p] = beta[p] = np.nan
            continue
        log_re = (z_re * x_re + z_im * x_im) / norm
        log_im = (z_im * x_re - z_re * x_im) / norm
        r[p] = np.sqrt(log_re * log_re + log_im * log_im)
        psi[p] = np.arctan2(log_im, log_re)
        beta[p] = np.arctan2(x_im, x_re)


class SparseLU:
    """SuperLU factors ``Pr A Pc = L U`` of a square sparse matrix, applied
    in place to blocks of right-hand sides that live in the permuted
    spaces: a right-hand side row ``r`` goes to row ``perm_r[r]``, and the
    solution of unknown ``u`` is found in row ``perm_c[u]``. Complex ones
    are split into real and imaginary parts."""

    def __init__(self, matrix):
        # The heat operators are symmetric (Hermitian) positive definite on
        # an intrinsic Delaunay triangulation: no pivoting, one symmetric
        # ordering. (SuperLU's default partial pivoting took 190 s instead
        # of 0.7 s for a 50k-vertex mesh, with the same fill.)
        lu = splu(sp.csc_matrix(matrix), permc_spec='MMD_AT_PLUS_A',
                  diag_pivot_thresh=0.0, options={'SymmetricMode': True})
        self.complex = np.iscomplexobj(lu.U.data)
        self.perm_r, self.perm_c = lu.perm_r, lu.perm_c
        lower, upper = lu.L.tocsc(), lu.U.tocsc()
        self.lower = (lower.indptr, lower.indices)
        self.upper = (upper.indptr, upper.indices)
        inv_diag = 1.0 / upper.diagonal()
        if self.complex:
            self.lower_value = (lower.data.real.copy(), lower.data.imag.copy())
            self.upper_value = (upper.data.real.copy(), upper.data.imag.copy(),
                                inv_diag.real.copy(), inv_diag.imag.copy())
        else:
            self.lower_value = (lower.data,)
            self.upper_value = (upper.data, inv_diag)

    def solve_in_place(self, x_re: np.ndarray, x_im=None):
        if self.complex:
            _lower_complex(*self.lower, *self.lower_value, x_re, x_im)
            _upper_complex(*self.upper, *self.upper_value, x_re, x_im)
        else:
            _lower_real(*self.lower, *self.lower_value, x_re)
            _upper_real(*self.upper, *self.upper_value, x_re)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """Solves for the columns of ``rhs`` (n x k), in the usual order."""
        x_re = np.empty(rhs.shape)
        x_re[self.perm_r] = rhs.real
        x_im = None
        if self.complex:
            x_im = np.empty(rhs.shape)
            x_im[self.perm_r] = rhs.imag
        self.solve_in_place(x_re, x_im)
        out = x_re[self.perm_c]
        return out + 1j * x_im[self.perm_c] if self.complex else out


class AffineHeatPatch:
    """Factorised heat operators of the triangles ``faces`` (of
    :attr:`MeshTangentData.face`) over their vertices; ``time`` is the
    diffusion time (the whole mesh's mean edge length squared). The mass
    of every vertex is its whole-mesh mass, so that a patch differs from
    the whole mesh only by the triangles it leaves out."""

    def __init__(self, data: MeshTangentData, faces: np.ndarray,
                 time: float):
        self.vertices = np.unique(data.face[faces])
        n = self.vertices.size
        self.local = np.full(data.mass.shape[0], -1, dtype=np.int64)
        self.local[self.vertices] = np.arange(n)
        row, col, weight, edge, transport = data.edge_terms(faces)
        row, col = self.local[row], self.local[col]
        diag = np.arange(n)
        rows, cols = np.concatenate([row, diag]), np.concatenate([col, diag])
        heat = data.mass[self.vertices] + time * np.bincount(
            row, weights=weight, minlength=n)
        self.scalar = SparseLU(sp.coo_matrix(
            (np.concatenate([-time * weight, heat]), (rows, cols)),
            shape=(n, n)))
        self.vector = SparseLU(sp.coo_matrix(
            (np.concatenate([-time * weight * transport, heat]),
             (rows, cols)), shape=(n, n)))
        # The drive of z by w, from the scalar solution's rows to the
        # vector right-hand side's rows.
        drive = -time * weight * edge
        at = (self.vector.perm_r[row], self.scalar.perm_c[col])
        self.drive_re = sp.csr_matrix((drive.real, at), shape=(n, n))
        self.drive_im = sp.csr_matrix((drive.imag, at), shape=(n, n))

    def solve(self, sources: np.ndarray, ptr: np.ndarray,
              targets: np.ndarray, threads: int = 1):
        """For every source ``s = sources[k]`` and target ``v`` in
        ``targets[ptr[k]:ptr[k + 1]]`` (whole-mesh indices): the log map of
        ``v`` at ``s`` in polar form ``(r, psi)`` (psi in ``s``'s tangent
        space) and the angle ``beta`` by which the transport from ``s``
        turns ``s``'s reference direction, in ``v``'s space. NaN where
        ``v`` is outside the patch or not connected to ``s`` inside it.
        Blocks of sources run in ``threads`` threads."""
        n = self.vertices.size
        out = [np.empty(targets.size) for _ in range(3)]
        target = self.local[targets]
        inside = target >= 0
        row_w = np.where(inside, self.scalar.perm_c[target], -1)
        row_z = np.where(inside, self.vector.perm_c[target], -1)
        source = self.local[sources]
        # Columns per block: five n x k arrays of about 128 MB at most, and
        # at least one block per thread.
        chunk = int(np.clip(min(128e6 / (40.0 * n),
                                -(-sources.size // max(threads, 1))),
                            16, CENTRE_CHUNK))

        def solve_block(lo):
            k = min(chunk, sources.size - lo)
            cols = np.arange(k)
            w = np.zeros((n, k))
            w[self.scalar.perm_r[source[lo:lo + k]], cols] = 1.0
            self.scalar.solve_in_place(w)
            z_re = np.zeros((n, 2 * k))
            z_im = np.zeros((n, 2 * k))
            z_re[:, :k] = self.drive_re @ w
            z_im[:, :k] = self.drive_im @ w
            z_re[self.vector.perm_r[source[lo:lo + k]], k + cols] = 1.0
            self.vector.solve_in_place(z_re, z_im)
            pairs = slice(ptr[lo], ptr[lo + k])
            col = np.repeat(cols, np.diff(ptr[lo:lo + k + 1]))
            _gather(col, row_w[pairs], row_z[pairs], w, z_re, z_im, k,
                    out[0][pairs], out[1][pairs], out[2][pairs])

        starts = range(0, sources.size, chunk)
        if threads > 1 and len(starts) > 1:
            with ThreadPoolExecutor(max_workers=threads) as pool:
                list(pool.map(solve_block, starts))
        else:
            for lo in starts:
                solve_block(lo)
        return out


__all__ = ['MeshTangentData', 'AffineHeatPatch', 'SparseLU', 'CENTRE_CHUNK']
