r"""Triangle-mesh utilities: areas, normals, mass, cotan Laplacian, topology.

Triangles use PyG's layout: ``face`` is a ``torch.long`` tensor of shape
``[3, F]`` whose columns are counter-clockwise vertex triples (seen from the
outside), and ``pos`` is ``[N, 3]``.
"""
from typing import Tuple

import numpy as np
import torch
from torch import Tensor

from .checks import (check_faces, check_nondegenerate, check_points,
                     check_referenced,
                      check_positive_float, check_positive_int)


_UNREFERENCED = "drop them with remove_unreferenced_vertices(pos, face)"


def _check_mesh(pos, face) -> Tuple[Tensor, Tensor]:
    pos = check_points(pos)
    face = check_faces(face, pos.size(0), pos)
    return pos, face


def _corners(pos: Tensor, face: Tensor) -> Tuple[Tensor, Tensor, Tensor]:
    return pos[face[0]], pos[face[1]], pos[face[2]]


def _cross_and_scale(pos: Tensor, face: Tensor) -> Tuple[Tensor, Tensor]:
    p0, p1, p2 = _corners(pos, face)
    cross = torch.linalg.cross(p1 - p0, p2 - p0)
    # Squared longest edge: the reference for "numerically zero" areas.
    scale = torch.stack([(p1 - p0).pow(2).sum(-1), (p2 - p1).pow(2).sum(-1),
                         (p0 - p2).pow(2).sum(-1)]).amax(0)
    return cross, scale


def triangle_cross(pos: Tensor, face: Tensor) -> Tensor:
    r"""The cross products :math:`(p_1 - p_0) \times (p_2 - p_0)` of the
    triangles (twice their area vectors) of a checked mesh, refusing
    zero-area triangles: what every function that divides by areas or
    normalises by them starts from.

    Shapes:
        - **input:** pos :math:`(N, 3)`, face :math:`(3, F)`
        - **output:** :math:`(F, 3)`
    """
    cross, scale = _cross_and_scale(pos, face)
    check_nondegenerate(0.5 * cross.norm(dim=-1), scale)
    return cross


def face_areas(pos: Tensor, face: Tensor) -> Tensor:
    r"""Area of every triangle,
    :math:`A_f = \frac{1}{2} \| (p_1 - p_0) \times (p_2 - p_0) \|`.

    Degenerate triangles (collinear corners or a repeated vertex) have
    area 0 (this is well defined, so no error: use it to find them). Every function that divides by areas or
    normalises by them (:func:`face_normals`, :func:`vertex_normals`,
    :func:`lumped_mass`, :func:`cotan_weights`, :func:`cotan_laplacian`,
    :func:`normalize_area`) raises :class:`ValueError` on them instead.

    Args:
        pos (torch.Tensor): Vertex positions.
        face (torch.Tensor): Triangles in PyG layout.

    Shapes:
        - **input:** pos :math:`(N, 3)`, face :math:`(3, F)`
        - **output:** :math:`(F)`
    """
    pos = check_points(pos)
    face = check_faces(face, pos.size(0), pos, allow_degenerate_indices=True)
    cross, _ = _cross_and_scale(pos, face)
    return 0.5 * cross.norm(dim=-1)


def face_normals(pos: Tensor, face: Tensor) -> Tensor:
    r"""Unit normal of every triangle,
    :math:`n_f = \frac{(p_1 - p_0) \times (p_2 - p_0)}
    {\| (p_1 - p_0) \times (p_2 - p_0) \|}`.

    Raises :class:`ValueError` on zero-area triangles, whose normal is
    undefined.

    Shapes:
        - **input:** pos :math:`(N, 3)`, face :math:`(3, F)`
        - **output:** :math:`(F, 3)`
    """
    pos, face = _check_mesh(pos, face)
    cross = triangle_cross(pos, face)
    return cross / cross.norm(dim=-1, keepdim=True)


