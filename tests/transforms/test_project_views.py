"""ProjectViews: per-point observations from calibrated images."""
import math
import warnings

import pytest
import torch
from torch_geometric.data import Data

from tg_intrinsic.geometry.appearance.cameras import camera_centers, project
from tg_intrinsic.geometry.appearance.sh import fibonacci_sphere
from tg_intrinsic.transforms import ProjectViews

SIZE = 96


def look_at(eye, target=(0.0, 0.0, 0.0), fov=40.0, size=SIZE):
    """OpenCV camera at `eye` looking at `target` (brute-force reference
    built here, independent of the library's camera helpers)."""
    eye = torch.tensor(eye, dtype=torch.float64)
    forward = torch.tensor(target, dtype=torch.float64) - eye
    forward = forward / forward.norm()
    up = torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64)
    if abs(float(forward @ up)) > 0.99:
        up = torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64)
    right = torch.linalg.cross(forward, up)
    right = right / right.norm()
    down = torch.linalg.cross(forward, right)
    rotation = torch.stack([right, down, forward])
    focal = size / 2 / math.tan(math.radians(fov) / 2)
    K = torch.tensor([[focal, 0, size / 2], [0, focal, size / 2], [0, 0, 1]],
                     dtype=torch.float64)
    return K, torch.cat([rotation, -(rotation @ eye)[:, None]], 1)


def sphere_scene(num_points=2000, eyes=((3.0, 0.5, 0.8), (-0.4, 3.2, -1.0),
                                       (0.3, -0.2, -3.5))):
    pos = fibonacci_sphere(num_points)
    cams = [look_at(e) for e in eyes]
    K = torch.stack([c[0] for c in cams])
    E = torch.stack([c[1] for c in cams])
    # a smooth radiance field painted on the image plane: u + 2 v + 1
    v, u = torch.meshgrid(torch.arange(SIZE, dtype=torch.float64) + 0.5,
                          torch.arange(SIZE, dtype=torch.float64) + 0.5,
                          indexing='ij')
    plane = (u + 2 * v + 1)[None, ..., None].expand(len(eyes), -1, -1, 3)
    images = plane * torch.tensor([1.0, 0.5, 0.25], dtype=torch.float64)
    return Data(pos=pos, normal=pos.clone(), images=images.contiguous(),
                intrinsics=K, extrinsics=E)


def test_visibility_matches_the_analytic_sphere():
    data = sphere_scene()
    out = ProjectViews()(data)
    assert out.obs_mask.shape == (2000, 3) and out.obs_mask.dtype == torch.bool
    centres = camera_centers(data.extrinsics)
    facing = ((centres[None] - data.pos[:, None]) * data.pos[:, None]).sum(-1)
    # analytic: visible iff in front of the tangent plane (the cameras see
    # the whole sphere); allow disagreement only near the silhouette
    cos = facing / (centres[None] - data.pos[:, None]).norm(dim=-1)
    clear = cos.abs() > 0.15
    assert torch.equal(out.obs_mask[clear], (facing > 0)[clear])
    assert 'obs_mask' not in data  # the input is not mutated


def test_radiance_and_directions():
    data = sphere_scene()
    out = ProjectViews()(data)
    uv, _ = project(data.pos, data.intrinsics, data.extrinsics)
    want = (uv[..., 0] + 2 * uv[..., 1] + 1).t()  # exact for a linear image
    mask = out.obs_mask
    inner = mask & (uv[..., 0].t() > 1) & (uv[..., 1].t() > 1) \
        & (uv[..., 0].t() < SIZE - 1) & (uv[..., 1].t() < SIZE - 1)
    assert torch.allclose(out.obs_radiance[..., 0][inner], want[inner])
    assert torch.allclose(out.obs_radiance[..., 1][inner],
                          0.5 * want[inner])
    assert bool((out.obs_radiance[~mask] == 0).all())
    centres = camera_centers(data.extrinsics)
    d = centres[None] - data.pos[:, None]
    assert torch.allclose(out.obs_dir, d / d.norm(dim=-1, keepdim=True))


def test_occluder_hides_points_behind_it():
    """A small disc of points between camera 0 and the sphere hides the
    sphere points behind it (brute-force: ray from point to camera)."""
    data = sphere_scene(eyes=((3.0, 0.0, 0.0), ))
    grid = torch.stack(torch.meshgrid(torch.linspace(-0.3, 0.3, 25),
                                      torch.linspace(-0.3, 0.3, 25),
                                      indexing='ij'), -1).reshape(-1, 2)
    disc = torch.cat([torch.full((625, 1), 1.8), grid], 1).double()
    normal = torch.tensor([[1.0, 0.0, 0.0]], dtype=torch.float64).expand(
        625, 3)
    both = Data(pos=torch.cat([data.pos, disc]),
                normal=torch.cat([data.normal, normal]), images=data.images,
                intrinsics=data.intrinsics, extrinsics=data.extrinsics)
    out = ProjectViews()(both)
    sphere_mask = out.obs_mask[:2000, 0]
    # brute force: the segment point -> camera crosses the plane x = 1.8
    # inside the square |y|, |z| < 0.3
    eye = torch.tensor([3.0, 0.0, 0.0], dtype=torch.float64)
    p = data.pos
    t = (1.8 - p[:, 0]) / (eye[0] - p[:, 0])
    hit = p + t[:, None] * (eye - p)
    blocked = (t > 0) & (t < 1) & (hit[:, 1].abs() < 0.3) \
        & (hit[:, 2].abs() < 0.3)
    margin = (hit[:, 1].abs() - 0.3).abs().minimum(
        (hit[:, 2].abs() - 0.3).abs()) > 0.05
    to_eye = eye - p
    facing = (to_eye * p).sum(-1) / to_eye.norm(dim=-1) > 0.15
    check = facing & margin
    assert blocked[check].sum() > 30
    assert torch.equal(sphere_mask[check], ~blocked[check])


