"""The tabulated full reflection integral against the independent numba
renderer, the split-sum albedo table, the white furnace and ray-cast
visibility against analytic occluders."""
import math

import pytest
import torch

from tg_intrinsic.geometry.appearance.brdf import ggx_albedo
from tg_intrinsic.geometry.appearance.direct_lighting import (
    direction_visibility, reflection_tables)
from tg_intrinsic.geometry.appearance.envmap import (equirect_directions,
                                                     irradiance)
from tg_intrinsic.geometry.appearance.lighting import render_radiance

from .scenes import D64, sky_with_sun, unit


def random_pairs(num=60, views=4, seed=0):
    g = torch.Generator().manual_seed(seed)
    normal = unit(torch.randn(num, 3, generator=g, dtype=D64))
    view = unit(torch.randn(num, views, 3, generator=g, dtype=D64))
    facing = (view * normal[:, None]).sum(-1, keepdim=True)
    view = torch.where(facing < 0, -view, view)
    # no grazing views: both estimators are noisiest there
    view = unit(view + 0.3 * normal[:, None])
    return normal, view, torch.ones(num, views, dtype=torch.bool)


def test_tables_match_the_independent_renderer():
    """Metals (no diffuse term): b A(r) + C(r) at the grid's roughness is
    the full integral of the numba multiple-importance renderer."""
    env = sky_with_sun()
    normal, view, mask = random_pairs()
    grid = torch.tensor([0.3, 0.6, 0.9], dtype=D64)
    _, tables = reflection_tables(normal, view, mask, env, grid,
                                  light_samples=256, brdf_samples=128)
    base = torch.rand(len(normal), 3, dtype=D64,
                      generator=torch.Generator().manual_seed(1))
    ones = torch.ones(len(normal), dtype=D64)
    for j, r in enumerate(grid):
        truth = render_radiance(normal, base, ones, r * ones, view, env,
                                specular_samples=1024, light_samples=1024,
                                mask=mask)
        ours = base[:, None] * tables[:, :, j, 0] + tables[:, :, j, 1]
        error = (ours - truth).abs().mean() / truth.abs().mean()
        assert error < 0.03, (float(r), float(error))
        # and no bias
        assert abs(float((ours - truth).mean() / truth.mean())) < 0.01


def test_white_furnace_is_the_albedo_table():
    """Under a constant unit sky A and C are the split-sum factors of the
    GGX directional albedo, and E = pi."""
    env = torch.ones(32, 64, 3, dtype=D64)
    normal, view, mask = random_pairs(40, 3)
    grid = torch.tensor([0.2, 0.5, 1.0], dtype=D64)
    irr, tables = reflection_tables(normal, view, mask, env, grid,
                                    light_samples=64, brdf_samples=256)
    assert torch.allclose(irr, torch.full_like(irr, math.pi), rtol=2e-3)
    cos_out = (view * normal[:, None]).sum(-1)
    for j, r in enumerate(grid):
        for r0 in (0.0, 1.0):
            expected = ggx_albedo(cos_out, r.expand(len(normal)),
                                  torch.full((len(normal), 3), r0,
                                             dtype=D64))
            got = r0 * tables[:, :, j, 0] + tables[:, :, j, 1]
            # Monte Carlo noise per pair, no bias
            assert (got - expected).abs().mean() < 0.01
            assert abs(float((got - expected).mean())) < 0.003


def test_tables_are_deterministic_and_zero_off_the_mask():
    env = sky_with_sun(16, 32)
    normal, view, mask = random_pairs(20, 3)
    mask[::2, 1] = False
    grid = torch.linspace(0.1, 1, 4, dtype=D64)
    a = reflection_tables(normal, view, mask, env, grid, seed=3)
    b = reflection_tables(normal, view, mask, env, grid, seed=3, chunk=7,
                          backend='torch')
    # the irradiance: two sums over the map (compiled, torch) to rounding
    torch.testing.assert_close(a[0], b[0], rtol=1e-12, atol=0)
    assert torch.allclose(a[1], b[1])
    assert (a[1][::2, 1] == 0).all() and (a[1][1::2, 1] != 0).any()
    c = reflection_tables(normal, view, mask, env, grid, seed=4)
    assert not torch.allclose(a[1], c[1])


@pytest.mark.parametrize('dtype', [torch.float64, torch.float32])
def test_compiled_and_torch_tables_agree(dtype):
    """The numba kernel takes the torch loop's samples and arithmetic: the
    same tables, with a visibility grid, a mask and grazing views."""
    import trimesh
    ico = trimesh.creation.icosphere(subdivisions=1)
    vertices = torch.tensor(ico.vertices, dtype=D64)
    faces = torch.tensor(ico.faces).t().contiguous()
    normal = unit(vertices)
    seen = direction_visibility(vertices, normal, vertices, faces, (8, 16))
    seen[::3] = False  # something for the grid lookup to find
    g = torch.Generator().manual_seed(5)
    view = unit(torch.randn(len(normal), 5, 3, generator=g, dtype=D64))
    mask = (view * normal[:, None]).sum(-1) > 0
    env = sky_with_sun(16, 32)
    grid = torch.linspace(0.1, 1, 5, dtype=D64)
    args = (normal.to(dtype), view.to(dtype), mask, env.to(dtype),
            grid.to(dtype))
    for visibility in (None, seen):
        compiled = reflection_tables(*args, visibility, light_samples=16,
                                     brdf_samples=8, backend='numba')
        plain = reflection_tables(*args, visibility, light_samples=16,
                                  brdf_samples=8, backend='torch')
        assert compiled[1].dtype == dtype
        tolerance = 1e-10 if dtype == torch.float64 else 2e-4
        torch.testing.assert_close(compiled[0], plain[0])
        scale = float(plain[1].abs().max())
        assert float((compiled[1] - plain[1]).abs().max()) \
            < tolerance * scale
        assert (compiled[1][~mask] == 0).all()


