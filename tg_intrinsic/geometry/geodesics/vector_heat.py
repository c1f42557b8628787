r"""Vector heat log maps and transport on local patches.

Private back end of :func:`tg_intrinsic.geometry.log_map` with
``method='vector_heat'``. The original Harmonic Surface Networks code solves
one log map and one transport problem per vertex on the *whole* surface; the
heat flows behind both (Sharp et al., "The Vector Heat Method", 2019) are
short-time, so the result inside a disc barely depends on the surface far
outside it: the influence of a patch rim at distance b decays like
exp(-2 b / h) for the diffusion time t = h^2 (h the mean edge length).
Here the centres are grouped around seeds, every group is solved on the
patch within a band of ``margin * h`` around its discs (one factorisation
per patch, the diffusion time of the whole surface), or on the whole
component where a cost model says so, and only the entries of the requested
edges are kept. Meshes use our own solver (:mod:`.affine_heat`, blocks of
centres in threads); point clouds use potpourri3d's point-cloud solver, with
large jobs in worker processes. :func:`_mesh_conversion` and
:func:`_solve_centres` also turn potpourri3d's mesh solver into the
original's per-vertex answer, which the tests and benchmarks compare with.

Everything here is numpy on the CPU; the public wrapper converts tensors.
"""
import inspect
import math
import os
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from typing import Dict, List, Optional

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.spatial import cKDTree

from .affine_heat import AffineHeatPatch, MeshTangentData
from .fast_marching import march_one, surface_index

# Group spacing as a fraction of the typical disc-plus-band radius: larger
# groups share one factorisation among more centres but solve on bigger
# patches (measured on 10k-vertex meshes: 0.2-0.3 is best, flat around it).
GROUP_FRACTION = 0.3
# Above this much estimated work (centres x patch vertices), point-cloud
# patches are farmed out to worker processes; below it, starting them
# costs more.
POOL_WORK = 1.5e7
# 'auto' solves on patches unless the cost model (:func:`solve_cost`) says
# that whole components are cheaper; 'patches' and 'whole' force a choice.
PLAN = 'auto'

_STATE: Dict = {}
_THREAD_VARIABLES = ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS',
                     'MKL_NUM_THREADS', 'NUMBA_NUM_THREADS')


def _log_map_kwargs():
    import potpourri3d as pp3d
    params = inspect.signature(pp3d.MeshVectorHeatSolver.compute_log_map)
    # 'AffineLocal' is accurate near the source; older potpourri3d versions
    # have no strategy argument and use the plain vector heat log map.
    return ({'strategy': 'AffineLocal'} if 'strategy' in params.parameters
            else {})


def mean_spacing(kind: str, pos: np.ndarray, face) -> float:
    """Mean edge length (meshes) or mean nearest-neighbour distance (point
    clouds): the length that sets the heat method's diffusion time."""
    if kind == 'mesh':
        return float(np.linalg.norm(pos[face] - pos[np.roll(face, 1, axis=1)],
                                    axis=2).mean())
    return float(cKDTree(pos).query(pos, k=2)[0][:, 1].mean())


def init_state(kind: str, pos: np.ndarray, face, frame: np.ndarray,
               spacing: float, tangent=None):
    """Stores the surface in this process (the worker initializer).
    ``spacing`` is :func:`mean_spacing` of the whole surface."""
    _STATE.clear()
    _STATE.update(kind=kind, pos=pos, face=face, frame=frame, spacing=spacing)
    if kind == 'mesh':
        _STATE['index'] = surface_index(pos, face)
        _STATE['label'] = _components(face, pos.shape[0])
        _STATE['tangent'] = (MeshTangentData(pos, face, frame)
                             if tangent is None else tangent)
    else:
        _STATE['tree'] = cKDTree(pos)


# ----------------------------------------------------------------------------
# patch extraction
# ----------------------------------------------------------------------------
def _components(face: np.ndarray, num_vertices: int):
    rows = face.reshape(-1)
    cols = np.roll(face, 1, axis=1).reshape(-1)
    graph = sp.coo_matrix((np.ones(rows.size), (rows, cols)),
                          shape=(num_vertices, num_vertices))
    return connected_components(graph, directed=False)[1]


# ----------------------------------------------------------------------------
# frame conversion: geometry-central's vertex tangent spaces -> our frames
# ----------------------------------------------------------------------------
def _wrap(angle: np.ndarray) -> np.ndarray:
    return np.mod(angle + np.pi, 2 * np.pi) - np.pi


