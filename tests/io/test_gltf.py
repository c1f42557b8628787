"""Textured glTF binaries and UVs read from mesh files: the .glb is read
back by pygltflib (a reader that is not ours, nor the writer's), its
textures decoded by Pillow and sampled at its own texture coordinates,
against the per-vertex maps it was made from."""
import io
import json

import numpy as np
import pytest
import torch
from scipy.spatial import cKDTree

from tg_intrinsic.io import read_face_uv, read_surface
from tg_intrinsic.io.gltf import (GLB_FILE, TEXTURE_FILES, srgb_encode,
                                  write_textured_model)


def icosphere(subdivisions=3):
    import trimesh
    sphere = trimesh.creation.icosphere(subdivisions)
    return (torch.tensor(sphere.vertices),
            torch.tensor(sphere.faces).t().contiguous())


def smooth_maps(pos):
    x, y, z = pos.t()
    return {'base_color': torch.stack([0.5 + 0.3 * x, 0.5 + 0.3 * y,
                                       0.5 + 0.3 * z], 1).numpy(),
            'metallic': (0.5 + 0.4 * x).numpy(),
            'roughness': (0.5 + 0.4 * z).numpy(),
            'entropy': (0.5 + 0.4 * y).numpy(),
            'roughness_std': (0.05 + 0.04 * x).numpy()}


def accessor(gltf, blob, index):
    """An accessor's array (float32 or index types, tightly packed)."""
    acc = gltf.accessors[index]
    view = gltf.bufferViews[acc.bufferView]
    dtype = {5126: np.float32, 5125: np.uint32, 5123: np.uint16}[
        acc.componentType]
    width = {'SCALAR': 1, 'VEC2': 2, 'VEC3': 3}[acc.type]
    start = (view.byteOffset or 0) + (acc.byteOffset or 0)
    return np.frombuffer(blob, dtype=dtype, count=acc.count * width,
                         offset=start).reshape(acc.count, width)


def image(gltf, blob, texture_index):
    from PIL import Image
    source = gltf.images[gltf.textures[texture_index].source]
    view = gltf.bufferViews[source.bufferView]
    data = blob[(view.byteOffset or 0):(view.byteOffset or 0)
                + view.byteLength]
    assert source.mimeType == 'image/png'
    return np.asarray(Image.open(io.BytesIO(data))).astype(np.float64) / 255


def srgb_decode(encoded):
    return np.where(encoded <= 0.04045, encoded / 12.92,
                    ((encoded + 0.055) / 1.055) ** 2.4)


@pytest.mark.parametrize('given_uv', [False, True])
def test_glb_holds_the_pbr_material_and_the_maps(tmp_path, given_uv):
    import pygltflib
    pos, face = icosphere()
    maps = smooth_maps(pos)
    face_uv = None
    if given_uv:  # the sphere's spherical UVs, cut at a seam per triangle
        from tg_intrinsic.geometry import uv_atlas
        face_uv = uv_atlas(pos, face)
    info = write_textured_model(str(tmp_path), pos, face, maps, 256,
                                face_uv=face_uv, normal=pos)
    assert info['uv'] == ('mesh' if given_uv else 'xatlas')
    assert info['size'] == 256 and 0.3 < info['coverage'] < 1
    assert sorted(info['files']) == sorted(
        str(tmp_path / n) for n in list(TEXTURE_FILES.values()) + [GLB_FILE])
    gltf = pygltflib.GLTF2().load(str(tmp_path / GLB_FILE))
    blob = gltf.binary_blob()
    material = gltf.materials[0]
    pbr = material.pbrMetallicRoughness
    assert pbr.metallicFactor == 1 and pbr.roughnessFactor == 1
    assert pbr.baseColorFactor == [1, 1, 1, 1]
    primitive = gltf.meshes[0].primitives[0]
    assert primitive.material == 0
    xyz = accessor(gltf, blob, primitive.attributes.POSITION)
    uv = accessor(gltf, blob, primitive.attributes.TEXCOORD_0)
    triangles = accessor(gltf, blob, primitive.indices).reshape(-1, 3)
    assert len(triangles) == face.size(1)
    # every glTF vertex is one of ours (seams split them)
    tree_distance, vertex = cKDTree(pos.numpy()).query(xyz)
    assert tree_distance.max() < 1e-6
    # the textures at the triangles' centroids in their own texture
    # coordinates (glTF: origin at the top left) hold the mean of the
    # corners' values, to the spread of a texel (the nearest texel centre
    # may lie a little off the centroid)
    base = image(gltf, blob, pbr.baseColorTexture.index)
    packed = image(gltf, blob, pbr.metallicRoughnessTexture.index)
    size = base.shape[0]
    centroid = uv[triangles].mean(1)
    rows = np.clip((centroid[:, 1] * size).astype(int), 0, size - 1)
    cols = np.clip((centroid[:, 0] * size).astype(int), 0, size - 1)
    corners = vertex[triangles]

    def close(found, values):
        error = np.abs(found - values[corners].mean(1))
        return np.quantile(error, 0.99) < 0.02 and np.median(error) < 0.005
    assert close(srgb_decode(base[rows, cols, :3]), maps['base_color'])
    assert close(packed[rows, cols, 1], maps['roughness'])
    assert close(packed[rows, cols, 2], maps['metallic'])
    assert np.all(packed[..., 0] == 1)  # no occlusion in the red channel
    # the PNGs beside it are the same textures
    from PIL import Image
    png = np.asarray(Image.open(tmp_path / TEXTURE_FILES['base_color'])
                     ).astype(np.float64) / 255
    assert np.abs(png - base[..., :3]).max() == 0
    entropy = np.asarray(Image.open(tmp_path / TEXTURE_FILES['entropy'])
                         ).astype(np.float64) / 255
    assert entropy.shape == (256, 256)
    # an uncertainty of 0-0.1 spans the grey values: 0.1 is white
    std = np.asarray(Image.open(tmp_path / TEXTURE_FILES['roughness_std'])
                     ).astype(np.float64) / 255
    assert close(std[rows, cols] / 10, maps['roughness_std'])
    # a second reader opens it with its material
    import trimesh
    loaded = trimesh.load(str(tmp_path / GLB_FILE), force='mesh')
    assert len(loaded.faces) == face.size(1)
    assert isinstance(loaded.visual.material,
                      trimesh.visual.material.PBRMaterial)


