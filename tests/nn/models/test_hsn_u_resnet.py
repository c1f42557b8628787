import math

import pytest
import torch
from torch_geometric.data import Batch

from tg_intrinsic.data import IntrinsicData
from tg_intrinsic.geometry.geodesics.harmonic import harmonic_terms
from tg_intrinsic.nn.models import HSNSegmentation, HSNUResNet
from tg_intrinsic.pool import ParallelTransportPool, ParallelTransportUnpool
from tg_intrinsic.transforms import (HarmonicPrecompute, LogMap,
                                     MultiscaleSupports)
from tests.conftest import grid_mesh, rel
from tests.nn.conftest import RINGS, disc_graph, two_level_data
from tests.nn.models.hsn_checks import (check_compile_and_precision,
                                        check_norm_is_validated,
                                        check_training_equals_evaluation)
from tests.symmetry import gauge_change, rotate_frames


def three_level_data(seed, angles=None, max_order=1):
    """Three levels of planar discs (50, 14, 5 points) with arbitrary
    transport angles, seen in frames turned by ``angles[l]`` on level l."""
    gen = torch.Generator().manual_seed(seed)
    sizes, radii = (50, 14, 5), (0.35, 0.6, 1.2)
    pos = [torch.rand(50, 2, dtype=torch.float64, generator=gen)]
    area = [torch.rand(50, dtype=torch.float64, generator=gen) + 0.5]
    data = {'x': torch.randn(50, 3, dtype=torch.float64, generator=gen)}
    for level, (n, eps) in enumerate(zip(sizes, radii)):
        key = '' if level == 0 else f'_{level}'
        if level > 0:
            sample = torch.randperm(sizes[level - 1], generator=gen)[:n]
            cluster = torch.cdist(pos[-1], pos[-1][sample]).argmin(1)
            phi = torch.rand(cluster.numel(), dtype=torch.float64,
                             generator=gen) * 6
            if angles is not None:
                phi = phi - angles[level][cluster] + angles[level - 1]
            pos.append(pos[-1][sample])
            area.append(area[-1][sample])
            data.update({f'pos{key}': pos[-1], f'cluster{key}': cluster,
                         f'sample_index{key}': sample,
                         f'pool_transport{key}': phi})
        edge_index, logmap = disc_graph(pos[-1], eps)
        transport = torch.rand(edge_index.size(1), dtype=torch.float64,
                               generator=gen) * 6
        if angles is not None:
            logmap, transport = gauge_change(edge_index, logmap, transport,
                                             angles[level])
        data.update({f'edge_index{key}': edge_index,
                     f'transport{key}': transport,
                     f'harmonic{key}': harmonic_terms(
                         edge_index, logmap, area[-1], eps, RINGS,
                         max_order)})
    data['pos'] = torch.cat([pos[0], torch.zeros(50, 1, dtype=torch.float64)],
                            1)
    return IntrinsicData(**data)


def perturbed(model):
    torch.manual_seed(0)
    model = model.double()
    with torch.no_grad():
        for p in model.parameters():  # no trivial zero outputs
            p.add_(0.05 * torch.randn_like(p))
    return model


@pytest.mark.parametrize('out', [5, None])
def test_output_shapes(out):
    torch.manual_seed(0)
    two = HSNUResNet(3, out, channels=(4, 6), rings=RINGS).double().eval()
    three = HSNUResNet(3, out, channels=(4, 6, 8),
                       rings=RINGS).double().eval()
    width = 4 if out is None else out
    assert two(two_level_data(1, max_order=1)).shape == (50, width)
    assert three(three_level_data(1)).shape == (50, width)
    # four stacks on two levels, six on three; two blocks each
    assert len(two.enc) + 1 + len(two.dec) == 4
    assert len(three.enc) + 1 + len(three.dec) == 6
    assert all(len(s) == 2 for s in (*three.enc, three.mid, *three.dec))


def test_deeper_than_hsn_segmentation():
    # the paper's U-ResNet has a stack on the coarse level besides the
    # encoder's, which HSNSegmentation lacks
    ours = HSNUResNet(3, 5, channels=(16, 32), rings=RINGS)
    seg = HSNSegmentation(3, 5, channels=(16, 32), rings=RINGS)
    count = sum(p.numel() for p in ours.parameters())
    assert count > sum(p.numel() for p in seg.parameters())
    assert len(ours.mid) == 2


