r"""Segmentation labels on disk, MeshCNN's edge order, and the rules that
turn per-face and per-edge labels into per-vertex labels.

Files:

* hard labels: one integer per line (``.txt``, ``.seg``, ``.labels``,
  ``.label``, MeshCNN's ``.eseg``) or a 1-D ``.npy`` array; whole numbers
  written as floats (``2.000000``) are accepted;
* soft labels: MeshCNN's ``.seseg``, one row of :math:`C` non-negative
  class weights per edge (column :math:`c` is class :math:`c`, 0-based).

Conversion to vertices (:func:`label_scores` and :func:`scores_to_labels`):
every face or edge votes for its label (soft labels: for every class with
their weight) at each of its vertices, weighted by its area (faces) or
length (edges); a vertex takes the class with the largest total, ties going
to the smaller label (equal within a relative :math:`10^{-9}`). The
same rule with unit weights carries labels
through a vertex weld (a merged vertex takes the majority label of the
vertices merged into it).
"""
import os
from typing import Optional, Tuple

import numpy as np

from tg_intrinsic.geometry.jit import jit

from .points import read_table

LABEL_KINDS = ('auto', 'vertex', 'face', 'edge')


def to_int_labels(values, source: str) -> np.ndarray:
    """``values`` as int64 labels; :obj:`source` (a file name) is named in
    the :class:`ValueError` raised when a value is not a whole number."""
    values = np.asarray(values, dtype=np.float64).reshape(-1)
    bad = np.nonzero(values != np.round(values))[0]
    if bad.size:
        raise ValueError(f"'{source}' holds the non-integer label "
                         f"{float(values[bad[0]])!r} (row {bad[0] + 1}); "
                         f"labels must be whole numbers")
    return values.astype(np.int64)


def read_labels(path: str) -> np.ndarray:
    """Reads a hard label file: ``[K]`` int64, one label per line (or per
    entry of a 1-D ``.npy`` array), as written in the file (no offset).

    Raises a :class:`ValueError` that names the file when it is missing,
    unreadable or empty, has more than one value per line, or holds values
    that are not whole numbers.
    """
    path = os.fspath(path)
    table = read_table(path)
    if table.shape[1] != 1:
        raise ValueError(f"'{path}' has {table.shape[1]} values per line; a "
                         f"label file holds one integer per line")
    return to_int_labels(table[:, 0], path)


def read_soft_labels(path: str) -> np.ndarray:
    """Reads MeshCNN's soft labels (``.seseg``): ``[E, C]`` float64, one
    row of non-negative class weights per edge.

    Raises a :class:`ValueError` that names the file when it is missing,
    unreadable or empty, or holds negative weights.
    """
    path = os.fspath(path)
    table = read_table(path)
    if (table < 0).any():
        row = int(np.nonzero((table < 0).any(1))[0][0])
        raise ValueError(f"'{path}' holds negative soft labels (first in row "
                         f"{row + 1}); every row holds class weights >= 0")
    return table


def check_labels(labels: np.ndarray, path: str, offset: int = 0,
                 num_classes: Optional[int] = None) -> np.ndarray:
    """Subtracts :obj:`offset` (1 for a 1-based file) and checks that every
    label lies in ``[0, num_classes)``; the :class:`ValueError` names
    :obj:`path`, the row and the value."""
    shifted = np.asarray(labels, dtype=np.int64) - offset
    based = f' (read as {offset}-based: label_offset={offset})' if offset \
        else ''
    bad = np.nonzero(shifted < 0)[0]
    if bad.size:
        raise ValueError(f"'{path}' holds the label {labels[bad[0]]} (row "
                         f"{bad[0] + 1}), which is negative{based}; labels "
                         f"must be 0-based class indices")
    if num_classes is not None:
        bad = np.nonzero(shifted >= num_classes)[0]
        if bad.size:
            raise ValueError(
                f"'{path}' holds the label {labels[bad[0]]} (row "
                f"{bad[0] + 1}){based}, out of range for num_classes="
                f"{num_classes}; labels must lie in [0, {num_classes - 1}]"
                f" (raise num_classes or fix the file)")
    return shifted