def _mesh_conversion(V, F, global_index, frame, basis_x, basis_n):
    """Per-vertex data to turn geometry-central angles into our angles.

    Interior vertices: their basis is a rotation of ours (in the tangent
    plane), possibly mirrored when their normal points the other way, so
    ``ours = offset + sign * theirs``. Boundary vertices: geometry-central
    rescales the fan of triangles (total angle Theta) to a half plane
    starting at the first halfedge counter-clockwise from the boundary, so
    an angle psi in [0, pi] is the fan angle psi * Theta / pi from that
    halfedge (see :func:`_to_ours` for directions off the surface)."""
    ours = frame[global_index]
    e_u, e_v, n = ours[:, 0], ours[:, 1], ours[:, 2]
    sign = np.where((basis_n * n).sum(1) < 0, -1.0, 1.0)
    offset = np.arctan2((basis_x * e_v).sum(1), (basis_x * e_u).sum(1))
    nv = V.shape[0]
    a = np.concatenate([F[:, 0], F[:, 1], F[:, 2]])
    b = np.concatenate([F[:, 1], F[:, 2], F[:, 0]])
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    _, inverse, count = np.unique(lo * nv + hi, return_inverse=True,
                                  return_counts=True)
    on_rim = count[inverse] == 1  # directed face edges on the boundary
    boundary = np.zeros(nv, dtype=bool)
    boundary[a[on_rim]] = True
    theta_sum = np.zeros(nv)
    ref = np.zeros(nv)
    if boundary.any():
        for s in range(3):  # corner angles
            p = V[F[:, s]]
            u = V[F[:, (s + 1) % 3]] - p
            w = V[F[:, (s + 2) % 3]] - p
            ang = np.arctan2(np.linalg.norm(np.cross(u, w), axis=1),
                             (u * w).sum(1))
            np.add.at(theta_sum, F[:, s], ang)
        # The fan of a boundary vertex starts at its outgoing rim halfedge.
        start, end = a[on_rim], b[on_rim]
        d = V[end] - V[start]
        ref[start] = np.arctan2((d * e_v[start]).sum(1),
                                (d * e_u[start]).sum(1))
    return dict(sign=sign, offset=offset, boundary=boundary,
                theta_sum=theta_sum, ref=ref)


def _to_ours(conv, local: np.ndarray, psi: np.ndarray,
             hint: Optional[np.ndarray] = None) -> np.ndarray:
    """Angles ``psi`` of tangent vectors at local vertices ``local`` in
    geometry-central's bases, as angles in our frames.

    At a boundary vertex with fan angle Theta, geometry-central's angle
    psi stands for the fan angles (psi + 2 pi k) Theta / pi for any integer
    k (the map z -> z^(pi / Theta) is not one to one). Without ``hint`` the
    vector points into the surface (a log map): k = 0, with psi taken in
    [-pi / 2, 3 pi / 2) around the half plane. With ``hint`` (an estimate of
    the answer in our frame, for transported vectors, which may point
    anywhere) the branch closest to it is taken."""
    sign = conv['sign'][local]
    out = conv['offset'][local] + sign * psi
    bnd = conv['boundary'][local] if 'boundary' in conv else None
    if bnd is not None and bnd.any():
        at = local[bnd]
        scale = conv['theta_sum'][at] / np.pi
        if hint is None:
            fan = (np.mod(psi[bnd] + 0.5 * np.pi, 2 * np.pi) - 0.5 * np.pi) \
                * scale
        else:
            want = _wrap(sign[bnd] * (hint[bnd] - conv['ref'][at]))
            # The fan angle (psi + 2 pi k) * scale closest to ``want``
            # modulo 2 pi: the nearest k for want and want -+ 2 pi.
            p = np.mod(psi[bnd], 2 * np.pi)
            best = np.full(p.shape, np.inf)
            fan = np.zeros_like(p)
            for shift in (-2 * np.pi, 0.0, 2 * np.pi):
                k = np.round(((want + shift) / scale - p) / (2 * np.pi))
                cand = (p + 2 * np.pi * k) * scale
                miss = np.abs(cand - want - shift)
                take = miss < best
                best[take] = miss[take]
                fan[take] = cand[take]
        out[bnd] = conv['ref'][at] + sign[bnd] * fan
    return _wrap(out)


