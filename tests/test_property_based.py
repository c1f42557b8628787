"""Property test over the Data-level entry points (transforms, solvers and
models): random small point clouds and meshes that are valid but awkward
(duplicate points, points on a line or a plane, scales from 1e-8 to 1e8,
two components) either give a finite result or raise a ValueError that
says what is wrong; never another exception, never a NaN."""
import warnings

import numpy as np
import pytest
import torch
import trimesh
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from torch_geometric.data import Data

from tg_intrinsic import transforms as T
from tg_intrinsic.geometry import estimate_normals, knn, vertex_normals
from tg_intrinsic.nn.models import DeltaNetClassification, HSNClassification
from tg_intrinsic.solvers import poisson, smooth

EXAMPLES = 50  # per entry point; 21 entry points make more than 1000
SETTINGS = settings(max_examples=EXAMPLES, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])


@st.composite
def clouds(draw):
    n = draw(st.sampled_from([4, 6, 12, 30]))
    rng = np.random.default_rng(draw(st.integers(0, 2 ** 16)))
    shape = draw(st.sampled_from(['sphere', 'sphere', 'plane', 'line',
                                  'duplicates', 'two']))
    pos = rng.normal(size=(n, 3))
    pos /= np.linalg.norm(pos, axis=1, keepdims=True)
    if shape == 'plane':
        pos[:, 2] = 0.0
    elif shape == 'line':
        pos[:, 1:] = 0.0
    elif shape == 'duplicates':
        pos[n // 2:] = pos[:n - n // 2]
    elif shape == 'two':
        pos[n // 2:] += 10.0
    scale = 10.0 ** draw(st.sampled_from([-8, -3, 0, 3, 8]))
    dtype = draw(st.sampled_from([torch.float32, torch.float64]))
    return Data(pos=torch.tensor(pos * scale, dtype=dtype))


@st.composite
def meshes(draw):
    mesh = trimesh.creation.icosphere(draw(st.sampled_from([0, 1])))
    pos, face = np.array(mesh.vertices), np.array(mesh.faces)
    rng = np.random.default_rng(draw(st.integers(0, 2 ** 16)))
    pos = pos * rng.uniform(0.5, 2.0, size=3)  # an ellipsoid
    kind = draw(st.sampled_from(['closed', 'closed', 'two', 'flat',
                                 'boundary']))
    if kind == 'two':
        face = np.concatenate([face, face + len(pos)])
        pos = np.concatenate([pos, pos + 5.0])
    elif kind == 'flat':  # squashed to (almost) a plane
        pos[:, 2] *= 1e-9
    elif kind == 'boundary':
        face = face[pos[face].mean(1)[:, 2] < 0.3]
        used = np.unique(face)
        remap = np.full(len(pos), -1)
        remap[used] = np.arange(len(used))
        pos, face = pos[used], remap[face]
    scale = 10.0 ** draw(st.sampled_from([-8, -3, 0, 3, 8]))
    dtype = draw(st.sampled_from([torch.float32, torch.float64]))
    return Data(pos=torch.tensor(pos * scale, dtype=dtype),
                face=torch.tensor(face.T.copy(), dtype=torch.long))


def finite(value):
    """Every tensor inside a result is finite (NaN never passes)."""
    if isinstance(value, Data):
        return all(finite(v) for _, v in value.items())
    if isinstance(value, (tuple, list)):
        return all(finite(v) for v in value)
    if isinstance(value, torch.Tensor):
        if value.is_sparse:
            value = value.coalesce().values()
        return not value.is_floating_point() or bool(
            torch.isfinite(value).all())
    return True


def outcome(call, data):
    """The result of ``call(data)`` if finite; a ValueError is an answer
    too. Any other exception, or a NaN, fails the test."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter('ignore')
            result = call(data)
    except ValueError as error:
        assert str(error), 'a ValueError must say what is wrong'
        return None
    assert finite(result), f'non-finite output from {call}'
    return result


def hsn(data):
    data = T.NormalizeArea()(data)
    data = T.MultiscaleSupports([0.5], [0.8])(T.LogMap(0.5)(data))
    data = T.HarmonicPrecompute()(data)
    data.x = data.pos
    model = HSNClassification(3, 4, channels=(4, 4)).to(data.pos.dtype)
    return model.eval()(data)


def deltanet(data):
    data = data.clone()
    data.x = data.pos
    model = DeltaNetClassification(3, 4, conv_channels=(4, 4), k=5,
                                   embedding_size=8).to(data.pos.dtype)
    return model.eval()(data)


CLOUD_CALLS = {
    'estimate_normals': lambda d: estimate_normals(d.pos, 4),
    'knn': lambda d: knn(d.pos, 3),
    'EstimateNormals': T.EstimateNormals(k=4),
    'TangentFrames': T.TangentFrames(k=4),
    'MLSOperators': T.MLSOperators(k=4),
    'LogMap': T.LogMap(0.5),
    'GravoHierarchy': T.GravoHierarchy(lower_bound=2, k=3),
    'RandomRotation': T.RandomRotation(),
    'RandomAxisScale': T.RandomAxisScale((0.5, 2.0)),
    'FarthestPointResample': T.FarthestPointResample(4),
    'DeltaNetClassification': deltanet,
}
MESH_CALLS = {
    'vertex_normals': lambda d: vertex_normals(d.pos, d.face),
    'NormalizeArea': T.NormalizeArea(),
    'CleanMesh': T.CleanMesh(),
    'Decimate': T.Decimate(num_vertices=8),
    'LogMap': T.LogMap(0.3),
    'GravoHierarchy': T.GravoHierarchy(lower_bound=4),
    'smooth': lambda d: smooth(d, 1e-2, y=d.pos),
    'poisson': lambda d: poisson(d, 1.0, y=d.pos),
    'RandomTranslation': T.RandomTranslation(0.1),
    'HSNClassification': hsn,
}


@pytest.mark.parametrize('name', sorted(CLOUD_CALLS))
@SETTINGS
@given(data=clouds())
def test_point_cloud_entry_points(name, data):
    outcome(CLOUD_CALLS[name], data)


@pytest.mark.parametrize('name', sorted(MESH_CALLS))
@SETTINGS
@given(data=meshes())
def test_mesh_entry_points(name, data):
    outcome(MESH_CALLS[name], data)
