"""TextureTexels: texel points of a UV-mapped mesh against exact answers (a
flat square with identity UVs, the UV sphere's analytic coverage), what
happens to the other attributes, the SVBRDF pipeline on its output, and
bad input."""
import math
import warnings

import numpy as np
import pytest
import torch
from torch_geometric.data import Data

from tg_intrinsic.geometry import vertex_normals, weld_vertices
from tg_intrinsic.geometry.texture import uv_sphere
from tg_intrinsic.transforms import TextureTexels

from tests.conftest import grid_mesh


def square(n=5, jitter=0.0, **extra):
    """The unit square z = 0 with UV = (x, y)."""
    pos, face = grid_mesh(n, jitter=jitter)
    return Data(pos=pos, face=face, uv=pos[:, :2].clone(), **extra)


def centres(height, width, dtype=torch.float64):
    r, c = torch.meshgrid(torch.arange(height, dtype=dtype),
                          torch.arange(width, dtype=dtype), indexing='ij')
    return torch.stack([(c.flatten() + 0.5) / width,
                        1 - (r.flatten() + 0.5) / height], 1)


@pytest.mark.parametrize('jitter', [0.0, 0.8])
def test_identity_uvs_put_texels_at_their_centres(jitter):
    out = TextureTexels((6, 9))(square(jitter=jitter))
    assert out.texture_shape == (6, 9)
    assert torch.equal(out.texel_index, torch.arange(54))
    torch.testing.assert_close(out.pos[:, :2], centres(6, 9), rtol=0,
                               atol=1e-14)
    assert bool((out.pos[:, 2] == 0).all())
    # the square's triangles are counter-clockwise seen from +z
    torch.testing.assert_close(out.normal, torch.tensor(
        [0.0, 0.0, 1.0], dtype=torch.float64).expand(54, 3))
    # the texels' triangles and barycentrics rebuild them
    corners = out.mesh_pos[out.mesh_face[:, out.texel_face]]  # (3, N, 3)
    torch.testing.assert_close((out.texel_bary.t().unsqueeze(-1)
                                * corners).sum(0), out.pos)


def uv_sphere_coverage(rows, cols, height, width):
    """Texels whose centre lies in a UV triangle of uv_sphere: every one
    between the rings next to the poles; in a cap row, those within the
    cap triangle, whose half-width shrinks linearly from half a column
    band at the ring to 0 at the pole."""
    r, c = np.meshgrid(np.arange(height), np.arange(width), indexing='ij')
    u, v = (c + 0.5) / width, 1 - (r + 0.5) / height
    band = 1 / rows
    to_pole = np.maximum(v - (1 - band), band - v)  # past the ring, or <0
    apex = (np.floor(u * cols) + 0.5) / cols
    half_width = (1 - to_pole / band) / (2 * cols)
    covered = (to_pole <= 0) | (np.abs(u - apex) <= half_width + 1e-12)
    return np.flatnonzero(covered.ravel())


@pytest.mark.parametrize('texture_shape', [(24, 40), (7, 13)])
def test_uv_sphere_texels_lie_on_it(texture_shape):
    rows, cols = 6, 10
    pos, face, uv = uv_sphere(rows, cols)
    out = TextureTexels(texture_shape)(Data(pos=pos, face=face, uv=uv,
                                            normal=pos.clone()))
    expected = uv_sphere_coverage(rows, cols, *texture_shape)
    np.testing.assert_array_equal(out.texel_index.numpy(), expected)
    # on the chords of the triangles: inside the sphere, by at most the
    # sagitta of the longest edge
    edge = (pos[face] - pos[face.roll(1, 0)]).norm(dim=-1).max()
    radius = out.pos.norm(dim=1)
    assert float(radius.max()) <= 1 + 1e-12
    assert float(radius.min()) >= 1 - float(edge) ** 2 / 2
    torch.testing.assert_close(out.normal, out.pos / radius.unsqueeze(1))
    # the texel lies in the latitude band its v says (the chord is not
    # the equirectangular map, so only to within a band)
    theta = torch.acos(out.normal[:, 2].clamp(-1, 1))
    v = centres(*texture_shape)[out.texel_index, 1]
    assert float(((1 - theta / math.pi) - v).abs().max()) < 1 / rows
    # per-corner UVs give the same texels
    corner = TextureTexels(texture_shape)(Data(pos=pos, face=face,
                                               face_uv=uv[face],
                                               normal=pos.clone()))
    assert torch.equal(corner.texel_index, out.texel_index)
    torch.testing.assert_close(corner.pos, out.pos)


def test_computed_normals_ignore_the_uv_seam():
    pos, face, uv = uv_sphere(6, 10)
    out = TextureTexels((12, 20))(Data(pos=pos, face=face, uv=uv))
    welded, welded_face, inverse = weld_vertices(pos, face)
    smooth = vertex_normals(welded, welded_face)[inverse]
    given = TextureTexels((12, 20))(Data(pos=pos, face=face, uv=uv,
                                         normal=smooth))
    torch.testing.assert_close(out.normal, given.normal)
    # unwelded, the seam's normals would crease
    seam = vertex_normals(pos, face)
    assert float((seam - smooth).norm(dim=1).max()) > 0.05
    torch.testing.assert_close(out.normal.norm(dim=1),
                               torch.ones(out.num_nodes, dtype=pos.dtype))