@pytest.mark.parametrize('levels,max_order', [(2, 1), (3, 1), (3, 2)])
def test_outputs_are_gauge_invariant(levels, max_order):
    gen = torch.Generator().manual_seed(9)
    sizes = (50, 14, 5) if levels == 3 else (50, 12)
    angles = [torch.rand(n, dtype=torch.float64, generator=gen) * 2 * math.pi
              for n in sizes]
    channels = (4, 6, 8)[:levels]
    model = perturbed(HSNUResNet(3, 5, channels=channels,
                                 max_order=max_order, rings=RINGS))

    def data(turned):
        if levels == 2:
            return two_level_data(1, max_order=max_order,
                                  angle0=angles[0] if turned else None,
                                  angle1=angles[1] if turned else None)
        return three_level_data(1, angles if turned else None, max_order)

    for train in (False, True):
        model.train(train)
        out, out2 = model(data(False)), model(data(True))
        assert out.abs().max() > 1e-3
        assert rel(out2, out) < 1e-8


def test_a_gauge_dependent_readout_would_be_caught():
    # the same features read out by their real part, not their magnitude,
    # change with the frames: the invariance test above is not vacuous
    gen = torch.Generator().manual_seed(9)
    angle0 = torch.rand(50, dtype=torch.float64, generator=gen) * 2 * math.pi
    angle1 = torch.rand(12, dtype=torch.float64, generator=gen) * 2 * math.pi
    model = perturbed(HSNUResNet(3, None, channels=(4, 6), rings=RINGS))
    model.eval()
    captured = []
    hook = model.dec[0][-1].register_forward_hook(
        lambda m, i, o: captured.append(o[:, 1].real))
    model(two_level_data(1, max_order=1))
    model(two_level_data(1, angle0=angle0, angle1=angle1, max_order=1))
    hook.remove()
    assert rel(captured[1], captured[0]) > 1e-2


def test_batched_equals_per_example():
    model = perturbed(HSNUResNet(3, 5, channels=(4, 6, 8), rings=RINGS))
    model.eval()
    data = [three_level_data(s) for s in (1, 2)]
    out = model(Batch.from_data_list(data))
    single = torch.cat([model(d) for d in data])
    assert out.shape == (100, 5)
    assert rel(out, single) < 1e-10
    # the two examples differ, so a mix-up of their levels would show
    assert rel(single[:50], single[50:]) > 1e-3


def flat_levels(seed=0):
    """Two levels on a flat jittered grid with randomly turned frames."""
    pos, face = grid_mesh(9, jitter=0.3, seed=0)
    gen = torch.Generator().manual_seed(seed)
    angle = torch.rand(pos.size(0), dtype=torch.float64, generator=gen) * 6
    base = torch.eye(3, dtype=torch.float64).expand(pos.size(0), 3, 3)
    data = IntrinsicData(pos=pos, face=face,
                         frame=rotate_frames(base.clone(), angle))
    data = LogMap(0.3)(data)
    data = MultiscaleSupports([0.25], [0.6])(data)
    return data, angle


@pytest.mark.parametrize('order', [1, 2])
def test_pool_and_unpool_move_a_parallel_field_exactly(order):
    # oracle: on a plane a constant vector field is parallel; in the frame
    # of point i (turned by a_i) its order-M coordinates are those of the
    # global field turned by -M a_i, written with real rotation matrices
    data, angle = flat_levels()
    cluster, phi = data.cluster_1, data.pool_transport_1
    coarse_angle = angle[data.sample_index_1]
    field = torch.tensor([0.3, -1.1], dtype=torch.float64)

    def local(a):  # [N, 2]: coordinates of the field in turned frames
        c, s = torch.cos(order * a), torch.sin(order * a)
        return torch.stack([c * field[0] + s * field[1],
                            -s * field[0] + c * field[1]], 1)

    def as_streams(v):  # stream `order` of a complex [N, order + 1, 1]
        z = torch.zeros(v.size(0), order + 1, 1, dtype=torch.complex128)
        z[:, order, 0] = torch.complex(v[:, 0], v[:, 1])
        return z

    fine = as_streams(local(angle))
    pooled = ParallelTransportPool()(fine, cluster, phi,
                                     data.pos_1.size(0))
    assert rel(pooled, as_streams(local(coarse_angle))) < 1e-9
    back = ParallelTransportUnpool()(pooled, cluster, phi)
    assert rel(back, fine) < 1e-9
    # without the transport the field would not survive the round trip
    wrong = ParallelTransportUnpool()(pooled, cluster, torch.zeros_like(phi))
    assert rel(wrong, fine) > 1e-2