def test_srgb_encode_is_the_standard_curve():
    linear = np.array([0.0, 0.0031308, 0.18, 0.5, 1.0, 2.0, -1.0])
    encoded = srgb_encode(linear)
    np.testing.assert_allclose(srgb_decode(encoded), np.clip(linear, 0, 1),
                               atol=1e-12)
    assert abs(encoded[2] - 0.4613561295) < 1e-9  # 18% grey


OBJ_WITH_SEAM = """v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
vt 0 0
vt 0.5 0
vt 0.5 0.5
vt 0 0.5
vt 0.9 0.9
f 1/1 2/2 3/3
f 1/5 3/3 4/4
"""


def test_read_face_uv_keeps_a_uv_per_corner(tmp_path):
    path = tmp_path / 'seam.obj'
    path.write_text(OBJ_WITH_SEAM)
    pos, face, _ = read_surface(str(path))
    assert len(pos) == 4  # the seam does not split the surface
    face_uv = read_face_uv(str(path), pos, face)
    expected = np.array([[[0, 0], [0.9, 0.9]], [[0.5, 0], [0.5, 0.5]],
                         [[0.5, 0.5], [0, 0.5]]])
    np.testing.assert_array_equal(face_uv, expected)
    plain = tmp_path / 'plain.obj'
    plain.write_text('v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\n'
                     'f 1 3 4\n')
    pos, face, _ = read_surface(str(plain))
    assert read_face_uv(str(plain), pos, face) is None
    tiled = tmp_path / 'tiled.obj'
    tiled.write_text(OBJ_WITH_SEAM.replace('vt 0.9 0.9', 'vt 1.5 0.9'))
    pos, face, _ = read_surface(str(tiled))
    with pytest.raises(ValueError, match=r"outside \[0, 1\]"):
        read_face_uv(str(tiled), pos, face)


def test_a_scene_with_uvs_reads_them(tmp_path):
    from tg_intrinsic.datasets import svbrdf_scene
    from tg_intrinsic.io import read_scene, write_scene
    data = svbrdf_scene('sphere', num_views=2, image_size=(8, 8),
                        resolution=1)
    write_scene(str(tmp_path / 'scene'), data)
    assert 'face_uv' not in read_scene(str(tmp_path / 'scene'))
    # the same mesh as an OBJ with UVs, named in cameras.json
    pos, face = data.pos.double().numpy(), data.face.t().numpy()
    uv = 0.5 + 0.4 * pos[:, :2]
    lines = [f'v {x:.17g} {y:.17g} {z:.17g}' for x, y, z in pos]
    lines += [f'vt {u:.17g} {v:.17g}' for u, v in uv]
    lines += ['f ' + ' '.join(f'{i + 1}/{i + 1}' for i in f) for f in face]
    (tmp_path / 'scene' / 'mesh.obj').write_text('\n'.join(lines) + '\n')
    spec = json.loads((tmp_path / 'scene' / 'cameras.json').read_text())
    spec['geometry'] = 'mesh.obj'
    (tmp_path / 'scene' / 'cameras.json').write_text(json.dumps(spec))
    read = read_scene(str(tmp_path / 'scene'))
    assert read.face_uv.shape == (3, face.shape[0], 2)
    np.testing.assert_allclose(read.face_uv.numpy(),
                               uv[face].transpose(1, 0, 2), atol=1e-7)
