"""Analytic log maps on spheres and the test surfaces shared by the log map
and vector heat tests."""
import importlib.util

import pytest
import torch

from tests.conftest import icosphere

needs_pp3d = pytest.mark.skipif(
    importlib.util.find_spec('potpourri3d') is None,
    reason="method='vector_heat' on point clouds needs potpourri3d")


def wrap(angle):
    return torch.atan2(torch.sin(angle), torch.cos(angle))


def arc(a, b):
    """Angle between unit vectors, accurate also for tiny angles."""
    return torch.atan2(torch.linalg.cross(a, b).norm(dim=-1),
                       (a * b).sum(-1))


def sphere_truth(pos, frame, edge_index):
    """Analytic log map and transport on the unit sphere: the geodesic from
    p_i to p_j lies in the plane through the origin, p_i and p_j; the
    rotation about p_j x p_i by the angle between them maps T_j onto T_i."""
    j, i = edge_index
    p_i, p_j = pos[i], pos[j]
    cos = (p_i * p_j).sum(-1).clamp(-1, 1)
    r = arc(p_i, p_j)
    d = p_j - cos.unsqueeze(-1) * p_i
    theta = torch.atan2((d * frame[i, 1]).sum(-1), (d * frame[i, 0]).sum(-1))
    axis = torch.linalg.cross(p_j, p_i)
    sin = axis.norm(dim=-1, keepdim=True)
    k = axis / sin.clamp_min(1e-300)
    v = frame[j, 0]
    c = cos.unsqueeze(-1)
    moved = v * c + torch.linalg.cross(k, v) * sin \
        + k * (k * v).sum(-1, keepdim=True) * (1 - c)
    moved = torch.where(sin > 1e-12, moved, v)
    phi = torch.atan2((moved * frame[i, 1]).sum(-1),
                      (moved * frame[i, 0]).sum(-1))
    return r, theta, phi


def angle_errors(r, theta, phi, truth, edge_index):
    r0, theta0, phi0 = truth
    off = edge_index[0] != edge_index[1]
    return ((r - r0).abs().max(), wrap(theta - theta0)[off].abs().max(),
            wrap(phi - phi0).abs().max())


def bumpy_sphere(subdivisions=3, amplitude=0.15):
    """An icosphere with smooth radial bumps: curvature varies, so neither
    method is exact and the comparisons mean something."""
    pos, face = icosphere(subdivisions)
    x, y, z = pos.unbind(-1)
    bump = 1 + amplitude * torch.sin(3 * x) * torch.cos(2 * y + z)
    return pos * bump.unsqueeze(-1), face


def some_centres(num, count, seed=0):
    g = torch.Generator().manual_seed(seed)
    return torch.randperm(num, generator=g)[:count].sort().values
