"""Shared fixtures of the capture readers' tests: one small synthetic
capture, and the same read back from a native scene folder."""
import pytest
import torch

from tg_intrinsic.datasets import svbrdf_scene
from tg_intrinsic.io import read_scene
from tg_intrinsic.io.capture_writer import write_capture


@pytest.fixture(scope='module')
def capture():
    return svbrdf_scene('sphere', num_views=5, image_size=(20, 24),
                        materials='metals', seed=1, resolution=1)

@pytest.fixture(scope='module')
def native(capture, tmp_path_factory):
    folder = tmp_path_factory.mktemp('native')
    write_capture(folder, capture, 'native')
    return read_scene(folder, dtype=torch.float64)
