import pytest
import torch

from tg_intrinsic.datasets import bumpy_torus
from tg_intrinsic.geometry import (face_areas, is_closed_manifold,
                                   vertex_normals)


def test_bumpy_torus_is_a_closed_outward_genus_one_surface():
    data = bumpy_torus(2000, seed=3)
    n = data.pos.size(0)
    assert n >= 2000 and data.face.size(1) == 2 * n
    assert is_closed_manifold(data.face, n)
    # Euler characteristic V - E + F = 0 (genus one): E = 3F / 2
    assert n - 3 * data.face.size(1) // 2 + data.face.size(1) == 0
    assert bool((face_areas(data.pos, data.face) > 0).all())
    # normals point away from the tube's centre line
    u = data.uv[:, 0]
    centre = torch.stack([u.cos(), u.sin(), torch.zeros_like(u)], 1)
    normal = vertex_normals(data.pos, data.face)
    assert bool((((data.pos - centre) * normal).sum(1) > 0).all())
    # deterministic per seed, different across seeds
    assert torch.equal(bumpy_torus(2000, seed=3).pos, data.pos)
    assert not torch.equal(bumpy_torus(2000, seed=4).pos, data.pos)
    with pytest.raises(ValueError, match='num_vertices'):
        bumpy_torus(10)
