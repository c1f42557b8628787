"""Shared helpers of the point-cloud operator tests."""
import pytest
import torch

from tg_intrinsic.geometry import knn, tangent_frames
from tg_intrinsic.geometry.pointcloud.mls import mls_grad_div
from tests.conftest import fibonacci_sphere


def build(pos, normal, k=20, batch=None, **kwargs):
    frame = tangent_frames(normal)
    edge_index = knn(pos, k, batch, loop=True)
    gw, dw = mls_grad_div(pos, frame, edge_index, batch, **kwargs)
    return frame, edge_index, gw, dw


def tangential(frame, ambient):
    """Coordinates of the tangential part of ambient vectors in the frame."""
    return torch.stack([(frame[:, 0] * ambient).sum(-1),
                        (frame[:, 1] * ambient).sum(-1)], -1)


@pytest.fixture(scope='module')
def sphere_ops():
    pos = fibonacci_sphere(3000)
    return (pos, ) + build(pos, pos, normalized=True)

