import os

import numpy as np
import pytest
import torch
import trimesh
from hypothesis import settings

# CI runs the same hypothesis examples every time (a failure there must be
# reproducible); local runs keep exploring new ones.
settings.register_profile('ci', derandomize=True)
if os.environ.get('CI'):
    settings.load_profile('ci')


def icosphere(subdivisions=2, dtype=torch.float64):
    mesh = trimesh.creation.icosphere(subdivisions=subdivisions)
    pos = torch.tensor(mesh.vertices, dtype=dtype)
    face = torch.tensor(mesh.faces, dtype=torch.long).t().contiguous()
    return pos, face


def grid_mesh(n=6, jitter=0.0, seed=0, dtype=torch.float64):
    """A triangulated unit square in the z = 0 plane, optionally jittered."""
    rng = np.random.default_rng(seed)
    u, v = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n),
                       indexing='ij')
    pos = np.stack([u.ravel(), v.ravel(), np.zeros(n * n)], 1)
    inner = (u.ravel() > 0) & (u.ravel() < 1) & (v.ravel() > 0) & (v.ravel() < 1)
    pos[inner, :2] += jitter * rng.uniform(-1, 1, (inner.sum(), 2)) / n
    idx = np.arange(n * n).reshape(n, n)
    a, b = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
    c, d = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    face = np.concatenate([np.stack([a, b, c]), np.stack([a, c, d])], 1)
    return torch.tensor(pos, dtype=dtype), torch.tensor(face, dtype=torch.long)


@pytest.fixture
def sphere_mesh():
    return icosphere(3)
