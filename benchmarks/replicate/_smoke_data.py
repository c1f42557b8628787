"""Tiny data sets in exactly the files and folder layouts of the real
releases, for the ``--smoke`` runs of the replication scripts (and their
tests): a few shapes of 100-200 vertices per class, made from trimesh
primitives with a seeded generator, so that a whole protocol runs in
seconds.

Every writer takes a parent folder, writes the release's top folder inside
it and returns that folder (the PATH a user would pass):

* :func:`write_modelnet40`:
  ``ModelNet40/<class>/{train,test}/<class>_XXXX.off`` (Princeton's
  ``ModelNet40.zip``; one file with the malformed ``OFF<nv> <nf> 0``
  header line some of the real files have);
* :func:`write_shrec16`: MeshCNN's ``shrec_16/<class>/{train,test}/T<id>.obj``;
* :func:`write_human_seg`: MeshCNN's ``human_seg/{train,test}/*.obj`` with
  ``seg/<name>.eseg`` (one 1-based label per edge, in MeshCNN's edge order)
  and ``sseg/<name>.seseg`` (one row of soft labels per edge);
* :func:`write_scanobjectnn`: ``h5_files/main_split/{training,test}_
  objectdataset_augmentedrot_scale75.h5`` (PB_T50_RS) with the datasets
  ``data`` (B, 2048, 3) float32, ``label`` (B,) and ``mask`` (B, 2048);
* :func:`write_shapenet_part`: ``shapenetcore_partanno_segmentation_
  benchmark_v0_normal/`` with ``synsetoffset2category.txt``,
  ``<synset>/<token>.txt`` (``x y z nx ny nz part`` per line) and
  ``train_test_split/shuffled_{train,val,test}_file_list.json``.
"""
import json
import os
import os.path as osp
from typing import Dict, List, Tuple

import numpy as np
import trimesh

from tg_intrinsic.io.labels import meshcnn_edges

Mesh = Tuple[np.ndarray, np.ndarray]


# ----------------------------------------------------------------- shapes
def _primitive(kind: str) -> Mesh:
    """A closed triangle mesh of 100-200 vertices."""
    if kind == 'sphere':
        mesh = trimesh.creation.icosphere(subdivisions=2)          # 162 v
    elif kind == 'capsule':
        mesh = trimesh.creation.capsule(height=1.2, radius=0.45,
                                        count=[12, 12])
    elif kind == 'box':
        mesh = trimesh.creation.box().subdivide().subdivide()     # 98 v
    else:
        raise ValueError(f"unknown primitive {kind!r}")
    return np.asarray(mesh.vertices, float), np.asarray(mesh.faces)


def _shape(kind: str, rng: np.random.Generator,
           stretch=(1.0, 1.0, 1.0)) -> Mesh:
    """:obj:`kind` stretched by :obj:`stretch` and a random factor in
    [0.8, 1.2] per axis, turned by a random angle about z."""
    V, F = _primitive(kind)
    V = V * np.asarray(stretch) * rng.uniform(0.8, 1.2, 3)
    a = rng.uniform(0, 2 * np.pi)
    turn = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0],
                     [0, 0, 1]])
    return V @ turn.T, F


def _sample(V: np.ndarray, F: np.ndarray, n: int,
            rng: np.random.Generator) -> Tuple[np.ndarray, np.ndarray]:
    """:obj:`n` points drawn uniformly by area, with their face normals."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    cross = np.cross(b - a, c - a)
    area = np.linalg.norm(cross, axis=1)
    face = rng.choice(len(F), n, p=area / area.sum())
    u, v = rng.random((2, n))
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    pos = a[face] + u[:, None] * (b - a)[face] + v[:, None] * (c - a)[face]
    return pos, cross[face] / area[face, None]


def _bands(values: np.ndarray, count: int) -> np.ndarray:
    """0-based band of each value when [min, max] is cut into
    :obj:`count` equal bands (labels "by height")."""
    lo, hi = values.min(), values.max()
    return np.minimum((count * (values - lo) / (hi - lo)).astype(int),
                      count - 1)


# ------------------------------------------------------------------ files
def _write_off(path: str, V: np.ndarray, F: np.ndarray,
               malformed: bool = False):
    """ModelNet's OFF: header, counts, ``x y z`` rows, ``3 i j k`` rows;
    :obj:`malformed` writes the counts on the header line (``OFF8 12 0``)
    as some files of the release do."""
    with open(path, 'w') as f:
        f.write(f'OFF{len(V)} {len(F)} 0\n' if malformed
                else f'OFF\n{len(V)} {len(F)} 0\n')
        f.writelines(' '.join(f'{x:.6f}' for x in p) + '\n' for p in V)
        f.writelines(f'3 {a} {b} {c}\n' for a, b, c in F)


def _write_obj(path: str, V: np.ndarray, F: np.ndarray):
    """MeshCNN's OBJ files: ``v`` lines and 1-based ``f`` lines only."""
    with open(path, 'w') as f:
        f.writelines('v ' + ' '.join(f'{x:.6f}' for x in p) + '\n'
                     for p in V)
        f.writelines(f'f {a + 1} {b + 1} {c + 1}\n' for a, b, c in F)


