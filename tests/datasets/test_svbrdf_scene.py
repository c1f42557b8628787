"""The synthetic SVBRDF scene: layout, determinism, material ranges,
visibility against the analytic answer on a sphere, images against the
per-vertex observations, cameras, real meshes and bad input."""
import math
import os

import numpy as np
import pytest
import torch

from tg_intrinsic.datasets import look_at_cameras, svbrdf_scene
from tg_intrinsic.geometry.appearance.cameras import camera_centers

MESHES = os.path.join(os.path.dirname(__file__), '..', '..', '..', 'shared',
                      'data', 'meshes')
SMALL = dict(resolution=2, num_views=6, image_size=(40, 40),
             envmap_size=(32, 64))


@pytest.fixture(scope='module')
def scene():
    return svbrdf_scene(**SMALL)


def project(data, points):
    K, E = data.intrinsics.double(), data.extrinsics.double()
    cam = torch.einsum('vij,nj->nvi', E[:, :, :3], points) + E[:, :, 3]
    u = K[:, 0, 0] * cam[..., 0] / cam[..., 2] + K[:, 0, 2]
    v = K[:, 1, 1] * cam[..., 1] / cam[..., 2] + K[:, 1, 2]
    return u, v, cam[..., 2]


def test_layout_and_dtypes(scene):
    N, V = scene.pos.size(0), 6
    assert N == 162 and scene.face.shape == (3, 320)
    assert scene.face.dtype == torch.long
    for key, shape in [('pos', (N, 3)), ('normal', (N, 3)),
                       ('base_color', (N, 3)), ('metallic', (N, )),
                       ('roughness', (N, )), ('envmap', (32, 64, 3)),
                       ('intrinsics', (V, 3, 3)), ('extrinsics', (V, 3, 4)),
                       ('obs_radiance', (N, V, 3)), ('obs_dir', (N, V, 3)),
                       ('images', (V, 40, 40, 3))]:
        assert scene[key].shape == shape, key
        assert scene[key].dtype == torch.float32, key
    assert scene.obs_mask.shape == (N, V) and scene.obs_mask.dtype == \
        torch.bool
    torch.testing.assert_close(scene.pos.norm(dim=1).max(),
                               torch.tensor(1.0))
    torch.testing.assert_close(scene.normal.norm(dim=1), torch.ones(N))
    torch.testing.assert_close(scene.obs_dir.norm(dim=-1), torch.ones(N, V))
    assert bool((scene.obs_radiance[~scene.obs_mask] == 0).all())
    assert bool((scene.obs_radiance[scene.obs_mask] > 0).all())
    # every camera sees the object; it fills most of the image
    assert bool(scene.obs_mask.any(0).all())
    covered = (scene.images.sum(-1) > 0).float().mean((1, 2))
    assert bool((covered > 0.4).all())


def test_deterministic_and_seeded():
    a = svbrdf_scene(render_images=False, **{**SMALL, 'num_views': 3})
    b = svbrdf_scene(render_images=False, **{**SMALL, 'num_views': 3})
    for key in a.keys():
        assert torch.equal(a[key], b[key]), key
    c = svbrdf_scene(render_images=False, seed=1,
                     **{**SMALL, 'num_views': 3})
    assert not torch.equal(a.base_color, c.base_color)


@pytest.mark.parametrize('materials', ['metals', 'dielectrics', 'mixed'])
def test_material_ranges(materials):
    d = svbrdf_scene(materials=materials, roughness_range=(0.3, 0.5),
                     render_images=False, **{**SMALL, 'num_views': 2})
    assert float(d.roughness.min()) >= 0.3 - 1e-6
    assert float(d.roughness.max()) <= 0.5 + 1e-6
    assert float(d.base_color.min()) >= 0 and float(d.base_color.max()) <= 1
    assert float(d.roughness.std()) > 0.01  # spatially varying
    if materials == 'metals':
        assert bool((d.metallic == 1).all())
        # coloured metals: channels differ
        assert float((d.base_color.max(1).values
                      - d.base_color.min(1).values).mean()) > 0.05
    elif materials == 'dielectrics':
        assert bool((d.metallic == 0).all())
    else:
        assert float(d.metallic.min()) < 0.05 and float(d.metallic.max()) \
            > 0.95


def test_visibility_on_a_sphere_is_analytic(scene):
    # On an inscribed polyhedron the tangent plane of a vertex supports the
    # mesh: camera v sees vertex i iff n . (c - p) > 0 and it projects
    # into the image. Ties are allowed at the silhouette only.
    pos, normal = scene.pos.double(), scene.normal.double()
    c = camera_centers(scene.extrinsics.double())
    facing = ((c[None] - pos[:, None]) * normal[:, None]).sum(-1)
    facing = facing / (c[None] - pos[:, None]).norm(dim=-1)
    u, v, z = project(scene, pos)
    inside = (u >= 0) & (u < 40) & (v >= 0) & (v < 40) & (z > 0)
    analytic = (facing > 0) & inside
    differ = analytic != scene.obs_mask
    assert bool((facing[differ].abs() < 1e-3).all())
    assert int(differ.sum()) <= 2


