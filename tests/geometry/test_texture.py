"""Texture space: the UV rasteriser against a brute-force point-in-triangle
test of every texel centre, the texel grid against an enumeration of
4-neighbour pairs, and the UV sphere against its formula."""
import math

import numpy as np
import pytest
import torch

from tg_intrinsic.geometry import face_normals
from tg_intrinsic.geometry.texture import (rasterize_uv, texture_grid_edges,
                                           uv_sphere)


def texel_centres(height, width):
    """(H * W, 2) UVs of the texel centres, row-major, row 0 at v = 1."""
    r, c = np.meshgrid(np.arange(height), np.arange(width), indexing='ij')
    return np.stack([(c.ravel() + 0.5) / width,
                     1 - (r.ravel() + 0.5) / height], 1)


def brute_force_owner(face_uv, height, width):
    """Lowest-index triangle containing each texel centre (-1: none), by
    signed areas, edges inclusive."""
    centres = texel_centres(height, width)
    owner = np.full(len(centres), -1)
    for f in range(face_uv.shape[1]):
        a, b, c = face_uv[:, f].numpy()

        def cross(p, q, x):
            return (q[0] - p[0]) * (x[:, 1] - p[1]) \
                - (q[1] - p[1]) * (x[:, 0] - p[0])
        s = np.stack([cross(a, b, centres), cross(b, c, centres),
                      cross(c, a, centres)])
        inside = (s >= -1e-12).all(0) | (s <= 1e-12).all(0)
        owner[(owner < 0) & inside] = f
    return owner


def test_identity_square_covers_every_texel_at_its_centre():
    face_uv = torch.tensor([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0],
                            [0.0, 0.0], [1.0, 1.0], [0.0, 1.0]],
                           dtype=torch.float64).view(2, 3, 2).transpose(0, 1)
    index, face, bary = rasterize_uv(face_uv, 5, 7)
    assert torch.equal(index, torch.arange(35))
    rebuilt = (bary.unsqueeze(-1) * face_uv[:, face].transpose(0, 1)).sum(1)
    torch.testing.assert_close(rebuilt, torch.from_numpy(texel_centres(5, 7)),
                               rtol=0, atol=1e-14)
    assert bool((bary >= 0).all())
    torch.testing.assert_close(bary.sum(1), torch.ones(35, dtype=bary.dtype))


def test_half_square_count_is_analytic():
    # the centre (u_c, v_r) is inside iff u_c + v_r <= 1, i.e. c <= r
    # for a square texture: the diagonal and below, n (n + 1) / 2 texels
    face_uv = torch.tensor([[[0.0, 0.0]], [[1.0, 0.0]], [[0.0, 1.0]]])
    for n in (1, 4, 9):
        index, _, _ = rasterize_uv(face_uv, n, n)
        assert index.numel() == n * (n + 1) // 2
        r, c = index // n, index % n
        assert bool((c <= r).all())


def test_random_triangles_match_brute_force():
    g = torch.Generator().manual_seed(0)
    face_uv = torch.rand(3, 12, 2, generator=g, dtype=torch.float64)
    face_uv[:, 3] = face_uv[:, 2].flip(0)  # a clockwise copy, overlapping
    index, face, bary = rasterize_uv(face_uv, 23, 31)
    owner = brute_force_owner(face_uv, 23, 31)
    np.testing.assert_array_equal(index.numpy(), np.flatnonzero(owner >= 0))
    np.testing.assert_array_equal(face.numpy(), owner[owner >= 0])
    assert (owner == 3).sum() == 0 and (owner == 2).sum() > 0  # the tie
    a, b, c = face_uv
    clockwise = ((b - a)[:, 0] * (c - a)[:, 1]
                 - (b - a)[:, 1] * (c - a)[:, 0]) < 0
    assert bool(clockwise[face].any()) and bool((~clockwise)[face].any())
    rebuilt = (bary.unsqueeze(-1) * face_uv[:, face].transpose(0, 1)).sum(1)
    centres = torch.from_numpy(texel_centres(23, 31))[index]
    torch.testing.assert_close(rebuilt, centres, rtol=0, atol=1e-12)


