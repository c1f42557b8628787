"""The scene of a ``tg_intrinsic.datasets.svbrdf_scene`` capture (metals)
in Mitsuba 3: the mesh with per-vertex ``principled`` parameters through
``mesh_attribute`` textures, the environment map in Mitsuba's convention
and one perspective sensor per camera. Shared by
``benchmarks/svbrdf_mitsuba.py`` and the renderer's Mitsuba oracle test.
"""
import math

import numpy as np
import torch

from tg_intrinsic.geometry.appearance.envmap import equirect_lookup

# Mitsuba's envmap frame has +y up and looks its map up with row
# coordinate theta / pi * (H - 1); ours has +z up and theta / pi * H - 1/2
# (columns agree). This rotation takes Mitsuba's frame to ours.
TO_OUR_FRAME = [[0, 0, 1, 0], [-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 0, 1]]


def mitsuba_bitmap(envmap):
    """Our map resampled to Mitsuba's rows (pixel centres on the poles)."""
    height, width = envmap.shape[:2]
    theta = torch.arange(height + 1, dtype=torch.float64) * math.pi / height
    phi = (torch.arange(width, dtype=torch.float64) + 0.5) * (
        2 * math.pi / width) - math.pi
    theta, phi = torch.meshgrid(theta, phi, indexing='ij')
    dirs = torch.stack([theta.sin() * phi.cos(), theta.sin() * phi.sin(),
                        theta.cos()], -1)
    return equirect_lookup(envmap.double(), dirs).float().numpy()


def build_scene(mi, data, envmap, image_size, spp):
    n = data.num_nodes
    bsdf = mi.load_dict({
        'type': 'principled', 'metallic': 1.0,
        'base_color': {'type': 'mesh_attribute', 'name': 'vertex_base'},
        'roughness': {'type': 'mesh_attribute', 'name': 'vertex_rough'}})
    props = mi.Properties()
    props['bsdf'] = bsdf
    mesh = mi.Mesh('object', n, data.face.size(1), props=props,
                   has_vertex_normals=True)
    params = mi.traverse(mesh)
    params['vertex_positions'] = mi.Float(data.pos.float().flatten().numpy())
    params['faces'] = mi.UInt32(
        data.face.t().flatten().numpy().astype(np.uint32))
    params['vertex_normals'] = mi.Float(data.normal.float().flatten().numpy())
    params.update()
    mesh.add_attribute('vertex_base', 3, mi.Float(
        data.base_color.float().flatten().numpy()))
    mesh.add_attribute('vertex_rough', 1, mi.Float(
        data.roughness.float().numpy()))
    scene = mi.load_dict({
        'type': 'scene',
        'integrator': {'type': 'prb', 'max_depth': 2, 'hide_emitters': True},
        'light': {'type': 'envmap',
                  'bitmap': mi.Bitmap(mitsuba_bitmap(envmap)),
                  'to_world': mi.ScalarTransform4f(TO_OUR_FRAME)},
        'object': mesh})
    height, width = image_size
    sensors = []
    for K, E in zip(data.intrinsics.double(), data.extrinsics.double()):
        to_world = torch.eye(4, dtype=torch.float64)
        to_world[:3, :3] = E[:, :3].t()
        to_world[:3, 3] = -E[:, :3].t() @ E[:, 3]
        # OpenCV camera (x right, y down) -> Mitsuba's (x left, y up)
        to_world = to_world @ torch.diag(torch.tensor(
            [-1.0, -1.0, 1.0, 1.0], dtype=torch.float64))
        fov = math.degrees(2 * math.atan(width / (2 * float(K[0, 0]))))
        sensors.append(mi.load_dict({
            'type': 'perspective', 'fov': fov, 'fov_axis': 'x',
            'to_world': mi.ScalarTransform4f(to_world.tolist()),
            'sampler': {'type': 'independent', 'sample_count': spp},
            'film': {'type': 'hdrfilm', 'width': width, 'height': height,
                     'rfilter': {'type': 'box'}, 'pixel_format': 'rgb'}}))
    return scene, sensors