def vertex_normals(pos: Tensor, face: Tensor) -> Tensor:
    r"""Area-weighted unit vertex normals,
    :math:`n_i = \frac{\sum_{f \ni i} A_f n_f}{\| \sum_{f \ni i} A_f n_f \|}`.

    Raises :class:`ValueError` on vertices that no triangle references and on
    vertices whose weighted normal sum vanishes (e.g. two opposite triangles
    sharing all vertices).

    Shapes:
        - **input:** pos :math:`(N, 3)`, face :math:`(3, F)`
        - **output:** :math:`(N, 3)`
    """
    pos, face = _check_mesh(pos, face)
    check_referenced(face, pos.size(0), 'triangle', _UNREFERENCED)
    cross = triangle_cross(pos, face)
    normal = torch.zeros_like(pos)
    for corner in range(3):  # three scatters, not a loop over faces
        normal.index_add_(0, face[corner], cross)
    norm = normal.norm(dim=-1)
    tiny = norm <= torch.finfo(pos.dtype).eps * cross.norm(dim=-1).max()
    if bool(tiny.any()):
        bad = tiny.nonzero().flatten()
        raise ValueError(f"the normal of {bad.numel()} vertex/vertices (first:"
                         f" {bad[:5].tolist()}) is undefined: their incident "
                         f"triangles cancel out; the mesh is not a manifold "
                         f"surface there")
    return normal / norm.unsqueeze(-1)


def lumped_mass(pos: Tensor, face: Tensor) -> Tensor:
    r"""Barycentric lumped mass matrix (vertex areas),
    :math:`M_{ii} = \frac{1}{3} \sum_{f \ni i} A_f`.

    The entries sum to the surface area. Raises :class:`ValueError` on
    unreferenced vertices, which would get a zero mass (and an infinite
    inverse), and on zero-area triangles.

    Shapes:
        - **input:** pos :math:`(N, 3)`, face :math:`(3, F)`
        - **output:** :math:`(N)`, the diagonal of :math:`M`
    """
    pos, face = _check_mesh(pos, face)
    check_referenced(face, pos.size(0), 'triangle', _UNREFERENCED)
    area = 0.5 * triangle_cross(pos, face).norm(dim=-1) / 3.0
    mass = torch.zeros(pos.size(0), dtype=pos.dtype, device=pos.device)
    for corner in range(3):
        mass.index_add_(0, face[corner], area)
    return mass


def cotan_weights(pos: Tensor, face: Tensor) -> Tensor:
    r"""The three cotangent half-weights of every triangle, one per edge.

    Column ``c`` belongs to the edge opposite corner ``c`` (from vertex
    ``face[(c + 1) % 3]`` to ``face[(c + 2) % 3]``) and holds
    :math:`\frac{1}{2} \cot \theta_c`.

    Shapes:
        - **input:** pos :math:`(N, 3)`, face :math:`(3, F)`
        - **output:** :math:`(F, 3)`
    """
    pos, face = _check_mesh(pos, face)
    double_area = triangle_cross(pos, face).norm(dim=-1)
    p = _corners(pos, face)
    cots = []
    for c in range(3):
        a = p[(c + 1) % 3] - p[c]
        b = p[(c + 2) % 3] - p[c]
        # cot = cos / sin = (a . b) / |a x b|, and |a x b| = 2 A for all corners
        cots.append((a * b).sum(-1) / double_area)
    return 0.5 * torch.stack(cots, dim=-1)


def cotan_laplacian(pos: Tensor, face: Tensor) -> Tensor:
    r"""The cotangent Laplacian as the positive semi-definite stiffness
    matrix :math:`S` (MacNeal 1949; Pinkall and Polthier 1993). Its entries
    are

    .. math::
        S_{ij} = -\frac{1}{2} (\cot \alpha_{ij} + \cot \beta_{ij}), \qquad
        S_{ii} = -\sum_{j \neq i} S_{ij},

    with :math:`\alpha_{ij}, \beta_{ij}` the angles opposite edge
    :math:`(i, j)`. :math:`S` is symmetric, :math:`S \mathbf{1} = 0`, and
    :math:`x^\top S x = \int \| \nabla x \|^2` for piecewise
    linear :math:`x`. The Laplace-Beltrami operator is
    :math:`-M^{-1} S` with :math:`M` from :func:`lumped_mass`.

    To use it with SciPy, convert with :func:`tg_intrinsic.geometry.to_scipy`
    (``scipy.sparse.csr_matrix``); the reverse is
    :func:`tg_intrinsic.geometry.from_scipy`.

    Args:
        pos (torch.Tensor): Vertex positions.
        face (torch.Tensor): Triangles in PyG layout. Zero-area triangles
            raise :class:`ValueError` (their cotangents are infinite).

    Shapes:
        - **input:** pos :math:`(N, 3)`, face :math:`(3, F)`
        - **output:** coalesced sparse COO tensor :math:`(N, N)`
    """
    pos, face = _check_mesh(pos, face)
    if face.size(1) == 0:
        raise ValueError("'face' holds no triangles, so there is no "
                         "Laplacian to build")
    half_cot = cotan_weights(pos, face)  # [F, 3]
    i = torch.cat([face[1], face[2], face[0]])  # edge opposite corner 0, 1, 2
    j = torch.cat([face[2], face[0], face[1]])
    w = half_cot.t().reshape(-1)
    n = pos.size(0)
    row = torch.cat([i, j, i, j])
    col = torch.cat([j, i, i, j])
    val = torch.cat([-w, -w, w, w])
    return torch.sparse_coo_tensor(torch.stack([row, col]), val, (n, n),
                                   check_invariants=False).coalesce()