def test_zero_area_and_sub_texel_triangles_cover_nothing():
    flat = torch.tensor([[[0.1, 0.1]], [[0.5, 0.5]], [[0.9, 0.9]]])
    assert rasterize_uv(flat, 8, 8)[0].numel() == 0
    tiny = torch.tensor([[[0.01, 0.01]], [[0.02, 0.01]], [[0.01, 0.02]]])
    assert rasterize_uv(tiny, 4, 4)[0].numel() == 0


def test_rasterize_uv_bad_input():
    good = torch.rand(3, 2, 2)
    with pytest.raises(ValueError, match=r'\[3, F, 2\]'):
        rasterize_uv(good.transpose(0, 1), 4, 4)
    with pytest.raises(ValueError, match=r'\[3, F, 2\]'):
        rasterize_uv(good.numpy(), 4, 4)
    with pytest.raises(ValueError, match=r'lie in \[0, 1\]'):
        rasterize_uv(good + 1, 4, 4)
    nan = good.clone()
    nan[0, 0, 0] = math.nan
    with pytest.raises(ValueError, match='NaN'):
        rasterize_uv(nan, 4, 4)
    with pytest.raises(ValueError, match="'height' must be at least 1"):
        rasterize_uv(good, 0, 4)


def brute_force_grid(texel_index, height, width):
    """Every ordered pair of given texels that share a side."""
    where = {int(t): i for i, t in enumerate(texel_index)}
    pairs = set()
    for t, i in where.items():
        r, c = divmod(t, width)
        for dr, dc in ((0, 1), (0, -1), (1, 0), (-1, 0)):
            rr, cc = r + dr, c + dc
            if 0 <= rr < height and 0 <= cc < width \
                    and rr * width + cc in where:
                pairs.add((where[rr * width + cc], i))
    return sorted(pairs, key=lambda p: (p[1], p[0]))


def test_texture_grid_edges_match_enumeration():
    g = torch.Generator().manual_seed(1)
    height, width = 9, 13
    texel_index = torch.randperm(height * width, generator=g)[:70]
    edges = texture_grid_edges(texel_index, (height, width))
    expected = brute_force_grid(texel_index.tolist(), height, width)
    assert [tuple(e) for e in edges.t().tolist()] == expected
    # the full texture: 2 H W - H - W undirected edges
    full = texture_grid_edges(torch.arange(height * width), (height, width))
    assert full.size(1) == 2 * (2 * height * width - height - width)
    # nothing wraps around: the last texel of a row and the first of the
    # next are not neighbours
    row_ends = texture_grid_edges(torch.tensor([width - 1, width]),
                                  (height, width))
    assert row_ends.size(1) == 0


def test_texture_grid_edges_bad_input():
    with pytest.raises(ValueError, match='repeats texels'):
        texture_grid_edges(torch.tensor([0, 1, 1]), (2, 2))
    with pytest.raises(ValueError, match=r'outside \[0, 4\)'):
        texture_grid_edges(torch.tensor([0, 4]), (2, 2))
    with pytest.raises(ValueError, match='torch.long'):
        texture_grid_edges(torch.tensor([0.0, 1.0]), (2, 2))
    with pytest.raises(ValueError, match='texture_shape'):
        texture_grid_edges(torch.tensor([0, 1]), (2, 0))