def rows_of(ptr: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Positions ``ptr[k]:ptr[k + 1]`` of all ``k`` in ``rows``, concatenated
    (vectorised)."""
    counts = ptr[rows + 1] - ptr[rows]
    total = int(counts.sum())
    starts = np.repeat(ptr[rows] - (np.cumsum(counts) - counts), counts)
    return starts + np.arange(total)


def _solve_centres(solver, conv, log_kwargs, centres_local, nbr_local,
                   nbr_ptr, hint_phi):
    """Log map and transport from every centre; returns r, theta, phi for
    the neighbour lists (``nbr_local`` local indices, all valid).
    ``hint_phi`` estimates phi (the 'fast' method); it only picks a branch
    at boundary vertices."""
    m = nbr_local.shape[0]
    r = np.empty(m)
    theta = np.empty(m)
    phi = np.empty(m)
    for k, c in enumerate(centres_local):  # one solve per centre
        lo, hi = nbr_ptr[k], nbr_ptr[k + 1]
        nb = nbr_local[lo:hi]
        log = solver.compute_log_map(int(c), **log_kwargs)[nb]
        moved = solver.transport_tangent_vector(int(c), [1.0, 0.0])[nb]
        at_c = np.full(nb.shape[0], c)
        r[lo:hi] = np.hypot(log[:, 0], log[:, 1])
        theta[lo:hi] = _to_ours(conv, at_c, np.arctan2(log[:, 1], log[:, 0]))
        # Their e_x at c has angle alpha in our frame at c and arrives at j
        # with angle beta in our frame at j: phi_cj = beta - alpha, and the
        # transport back along the same geodesic is phi_jc = alpha - beta.
        alpha = _to_ours(conv, np.array([c]), np.zeros(1))[0]
        beta = _to_ours(conv, nb, np.arctan2(moved[:, 1], moved[:, 0]),
                        alpha - hint_phi[lo:hi])
        phi[lo:hi] = _wrap(alpha - beta)
        self_loop = nb == c
        r[lo:hi][self_loop] = 0.0
        theta[lo:hi][self_loop] = 0.0
        phi[lo:hi][self_loop] = 0.0
    return r, theta, phi


def _same_time(patch_spacing: float) -> float:
    # geometry-central diffuses for t = t_coef * (mean edge length)^2 of the
    # mesh it is given; a patch has its own mean, so rescale t_coef to keep
    # the diffusion time of the whole surface.
    return (_STATE['spacing'] / patch_spacing) ** 2


def run_job(job):
    """Solves one group of centres. Returns ``(edge_id, r, theta, phi,
    failed)``: ``failed`` lists centres whose neighbours were not all inside
    the patch component of the centre (they are redone on a larger patch)."""
    if _STATE['kind'] == 'mesh':
        return _run_mesh_job(job)
    return _run_cloud_job(job)


def _run_mesh_job(job):
    """Solves the centres of one job on its patch (our own affine heat
    solves, :class:`AffineHeatPatch`). Returns ``(edge_id, r, psi, beta,
    failed)`` for the edges of the centres that succeeded."""
    sources, ptr, targets = job['centres'], job['ptr'], job['nbr']
    tangent = _STATE['tangent']
    inside = np.zeros(_STATE['pos'].shape[0], dtype=bool)
    if math.isinf(job['band']):
        inside[:] = _STATE['label'] == _STATE['label'][sources[0]]
    else:
        ball, _ = march_one(_STATE['face'], _STATE['index'],
                            np.union1d(sources, targets), job['band'])
        inside[ball] = True
    patch = AffineHeatPatch(tangent,
                            np.flatnonzero(inside[tangent.face].all(axis=1)),
                            tangent.mean_edge ** 2)
    counts = np.diff(ptr)
    rows = np.flatnonzero(patch.local[sources] >= 0)
    edges = rows_of(ptr, rows)
    r, psi, beta = (np.full(targets.size, np.nan) for _ in range(3))
    r[edges], psi[edges], beta[edges] = patch.solve(
        sources[rows], np.concatenate([[0], np.cumsum(counts[rows])]),
        targets[edges], threads=_STATE['threads'])
    return _finish(job, np.ones(sources.size, dtype=bool), r, psi, beta)


def _run_cloud_job(job):
    import potpourri3d as pp3d
    pos, frame = _STATE['pos'], _STATE['frame']
    n = pos.shape[0]
    centres, ptr, nbr = job['centres'], job['ptr'], job['nbr']
    if math.isinf(job['band']):
        ball = np.arange(n)
    else:
        # A Euclidean ball around the seed holding every disc plus the band.
        reach = np.linalg.norm(pos[nbr] - pos[job['seed']], axis=1).max()
        ball = np.asarray(_STATE['tree'].query_ball_point(
            pos[job['seed']], reach + job['band']), dtype=np.int64)
        ball = np.union1d(ball, np.union1d(centres, nbr))
    local = np.full(n, -1, dtype=np.int64)
    local[ball] = np.arange(ball.size)
    counts = np.diff(ptr)
    c_loc = local[centres]
    n_loc = local[nbr]
    centre_ok = np.ones(centres.size, dtype=bool)
    np.logical_and.at(centre_ok, np.repeat(np.arange(centres.size), counts),
                      n_loc >= 0)
    r = np.empty(nbr.size)
    theta = np.empty(nbr.size)
    phi = np.empty(nbr.size)
    ok = np.flatnonzero(centre_ok)
    if ok.size:
        solver = pp3d.PointCloudHeatSolver(
            pos[ball], t_coef=_same_time(mean_spacing('cloud', pos[ball],
                                                      None)))
        basis_x, _, basis_n = solver.get_tangent_frames()
        ours = frame[ball]
        conv = dict(sign=np.where((basis_n * ours[:, 2]).sum(1) < 0, -1.0,
                                  1.0),
                    offset=np.arctan2((basis_x * ours[:, 1]).sum(1),
                                      (basis_x * ours[:, 0]).sum(1)))
        sel_ptr = np.concatenate([[0], np.cumsum(counts[ok])])
        edges = rows_of(ptr, ok)
        rr, tt, pp = _solve_centres(solver, conv, {}, c_loc[ok],
                                    n_loc[edges], sel_ptr,
                                    job['hint_phi'][edges])
        r[edges], theta[edges], phi[edges] = rr, tt, pp
    return _finish(job, centre_ok, r, theta, phi)


def _finish(job, centre_ok, r, theta, phi):
    counts = np.diff(job['ptr'])
    keep = np.repeat(centre_ok, counts)
    # A solve that produced NaN (e.g. a sliver patch) is redone like a
    # centre whose neighbours fell outside the patch.
    bad = keep & ~(np.isfinite(r) & np.isfinite(theta) & np.isfinite(phi))
    if bad.any():
        rows = np.repeat(np.arange(counts.size), counts)
        centre_ok = centre_ok.copy()
        centre_ok[np.unique(rows[bad])] = False
        keep = np.repeat(centre_ok, counts)
    return (job['edge_id'][keep], r[keep], theta[keep], phi[keep],
            job['centres'][~centre_ok])


# ----------------------------------------------------------------------------
# planning and running
# ----------------------------------------------------------------------------
def _farthest_seeds(points: np.ndarray, spacing: float) -> np.ndarray:
    """Farthest point sampling until every point is within ``spacing`` of a
    seed (a loop over seeds, vectorised over points)."""
    seeds = [0]
    nearest = np.linalg.norm(points - points[0], axis=1)
    while True:
        far = int(np.argmax(nearest))
        if nearest[far] <= spacing:
            return np.asarray(seeds)
        seeds.append(far)
        np.minimum(nearest, np.linalg.norm(points - points[far], axis=1),
                   out=nearest)


def _edge_graph(pos: np.ndarray, face: np.ndarray):
    a = np.concatenate([face[:, 0], face[:, 1], face[:, 2]])
    b = np.concatenate([face[:, 1], face[:, 2], face[:, 0]])
    w = np.linalg.norm(pos[a] - pos[b], axis=1)
    n = pos.shape[0]
    g = sp.coo_matrix((w, (a, b)), shape=(n, n)).tocsr()
    return g.maximum(g.T)


def _job(seed, band, size, rows, centres, ptr, nbr, edge_id, hint_phi):
    edges = rows_of(ptr, rows)
    counts = ptr[rows + 1] - ptr[rows]
    return dict(seed=int(seed), band=float(band), size=float(size),
                centres=centres[rows],
                ptr=np.concatenate([[0], np.cumsum(counts)]),
                nbr=nbr[edges], edge_id=edge_id[edges],
                hint_phi=hint_phi[edges])


def vertex_components(kind, pos, face) -> np.ndarray:
    if kind == 'mesh':
        return _components(face, pos.shape[0])
    return np.zeros(pos.shape[0], dtype=np.int64)


def plan_jobs(kind, pos, face, label, centres, ptr, nbr, edge_id, reach,
              band, hint_phi) -> List[dict]:
    """Groups centres around seeds; one job (patch) per group.

    ``centres`` are the distinct centres, their neighbours
    ``nbr[ptr[k]:ptr[k + 1]]`` (original edge positions ``edge_id``), and
    ``reach[k]`` the estimated distance from centre k to its farthest
    neighbour. A group's patch holds every vertex within ``band`` of one of
    its discs. ``size`` estimates the patch radius around the seed (for the
    work estimate). ``hint_phi`` is the 'fast' phi of every edge, in the
    order of ``nbr``."""
    typical = float(np.median(reach))
    spacing = GROUP_FRACTION * (typical + band)
    seeds = []
    for comp in np.unique(label[centres]):  # a loop over components
        members = centres[label[centres] == comp]
        seeds.append(members[_farthest_seeds(pos[members], spacing)])
    seeds = np.concatenate(seeds)
    if kind == 'mesh':
        # Graph distances (>= geodesic) keep groups from spanning gaps.
        dist, _, src = dijkstra(_edge_graph(pos, face), indices=seeds,
                                min_only=True, return_predecessors=True)
        owner, to_seed = src[centres], dist[centres]
    else:
        to_seed, which = cKDTree(pos[seeds]).query(pos[centres])
        owner = seeds[which]
    order = np.argsort(owner, kind='stable')
    bounds = np.flatnonzero(np.diff(owner[order])) + 1
    jobs = []
    for rows in np.split(order, bounds):  # a loop over patches
        size = to_seed[rows].max() + reach[rows].max() + band
        jobs.append(_job(owner[rows[0]], band, size, rows, centres, ptr, nbr,
                         edge_id, hint_phi))
    # Largest patches first, so that the pool finishes evenly.
    jobs.sort(key=lambda job: -job['size'] * job['centres'].size)
    return jobs


def whole_jobs(label, rows, centres, ptr, nbr, edge_id, hint_phi,
               chunks=1):
    """Jobs that solve the given centres on their whole connected component
    (as the original per-vertex approach does), split into up to
    ``chunks`` jobs per component (each factorises the component)."""
    jobs = []
    comp_of = label[centres[rows]]
    for comp in np.unique(comp_of):
        mine = rows[comp_of == comp]
        for part in np.array_split(mine, min(chunks, mine.size)):
            jobs.append(_job(centres[part[0]], math.inf, math.inf, part,
                             centres, ptr, nbr, edge_id, hint_phi))
    return jobs


def solve_cost(kind, patch_vertices, centres, factorisations=1):
    """Relative cost of solving ``centres`` on a patch, in solves per source
    on a 2.5k-vertex patch. Meshes (our solves): a source costs about
    P^1.2 (the fill of the factors) and a factorisation about 40 sources
    (measured on 2.5k-50k vertex meshes). Point clouds (potpourri3d, log
    map and transport per centre): P^1.5, and a factorisation about 60 of
    those, growing like P^(4/3)."""
    p = np.asarray(patch_vertices, dtype=np.float64) / 2500.0
    centres = np.asarray(centres)
    factorisations = np.asarray(factorisations)
    if kind == 'mesh':
        return float(np.sum((centres + 40.0 * factorisations) * p ** 1.2))
    return float(np.sum(centres * p ** 1.5
                        + 60.0 * factorisations * p ** (4.0 / 3.0)))


def solve_all(kind, pos, face, frame, label, centres, ptr, nbr, pair_id,
              reach, hint_phi, spacing, area, margin, workers,
              tangent=None):
    """Plans the jobs for ``centres`` (sources) and their neighbours
    (targets) ``nbr[ptr[k]:ptr[k + 1]]``, patches or whole components as the
    cost model says, runs them, and redoes failed centres on their whole
    component. Returns the job results."""
    band = margin * spacing
    jobs = plan_jobs(kind, pos, face, label, centres, ptr, nbr, pair_id,
                     reach, band, hint_phi)
    density = pos.shape[0] / max(area, 1e-300)
    patch = np.array([min(pos.shape[0], density * math.pi * job['size'] ** 2)
                      for job in jobs])
    sizes = np.array([job['centres'].size for job in jobs])
    work = float((sizes * patch).sum())
    # Where the discs cover much of the surface, patches are nearly the
    # whole surface and only add factorisations: then solve on the whole
    # components (split across the workers), as the original does.
    comps, per_comp = np.unique(label[centres], return_counts=True)
    comp_vertices = np.bincount(label)[comps]
    whole_work = float((per_comp * comp_vertices).sum())
    # Each worker process factorises its component; split only if they
    # will start (meshes solve in threads, with one factorisation).
    chunks = workers if kind == 'cloud' and whole_work > POOL_WORK else 1
    whole = solve_cost(kind, comp_vertices, per_comp,
                       np.minimum(chunks, per_comp))
    if PLAN == 'whole' or (PLAN == 'auto'
                           and whole <= solve_cost(kind, patch, sizes)):
        work = whole_work
        jobs = whole_jobs(label, np.arange(centres.size), centres, ptr, nbr,
                          pair_id, hint_phi, chunks=chunks)
    results = run_jobs(jobs, kind, pos, face, frame, spacing, workers, work,
                       tangent)
    failed = np.concatenate([res[-1] for res in results])
    if failed.size:
        rows = np.searchsorted(centres, failed)
        more = run_jobs(whole_jobs(label, rows, centres, ptr, nbr, pair_id,
                                   hint_phi), kind, pos, face, frame,
                        spacing, workers, work, tangent)
        still = np.concatenate([res[-1] for res in more])
        if still.size:
            raise ValueError(f"the vector heat solve failed for "
                             f"{still.size} centre(s) (first: "
                             f"{still[:5].tolist()}) even on their whole "
                             f"connected component; check the mesh for "
                             f"slivers or use method='fast'")
        results += more
    return results


def mesh_log_map(pos, face, frame, label, j, i, estimate, spacing, area,
                 margin, workers):
    """r, theta, phi of the edges ``j -> i`` of a mesh (numpy arrays), from
    the original's solves per centre, on patches or whole components."""
    tangent = MeshTangentData(pos, face, frame)
    order = np.argsort(i, kind='stable')
    centres, start = np.unique(i[order], return_index=True)
    ptr = np.append(start, i.size).astype(np.int64)
    results = solve_all('mesh', pos, face, frame, label, centres, ptr,
                        j[order], order,
                        np.maximum.reduceat(estimate[order], start),
                        np.zeros(i.size), spacing, area, margin, workers,
                        tangent)
    r, psi, beta = (np.empty(i.size) for _ in range(3))
    for edge, rr, pp, bb, _ in results:  # a loop over patches
        r[edge], psi[edge], beta[edge] = rr, pp, bb
    sign, offset = tangent.sign, tangent.offset
    theta = _wrap(offset[i] + sign[i] * psi)
    # e_u(j) is at angle -sign_j offset_j in j's space, and the transport
    # from i to j turns i's reference direction (angle 0) by beta.
    phi = _wrap(offset[i] - sign[i] * (sign[j] * offset[j] + beta))
    loop = i == j
    r[loop], theta[loop], phi[loop] = 0.0, 0.0, 0.0
    return r, theta, phi


def run_jobs(jobs, kind, pos, face, frame, spacing, workers, work_estimate,
             tangent=None):
    """Runs the jobs in this process (meshes: the solves in ``workers``
    threads) or, for point clouds, in ``workers`` spawned processes."""
    results = []
    if (kind == 'cloud' and workers > 1 and len(jobs) > 1
            and work_estimate > POOL_WORK):
        # 'spawn': the parent may hold torch/numba thread pools, which a
        # forked child must not inherit. One thread per worker: BLAS
        # threads (SuperLU's) spinning beside the other workers slowed a
        # 10k-vertex run twentyfold.
        saved = {name: os.environ.get(name) for name in _THREAD_VARIABLES}
        os.environ.update({name: '1' for name in _THREAD_VARIABLES})
        try:
            with ProcessPoolExecutor(
                    max_workers=min(workers, len(jobs)),
                    mp_context=get_context('spawn'), initializer=init_state,
                    initargs=(kind, pos, face, frame, spacing)) as pool:
                results = list(pool.map(run_job, jobs, chunksize=1))
        finally:
            for name, value in saved.items():
                if value is None:
                    os.environ.pop(name, None)
                else:
                    os.environ[name] = value
    else:
        init_state(kind, pos, face, frame, spacing, tangent)
        _STATE['threads'] = workers
        try:
            results = [run_job(job) for job in jobs]
        finally:
            _STATE.clear()
    return results


def default_workers() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover (not Linux)
        return max(1, os.cpu_count() or 1)
