"""Small scenes shared by the appearance tests: cameras looking at a point,
a small sphere with a triangle through the camera plane, a sky with a sun
and constant materials."""
import math

import torch
import trimesh

from tg_intrinsic.geometry.appearance.cameras import look_at_cameras
from tg_intrinsic.geometry.appearance.envmap import equirect_directions

D64 = torch.float64


def unit(x):
    return x / x.norm(dim=-1, keepdim=True)


def sky_with_sun(height=32, width=64):
    """A smooth sky plus a sun about one pixel wide, 300x brighter."""
    g = torch.Generator().manual_seed(0)
    d = equirect_directions(height, width)
    env = 0.2 + 0.5 * d[..., 2:].clamp_min(0) * torch.tensor(
        [0.4, 0.6, 1.0], dtype=D64)
    env = env + 0.2 * torch.rand(height, width, 3, dtype=D64, generator=g)
    sun = unit(torch.tensor([0.5, 0.3, 0.6], dtype=D64))
    env = env + ((d @ sun) > math.cos(0.06))[..., None].double() * 300.0
    return env


def material(num, metallic, roughness):
    return (torch.tensor([0.8, 0.5, 0.3], dtype=D64).expand(num, 3),
            torch.full((num, ), metallic, dtype=D64),
            torch.full((num, ), roughness, dtype=D64))


def camera(eye, target=(0, 0, 0), focal=40.0, size=(40, 48)):
    fov = 2 * math.degrees(math.atan(size[0] / 2 / focal))
    K, E = look_at_cameras(torch.tensor([eye], dtype=D64), target, fov,
                           size)
    return K[0], E[0]


def small_mesh():
    ico = trimesh.creation.icosphere(subdivisions=1)
    V = torch.tensor(ico.vertices, dtype=D64) * 0.8
    F = torch.tensor(ico.faces, dtype=torch.long)
    # a big triangle through the camera plane, partly behind the camera
    extra = torch.tensor([[-3.0, -2.0, 3.5], [3.0, -1.5, 3.5],
                          [0.0, 2.5, -1.5]], dtype=D64)
    V = torch.cat([V, extra])
    F = torch.cat([F, torch.tensor([[len(V) - 3, len(V) - 2, len(V) - 1]])])
    return V, F.t().contiguous()