def test_uv_sphere_matches_its_formula():
    rows, cols = 6, 10
    pos, face, uv = uv_sphere(rows, cols)
    assert pos.shape == ((rows - 1) * (cols + 1) + 2 * cols, 3)
    assert face.shape == (3, 2 * cols * (rows - 1))
    torch.testing.assert_close(pos.norm(dim=1), torch.ones(len(pos),
                                                           dtype=pos.dtype))
    theta = torch.acos(pos[:, 2].clamp(-1, 1))
    torch.testing.assert_close(uv[:, 1], 1 - theta / math.pi)
    ring = (theta > 1e-9) & (theta < math.pi - 1e-9)
    phi = torch.remainder(torch.atan2(pos[:, 1], pos[:, 0]), 2 * math.pi)
    gap = torch.remainder(2 * math.pi * uv[:, 0] - phi + 1, 2 * math.pi) - 1
    assert float(gap[ring].abs().max()) < 1e-12
    seam = ring & ((phi < 1e-9) | (phi > 2 * math.pi - 1e-9))
    assert sorted(set(uv[seam, 0].tolist())) == [0.0, 1.0]
    assert int(seam.sum()) == 2 * (rows - 1)
    # counter-clockwise from outside and in UV space
    centre = pos[face].mean(0)
    assert bool(((face_normals(pos, face) * centre).sum(1) > 0).all())
    a, b, c = uv[face]
    signed = (b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0]
    assert bool((signed > 0).all())
    assert uv_sphere(4, 8, dtype=torch.float32)[0].dtype == torch.float32
    with pytest.raises(ValueError, match="'rows' must be at least 2"):
        uv_sphere(1, 8)


# ------------------------------------------------------------------ baking
def grid_mesh(n=6):
    """A flat (n x n)-vertex grid over [0, 1]^2 in the xy plane."""
    x, y = torch.meshgrid(torch.linspace(0, 1, n, dtype=torch.float64),
                          torch.linspace(0, 1, n, dtype=torch.float64),
                          indexing='ij')
    pos = torch.stack([x.reshape(-1), y.reshape(-1),
                       torch.zeros(n * n, dtype=torch.float64)], 1)
    i = torch.arange(n - 1)
    a = (i[:, None] * n + i[None, :]).reshape(-1)
    face = torch.cat([torch.stack([a, a + n, a + n + 1]),
                      torch.stack([a, a + n + 1, a + 1])], 1)
    return pos, face


def test_bake_texture_interpolates_linear_maps_exactly():
    """Barycentric interpolation reproduces a linear function at every
    texel centre; texels outside the UVs take the nearest covered texel's
    value (here: the clamped one)."""
    from tg_intrinsic.geometry import bake_texture
    pos, face = grid_mesh()
    values = torch.stack([0.2 + 0.5 * pos[:, 0] - 0.1 * pos[:, 1],
                          0.3 * pos[:, 1] + 0.1], 1)
    # the grid mapped onto the lower-left quarter of the texture
    face_uv = 0.5 * pos[:, :2][face]
    texture, coverage = bake_texture(values, face, face_uv, (16, 16))
    assert texture.shape == (16, 16, 2) and texture.dtype == torch.float64
    centres = torch.from_numpy(texel_centres(16, 16)).view(16, 16, 2)
    rows, cols = torch.meshgrid(torch.arange(16), torch.arange(16),
                                indexing='ij')
    inside = (centres[..., 0] < 0.5) & (centres[..., 1] < 0.5)
    assert torch.equal(coverage, inside)
    # the oracle: the linear function at the texel centre, clamped into
    # the covered quarter (rows 8-15, columns 0-7) for the padding
    r, c = rows.clamp(min=8), cols.clamp(max=7)
    u, v = centres[r, c, 0] / 0.5, centres[r, c, 1] / 0.5
    expected = torch.stack([0.2 + 0.5 * u - 0.1 * v, 0.3 * v + 0.1], -1)
    torch.testing.assert_close(texture, expected, rtol=0, atol=1e-12)
    grey, _ = bake_texture(values[:, 0].float(), face, face_uv, (16, 16))
    assert grey.shape == (16, 16) and grey.dtype == torch.float32


def test_bake_texture_bad_input():
    from tg_intrinsic.geometry import bake_texture
    pos, face = grid_mesh(3)
    values = pos[:, 0]
    face_uv = pos[:, :2][face]
    with pytest.raises(ValueError, match=r"'face_uv' must have shape "
                       r"\[3, 8, 2\]"):
        bake_texture(values, face, face_uv[:, :4], (8, 8))
    with pytest.raises(ValueError, match=r"'values' must be a tensor of "
                       r"shape \[V\] or \[V, C\]"):
        bake_texture(values.view(3, 3, 1), face, face_uv, (8, 8))
    with pytest.raises(ValueError, match="no texel centre"):
        bake_texture(values, face, torch.zeros_like(face_uv), (8, 8))
    with pytest.raises(ValueError, match=r"'face' must have shape \[3, F\]"):
        bake_texture(values, face.t(), face_uv, (8, 8))