@jit
def _keep_first_directed(ids, keep, num_ids):  # pragma: no cover (numba)
    # MeshCNN's remove_non_manifolds: walk the faces in order; drop a face
    # if one of its directed edges belongs to an earlier kept face.
    seen = np.zeros(num_ids, dtype=np.bool_)
    for f in range(ids.shape[0]):
        if not keep[f]:
            continue
        if seen[ids[f, 0]] or seen[ids[f, 1]] or seen[ids[f, 2]]:
            keep[f] = False
        else:
            seen[ids[f, 0]] = True
            seen[ids[f, 1]] = True
            seen[ids[f, 2]] = True
    return keep


def meshcnn_edges(pos: np.ndarray, face: np.ndarray) -> np.ndarray:
    r"""The edges of a triangle mesh in MeshCNN's order (Hanocka et al.,
    "MeshCNN: a network with an edge", 2019), the order of its per-edge
    label files (``seg/*.eseg``, ``sseg/*.seseg``): ``[E, 2]`` int64,
    each row sorted.

    MeshCNN (``models/layers/mesh_prepare.py``) reads the vertices and
    triangles in file order, then first drops faces: those of exactly zero
    area, and, walking the faces in order, every face with a directed edge
    :math:`(v_a, v_b)` that an earlier kept face already has (a
    non-manifold or inconsistently oriented face). It then numbers the
    undirected edges in the order of their first appearance, walking the
    kept faces in order and each face's edges as :math:`(v_0, v_1), (v_1,
    v_2), (v_2, v_0)`.

    Args:
        pos (numpy.ndarray): Vertex positions :math:`(N, 3)`.
        face (numpy.ndarray): Triangles :math:`(F, 3)`, in file order.
    """
    pos = np.asarray(pos, dtype=np.float64)
    face = np.asarray(face, dtype=np.int64).reshape(-1, 3)
    n = max(len(pos), 1)
    p0, p1, p2 = pos[face[:, 0]], pos[face[:, 1]], pos[face[:, 2]]
    keep = np.linalg.norm(np.cross(p1 - p0, p2 - p1), axis=1) != 0
    head = np.roll(face, -1, axis=1)
    directed = face * n + head
    if len(np.unique(directed[keep])) < 3 * int(keep.sum()):
        uniq, ids = np.unique(directed, return_inverse=True)
        keep = _keep_first_directed(ids.reshape(-1, 3), keep, len(uniq))
    lo = np.minimum(face[keep], head[keep]).reshape(-1)
    hi = np.maximum(face[keep], head[keep]).reshape(-1)
    _, first = np.unique(lo * n + hi, return_index=True)
    first = np.sort(first)
    return np.stack([lo[first], hi[first]], axis=1)