def mesh_edges(face: Tensor, num_vertices: int = None) -> Tensor:
    r"""The undirected edges of a triangle mesh, both directions, sorted by
    centre (``edge_index[1]``) then neighbour, without duplicates.

    Follows PyG's ``source_to_target`` flow: ``edge_index[0]`` is the
    neighbour :math:`j`, ``edge_index[1]`` the centre :math:`i`.

    Args:
        face (torch.Tensor): Triangles in PyG layout.
        num_vertices (int, optional): Number of vertices, used to validate
            indices. (default: :obj:`None`, taken as ``face.max() + 1``)

    Shapes:
        - **input:** face :math:`(3, F)`
        - **output:** :math:`(2, E)`
    """
    if not isinstance(face, Tensor):
        raise ValueError("'face' must be a torch.Tensor of shape [3, F]")
    n = num_vertices if num_vertices is not None else (
        int(face.max()) + 1 if face.numel() > 0 else 0)
    face = check_faces(face, n, face)
    src = torch.cat([face[0], face[1], face[2], face[1], face[2], face[0]])
    dst = torch.cat([face[1], face[2], face[0], face[0], face[1], face[2]])
    key = torch.unique(dst * max(n, 1) + src)
    return torch.stack([key % max(n, 1), key // max(n, 1)])


def edge_face_counts(face: Tensor, num_vertices: int) -> Tuple[Tensor, Tensor]:
    """Undirected edges ``[2, E]`` (``i < j``) and how many triangles hold
    each. A closed 2-manifold has every count equal to 2."""
    face = check_faces(face, num_vertices, face)
    a = torch.cat([face[0], face[1], face[2]])
    b = torch.cat([face[1], face[2], face[0]])
    lo, hi = torch.minimum(a, b), torch.maximum(a, b)
    key, count = torch.unique(lo * num_vertices + hi, return_counts=True)
    return torch.stack([key // num_vertices, key % num_vertices]), count


def is_closed_manifold(face: Tensor, num_vertices: int) -> bool:
    r"""Whether the mesh is a closed, consistently oriented 2-manifold
    without unreferenced vertices: every undirected edge lies in exactly two
    triangles that traverse it in opposite directions, and the triangles
    around every vertex form a single fan."""
    face = check_faces(face, num_vertices, face)
    if face.size(1) == 0:
        return False
    _, count = edge_face_counts(face, num_vertices)
    if not bool((count == 2).all()):
        return False
    # Consistent orientation: every directed edge occurs exactly once.
    a = torch.cat([face[0], face[1], face[2]])
    b = torch.cat([face[1], face[2], face[0]])
    _, directed = torch.unique(a * num_vertices + b, return_counts=True)
    if not bool((directed == 1).all()):
        return False
    used = torch.zeros(num_vertices, dtype=torch.bool, device=face.device)
    used[face.flatten()] = True
    if not bool(used.all()):
        return False
    # Single fan per vertex: in a closed oriented manifold the directed edges
    # (v -> next) around v form one cycle; count cycles via the Euler-type
    # identity  #corners(v) == #edges(v)  and link connectivity.
    return _vertex_links_are_cycles(face, num_vertices)


def _vertex_links_are_cycles(face: Tensor, num_vertices: int) -> bool:
    import numpy as np
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    f = face.t().cpu().numpy()
    # Link of vertex v: for each corner (v, a, b) the link edge (a, b). Treat
    # corner nodes (v, a) as graph nodes; connect link edges around v.
    v = np.concatenate([f[:, 0], f[:, 1], f[:, 2]])
    a = np.concatenate([f[:, 1], f[:, 2], f[:, 0]])
    b = np.concatenate([f[:, 2], f[:, 0], f[:, 1]])
    node_a = v.astype(np.int64) * num_vertices + a
    node_b = v.astype(np.int64) * num_vertices + b
    keys, inv = np.unique(np.concatenate([node_a, node_b]), return_inverse=True)
    m = len(v)
    graph = sp.coo_matrix((np.ones(m), (inv[:m], inv[m:])),
                          shape=(len(keys), len(keys)))
    _, labels = connected_components(graph, directed=False)
    owner = keys // num_vertices
    num_link_components = np.zeros(num_vertices, dtype=np.int64)
    first = np.unique(labels, return_index=True)[1]
    np.add.at(num_link_components, owner[first], 1)
    return bool((num_link_components == 1).all())


def remove_unreferenced_vertices(pos: Tensor, face: Tensor
                                 ) -> Tuple[Tensor, Tensor, Tensor]:
    r"""Drops vertices that no triangle references.

    Returns:
        (pos, face, index): the kept positions, the re-indexed triangles and
        the original index of every kept vertex.
    """
    pos, face = _check_mesh(pos, face)
    used = torch.zeros(pos.size(0), dtype=torch.bool, device=pos.device)
    used[face.flatten()] = True
    index = used.nonzero().flatten()
    remap = torch.full((pos.size(0), ), -1, dtype=torch.long,
                       device=pos.device)
    remap[index] = torch.arange(index.numel(), device=pos.device)
    return pos[index], remap[face], index


def normalize_area(pos: Tensor, face: Tensor, area: float = 1.0) -> Tensor:
    r"""Centres a mesh at its area-weighted centroid and scales it to the
    given total surface area,
    :math:`p_i \leftarrow \sqrt{A^* / A} \, (p_i - c)`.

    Raises :class:`ValueError` on zero-area triangles.

    Args:
        area (float, optional): Target surface area. (default: :obj:`1.0`)

    Shapes:
        - **input:** pos :math:`(N, 3)`, face :math:`(3, F)`
        - **output:** :math:`(N, 3)`
    """
    pos, face = _check_mesh(pos, face)
    area = check_positive_float(area, 'area')
    face_area = 0.5 * triangle_cross(pos, face).norm(dim=-1)
    total = face_area.sum()
    if not bool(total > torch.finfo(pos.dtype).tiny):
        raise ValueError("the mesh has zero surface area; cannot normalise it")
    centroid = (face_area.unsqueeze(-1) * pos[face].mean(0)).sum(0) / total
    return (pos - centroid) * torch.sqrt(area / total)


def laplacian_spectrum(pos: Tensor, face: Tensor,
                       num_eigenvalues: int = 16) -> Tensor:
    r"""The smallest non-zero eigenvalues of the cotan Laplacian,
    :math:`S \phi = \lambda M \phi` (lumped :math:`M`), times the surface
    area :math:`A` so that they do not depend on the shape's size. They are
    the "Shape-DNA" descriptor of Reuter et al. (2006), invariant to
    isometric (non-rigid) deformations. On the unit sphere,
    :math:`\lambda A = 4\pi l(l + 1)` with multiplicity :math:`2l + 1`.

    Uses shift-invert Lanczos (``scipy.sparse.linalg.eigsh``) in float64 on
    the CPU; the mesh must be connected (a second zero eigenvalue would
    appear in the output otherwise).

    Shapes:
        - **input:** pos :math:`(N, 3)`, face :math:`(3, F)`
        - **output:** :math:`(\text{num\_eigenvalues})`, ascending
    """
    import scipy.sparse as sp
    import scipy.sparse.linalg as sla
    from .sparse import to_scipy
    pos, face = _check_mesh(pos, face)
    num_eigenvalues = check_positive_int(num_eigenvalues, 'num_eigenvalues')
    if num_eigenvalues + 2 > pos.size(0):
        raise ValueError(f"'num_eigenvalues' is {num_eigenvalues} but the "
                         f"mesh has only {pos.size(0)} vertices; ask for at "
                         f"most {pos.size(0) - 2}")
    pos = pos.detach().double().cpu()
    face = face.cpu()
    S = to_scipy(cotan_laplacian(pos, face))
    mass = lumped_mass(pos, face).numpy()
    # Lanczos can miss copies of a repeated eigenvalue (the sphere's have
    # multiplicity 2l + 1) when the wanted block ends inside a cluster:
    # compute a margin of extra values, from a fixed start vector so that
    # the result does not depend on ARPACK's internal random state.
    n = pos.size(0)
    wanted = num_eigenvalues + 1
    k = min(n - 1, wanted + max(8, wanted // 2))
    start = np.random.default_rng(0).standard_normal(n)
    values = sla.eigsh(S, k=k, M=sp.diags(mass), sigma=-1e-8, which='LM',
                       v0=start, ncv=min(n, max(2 * k + 1, 20)),
                       return_eigenvectors=False)
    return torch.from_numpy(np.sort(values)[1:wanted] * mass.sum())


def weld_vertices(pos: Tensor, face: Tensor, tolerance: float = 0.0
                  ) -> Tuple[Tensor, Tensor, Tensor]:
    r"""Merges vertices at the same position, for example to turn a triangle
    soup (every face with its own three vertices, as many exporters write
    OBJ files) into a connected mesh.

    With :obj:`tolerance=0` exactly equal positions are merged. With
    :obj:`tolerance > 0`, vertices closer than :obj:`tolerance` times the
    bounding-box diagonal are merged, transitively (the connected
    components of the "closer than" graph, found with a
    :class:`scipy.spatial.cKDTree`). A merged vertex keeps the position of
    its first (lowest-index) member, and new vertices are numbered in the
    order of their first occurrence, so a mesh without duplicates comes
    back unchanged (:obj:`inverse` is the identity). Faces are only
    re-indexed: none is dropped, even if welding with a tolerance makes
    it degenerate. Per-vertex values follow the weld through
    :obj:`inverse` (e.g. ``scatter(x, inverse, reduce='mean')``).

    Args:
        pos (torch.Tensor): Vertex positions.
        face (torch.Tensor): Triangles in PyG layout.
        tolerance (float, optional): Merge distance relative to the
            bounding-box diagonal. (default: :obj:`0.0`, exact duplicates)

    Returns:
        (pos, face, inverse): the welded positions, the re-indexed
        triangles and, for every old vertex, its new index.

    Shapes:
        - **input:** pos :math:`(N, 3)`, face :math:`(3, F)`
        - **output:** pos :math:`(M, 3)`, face :math:`(3, F)`,
          inverse :math:`(N)` long, :math:`M \le N`
    """
    pos = check_points(pos)
    face = check_faces(face, pos.size(0), pos, allow_degenerate_indices=True)
    tolerance = check_positive_float(tolerance, 'tolerance', allow_zero=True)
    p = pos.detach().cpu().numpy() + 0.0  # + 0.0 turns -0.0 into 0.0
    if tolerance == 0.0:
        _, group = np.unique(p, axis=0, return_inverse=True)
        group = group.reshape(-1)
    else:
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components
        from scipy.spatial import cKDTree
        radius = tolerance * float(np.linalg.norm(np.ptp(p, axis=0)))
        pairs = cKDTree(p).query_pairs(radius, p=2.0, output_type='ndarray')
        graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                           shape=(len(p), len(p)))
        _, group = connected_components(graph, directed=False)
    # Renumber the groups in the order of their first vertex.
    first = np.full(group.max() + 1, len(p), dtype=np.int64)
    np.minimum.at(first, group, np.arange(len(p)))
    rank = np.empty_like(first)
    order = np.argsort(first, kind='stable')
    rank[order] = np.arange(len(order))
    inverse = torch.from_numpy(rank[group]).to(pos.device)
    keep = torch.from_numpy(first[order]).to(pos.device)
    return pos[keep], inverse[face], inverse
