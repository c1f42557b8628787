import numpy as np
import pytest
import torch

from tg_intrinsic.geometry.appearance import PhotographStack


def stack(views=4, size=(3, 5)):
    photographs = torch.rand(views, *size, 3)
    reads = []

    def read(view):
        reads.append(view)
        return photographs[view].numpy()
    return PhotographStack(read, views, size, [f'p{v}.png' for v in
                                               range(views)]), \
        photographs, reads


def test_answers_as_the_tensor_would():
    images, photographs, reads = stack()
    assert images.shape == photographs.shape and len(images) == 4
    assert images.size(0) == 4 and images.size() == photographs.size()
    assert images.dim() == 4 and images.dtype == torch.float32
    assert images.numel() == photographs.numel()
    assert reads == []  # nothing read until asked
    assert torch.equal(images[2], photographs[2]) and reads == [2]
    assert torch.equal(images[-1], photographs[-1])
    assert torch.equal(images[np.int64(1)], photographs[1])
    assert torch.equal(images[1:3], photographs[1:3])
    assert torch.equal(images[[3, 0]], photographs[[3, 0]])
    assert torch.equal(images[0, :2, 1:], photographs[0, :2, 1:])
    assert torch.equal(images[1:, 0], photographs[1:, 0])
    assert torch.equal(images.tensor(), photographs)
    assert torch.equal(torch.stack(list(images)), photographs)
    assert images.to('cpu') is images
    assert images.to(torch.float64).dtype == torch.float64
    assert '4 photographs of 3 x 5' in repr(images)


def test_bad_reads_are_named():
    images, _, _ = stack()
    with pytest.raises(IndexError, match='view 4 of a stack of 4'):
        images[4]
    wrong = PhotographStack(lambda v: np.zeros((2, 2, 3)), 2, (3, 5),
                            ['a.png', 'b.png'])
    with pytest.raises(ValueError, match=r"'a.png' read as \[2, 2, 3\]"):
        wrong[0]
