"""Helpers shared by several transform test modules: the Harmonic Surface
Network precomputation on a bumpy sphere, and the checks that a real mesh
ran through it (and, sampled as a point cloud, through DeltaNet's
operators). Import them as ``from tests.transforms.conftest import ...``,
like the helpers of ``tests/conftest.py``."""
import math

import torch
from torch_geometric.data import Data
from torch_geometric.transforms import SamplePoints

from tg_intrinsic.train import hsn_pipeline
from tg_intrinsic.transforms import (HarmonicPrecompute, LogMap,
                                     MLSOperators, MultiscaleSupports,
                                     NormalizeArea)
from tests.conftest import icosphere


def angle_gap(a, b):
    """Largest difference of two angle tensors, modulo 2 pi."""
    return float((torch.remainder(a - b + math.pi, 2 * math.pi)
                  - math.pi).abs().max())


def edge_order(edge_index):
    """The permutation that sorts edges ``(j -> i)`` by centre, then
    neighbour: compares graphs whose equidistant neighbours may come in
    another order."""
    j, i = edge_index
    return torch.argsort(i * (int(edge_index.max()) + 1) + j)


def sphere_data(subdivisions=3):
    """A bumpy sphere (no symmetric ties between distances)."""
    pos, face = icosphere(subdivisions)
    gen = torch.Generator().manual_seed(0)
    pos = pos * (1 + 0.05 * torch.rand(pos.size(0), 1, dtype=pos.dtype,
                                       generator=gen))
    return Data(pos=pos, face=face, x=pos.clone())


def pipeline(method='fast', max_order=1):
    """The HSN precomputation with one pooling level."""
    return [NormalizeArea(), LogMap(0.2, method=method),
            MultiscaleSupports([0.25], [0.4], method=method),
            HarmonicPrecompute(rings=4, max_order=max_order)]


def apply(data, transforms):
    for t in transforms:
        data = t(data)
    return data


# Real-mesh conditions ------------------------------------------------------
RADIUS = 0.15  # smaller than the paper's 0.2: the same code, faster


def hsn(data):
    return hsn_pipeline(radius=RADIUS, rings=4)(data)


def assert_hsn_inputs(out, num_nodes):
    assert out.num_nodes == num_nodes
    for key in ('logmap', 'transport', 'harmonic', 'area', 'logmap_1',
                'transport_1', 'harmonic_1', 'pool_transport_1'):
        assert torch.isfinite(out[key]).all(), key
    e = out.edge_index.size(1)
    assert out.logmap.shape == (e, 2) and out.harmonic.shape[0] == e
    assert num_nodes < e < num_nodes ** 2  # discs, not single points
    loops = out.edge_index[0] == out.edge_index[1]
    assert int(loops.sum()) == num_nodes
    assert torch.isclose(out.area.sum().double(),
                         torch.tensor(1.0, dtype=torch.float64), atol=1e-4)
    assert (out.logmap[:, 0] < RADIUS * 1.05).all()


def assert_point_cloud_operators(mesh, num_points=512):
    torch.manual_seed(0)
    cloud = SamplePoints(num_points, include_normals=True)(
        Data(pos=mesh.pos.float(), face=mesh.face))
    out = MLSOperators(k=16)(cloud)
    assert out.num_nodes == num_points
    assert out.grad_weight.shape == (out.edge_index.size(1), 2)
    for key in ('grad_weight', 'div_weight', 'frame'):
        assert torch.isfinite(out[key]).all(), key


def sphere_pos_face(subdivisions=3, scale=1.0, offset=0.0):
    """A scaled, shifted icosphere as ``(pos, face)``."""
    pos, face = icosphere(subdivisions)
    return scale * pos + offset, face
