"""Shared helpers of the layer and model tests: surfaces and batches for
DeltaConv / DeltaNet, disc graphs for the harmonic layers and HSN models,
and a guard that no sparse kernel runs before the input checks."""
import math

import torch
from torch_geometric.data import Data

from tg_intrinsic.data import IntrinsicData
from tg_intrinsic.geometry import knn, tangent_frames
from tg_intrinsic.geometry.geodesics.harmonic import harmonic_terms
from tg_intrinsic.geometry.pointcloud.mls import mls_grad_div
from tg_intrinsic.geometry.pointcloud.operators import SurfaceOperators
from tests.conftest import fibonacci_sphere
from tests.symmetry import gauge_change

C128 = torch.complex128
RINGS = 4


def blob(n=300, seed=0, dtype=torch.float64):
    """A bumpy closed surface with analytic-ish normals (from a sphere)."""
    g = torch.Generator().manual_seed(seed)
    unit = fibonacci_sphere(n, dtype)
    radius = 1 + 0.2 * torch.sin(3 * unit[:, 0]) * torch.cos(2 * unit[:, 1])
    pos = unit * radius[:, None] + 0.01 * torch.randn(n, 3, generator=g,
                                                      dtype=dtype)
    return pos, unit


def operators(pos, frame, k=12):
    ei = knn(pos, k, loop=True)
    gw, dw = mls_grad_div(pos, frame, ei)
    return ei, SurfaceOperators(ei, gw, dw, pos.size(0))


def make_batch(sizes=(200, 260, 230), dtype=torch.float64, frames=True):
    data_list = []
    for seed, n in enumerate(sizes):
        pos, normal = blob(n, seed, dtype)
        data = Data(pos=pos, normal=normal, y=torch.tensor([seed % 2]))
        if frames:
            data.frame = tangent_frames(normal)
        data_list.append(data)
    return data_list


def random_discs(n=60, radius=0.45, seed=0):
    """Random points in the unit square with their radius graph; the log
    map is planar, the transport angles are arbitrary (the layer must not
    care where they come from)."""
    gen = torch.Generator().manual_seed(seed)
    pos = torch.rand(n, 2, dtype=torch.float64, generator=gen)
    j, i = (torch.cdist(pos, pos) < radius).nonzero().t()
    diff = pos[j] - pos[i]
    logmap = torch.stack([diff.norm(dim=1),
                          torch.atan2(diff[:, 1], diff[:, 0])], 1)
    transport = torch.rand(j.numel(), dtype=torch.float64,
                           generator=gen) * 2 * math.pi
    transport[j == i] = 0
    weight = torch.rand(n, dtype=torch.float64, generator=gen) + 0.5
    return torch.stack([j, i]), logmap, transport, weight, radius


def disc_graph(pos, radius):
    j, i = (torch.cdist(pos, pos) < radius).nonzero().t()
    diff = pos[j] - pos[i]
    logmap = torch.stack([diff.norm(dim=1),
                          torch.atan2(diff[:, 1], diff[:, 0])], 1)
    return torch.stack([j, i]), logmap


def two_level_data(seed, n=50, n1=12, angle0=None, angle1=None,
                   max_order=2):
    """Two levels of planar discs with arbitrary transport angles, seen in
    frames turned by angle0 (level 0) and angle1 (level 1)."""
    gen = torch.Generator().manual_seed(seed)
    pos = torch.rand(n, 2, dtype=torch.float64, generator=gen)
    sample = torch.randperm(n, generator=gen)[:n1]
    cluster = torch.cdist(pos, pos[sample]).argmin(1)
    edge_index, logmap = disc_graph(pos, 0.35)
    edge_index1, logmap1 = disc_graph(pos[sample], 0.6)
    transport = torch.rand(edge_index.size(1), dtype=torch.float64,
                           generator=gen) * 6
    transport1 = torch.rand(edge_index1.size(1), dtype=torch.float64,
                            generator=gen) * 6
    pool_transport = torch.rand(n, dtype=torch.float64, generator=gen) * 6
    x = torch.randn(n, 3, dtype=torch.float64, generator=gen)
    area = torch.rand(n, dtype=torch.float64, generator=gen) + 0.5
    if angle0 is not None:
        logmap, transport = gauge_change(edge_index, logmap, transport,
                                         angle0)
        logmap1, transport1 = gauge_change(edge_index1, logmap1, transport1,
                                           angle1)
        pool_transport = pool_transport - angle1[cluster] + angle0
    return IntrinsicData(
        x=x, pos=torch.cat([pos, torch.zeros(n, 1, dtype=pos.dtype)], 1),
        edge_index=edge_index, transport=transport,
        harmonic=harmonic_terms(edge_index, logmap, area, 0.35, RINGS,
                                max_order),
        pos_1=pos[sample], edge_index_1=edge_index1, transport_1=transport1,
        harmonic_1=harmonic_terms(edge_index1, logmap1, area[sample], 0.6,
                                  RINGS, max_order),
        cluster_1=cluster, sample_index_1=sample,
        pool_transport_1=pool_transport, y=torch.tensor([seed % 3]))


def no_sparse_kernel(monkeypatch):
    """Makes every sparse product fail loudly: the checks must come first."""
    def fail(*args):
        raise AssertionError('a sparse kernel ran before the input checks')

    monkeypatch.setattr(torch.sparse, 'mm', fail)


def permute_points(data, order):
    """The same two-level data with its level-0 points listed in ``order``
    (new point k is old point ``order[k]``); edges keep their order, so the
    per-edge terms stay as they are."""
    inverse = torch.empty_like(order)
    inverse[order] = torch.arange(order.numel())
    out = data.clone()
    out.x, out.pos = data.x[order], data.pos[order]
    out.edge_index = inverse[data.edge_index]
    out.cluster_1 = data.cluster_1[order]
    out.pool_transport_1 = data.pool_transport_1[order]
    out.sample_index_1 = inverse[data.sample_index_1]
    return out


def assert_eval_matches_batch_statistics(model, data, tolerance=1e-2):
    """After ``recalibrate_batch_norm(model, [data])``, eval mode on
    ``data`` gives the batch-statistics output but for the variance's
    n / (n - 1) in every batch norm (running variances are unbiased,
    batch statistics not): with that factor undone, the two agree to
    ``tolerance`` of the largest entry; without the recalibration they do
    not."""
    from tg_intrinsic.nn import recalibrate_batch_norm
    from tg_intrinsic.nn.recalibrate_batch_norm import (
        batch_norms, batch_statistics_copy)
    from tests.conftest import rel
    before = model.eval()(data)
    recalibrate_batch_norm(model, [data])
    clone = batch_statistics_copy(model)
    counts = {}
    hooks = [m.register_forward_hook(
        lambda m, inputs, _: counts.__setitem__(m, inputs[0].size(0)))
        for m in batch_norms(clone)]
    expected = clone(data)
    for hook in hooks:
        hook.remove()
    names = {m: name for name, m in clone.named_modules()}
    own = dict(model.named_modules())
    with torch.no_grad():
        for module, n in counts.items():
            own[names[module]].running_var.mul_((n - 1) / n)
    assert rel(before, expected) > 0.1
    assert rel(model(data), expected) < tolerance