def test_images_match_observations():
    d = svbrdf_scene(materials='dielectrics', roughness_range=(0.6, 0.7),
                     image_specular_samples=64, image_light_samples=64,
                     resolution=3, num_views=3, image_size=(96, 96),
                     envmap_size=(32, 64))
    pos = d.pos.double()
    u, v, _ = project(d, pos)
    cos = (d.obs_dir.double() * d.normal.double()[:, None]).sum(-1)
    pick = d.obs_mask & (cos > 0.5)
    i, view = pick.nonzero(as_tuple=True)
    row = v[i, view].floor().long()
    col = u[i, view].floor().long()
    pixel = d.images[view, row, col].double()
    obs = d.obs_radiance[i, view].double()
    rel = ((pixel - obs).abs() / obs).mean(-1)
    assert len(rel) > 200
    assert float(rel.median()) < 0.02 and float(rel.quantile(0.95)) < 0.06


def test_look_at_cameras():
    pos = torch.tensor([[3.0, 0.0, 0.0], [0.0, 0.0, 2.0], [1.0, -2.0, 1.0]],
                       dtype=torch.float64)
    K, E = look_at_cameras(pos, fov_degrees=60.0, image_size=(30, 50))
    R = E[:, :, :3]
    torch.testing.assert_close(R @ R.transpose(1, 2),
                               torch.eye(3, dtype=torch.float64).expand(3, 3,
                                                                        3))
    torch.testing.assert_close(torch.linalg.det(R),
                               torch.ones(3, dtype=torch.float64))
    torch.testing.assert_close(camera_centers(E), pos)
    assert math.isclose(float(K[0, 1, 1]), 15 / math.tan(math.radians(30)))
    # the target at the image centre; world up goes up on screen
    up = torch.tensor([[0.0, 0.0, 0.3]], dtype=torch.float64)
    points = torch.cat([torch.zeros(1, 3, dtype=torch.float64), up])
    cam = torch.einsum('vij,nj->vni', R, points) + E[:, None, :, 3]
    uv = torch.einsum('vij,vnj->vni', K, cam)
    uv = uv[..., :2] / uv[..., 2:]
    torch.testing.assert_close(uv[:, 0], torch.tensor([[25.0, 15.0]] * 3,
                                                      dtype=torch.float64))
    assert bool((uv[[0, 2], 1, 1] < 15).all())


def test_upper_hemisphere_and_mesh_inputs():
    import trimesh
    box = trimesh.creation.box(extents=(1.0, 2.0, 0.5))
    box = box.subdivide().subdivide()
    d = svbrdf_scene(shape=(np.asarray(box.vertices), np.asarray(box.faces)),
                     upper_hemisphere=True, render_images=False,
                     num_views=5, image_size=(32, 32), envmap_size=(16, 32))
    c = camera_centers(d.extrinsics)
    assert bool((c[:, 2] > 0).all())
    torch.testing.assert_close(d.pos.norm(dim=1).max(), torch.tensor(1.0))
    # flat faces: occluded (far side) vertices are masked out
    assert 0.1 < float(d.obs_mask.float().mean()) < 0.6
    env = torch.ones(8, 16, 3)
    d2 = svbrdf_scene(envmap=env, render_images=False,
                      **{**SMALL, 'num_views': 2})
    torch.testing.assert_close(d2.envmap, env)


def test_uv_sphere_carries_its_uvs():
    from tg_intrinsic.geometry.texture import uv_sphere
    d = svbrdf_scene('uv_sphere', render_images=False,
                     **{**SMALL, 'resolution': 4, 'num_views': 3})
    pos, face, uv = uv_sphere(4, 8)
    assert torch.equal(d.face, face)
    torch.testing.assert_close(d.pos, pos.float())
    torch.testing.assert_close(d.uv, uv.float())
    torch.testing.assert_close(d.normal, d.pos)  # exact, not faceted
    assert 'uv' not in svbrdf_scene(render_images=False,
                                    **{**SMALL, 'num_views': 3})


@pytest.mark.skipif(not os.path.exists(os.path.join(MESHES, 'koala.obj')),
                    reason='real meshes are not available')
def test_real_mesh():
    d = svbrdf_scene(shape=os.path.join(MESHES, 'koala.obj'), num_views=4,
                     image_size=(64, 64), render_images=False,
                     specular_samples=8, light_samples=8)
    assert d.pos.size(0) > 10000
    seen = d.obs_mask.float().mean()
    assert 0.05 < float(seen) < 0.6


def test_bad_input():
    with pytest.raises(ValueError, match='materials'):
        svbrdf_scene(materials='wood', **SMALL)
    with pytest.raises(ValueError, match='roughness_range'):
        svbrdf_scene(roughness_range=(0.5, 1.2), **SMALL)
    with pytest.raises(ValueError, match='envmap'):
        svbrdf_scene(envmap=torch.full((8, 16, 3), float('nan')), **SMALL)
    with pytest.raises(ValueError, match='num_views'):
        svbrdf_scene(**{**SMALL, 'num_views': 0})
    with pytest.raises(ValueError, match='shape'):
        svbrdf_scene(shape='/nonexistent/mesh.obj', **SMALL)
    pos = torch.rand(4, 3, dtype=torch.float64)
    pos[0, 0] = float('nan')
    with pytest.raises(ValueError, match='vertices'):
        svbrdf_scene(shape=(pos, torch.tensor([[0], [1], [2]])), **SMALL)
    with pytest.raises(ValueError, match='camera_distance'):
        svbrdf_scene(camera_distance=0.5, **SMALL)
    # a field of view too narrow to contain a vertex: the documented error
    with pytest.raises(ValueError, match='see no vertex'):
        svbrdf_scene(fov_degrees=0.01, **SMALL)
