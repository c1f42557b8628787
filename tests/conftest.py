import math
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


def rel(a, b):
    """Largest difference relative to the largest entry of ``b``."""
    return float((a - b).abs().max().detach() / b.abs().max().detach())


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


def fibonacci_sphere(n, dtype=torch.float64):
    """n points of a Fibonacci spiral on the unit sphere."""
    i = torch.arange(n, dtype=dtype) + 0.5
    phi = torch.acos(1 - 2 * i / n)
    theta = math.pi * (1 + 5 ** 0.5) * i
    return torch.stack([torch.cos(theta) * torch.sin(phi),
                        torch.sin(theta) * torch.sin(phi), torch.cos(phi)], 1)


@pytest.fixture
def sphere_mesh():
    return icosphere(3)


def sky_envmap(height=32, width=64, sun=(0.4, -0.3, 0.866), sun_width=0.08,
               dtype=torch.float64):
    """A small HDR sky: a blue gradient, a dim ground and a Gaussian sun."""
    from tg_intrinsic.geometry.appearance.envmap import equirect_directions
    d = equirect_directions(height, width, dtype)
    z = d[..., 2:3]
    sky = torch.tensor([0.3, 0.5, 0.9], dtype=dtype) * (0.4 + 0.6 * z.clamp(0))
    ground = torch.tensor([0.15, 0.12, 0.1], dtype=dtype).expand_as(sky)
    env = torch.where(z > 0, sky, ground)
    s = torch.tensor(sun, dtype=dtype)
    s = s / s.norm()
    angle = torch.acos((d @ s).clamp(-1, 1)).unsqueeze(-1)
    sun_rgb = torch.tensor([30.0, 27.0, 22.0], dtype=dtype)
    return env + sun_rgb * torch.exp(-(angle / sun_width) ** 2)


def svbrdf_observation_geometry(num_points=200, num_views=40, seed=0,
                                dtype=torch.float64):
    """Sphere points with normals, camera directions around them and the
    facing mask: the inputs FitSphericalHarmonics reads, radiance zero."""
    from torch_geometric.data import Data
    from tg_intrinsic.geometry.appearance.sh import fibonacci_sphere
    pos = fibonacci_sphere(num_points, dtype=dtype)
    g = torch.Generator().manual_seed(seed)
    cams = 3 * fibonacci_sphere(num_views, dtype=dtype)
    cams = cams + 0.05 * torch.randn(num_views, 3, generator=g, dtype=dtype)
    to_cam = cams[None] - pos[:, None]
    obs_dir = to_cam / to_cam.norm(dim=-1, keepdim=True)
    mask = (obs_dir * pos[:, None]).sum(-1) > 0.05
    return Data(pos=pos, normal=pos.clone(), obs_dir=obs_dir, obs_mask=mask,
                obs_radiance=torch.zeros(num_points, num_views, 3,
                                         dtype=dtype),
                envmap=sky_envmap(dtype=dtype))


# ----------------------------------------------------------------------
# The device mode: `pytest --device cuda` runs the device tests
# (tests/test_device_mode.py and the tests that take the `device` fixture)
# on that device, against the CPU where they have a reference.

def pytest_addoption(parser):
    parser.addoption('--device', default='cpu',
                     help="device of the device tests: cpu (default), "
                     "cuda or cuda:N")


def pytest_configure(config):
    requested = config.getoption('--device')
    if requested != 'cpu' and not torch.cuda.is_available():
        # one line, not a skip per test
        pytest.exit(f"--device {requested}: no CUDA device on this "
                    f"machine; the device tests were not run", returncode=0)


@pytest.fixture(scope='session')
def device(request):
    """The device of ``pytest --device`` (indexed: cuda means cuda:0)."""
    from tg_intrinsic.devices import resolve_device
    return resolve_device(request.config.getoption('--device'), '--device')


@pytest.fixture
def hide_module(monkeypatch):
    """``hide_module('xatlas')``: importing the package raises
    ImportError for the rest of the test, as on a machine without it."""
    import builtins
    real_import = builtins.__import__
    hidden = set()

    def importing(name, *args, **kwargs):
        if name.split('.')[0] in hidden:
            raise ImportError(f'No module named {name!r}')
        return real_import(name, *args, **kwargs)
    monkeypatch.setattr(builtins, '__import__', importing)
    return hidden.add
