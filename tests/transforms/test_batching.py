"""Every transform on a collated Batch: it runs on each graph alone and
collates the results (valid ``ptr``/``batch``, ``to_data_list()`` returns
what the transform gives every graph by itself, random ones drawing per
graph), or it refuses the batch in one line that says to apply it per
sample."""
import functools

import pytest
import torch
from torch import Tensor
from torch_geometric.data import Batch, Data

import tg_intrinsic.transforms as T
from tg_intrinsic.data import IntrinsicData
from tg_intrinsic.datasets import svbrdf_scene
from tg_intrinsic.transforms import keep_views
from tests.conftest import fibonacci_sphere, grid_mesh
from tests.transforms.conftest import sphere_data


# Two graphs of different sizes of every kind the transforms read --------
@functools.lru_cache()
def meshes():
    small = sphere_data(1)
    return [sphere_data(2), Data(pos=1.3 * small.pos + 0.1, face=small.face,
                                 x=small.x)]


@functools.lru_cache()
def unit_area_meshes():
    return [T.NormalizeArea()(mesh) for mesh in meshes()]


@functools.lru_cache()
def disc_meshes():
    return [T.LogMap(0.4)(mesh) for mesh in unit_area_meshes()]


@functools.lru_cache()
def level_meshes():
    supports = T.MultiscaleSupports([0.25], [0.8])
    return [supports(mesh) for mesh in disc_meshes()]


def clouds(normals=True):
    graphs = []
    for num_points, seed in ((150, 0), (90, 1)):
        generator = torch.Generator().manual_seed(seed)
        pos = fibonacci_sphere(num_points) * (1 + 0.05 * torch.rand(
            num_points, 1, dtype=torch.float64, generator=generator))
        graph = Data(pos=pos, y=torch.arange(num_points) % 3)
        if normals:
            graph.normal = pos / pos.norm(dim=-1, keepdim=True)
        graphs.append(graph)
    return graphs


@functools.lru_cache()
def gravo_meshes():
    return [T.GravoHierarchy(ratio=4, lower_bound=5, max_levels=1)(mesh)
            for mesh in meshes()]


@functools.lru_cache()
def captures():
    """Two SVBRDF captures of different sizes with the same views."""
    return [svbrdf_scene('sphere', num_views=4, resolution=resolution,
                         image_size=(12, 12), envmap_size=(16, 32),
                         dtype=torch.float64, seed=resolution,
                         specular_samples=8, light_samples=8,
                         image_specular_samples=1, image_light_samples=1)
            for resolution in (2, 1)]


def unobserved_captures():
    return [Data(**{key: value for key, value in capture.items()
                    if not key.startswith('obs_')})
            for capture in captures()]


@functools.lru_cache()
def fitted_captures():
    fit = T.FitSphericalHarmonics(l_max=2, num_light_samples=64)
    return [fit(capture) for capture in captures()]


def textured_squares():
    graphs = []
    for n in (5, 4):
        pos, face = grid_mesh(n)
        graphs.append(Data(pos=pos, face=face, uv=pos[:, :2].clone()))
    return graphs


# name: (the transform, its two input graphs, whether it draws randomness)
CASES = {
    'EstimateNormals': (lambda: T.EstimateNormals(k=8),
                        lambda: clouds(normals=False), False),
    'TangentFrames': (lambda: T.TangentFrames(), lambda: clouds(), False),
    'MLSOperators': (lambda: T.MLSOperators(k=8), lambda: clouds(), False),
    'RandomRotation': (lambda: T.RandomRotation(), lambda: clouds(), True),
    'RandomAxisScale': (lambda: T.RandomAxisScale((0.8, 1.2)),
                        lambda: clouds(), True),
    'RandomTranslation': (lambda: T.RandomTranslation(0.2),
                          lambda: clouds(), True),
    'NormalizeArea': (lambda: T.NormalizeArea(2.0), meshes, False),
    'LogMap': (lambda: T.LogMap(0.4), unit_area_meshes, False),
    'ParallelTransport': (lambda: T.ParallelTransport(), disc_meshes,
                          False),
    'MultiscaleSupports': (lambda: T.MultiscaleSupports([0.25], [0.8]),
                           disc_meshes, False),
    'HarmonicPrecompute': (lambda: T.HarmonicPrecompute(rings=2),
                           level_meshes, False),
    'GravoHierarchy': (lambda: T.GravoHierarchy(ratio=4, lower_bound=5,
                                                max_levels=1),
                       meshes, False),
    'ProjectViews': (lambda: T.ProjectViews(), unobserved_captures, False),
    'FitSphericalHarmonics': (lambda: T.FitSphericalHarmonics(
        l_max=2, num_light_samples=64), captures, False),
    'SpectralUncertainty': (lambda: T.SpectralUncertainty(grid=(6, 6)),
                            fitted_captures, False),
    'SelectViews': (lambda: T.SelectViews(2, l_max=2, num_light_samples=64,
                                          grid=(6, 6)), captures, False),
    'CleanMesh': (lambda: T.CleanMesh(), meshes, False),
    'Decimate': (lambda: T.Decimate(ratio=0.5), meshes, False),
    'FarthestPointResample': (lambda: T.FarthestPointResample(30), meshes,
                              False),
    'TextureTexels': (lambda: T.TextureTexels((4, 4)), textured_squares,
                      False),
    'PoolingLevels': (lambda: T.PoolingLevels(num_levels=1, k=8),
                      lambda: clouds(), False),
    # a transform on a batch of multi-level data keeps its class
    'RandomRotation on levels': (lambda: T.RandomRotation(), gravo_meshes,
                                 True),
}
REFUSED = {'TextureTexels'}