def _write_lines(path: str, rows: List[str]):
    os.makedirs(osp.dirname(path), exist_ok=True)
    with open(path, 'w') as f:
        f.writelines(row + '\n' for row in rows)


def _fresh(parent: str, name: str) -> str:
    root = osp.join(os.fspath(parent), name)
    if osp.exists(root):
        raise ValueError(f"'{root}' exists already; smoke data are written "
                         f"into a fresh folder")
    os.makedirs(root)
    return root


# --------------------------------------------------------------- writers
MODELNET_CLASSES = {'bottle': 'capsule', 'bowl': 'sphere',
                    'glass_box': 'box'}
SHREC_CLASSES = {'alien': 'capsule', 'ants': 'sphere', 'armadillo': 'box'}


def _classification_tree(root: str, classes: Dict[str, str], per_split,
                          write, seed: int):
    rng = np.random.default_rng(seed)
    count = 0
    for name, kind in classes.items():
        for split, n in zip(('train', 'test'), per_split):
            folder = osp.join(root, name, split)
            os.makedirs(folder)
            for _ in range(n):
                count += 1
                write(folder, name, count, *_shape(kind, rng))


def write_modelnet40(parent: str, per_split=(3, 2), seed: int = 0) -> str:
    """``ModelNet40/<class>/{train,test}/<class>_XXXX.off`` with three
    classes; returns the ``ModelNet40`` folder."""
    root = _fresh(parent, 'ModelNet40')

    def write(folder, name, i, V, F):
        _write_off(osp.join(folder, f'{name}_{i:04d}.off'), V, F,
                   malformed=i == 1)
    _classification_tree(root, MODELNET_CLASSES, per_split, write, seed)
    return root


def write_shrec16(parent: str, per_split=(3, 2), seed: int = 1) -> str:
    """MeshCNN's ``shrec_16/<class>/{train,test}/T<id>.obj`` with three
    classes; returns the ``shrec_16`` folder."""
    root = _fresh(parent, 'shrec_16')

    def write(folder, name, i, V, F):
        _write_obj(osp.join(folder, f'T{i}.obj'), V, F)
    _classification_tree(root, SHREC_CLASSES, per_split, write, seed)
    return root


def write_human_seg(parent: str, per_split=(4, 2), parts: int = 3,
                    seed: int = 2) -> str:
    """MeshCNN's ``human_seg``: upright shapes in ``{train,test}/*.obj``,
    cut by height into :obj:`parts` parts; ``seg/<name>.eseg`` holds the
    1-based part of each edge (by its midpoint) in MeshCNN's edge order,
    ``sseg/<name>.seseg`` its soft labels (both parts of its endpoints,
    equally weighted). Returns the ``human_seg`` folder."""
    root = _fresh(parent, 'human_seg')
    rng = np.random.default_rng(seed)
    kinds = ('capsule', 'sphere', 'box')
    for split, n, prefix in zip(('train', 'test'), per_split,
                                ('faust', 'shrec')):
        os.makedirs(osp.join(root, split))
        for i in range(n):
            V, F = _shape(kinds[i % len(kinds)], rng, stretch=(0.6, 0.6, 2))
            stem = f'{prefix}__{i + 1}'
            _write_obj(osp.join(root, split, stem + '.obj'), V, F)
            edges = meshcnn_edges(V, F)
            mid = _bands(V[edges].mean(1)[:, 2], parts)
            _write_lines(osp.join(root, 'seg', stem + '.eseg'),
                         [str(p + 1) for p in mid])
            ends = _bands(V[:, 2], parts)[edges]
            soft = np.zeros((len(edges), parts))
            for end in ends.T:
                soft[np.arange(len(edges)), end] += 0.5
            _write_lines(osp.join(root, 'sseg', stem + '.seseg'),
                         [' '.join(f'{x:.6f}' for x in row) for row in soft])
    return root


