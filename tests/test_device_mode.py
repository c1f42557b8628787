"""The device mode: ``pytest --device cuda`` runs these on the GPU and
compares every result with the CPU's (plain ``pytest`` runs them on the
CPU, where they check that results stay on the device they were given).

Each test computes on the CPU first, then on ``device`` from copies of the
same inputs, and checks that the outputs are on ``device`` and match: the
models' logits and gradients, the point-cloud operators (the same
neighbours), the Gravo MG solve, the SVBRDF pipeline, and the train and
svbrdf commands."""
import copy
import json

import torch
from torch_geometric.data import Batch, Data

from tg_intrinsic.cli import main
from tests.conftest import rel
from tests.nn.conftest import two_level_data


def on(data, device):
    """A copy of ``data`` on ``device`` (PyG's ``to`` works in place)."""
    return copy.copy(data).to(device)


def check_same(cpu, other, device, tol, what):
    assert other.device == device, f'{what} is on {other.device}'
    assert rel(other.cpu().double(), cpu.double()) < tol, what


def _clouds(sizes, seed=0):
    generator = torch.Generator().manual_seed(seed)
    items = []
    for n in sizes:
        pos = torch.randn(n, 3, generator=generator)
        items.append(Data(pos=pos, normal=pos / pos.norm(dim=1,
                                                         keepdim=True)))
    return Batch.from_data_list(items)


def test_deltanet_logits_and_gradients(device):
    from tg_intrinsic.nn.models import DeltaNetClassification
    torch.manual_seed(0)
    model = DeltaNetClassification(3, 4, conv_channels=(8, 8), k=6,
                                   embedding_size=32).eval()
    data = _clouds([64, 64])
    out = model(data)
    grads = torch.autograd.grad(out.square().sum(), list(model.parameters()))
    moved = copy.deepcopy(model).to(device)
    out_d = moved(on(data, device))
    grads_d = torch.autograd.grad(out_d.square().sum(),
                                  list(moved.parameters()))
    check_same(out, out_d, device, 1e-4, 'logits')
    for g, g_d in zip(grads, grads_d):
        check_same(g, g_d, device, 1e-3, 'a gradient')


def test_hsn_logits(device):
    from tg_intrinsic.nn.models import HSNClassification
    from tests.nn.conftest import RINGS
    torch.manual_seed(0)
    model = HSNClassification(3, 5, rings=RINGS).double().eval()
    data = two_level_data(1)
    out = model(data)
    out_d = copy.deepcopy(model).to(device)(on(data, device))
    check_same(out, out_d, device, 1e-9, 'HSN logits')


def test_operators_and_neighbours(device):
    from tg_intrinsic.geometry.pointcloud.mls import build_mls_operators
    pos = torch.randn(2000, 3, generator=torch.Generator().manual_seed(1),
                      dtype=torch.float64)
    cpu = build_mls_operators(pos, k=10)
    dev = build_mls_operators(pos.to(device), k=10)
    for name in ('edge_index', 'grad_weight', 'div_weight'):
        a, b = getattr(cpu, name, None), getattr(dev, name, None)
        if a is None:
            continue
        assert b.device == device, name
        if name == 'edge_index':  # one tie-break rule: the same graph
            assert torch.equal(a, b.cpu()), 'the neighbours differ'
        else:
            check_same(a, b, device, 1e-8, name)


def test_gravo_mg_solve(device):
    from tg_intrinsic.solvers import smooth
    from tests.conftest import icosphere
    pos, face = icosphere(3)
    data = Data(pos=pos, face=face)
    y = pos[:, :1].clone()
    x = smooth(data, 1e-2, y=y)
    x_d = smooth(on(data, device), 1e-2, y=y.to(device))
    check_same(x, x_d, device, 1e-6, 'the smoothed signal')


def test_svbrdf_pipeline(device):
    from tg_intrinsic.datasets import svbrdf_scene
    from tg_intrinsic.nn import FrequencySVBRDF
    from tg_intrinsic.transforms import (FitSphericalHarmonics, ProjectViews,
                                         SpectralUncertainty)
    scene = svbrdf_scene('sphere', num_views=6, image_size=(24, 24),
                         materials='metals', seed=0, resolution=1)

    def run(data):
        data = SpectralUncertainty()(FitSphericalHarmonics()(
            ProjectViews()(data)))
        result = FrequencySVBRDF(data.num_nodes).to(
            data.pos.device).fit(data, steps=20)
        return data, result
    data, result = run(copy.copy(scene))
    data_d, result_d = run(on(scene, device))
    check_same(data.entropy, data_d.entropy, device, 1e-5, 'the entropy')
    for name in ('roughness', 'metallic', 'base_color'):
        check_same(getattr(result, name), getattr(result_d, name), device,
                   1e-3, name)


def test_train_command(device, tmp_path):
    argv = ['train', 'deltanet', '--epochs', '1', '--num-points', '64',
            '--shapes-per-class', '2', '--batch-size', '4', '--quiet',
            '--root', str(tmp_path / 'data')]
    scores = []
    for name, where in (('reference', 'cpu'), ('device', str(device))):
        out = tmp_path / name
        assert main(argv + ['--device', where, '--out', str(out)]) == 0
        with open(out / 'metrics.json') as f:
            scores.append(json.load(f)['history'][-1]['train_loss'])
    assert abs(scores[0] - scores[1]) < 1e-3 * abs(scores[0])


def test_svbrdf_command_with_refinement(device, tmp_path):
    scene = str(tmp_path / 'scene')
    assert main(['svbrdf', '--write-example', scene, '--example-views', '4',
                 '--example-image-size', '24', '--example-subdivisions', '1',
                 '--quiet']) == 0
    assert main(['svbrdf', scene, '--device', str(device), '--solver', 'lm',
                 '--refine', '1', '--out', str(tmp_path / 'out'),
                 '--quiet']) == 0
    with open(tmp_path / 'out' / 'report.json') as f:
        assert json.load(f)['options']['device'] == str(device)
