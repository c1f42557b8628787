"""Shared helpers for testing symmetries directly (as e3nn's
``assert_equivariant``): gauge changes of tangent frames and of the
quantities measured in them, and rotations of space."""
import torch


def rotate_frames(frame, angle):
    """Frames ``[N, 3, 3]`` (rows e_u, e_v, n) turned about their normals
    by ``angle[i]``."""
    c, s = torch.cos(angle)[:, None], torch.sin(angle)[:, None]
    e_u = c * frame[:, 0] + s * frame[:, 1]
    e_v = -s * frame[:, 0] + c * frame[:, 1]
    return torch.stack([e_u, e_v, frame[:, 2]], 1)


def rotate_vectors(v, angle):
    """Coordinates ``[..., 2]`` of the same tangent vectors in frames turned
    by ``angle`` (per point, the first dimension)."""
    shape = (-1, ) + (1, ) * (v.dim() - 2)
    c, s = torch.cos(angle).view(shape), torch.sin(angle).view(shape)
    return torch.stack([c * v[..., 0] + s * v[..., 1],
                        -s * v[..., 0] + c * v[..., 1]], -1)


def rotate_streams(x, angle):
    """Complex features ``[N, M + 1, C]`` of rotation orders 0..M in frames
    turned by ``angle``: order m is multiplied by e^{-i m angle}."""
    orders = torch.arange(x.size(1), dtype=angle.dtype, device=angle.device)
    return x * torch.polar(torch.ones_like(angle)[:, None],
                           -angle[:, None] * orders)[:, :, None]


def gauge_change(edge_index, logmap, transport, angle):
    """Log maps ``(r, theta)`` and transport angles of a graph after frame
    i turns by ``angle[i]``: angles measured in it drop by ``angle[i]``."""
    j, i = edge_index
    theta = torch.where(logmap[:, 0] > 0, logmap[:, 1] - angle[i], 0.0)
    return (torch.stack([logmap[:, 0], theta], 1),
            transport - angle[i] + angle[j])


def random_rotation(dtype=torch.float64, seed=0):
    """A random rotation of space (det +1), reproducible by seed."""
    g = torch.Generator().manual_seed(seed)
    q, _ = torch.linalg.qr(torch.randn(3, 3, generator=g, dtype=dtype))
    return q * torch.sign(torch.linalg.det(q))
