"""The rasteriser against per-pixel ray casting in numpy, cameras that look
away, point visibility between two layers, and bad input."""
import numpy as np
import pytest
import torch

from tg_intrinsic.geometry.appearance.cameras import camera_centers
from tg_intrinsic.geometry.appearance.raster import (point_visibility,
                                                     rasterize)

from tests.geometry.appearance.scenes import D64, camera, small_mesh


def moller_trumbore(d, A, B, C):
    """Rays from the origin along ``d`` (..., 3) against triangle (A, B,
    C): the barycentrics (u, v) of the hit and its parameter t (NaN or
    infinite for rays parallel to the triangle)."""
    e1, e2 = B - A, C - A
    p = np.cross(d, e2)
    det = p @ e1
    with np.errstate(divide='ignore', invalid='ignore'):
        u = (p * (-A)).sum(-1) / det
        q = np.cross(-A, e1)
        v = (q * d).sum(-1) / det
        t = (q @ e2) / det
    return u, v, t


def brute_force_raster(V, F, K, E, height, width, near=1e-6):
    """Moller-Trumbore of every pixel-centre ray with every triangle."""
    cam = (V @ E[:, :3].T + E[:, 3]).numpy()
    Kinv = np.linalg.inv(K.numpy())
    jj, ii = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    d = np.stack([jj, ii, np.ones_like(jj)], -1) @ Kinv.T  # d_z = 1
    best = np.full((height, width), np.inf)
    fid = np.full((height, width), -1)
    edge = np.full((height, width), np.inf)
    for f, (a, b, c) in enumerate(F.t().numpy()):
        u, v, t = moller_trumbore(d, cam[a], cam[b], cam[c])
        hit = (u >= 0) & (v >= 0) & (u + v <= 1) & (t >= near)
        closer = hit & (t < best)
        best[closer] = t[closer]
        fid[closer] = f
        margin = np.minimum(np.minimum(u, v), 1 - u - v)
        edge = np.where(hit, np.minimum(edge, np.abs(margin)), edge)
    return fid, best, edge


def test_rasterize_matches_ray_casting():
    V, F = small_mesh()
    K, E = camera([0.3, -2.2, 1.0])
    face_id, bary, depth = rasterize(V, F, K, E, 40, 48)
    ref, ref_depth, edge = brute_force_raster(V, F, K, E, 40, 48)
    assert (ref >= 0).sum() > 200 and (ref == F.size(1) - 1).sum() > 20
    differ = face_id.numpy() != ref
    # only where the pixel centre is within 1e-6 of a triangle edge
    assert np.all(edge[differ] < 1e-6)
    same = ~differ & (ref >= 0)
    np.testing.assert_allclose(depth.numpy()[same], ref_depth[same],
                               rtol=1e-9)
    # the barycentrics rebuild the hit point on the ray
    cam = V @ E[:, :3].T + E[:, 3]
    corners = F.t()[face_id.clamp_min(0)]
    hit = (bary[..., None] * cam[corners]).sum(-2)
    u = K[0, 0] * hit[..., 0] / hit[..., 2] + K[0, 2]
    v = K[1, 1] * hit[..., 1] / hit[..., 2] + K[1, 2]
    jj, ii = np.meshgrid(np.arange(48) + 0.5, np.arange(40) + 0.5)
    covered = face_id.numpy() >= 0
    np.testing.assert_allclose(u.numpy()[covered], jj[covered], atol=1e-8)
    np.testing.assert_allclose(v.numpy()[covered], ii[covered], atol=1e-8)
    assert np.all(np.isinf(depth.numpy()[~covered]))


def test_rasterize_behind_camera_is_empty():
    V, F = small_mesh()
    K, E = camera([0.0, -3.0, 0.0], target=(0.0, -6.0, 0.0))
    face_id, _, depth = rasterize(V[:-3], F[:, :-1], K, E, 20, 24)
    assert bool((face_id == -1).all()) and bool(torch.isinf(depth).all())


