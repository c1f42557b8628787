import pytest
import torch
from torch_geometric.data import Batch, Data

from tg_intrinsic.geometry import (estimate_normals, tangent_frames,
                                   vertex_normals)
from tg_intrinsic.nn.models import DeltaNetClassification
from tg_intrinsic.surface_attributes import (check_mls_parameters,
                                             computed_normals, given_normals,
                                             mls_parameters, operator_graph,
                                             resolve_frames, resolve_normals)
from tg_intrinsic.transforms import (EstimateNormals, LogMap, MLSOperators,
                                     TangentFrames)

from tests.conftest import icosphere


def sphere_cloud(n=150, seed=0, dtype=torch.float64):
    g = torch.Generator().manual_seed(seed)
    pos = torch.randn(n, 3, generator=g, dtype=dtype)
    return pos / pos.norm(dim=1, keepdim=True)


def test_resolution_order():
    pos, face = icosphere(2)
    inward = -vertex_normals(pos, face)
    frame = tangent_frames(inward)
    # 1. frames win over everything
    data = Data(pos=pos, face=face, frame=frame, normal=-inward)
    assert torch.equal(resolve_frames(data), frame)
    assert torch.equal(resolve_normals(data), frame[:, 2])
    # 2. normals, then PyG's older 'norm'
    data = Data(pos=pos, face=face, normal=inward)
    assert torch.equal(resolve_normals(data), inward)
    assert torch.equal(resolve_frames(data), tangent_frames(inward))
    assert torch.equal(resolve_normals(Data(pos=pos, norm=inward)), inward)
    # 3. a mesh gets its vertex normals
    data = Data(pos=pos, face=face)
    assert given_normals(data) is None
    assert torch.equal(resolve_normals(data), vertex_normals(pos, face))
    # 4. a cloud gets estimated normals, per example of a batch
    cloud = sphere_cloud()
    assert torch.equal(resolve_normals(Data(pos=cloud), k=12),
                       estimate_normals(cloud, 12))
    batch = Batch.from_data_list([Data(pos=cloud), Data(pos=cloud + 5)])
    both = computed_normals(batch)
    assert torch.allclose(both[:150], both[150:])


def test_dtype_follows_the_positions():
    pos, face = icosphere(1, dtype=torch.float32)
    normal64 = vertex_normals(pos.double(), face)
    data = Data(pos=pos, normal=normal64)
    assert resolve_normals(data).dtype == torch.float32
    assert resolve_frames(data).dtype == torch.float32
    data = Data(pos=pos, frame=tangent_frames(normal64))
    assert resolve_frames(data).dtype == torch.float32


@pytest.mark.parametrize('data, match', [
    (Data(pos=torch.rand(10, 3), normal=torch.rand(9, 3)),
     "'data.normal' has 9 rows"),
    (Data(pos=torch.rand(10, 3), norm=torch.rand(10, 2)),
     r"'data.norm' must have shape \[N, 3\]"),
    (Data(pos=torch.rand(10, 3), frame=torch.rand(10, 3, 3)),
     'orthonormal'),
    (Data(pos=torch.rand(10, 3), frame=torch.eye(3).expand(9, 3, 3)),
     r"'frame' must be a tensor of shape \[N, 3, 3\]|has 27 rows"),
    (Data(x=torch.rand(10, 3)), "no positions"),
    (Data(pos=torch.full((10, 3), float('nan'))), 'NaN'),
])
def test_bad_attributes_are_named(data, match):
    with pytest.raises(ValueError, match=match):
        resolve_frames(data)


def test_transforms_share_one_resolution():
    cloud = sphere_cloud()
    data = Data(pos=cloud)
    frames = TangentFrames()(data)
    assert torch.equal(frames.frame, resolve_frames(data))
    assert torch.equal(frames.normal, frames.frame[:, 2])
    normals = EstimateNormals()(Data(pos=cloud, frame=frames.frame))
    assert torch.equal(normals.normal, frames.frame[:, 2])
    mls = MLSOperators(k=10)(data)
    assert torch.equal(mls.frame, frames.frame)
    logmap = LogMap(0.5)(data)
    assert torch.equal(logmap.frame, frames.frame)
    # given frames are validated, not trusted blindly
    with pytest.raises(ValueError, match='orthonormal'):
        TangentFrames()(Data(pos=cloud, frame=2 * frames.frame))


def test_mls_parameters_have_one_owner():
    cloud = sphere_cloud(200).float()
    data = Batch.from_data_list(
        [MLSOperators(k=10)(Data(pos=cloud, x=cloud))] * 2)
    assert data.mls_parameters.shape == (2, 4)
    same = DeltaNetClassification(3, 4, k=10, conv_channels=[8, 8],
                                  embedding_size=16)
    same.eval()
    same(data)
    other = DeltaNetClassification(3, 4, k=20, conv_channels=[8, 8],
                                   embedding_size=16)
    with pytest.raises(ValueError, match='built with k=10.*model uses k=20'):
        other(data)
    with pytest.raises(ValueError, match='regularizer=0.01'):
        check_mls_parameters(data, 10, 1e-2, 1.0)
    with pytest.raises(ValueError, match='normalized=False'):
        check_mls_parameters(
            MLSOperators(k=10, normalized=False)(Data(pos=cloud)),
            10, 1e-3, 1.0)
    del data.mls_parameters
    with pytest.warns(UserWarning, match='no record'):
        check_mls_parameters(data, 10, 1e-3, 1.0)
    assert mls_parameters(10, 1e-3, 1.0).tolist() == [[10, 1e-3, 1.0, 1.0]]


@pytest.mark.parametrize('edit', ['ToUndirected', 'RemoveDuplicatedEdges',
                                  'AddRemainingSelfLoops', 'by hand'])
def test_models_refuse_operators_on_another_graph(edit):
    # issue 39: ToUndirected after MLSOperators ran without a word
    import torch_geometric.transforms as T
    data = MLSOperators(k=8)(Data(pos=sphere_cloud(120, dtype=torch.float32)))
    model = DeltaNetClassification(3, 2, k=8).eval()
    model(data)  # untouched: accepted
    if edit == 'by hand':
        changed = data.clone()
        changed.edge_index = data.edge_index.clone()
        changed.edge_index[0, 3] = (changed.edge_index[0, 3] + 1) % 120
    else:
        changed = getattr(T, edit)()(data.clone())
    with pytest.raises(ValueError, match='must run before MLSOperators'):
        model(changed)


def test_operator_graph_survives_batching():
    graphs = [MLSOperators(k=6)(Data(pos=sphere_cloud(n, seed=n)))
              for n in (50, 70)]
    batch = Batch.from_data_list(graphs)
    assert torch.equal(batch.operator_graph, operator_graph(
        batch.edge_index, batch.num_nodes, batch.batch))
    # the record follows the edges' order, not only their set
    ei = graphs[0].edge_index
    assert not torch.equal(operator_graph(ei, 50),
                           operator_graph(ei[:, torch.randperm(ei.size(1))],
                                          50))


def test_a_cast_record_is_compared_at_its_precision():
    # issue 39: a batch cast to bfloat16 said regularizer=0.0010004 != 0.001
    data = Data(pos=torch.zeros(1, 3))
    data.mls_parameters = mls_parameters(20, 1e-3, 1.0).to(torch.bfloat16)
    check_mls_parameters(data, 20, 1e-3, 1.0)
    with pytest.raises(ValueError, match='regularizer'):
        check_mls_parameters(data, 20, 2e-3, 1.0)