def test_uv_atlas_charts_cover_without_overlap():
    """xatlas's charts: every corner in [0, 1], no two triangles on one
    texel (the covered area equals the sum of the UV triangles' areas),
    and each chart a faithful map (UV area proportional to surface area
    to within xatlas's stretch)."""
    from tg_intrinsic.geometry import face_areas, uv_atlas
    import trimesh
    sphere = trimesh.creation.icosphere(2)
    pos = torch.tensor(sphere.vertices)
    face = torch.tensor(sphere.faces).t().contiguous()
    face_uv = uv_atlas(pos, face)
    assert face_uv.shape == (3, face.size(1), 2)
    assert face_uv.dtype == pos.dtype
    assert float(face_uv.min()) >= 0 and float(face_uv.max()) <= 1
    a, b, c = face_uv[0], face_uv[1], face_uv[2]
    uv_area = 0.5 * ((b - a)[:, 0] * (c - a)[:, 1]
                     - (b - a)[:, 1] * (c - a)[:, 0]).abs()
    size = 1024
    index, _, _ = rasterize_uv(face_uv, size, size)
    assert abs(index.numel() / size ** 2 - float(uv_area.sum())) < 0.02
    ratio = uv_area / face_areas(pos, face)
    assert float(ratio.max() / ratio.min()) < 3


def test_uv_atlas_without_xatlas_says_how_to_get_it(hide_module):
    from tg_intrinsic.geometry import uv_atlas
    hide_module('xatlas')
    pos, face = grid_mesh(3)
    with pytest.raises(ImportError, match='pip install xatlas'):
        uv_atlas(pos, face)


def test_grid_atlas_gives_every_triangle_its_own_texels():
    from tg_intrinsic.geometry import grid_atlas
    for num_faces in (1, 2, 7, 1280):
        face_uv = grid_atlas(num_faces)
        assert face_uv.shape == (3, num_faces, 2)
        assert float(face_uv.min()) > 0 and float(face_uv.max()) < 1
        a, b, c = face_uv[0], face_uv[1], face_uv[2]
        signed = 0.5 * ((b - a)[:, 0] * (c - a)[:, 1]
                        - (b - a)[:, 1] * (c - a)[:, 0])
        assert bool((signed > 0).all())  # counter-clockwise, not flipped
        # no texel claimed twice: overlapping triangles would cover less
        # than their summed area (texel centres on edges count for both
        # neighbours, a few percent more)
        size = max(128, int(32 * num_faces ** 0.5))
        index, _, _ = rasterize_uv(face_uv, size, size)
        assert 0.98 < index.numel() / size ** 2 / float(signed.sum()) < 1.1
        # and at the size the docstring asks for, every triangle has texels
        size = max(16, int(8 * num_faces ** 0.5))
        _, owner, _ = rasterize_uv(face_uv, size, size)
        assert torch.unique(owner).numel() == num_faces


def test_a_crashing_xatlas_is_an_error_not_the_end(monkeypatch):
    pytest.importorskip('xatlas')
    import tg_intrinsic.geometry.texture as texture
    from tg_intrinsic.geometry import uv_atlas
    pos, face = grid_mesh(3)
    monkeypatch.setattr(texture, '_XATLAS_CHILD', 'import os, signal; '
                        'os.kill(os.getpid(), signal.SIGSEGV)')
    with pytest.raises(RuntimeError, match=r'xatlas crashed \(signal 11\) '
                       r'on this mesh of \d+ triangles'):
        uv_atlas(pos, face)
    # the glTF writer goes on with the grid atlas, and says why
    from tg_intrinsic.io.gltf import _atlas
    with pytest.warns(UserWarning, match='xatlas crashed .* grid atlas'):
        face_uv, how = _atlas(pos, face)
    assert how == 'grid' and face_uv.shape == (3, face.size(1), 2)