SCANOBJECTNN_FILE = 'objectdataset_augmentedrot_scale75.h5'


def write_scanobjectnn(parent: str, per_split=(3, 2), seed: int = 3) -> str:
    """ScanObjectNN's PB_T50_RS files in ``h5_files/main_split/``: three
    classes (labels 0-2 of the 15), 2048 points per object, a quarter of
    them background (a floor patch, mask -1), the object rotated about
    the vertical y axis. Returns the folder holding ``h5_files``."""
    import h5py
    root = _fresh(parent, 'ScanObjectNN')
    folder = osp.join(root, 'h5_files', 'main_split')
    os.makedirs(folder)
    rng = np.random.default_rng(seed)
    kinds = ('capsule', 'sphere', 'box')
    for split, n in zip(('training', 'test'), per_split):
        data, label, mask = [], [], []
        for c, kind in enumerate(kinds):
            for _ in range(n):
                V, F = _shape(kind, rng)
                obj, _ = _sample(V[:, [0, 2, 1]], F, 1536, rng)  # y up
                floor = np.column_stack([
                    rng.uniform(-1, 1, 512), np.full(512, obj[:, 1].min()),
                    rng.uniform(-1, 1, 512)])
                data.append(np.concatenate([obj, floor]))
                label.append(c)
                mask.append(np.r_[np.full(1536, 1), np.full(512, -1)])
        with h5py.File(osp.join(folder, f'{split}_{SCANOBJECTNN_FILE}'),
                       'w') as f:
            f.create_dataset('data', data=np.asarray(data, np.float32))
            f.create_dataset('label', data=np.asarray(label, np.uint8))
            f.create_dataset('mask', data=np.asarray(mask, np.int32))
    return root


SHAPENET_CATEGORIES = (
    ('Airplane', '02691156'), ('Bag', '02773838'), ('Cap', '02954340'),
    ('Car', '02958343'), ('Chair', '03001627'), ('Earphone', '03261776'),
    ('Guitar', '03467517'), ('Knife', '03624134'), ('Lamp', '03636649'),
    ('Laptop', '03642806'), ('Motorbike', '03790512'), ('Mug', '03797390'),
    ('Pistol', '03948459'), ('Rocket', '04099429'),
    ('Skateboard', '04225987'), ('Table', '04379243'))
# category: (synset, primitive, first global part label, parts)
SHAPENET_SHAPES = {'Airplane': ('02691156', 'capsule', 0, 4),
                   'Mug': ('03797390', 'sphere', 36, 2),
                   'Table': ('04379243', 'box', 47, 3)}


def write_shapenet_part(parent: str, per_split=(2, 1, 2), points: int = 160,
                        seed: int = 4) -> str:
    """``shapenetcore_partanno_segmentation_benchmark_v0_normal/`` with
    three categories (Airplane, Mug, Table), :obj:`per_split` shapes per
    category in train, val and test, :obj:`points` points per shape with
    their normals and global part label (the category's parts by height).
    Returns that folder."""
    root = _fresh(parent,
                  'shapenetcore_partanno_segmentation_benchmark_v0_normal')
    rng = np.random.default_rng(seed)
    _write_lines(osp.join(root, 'synsetoffset2category.txt'),
                 [f'{name}\t{synset}' for name, synset in SHAPENET_CATEGORIES])
    lists = {split: [] for split in ('train', 'val', 'test')}
    for name, (synset, kind, first, parts) in SHAPENET_SHAPES.items():
        os.makedirs(osp.join(root, synset))
        for split, n in zip(lists, per_split):
            for _ in range(n):
                token = ''.join(rng.choice(list('0123456789abcdef'), 31))
                pos, normal = _sample(*_shape(kind, rng, (1, 1, 1.5)),
                                      points, rng)
                part = first + _bands(pos[:, 2], parts)
                _write_lines(osp.join(root, synset, token + '.txt'), [
                    ' '.join(f'{x:.6f}' for x in row) + f' {p:.6f}'
                    for row, p in zip(np.hstack([pos, normal]), part)])
                lists[split].append(f'shape_data/{synset}/{token}')
    os.makedirs(osp.join(root, 'train_test_split'))
    for split, names in lists.items():
        order = rng.permutation(len(names))
        with open(osp.join(root, 'train_test_split',
                           f'shuffled_{split}_file_list.json'), 'w') as f:
            json.dump([names[i] for i in order], f)
    return root