def test_precomputed_meshes_give_the_same_outputs_in_any_frames():
    # end to end: the log maps, transport and pooling angles computed by
    # the transforms in two sets of random frames give the same outputs
    model = perturbed(HSNUResNet(3, 5, channels=(4, 6), rings=RINGS))
    model.eval()
    outs, angles = [], []
    for seed in (1, 2):
        data, _ = flat_levels(seed)
        data = HarmonicPrecompute(RINGS, 1)(data)
        data.x = data.pos.clone()
        outs.append(model(data))
        angles.append(data.logmap[:, 1])
    # the inputs differ: the angles are measured in other frames
    assert (angles[0] - angles[1]).abs().max() > 0.1
    assert outs[0].abs().max() > 1e-3
    assert rel(outs[1], outs[0]) < 1e-8


def test_runs_on_transformed_meshes_of_three_levels():
    data, _ = flat_levels()
    data = MultiscaleSupports([0.25, 0.08], [0.6, 1.2])(
        IntrinsicData(pos=data.pos, face=data.face, frame=data.frame,
                      edge_index=data.edge_index, logmap=data.logmap,
                      transport=data.transport, area=data.area,
                      logmap_radius=data.logmap_radius))
    data = HarmonicPrecompute(RINGS, 1)(data)
    model = perturbed(HSNUResNet(3, 2, channels=(4, 6, 8), rings=RINGS))
    out = model(data)
    assert out.shape == (81, 2) and torch.isfinite(out).all()


def test_bad_input_is_explained():
    with pytest.raises(ValueError, match="'in_channels' must be at least 1"):
        HSNUResNet(0, 5)
    with pytest.raises(ValueError, match="'out_channels' must be at least"):
        HSNUResNet(3, 0)
    with pytest.raises(ValueError, match="'channels' must hold at least 2"):
        HSNUResNet(3, 5, channels=(4, ))
    with pytest.raises(ValueError, match="'blocks' must be at least 1"):
        HSNUResNet(3, 5, blocks=0)
    with pytest.raises(ValueError, match="'rings' must be at least 1"):
        HSNUResNet(3, 5, rings=0)
    model = HSNUResNet(3, 5, channels=(4, 6, 8), rings=RINGS).double()
    with pytest.raises(ValueError, match="the data lacks 'cluster_2'"):
        model(two_level_data(1, max_order=1))
    with pytest.raises(ValueError, match="expects 4 input channels"):
        HSNUResNet(4, 5, channels=(4, 6), rings=RINGS).double()(
            two_level_data(1, max_order=1))


def test_repr():
    model = HSNUResNet(3, 5, channels=(4, 6, 8), max_order=2, rings=RINGS)
    assert repr(model) == ('HSNUResNet(3, 5, channels=(4, 6, 8), '
                           'max_order=2, rings=4, blocks=2)')


def make(norm='default'):
    norm = {} if norm == 'default' else {'norm': norm}
    return HSNUResNet(3, 5, channels=(4, 6, 8), rings=RINGS, **norm)


def test_training_and_evaluation_compute_the_same_function():
    check_training_equals_evaluation(
        make, [three_level_data(s) for s in (1, 2, 3)])


def test_norm_is_validated_and_per_mesh_by_default():
    check_norm_is_validated(make)
    assert make().norm == 'instance'
    assert make(None).norm is None


def test_compile_and_mixed_precision():
    check_compile_and_precision(HSNUResNet)
