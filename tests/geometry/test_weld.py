import numpy as np
import pytest
import torch
import trimesh

from tg_intrinsic.geometry import weld_vertices


def soup():
    """An icosphere as a triangle soup: every face its own 3 vertices."""
    m = trimesh.creation.icosphere(subdivisions=1)
    pos = torch.from_numpy(np.asarray(m.vertices)[np.asarray(m.faces)]
                           .reshape(-1, 3))
    face = torch.arange(pos.size(0)).view(-1, 3).t()
    return pos, face, m


def test_welds_a_triangle_soup():
    pos, face, m = soup()
    new_pos, new_face, inverse = weld_vertices(pos, face)
    # independent count: trimesh's exact merge
    ref = trimesh.Trimesh(pos.numpy(), face.t().numpy(), process=False)
    ref.merge_vertices(merge_tex=True, merge_norm=True, digits_vertex=12)
    assert new_pos.size(0) == len(ref.vertices) == len(m.vertices) == 42
    assert new_face.shape == face.shape
    assert torch.equal(new_face, inverse[face])
    assert torch.equal(new_pos[inverse], pos)  # every vertex kept its spot
    # faces now share vertices: a closed mesh, each edge in two faces
    welded = trimesh.Trimesh(new_pos.numpy(), new_face.t().numpy(),
                             process=False)
    assert welded.is_watertight
    # new vertices are numbered in order of first occurrence
    first = [int((inverse == k).nonzero()[0]) for k in range(42)]
    assert first == sorted(first)


def test_no_duplicates_is_identity():
    m = trimesh.creation.icosphere(subdivisions=1)
    pos = torch.from_numpy(np.asarray(m.vertices)).float()
    face = torch.from_numpy(np.asarray(m.faces)).t().contiguous()
    new_pos, new_face, inverse = weld_vertices(pos, face)
    assert torch.equal(new_pos, pos) and torch.equal(new_face, face)
    assert torch.equal(inverse, torch.arange(pos.size(0)))
    assert new_pos.dtype == torch.float32


def test_tolerance_and_signed_zero():
    pos, face, _ = soup()
    gen = torch.Generator().manual_seed(0)
    noisy = pos + 1e-9 * torch.randn(pos.shape, dtype=pos.dtype,
                                     generator=gen)
    assert weld_vertices(noisy, face)[0].size(0) == pos.size(0)
    assert weld_vertices(noisy, face, tolerance=1e-6)[0].size(0) == 42
    # -0.0 and 0.0 are the same position
    p = torch.tensor([[0., 0, 0], [1, 0, 0], [0, 1, 0], [-0., 0, 0]])
    f = torch.tensor([[0, 1, 2], [3, 2, 1]]).t()
    assert weld_vertices(p, f)[2].tolist() == [0, 1, 2, 0]


def test_bad_input():
    pos, face, _ = soup()
    with pytest.raises(ValueError, match=r'\[3, F\]'):
        weld_vertices(pos, face.t())
    with pytest.raises(ValueError, match='tolerance'):
        weld_vertices(pos, face, tolerance=-1)