def test_point_visibility_two_layers():
    # two parallel squares; the back one is hidden where the front one is
    quad = torch.tensor([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0.0]],
                        dtype=D64)
    front = quad * torch.tensor([0.5, 0.5, 1], dtype=D64) \
        + torch.tensor([0, 0, 1.0], dtype=D64)
    V = torch.cat([quad, front])
    F = torch.tensor([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]]).t()
    K, E = camera([0.0, 0.0, 5.0], focal=30.0, size=(32, 32))
    pts = torch.tensor([[0.0, 0.1, 0.0], [0.9, 0.9, 0.0], [0.1, 0.2, 1.0],
                        [0.0, 0.0, 9.0], [30.0, 0.0, 0.0]], dtype=D64)
    vis = point_visibility(pts, V, F, K[None], E[None], 32, 32)[:, 0]
    assert vis.tolist() == [False, True, True, False, False]
    torch.testing.assert_close(camera_centers(E[None])[0],
                               torch.tensor([0.0, 0.0, 5.0], dtype=D64))


def brute_force_visibility(points, V, F, K, E, height, width):
    """Every point against every triangle: hidden iff the segment from the
    camera centre to it crosses a triangle before it (Moller-Trumbore)."""
    out = np.zeros((len(points), len(K)), dtype=bool)
    for v in range(len(K)):
        cam = (V @ E[v, :, :3].T + E[v, :, 3]).numpy()
        pts = (points @ E[v, :, :3].T + E[v, :, 3]).numpy()
        uv = pts @ K[v].numpy().T
        inside = (pts[:, 2] > 1e-6) & (uv[:, 0] / uv[:, 2] >= 0) & (
            uv[:, 0] / uv[:, 2] < width) & (uv[:, 1] / uv[:, 2] >= 0) & (
            uv[:, 1] / uv[:, 2] < height)
        hidden = np.zeros(len(pts), dtype=bool)
        for a, b, c in F.t().numpy():
            # the segment from the camera centre to the point: t in (0, 1)
            u, w, t = moller_trumbore(pts, cam[a], cam[b], cam[c])
            hidden |= (u >= 0) & (w >= 0) & (u + w <= 1) & (t > 0) & (
                t < 1 - 1e-9)
        out[:, v] = inside & ~hidden
    return out


def test_many_cameras_cast_in_parallel_agree_with_brute_force():
    """From 16 cameras on the cameras are cast in parallel; both paths
    agree with brute force, and 'needed' casts only its pairs."""
    import trimesh
    from tg_intrinsic.geometry.appearance.cameras import look_at_cameras
    sphere = trimesh.creation.icosphere(2)
    V = torch.tensor(sphere.vertices, dtype=D64)
    F = torch.tensor(sphere.faces).t().contiguous()
    g = torch.Generator().manual_seed(0)
    points = torch.cat([V * 1.001, V[:40] * 0.5,
                        torch.randn(30, 3, generator=g, dtype=D64) * 1.5])
    directions = torch.nn.functional.normalize(
        torch.randn(20, 3, generator=g, dtype=D64), dim=1)
    K, E = look_at_cameras(4 * directions, fov_degrees=50,
                           image_size=(48, 48))
    parallel = point_visibility(points, V, F, K, E, 48, 48)
    one_by_one = torch.cat([point_visibility(points, V, F, K[v:v + 1],
                                             E[v:v + 1], 48, 48)
                            for v in range(20)], 1)
    assert torch.equal(parallel, one_by_one)
    assert np.array_equal(parallel.numpy(), brute_force_visibility(
        points, V, F, K, E, 48, 48))
    assert 0.2 < parallel.double().mean() < 0.8
    needed = torch.rand(len(points), 20, generator=g) > 0.5
    some = point_visibility(points, V, F, K, E, 48, 48, needed=needed)
    assert torch.equal(some, parallel & needed)
    with pytest.raises(ValueError, match=r"'needed' must be a bool tensor "
                       r"of shape \[\d+, 20\]"):
        point_visibility(points, V, F, K, E, 48, 48, needed=needed[:5])


def test_bad_input():
    V, F = small_mesh()
    K, E = camera([0.3, -2.2, 1.0], size=(24, 24))
    with pytest.raises(ValueError, match='face'):
        rasterize(V, F.t(), K, E, 24, 24)
    with pytest.raises(ValueError, match='intrinsics'):
        rasterize(V, F, K[:2], E, 24, 24)
    with pytest.raises(ValueError, match='extrinsics'):
        bad = E.clone()
        bad[:, :3] *= 2
        rasterize(V, F, K, bad, 24, 24)
    with pytest.raises(ValueError, match='points'):
        point_visibility(V[:, :2], V, F, K[None], E[None], 24, 24)