def label_kind(path: str, num_labels: int, pos: np.ndarray,
               face: np.ndarray, kind: str = 'auto',
               mesh_path: str = 'the mesh'
               ) -> Tuple[str, Optional[np.ndarray]]:
    """Which elements a label file of :obj:`num_labels` entries labels:
    ``('vertex' | 'face' | 'edge', edges)``, with MeshCNN's edges
    (:func:`meshcnn_edges`) for ``'edge'`` and :obj:`None` otherwise.

    With :obj:`kind='auto'` the count decides, checked in this order:
    the vertex count, the face count, MeshCNN's edge count (so a file
    whose length equals both the vertex and the face count is read per
    vertex; pass :obj:`kind` to decide otherwise). An explicit
    :obj:`kind` must match its count. Either way a mismatch raises a
    :class:`ValueError` naming :obj:`path`, the expected and found counts.
    """
    if kind not in LABEL_KINDS:
        raise ValueError(f"'label_kind' must be one of {LABEL_KINDS}, got "
                         f"{kind!r}")
    counts = {'vertex': len(pos), 'face': len(face)}
    if kind == 'auto':
        for name, count in counts.items():
            if num_labels == count:
                return name, None
        edges = meshcnn_edges(pos, face)
        if num_labels == len(edges):
            return 'edge', edges
        raise ValueError(
            f"'{path}' holds {num_labels} labels, but {mesh_path} has "
            f"{counts['vertex']} vertices, {counts['face']} faces and "
            f"{len(edges)} edges (MeshCNN's count); give one label per "
            f"vertex, face or edge")
    edges = meshcnn_edges(pos, face) if kind == 'edge' else None
    expected = len(edges) if kind == 'edge' else counts[kind]
    if num_labels != expected:
        raise ValueError(
            f"'{path}' holds {num_labels} labels, but per-{kind} labels of "
            f"{mesh_path} need {expected} (one per {kind}"
            f"{' in MeshCNN order' if kind == 'edge' else ''})")
    return kind, edges


def label_scores(index: np.ndarray, labels: np.ndarray, num_targets: int,
                 weight: Optional[np.ndarray] = None) -> np.ndarray:
    """The votes for every class at every target, ``[num_targets, C]``:
    item :math:`k` adds :obj:`weight[k]` (default 1) to class
    :obj:`labels[k]` of target :obj:`index[k]` (hard labels ``[K]``), or
    :obj:`weight[k]` times its row to every class (soft labels ``[K,
    C]``)."""
    index = np.asarray(index, dtype=np.int64).reshape(-1)
    labels = np.asarray(labels)
    weight = np.ones(len(index)) if weight is None else \
        np.asarray(weight, dtype=np.float64)
    if labels.ndim == 1:
        labels = labels.astype(np.int64)
        c = int(labels.max()) + 1 if labels.size else 1
        flat = np.bincount(index * c + labels, weights=weight,
                           minlength=num_targets * c)
        return flat.reshape(num_targets, c)
    return np.stack([np.bincount(index, weights=weight * column,
                                 minlength=num_targets)
                     for column in labels.T], axis=1)


def scores_to_labels(scores: np.ndarray) -> np.ndarray:
    """The class with the largest score per row; ties (scores within a
    relative :math:`10^{-9}` of the largest, so that the order of the float
    sums does not decide) go to the smaller label; ``-1`` where no item
    voted (all scores zero)."""
    best = scores.max(1, keepdims=True) if scores.size else scores
    out = np.argmax(scores >= best * (1 - 1e-9), axis=1)
    out[~(scores > 0).any(1)] = -1
    return out


def face_label_scores(pos: np.ndarray, face: np.ndarray,
                      labels: np.ndarray) -> np.ndarray:
    """Per-vertex votes ``[N, C]`` of per-face labels ``[F]``, weighted by
    face area (see :func:`label_scores`)."""
    face = np.asarray(face, dtype=np.int64).reshape(-1, 3)
    p0, p1, p2 = pos[face[:, 0]], pos[face[:, 1]], pos[face[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(p1 - p0, p2 - p0), axis=1)
    return label_scores(face.reshape(-1), np.repeat(labels, 3, axis=0),
                        len(pos), np.repeat(area, 3))


def edge_label_scores(pos: np.ndarray, edge: np.ndarray,
                      labels: np.ndarray) -> np.ndarray:
    """Per-vertex votes ``[N, C]`` of per-edge labels, hard ``[E]`` or soft
    ``[E, C]``, weighted by edge length (see :func:`label_scores`)."""
    edge = np.asarray(edge, dtype=np.int64).reshape(-1, 2)
    length = np.linalg.norm(pos[edge[:, 0]] - pos[edge[:, 1]], axis=1)
    return label_scores(edge.T.reshape(-1), np.concatenate([labels, labels]),
                        len(pos), np.concatenate([length, length]))