def test_attributes_kept_interpolated_or_dropped():
    pos, face = grid_mesh(4)
    g = torch.Generator().manual_seed(0)
    capture = dict(images=torch.rand(16, 3, 4, 3, generator=g),
                   intrinsics=torch.eye(3).repeat(16, 1, 1),
                   extrinsics=torch.rand(16, 3, 4, generator=g),
                   envmap=torch.rand(4, 8, 3, generator=g),
                   scale=torch.tensor([2.0]))
    affine = pos @ torch.tensor([[1.0, 2.0], [3.0, -1.0], [0.5, 0.5]],
                                dtype=pos.dtype) + 0.25
    data = square(4, albedo=affine, obs_mask=torch.ones(16, 5,
                                                        dtype=torch.bool),
                  label=torch.arange(face.size(1)), **capture)
    assert pos.size(0) == 16  # as many vertices as views: still kept
    before = {k: v.clone() for k, v in data.items()}
    out = TextureTexels((5, 5), interpolate=['albedo'])(data)
    for key, value in capture.items():
        assert torch.equal(out[key], value)
    assert 'obs_mask' not in out and 'uv' not in out and 'face' not in out
    # an affine per-vertex field is interpolated exactly
    torch.testing.assert_close(out.albedo, out.pos @ torch.tensor(
        [[1.0, 2.0], [3.0, -1.0], [0.5, 0.5]], dtype=pos.dtype) + 0.25)
    assert torch.equal(out.label, out.texel_face)  # per triangle
    assert torch.equal(out.mesh_pos, pos) and torch.equal(out.mesh_face,
                                                         face)
    for key, value in before.items():  # the input is not mutated
        assert torch.equal(data[key], value)
    bare = TextureTexels((5, 5), keep_mesh=False)(square(4))
    assert 'mesh_pos' not in bare and 'mesh_face' not in bare
    assert repr(TextureTexels((5, 6), ['albedo'])) == (
        "TextureTexels(texture_shape=(5, 6), interpolate=['albedo'], "
        "keep_mesh=True)")


def test_texels_run_through_the_svbrdf_pipeline():
    from tg_intrinsic.datasets import svbrdf_scene
    from tg_intrinsic.nn import FrequencySVBRDF
    from tg_intrinsic.transforms import (FitSphericalHarmonics,
                                         ProjectViews, SpectralUncertainty)
    scene = svbrdf_scene('uv_sphere', resolution=6, num_views=10,
                         image_size=(48, 48), envmap_size=(16, 32),
                         specular_samples=8, light_samples=8,
                         image_specular_samples=4, image_light_samples=4)
    data = TextureTexels((12, 24), interpolate=('roughness', ))(scene)
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')  # texels no camera sees
        data = ProjectViews()(data)
    data = SpectralUncertainty()(FitSphericalHarmonics(l_max=3)(data))
    model = FrequencySVBRDF(data.num_nodes)
    result = model.fit(data, steps=3, tv_weight=0.1, progress=False)
    maps = result.maps()
    assert maps['roughness'].shape == (12, 24)
    coverage = np.zeros(12 * 24, dtype=bool)
    coverage[data.texel_index.numpy()] = True
    np.testing.assert_array_equal(maps['coverage'].ravel(), coverage)
    assert np.isnan(maps['roughness'].ravel()[~coverage]).all()


def test_bad_input():
    with pytest.raises(ValueError, match="'texture_shape\\[0\\]' must be at "
                                         "least 1"):
        TextureTexels((0, 4))
    with pytest.raises(ValueError, match="'texture_shape' must be"):
        TextureTexels(8)
    with pytest.raises(ValueError, match="'interpolate' must be a sequence"):
        TextureTexels((4, 4), interpolate='albedo')
    transform = TextureTexels((4, 4))
    data = square(4)
    with pytest.raises(ValueError, match='needs UVs'):
        transform(Data(pos=data.pos, face=data.face))
    with pytest.raises(ValueError, match='needs a UV-mapped mesh'):
        transform(Data(pos=data.pos, uv=data.uv))
    for bad, match in ((data.uv * 2, r'lie in \[0, 1\]'),
                       (data.uv.t(), r"'uv' must have shape \[16, 2\]"),
                       (data.uv.long(), 'float'),
                       (data.uv.clone().fill_(math.nan), 'NaN')):
        with pytest.raises(ValueError, match=match):
            transform(Data(pos=data.pos, face=data.face, uv=bad))
    with pytest.raises(ValueError, match=r"'face_uv' must have shape "
                                         r"\[3, 18, 2\]"):
        transform(Data(pos=data.pos, face=data.face,
                       face_uv=data.uv[data.face].transpose(0, 1)))
    with pytest.raises(ValueError, match=r"'face' must have shape \[3, F\]"):
        transform(Data(pos=data.pos, face=data.face.t(), uv=data.uv))
    # UV triangles smaller than a texel: nothing to recover
    tiny = Data(pos=data.pos, face=data.face, uv=data.uv * 0.01)
    with pytest.raises(ValueError, match='no texel centre'):
        transform(tiny)
    with pytest.raises(ValueError, match="names 'albedo'"):
        TextureTexels((4, 4), ['albedo'])(data)
    with pytest.raises(ValueError, match="names 'uv'"):
        TextureTexels((4, 4), ['uv'])(data)
    labels = square(4, labels=torch.arange(16))
    with pytest.raises(ValueError, match='only float attributes'):
        TextureTexels((4, 4), ['labels'])(labels)