def test_bad_and_imperfect_input():
    data = sphere_scene()
    with pytest.raises(ValueError, match='images'):
        ProjectViews()(Data(pos=data.pos))
    with pytest.raises(ValueError, match=r'\[V, 3, 4\]'):
        ProjectViews()(Data(pos=data.pos, images=data.images,
                            intrinsics=data.intrinsics,
                            extrinsics=data.extrinsics[:, :, :3]))
    with pytest.raises(ValueError, match='2 images but 3 cameras'):
        ProjectViews()(Data(pos=data.pos, images=data.images[:2],
                            intrinsics=data.intrinsics,
                            extrinsics=data.extrinsics))
    with pytest.raises(ValueError, match='floating-point'):
        ProjectViews()(Data(pos=data.pos, images=data.images.to(torch.uint8),
                            intrinsics=data.intrinsics,
                            extrinsics=data.extrinsics))
    bad = data.images.clone()
    bad[0, 3, 3, 0] = math.inf
    with pytest.raises(ValueError, match='infinite or negative'):
        ProjectViews()(Data(pos=data.pos, images=bad,
                            intrinsics=data.intrinsics,
                            extrinsics=data.extrinsics))
    with pytest.raises(ValueError, match='depth_tolerance'):
        ProjectViews(depth_tolerance=-1)
    # NaN pixels: those observations are masked, with a warning
    holes = data.images.clone()
    holes[:, 40:56, 40:56] = math.nan
    with pytest.warns(UserWarning, match='NaN pixels'):
        out = ProjectViews()(Data(pos=data.pos, normal=data.normal,
                                  images=holes, intrinsics=data.intrinsics,
                                  extrinsics=data.extrinsics))
    assert bool(torch.isfinite(out.obs_radiance).all())
    assert out.obs_mask.sum() < ProjectViews()(data).obs_mask.sum()
    # 8-bit-like images warn
    ldr = (data.images / data.images.max() * 255).round() / 255
    with pytest.warns(UserWarning, match='8-bit or clipped'):
        ProjectViews()(Data(pos=data.pos, images=ldr,
                            intrinsics=data.intrinsics,
                            extrinsics=data.extrinsics))
    # a camera turned away sees nothing: warned and masked; all turned
    # away is an error
    K, E = data.intrinsics.clone(), data.extrinsics.clone()
    E[1, :, :3] = -E[1, :, :3]  # points behind camera 1
    E[1, :, 3] = -E[1, :, 3]
    E[1, 0] = -E[1, 0]  # keep a rotation (det +1)
    with pytest.warns(UserWarning, match=r'camera\(s\) \[1\] see no point'):
        out = ProjectViews()(Data(pos=data.pos, normal=data.normal,
                                  images=data.images, intrinsics=K,
                                  extrinsics=E))
    assert not bool(out.obs_mask[:, 1].any())
    far = E.clone()
    far[:, 2, 3] = -10.0  # every point behind every camera
    with pytest.raises(ValueError, match='no camera sees any point'):
        with warnings.catch_warnings():
            warnings.simplefilter('ignore')
            ProjectViews()(Data(pos=data.pos, images=data.images,
                                intrinsics=K, extrinsics=far))
    # points seen by no view are counted in a warning
    one = sphere_scene(eyes=((3.0, 0.0, 0.0), ))
    with pytest.warns(UserWarning, match='seen by no view'):
        out = ProjectViews()(one)
    assert (~out.obs_mask.any(1)).sum() > 500


def test_photographs_streamed_from_disk_a_few_views_at_a_time(monkeypatch):
    """Photographs in a PhotographStack are read a block of views at a
    time, each once: the observations equal those of the tensor, whatever
    the block size."""
    from tg_intrinsic.geometry.appearance import PhotographStack
    from tg_intrinsic.transforms import project_views
    data = sphere_scene()
    whole = ProjectViews()(data)
    reads = []

    def read(view):
        reads.append(view)
        return data.images[view].float()

    for pixels in (SIZE * SIZE, 2 * SIZE * SIZE):
        monkeypatch.setattr(project_views, 'VIEW_PIXELS', pixels)
        reads.clear()
        streamed = data.clone()
        streamed.images = PhotographStack(read, 3, (SIZE, SIZE))
        out = ProjectViews()(streamed)
        assert sorted(reads) == [0, 1, 2]
        # the stack holds float32 photographs; the tensor float64 ones
        expected = ProjectViews()(data.clone().update(
            {'images': data.images.float()}))
        for key in ('obs_mask', 'obs_dir', 'obs_radiance'):
            assert torch.equal(out[key], expected[key])
        assert torch.equal(out.obs_mask, whole.obs_mask)
    bad = data.clone()
    bad.images = PhotographStack(lambda v: -data.images[v].float(), 3,
                                 (SIZE, SIZE))
    with pytest.raises(ValueError, match='infinite or negative'):
        ProjectViews()(bad)
