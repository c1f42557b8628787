"""smooth / poisson against scipy's direct solves, on a mesh (cotan), a
non-manifold mesh and a point cloud (robust Laplacian); bad input."""
import numpy as np
import pytest
import scipy.sparse as sp
import torch
from scipy.sparse.linalg import spsolve
from torch_geometric.data import Data

from tg_intrinsic.solvers import poisson, smooth, stiffness_and_mass

from ..conftest import icosphere


def direct(matrix, m, y):
    y = y.numpy().reshape(m.size, -1)
    return np.stack([spsolve(matrix.tocsc(), m * c) for c in y.T], 1)


def sphere_data():
    pos, face = icosphere(5)
    g = torch.Generator().manual_seed(0)
    return Data(pos=pos, face=face,
                x=torch.randn(pos.size(0), 3, generator=g,
                              dtype=torch.float64))


def test_smooth_and_poisson_match_direct_solves():
    data = sphere_data()
    S, m = stiffness_and_mass(data)
    assert np.abs(S @ np.ones(m.size)).max() < 1e-10
    assert abs(m.sum() - 4 * np.pi) < 0.05
    out = smooth(data, 1e-2)
    assert out.shape == data.x.shape and out.dtype == data.x.dtype
    exact = direct(sp.diags(m) + 1e-2 * S, m, data.x)
    assert np.abs(out.numpy() - exact).max() < 1e-6 * np.abs(exact).max()
    # Smoothing damps the signal.
    assert out.norm() < data.x.norm()
    out = poisson(data, 1.0, y=data.x[:, 0])
    exact = direct(S + sp.diags(m), m, data.x[:, 0])[:, 0]
    assert out.shape == (data.x.size(0), )
    assert np.abs(out.numpy() - exact).max() < 1e-6 * np.abs(exact).max()


def test_robust_laplacian_for_clouds_and_non_manifold_meshes():
    data = sphere_data()
    cloud = Data(pos=data.pos, x=data.x)
    S, m = stiffness_and_mass(cloud)
    assert abs(m.sum() - 4 * np.pi) < 0.2
    out = smooth(cloud, 1e-2)
    exact = direct(sp.diags(m) + 1e-2 * S, m, cloud.x)
    assert np.abs(out.numpy() - exact).max() < 1e-6 * np.abs(exact).max()
    # A fin: one edge shared by three triangles.
    pos = torch.cat([data.pos, torch.tensor([[0.0, 0.0, 2.0]],
                                            dtype=torch.float64)])
    e = data.face[:, 0]
    face = torch.cat([data.face, torch.tensor([[e[0]], [e[1]],
                                               [pos.size(0) - 1]])], 1)
    fin = Data(pos=pos, face=face,
               x=torch.ones(pos.size(0), dtype=torch.float64))
    S, m = stiffness_and_mass(fin)  # robust, chosen automatically
    assert np.abs(S @ np.ones(m.size)).max() < 1e-10
    out = smooth(fin, 1e-2)
    assert torch.allclose(out, fin.x, atol=1e-6)  # constants are kept


def test_bad_input():
    data = sphere_data()
    with pytest.raises(ValueError, match='alpha'):
        smooth(data, 0.0)
    with pytest.raises(ValueError, match='singular'):
        poisson(data, 0.0)
    with pytest.raises(ValueError, match='rows'):
        smooth(data, 1e-2, y=data.x[:5])
    with pytest.raises(ValueError, match='nothing'):
        smooth(Data(pos=data.pos, face=data.face), 1e-2)