def test_irradiance_of_a_large_map_is_summed_in_blocks():
    """A map over IRRADIANCE_PIXELS is summed in 2 x 2 blocks by the
    compiled path: against the torch sum over every pixel (with a
    visibility grid), the cosine moves by at most a block."""
    from tg_intrinsic.geometry.appearance import direct_lighting
    env = sky_with_sun(128, 256)
    normal, view, mask = random_pairs(30, 2)
    seen = torch.rand(30, 2 * 4 * 4, generator=torch.Generator(
        ).manual_seed(2)) > 0.3
    grid = torch.linspace(0.1, 1, 3, dtype=D64)
    plain = reflection_tables(normal, view, mask, env, grid, seen,
                              light_samples=4, brdf_samples=2,
                              backend='torch')[0]
    old = direct_lighting.IRRADIANCE_PIXELS
    try:
        direct_lighting.IRRADIANCE_PIXELS = 64 * 128
        pooled = reflection_tables(normal, view, mask, env, grid, seen,
                                   light_samples=4, brdf_samples=2,
                                   backend='numba')[0]
    finally:
        direct_lighting.IRRADIANCE_PIXELS = old
    assert not torch.equal(pooled, plain)
    error = ((pooled - plain).abs() / plain).max()
    assert error < 0.01


def two_squares():
    """A unit square at z = 0 (the floor) and a roof of half-width 0.5 at
    height 1 above its centre; both as two triangles each."""
    floor = torch.tensor([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0.0]],
                         dtype=D64)
    roof = torch.tensor([[-0.5, -0.5, 1], [0.5, -0.5, 1], [0.5, 0.5, 1],
                         [-0.5, 0.5, 1.0]], dtype=D64)
    vertices = torch.cat([floor, roof])
    faces = torch.tensor([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]]).t()
    return vertices, faces


def test_visibility_against_an_analytic_roof():
    vertices, faces = two_squares()
    points = torch.tensor([[0.0, 0.0, 0.0], [0.3, -0.2, 0.0],
                           [0.9, 0.9, 0.0]], dtype=D64)
    normal = torch.tensor([[0, 0, 1.0]], dtype=D64).expand(3, 3)
    seen = direction_visibility(points, normal, vertices, faces, (8, 16))
    directions = equirect_directions(8, 16).reshape(-1, 3)
    # the ray p + t d meets the roof plane z = 1 at t = 1 / d_z
    up = directions[:, 2] > 0
    t = 1 / directions[:, 2].clamp_min(1e-9)
    hit = points[:, None, :2] + t[None, :, None] * directions[None, :, :2]
    blocked = up & (hit.abs() < 0.5).all(-1)
    # directions down go through the floor (no cell centre is grazing)
    below = directions[:, 2] < 0
    expected = ~blocked & ~below
    assert torch.equal(seen[:, ~below], expected[:, ~below])
    assert blocked[0].sum() > blocked[2].sum() > 0
    assert not seen[:, below].any()


def test_visibility_of_a_convex_shape_is_its_horizon():
    import trimesh
    ico = trimesh.creation.icosphere(subdivisions=2)
    vertices = torch.tensor(ico.vertices, dtype=D64)
    faces = torch.tensor(ico.faces).t().contiguous()
    normal = unit(vertices)
    seen = direction_visibility(vertices, normal, vertices, faces, (8, 16))
    cosine = normal @ equirect_directions(8, 16).reshape(-1, 3).T
    assert seen[cosine > 0.2].all()
    assert not seen[cosine < -0.2].any()
    # the shadowed irradiance is then the unshadowed one
    env = sky_with_sun(16, 32)
    irr, _ = reflection_tables(normal, normal[:, None], torch.ones(
        len(normal), 1, dtype=torch.bool), env, torch.tensor([0.5, 1.0],
                                                             dtype=D64),
        seen)
    free = irradiance(env, normal)
    assert ((irr - free).abs().mean() / free.mean()) < 0.05


def test_bad_input():
    env = sky_with_sun(8, 16)
    normal, view, mask = random_pairs(5, 2)
    grid = torch.tensor([0.2, 0.8], dtype=D64)
    with pytest.raises(ValueError, match='must agree'):
        reflection_tables(normal[:4], view, mask, env, grid)
    with pytest.raises(ValueError, match='increasing grid'):
        reflection_tables(normal, view, mask, env, grid.flip(0))
    with pytest.raises(ValueError, match='increasing grid'):
        reflection_tables(normal, view, mask, env, torch.tensor([0.5, 1.5]))
    with pytest.raises(ValueError, match='negative radiance'):
        reflection_tables(normal, view, mask, -env, grid)
    with pytest.raises(ValueError, match=r'\(R, 2R\) grid'):
        reflection_tables(normal, view, mask, env, grid,
                          torch.ones(5, 10, dtype=torch.bool))
    with pytest.raises(ValueError, match="'light_samples'"):
        reflection_tables(normal, view, mask, env, grid, light_samples=0)