def assert_same_graph(actual, expected):
    assert type(actual) is type(expected)
    assert set(actual.keys()) == set(expected.keys())
    for key, value in expected.items():
        if isinstance(value, Tensor):
            assert actual[key].dtype == value.dtype, key
            assert torch.equal(actual[key], value), key
        else:
            assert actual[key] == value, key


def test_every_public_transform_has_a_case():
    classes = {name for name in T.__all__ if isinstance(getattr(T, name),
                                                         type)}
    assert classes <= set(CASES)


def run_seeded(transform, data, random):
    if random:
        torch.manual_seed(12345)
    return transform(data)


@pytest.mark.filterwarnings('ignore:.*seen by no view')  # ProjectViews
@pytest.mark.parametrize('name', sorted(CASES))
def test_transform_on_a_batch_runs_per_graph_or_refuses(name):
    make, inputs, random = CASES[name]
    transform, graphs = make(), inputs()
    batch = Batch.from_data_list(graphs)
    if name in REFUSED:
        with pytest.raises(ValueError, match='pre_transform') as error:
            transform(batch)
        assert '\n' not in str(error.value)
        return
    out = run_seeded(transform, batch, random)
    # each graph alone, drawing the same random numbers in the same order
    if random:
        torch.manual_seed(12345)
    alone = [transform(graph) for graph in graphs]
    assert isinstance(out, Batch) and out.num_graphs == len(graphs)
    sizes = torch.tensor([graph.num_nodes for graph in alone])
    assert out.ptr.tolist() == [0] + sizes.cumsum(0).tolist()
    assert torch.equal(out.batch, torch.arange(len(graphs))
                       .repeat_interleave(sizes))
    for actual, expected in zip(out.to_data_list(), alone, strict=True):
        assert_same_graph(actual, expected)
    # the input batch is left as it was
    assert_same_graph(batch, Batch.from_data_list(graphs))


@pytest.mark.parametrize('name', ['RandomRotation', 'RandomAxisScale',
                                  'RandomTranslation'])
def test_random_transforms_draw_per_graph(name):
    make, inputs, _ = CASES[name]
    cloud = inputs()[0]
    torch.manual_seed(0)
    first, second = make()(Batch.from_data_list([cloud, cloud])
                           ).to_data_list()
    assert not torch.allclose(first.pos, second.pos)


def test_farthest_point_resample_takes_the_count_per_graph():
    out = T.FarthestPointResample(100)(Batch.from_data_list(meshes()))
    assert out.ptr.tolist() == [0, 100, 200]
    assert [graph.num_nodes for graph in out.to_data_list()] == [100, 100]
    # every triangle lies in one graph
    corners = out.batch[out.face]
    assert bool((corners == corners[0]).all())
    assert out.face.size(1) == sum(graph.face.size(1)
                                   for graph in out.to_data_list())


def test_multilevel_results_collate_with_level_offsets():
    out = T.GravoHierarchy(ratio=4, lower_bound=5, max_levels=1)(
        Batch.from_data_list(meshes()))
    assert isinstance(out, IntrinsicData)
    sizes = [graph.pos_1.size(0) for graph in gravo_meshes()]
    assert torch.equal(out.level_batch(1), torch.arange(2).repeat_interleave(
        torch.tensor(sizes)))
    assert int(out.edge_index_1.max()) == sum(sizes) - 1


def test_results_with_different_keys_are_refused():
    # the small mesh stops coarsening a level earlier than the large one
    with pytest.raises(ValueError, match='different attributes.*'
                       'pre_transform'):
        T.GravoHierarchy(ratio=4, lower_bound=5)(
            Batch.from_data_list(meshes()))


@pytest.mark.filterwarnings('ignore:.*seen by no view')
def test_results_that_do_not_concatenate_are_refused():
    large, small = unobserved_captures()
    small = small.clone()
    for key in ('images', 'intrinsics', 'extrinsics'):
        small[key] = small[key][:3]  # obs_radiance [N, 3, 3], not [N, 4, 3]
    with pytest.raises(ValueError, match='cannot be collated.*'
                       'pre_transform'):
        T.ProjectViews()(Batch.from_data_list([large, small]))


def test_follow_batch_vectors_are_kept():
    graphs = meshes()
    out = T.NormalizeArea()(Batch.from_data_list(graphs,
                                                 follow_batch=['face']))
    expected = Batch.from_data_list([T.NormalizeArea()(graph)
                                     for graph in graphs],
                                    follow_batch=['face'])
    assert torch.equal(out.face_batch, expected.face_batch)
    assert torch.equal(out.face_ptr, expected.face_ptr)


def test_a_batch_changed_after_collation_is_refused():
    batch = Batch.from_data_list(meshes())
    batch.area = torch.ones(batch.num_nodes)  # to_data_list would drop it
    with pytest.raises(ValueError, match=r"\['area'\] changed after"):
        T.NormalizeArea()(batch)
    batch = Batch.from_data_list(meshes())
    batch.x = batch.x[:10]  # to_data_list would slice it wrongly
    with pytest.raises(ValueError, match=r"\['x'\] changed after"):
        T.NormalizeArea()(batch)
    with pytest.raises(ValueError, match='from_data_list'):
        T.NormalizeArea()(Batch(pos=batch.pos, face=batch.face))


def test_keep_views_keeps_the_views_of_every_capture():
    out = keep_views(Batch.from_data_list(captures()), [2, 0])
    for actual, capture in zip(out.to_data_list(), captures(), strict=True):
        assert_same_graph(actual, keep_views(capture, [2, 0]))
