r"""The photographs of a capture, read from disk one at a time when a view
is asked for, so that a capture of a hundred 2-megapixel photographs is
never held in memory at once (2.3 GB in float32).
"""
import os.path as osp
from typing import Callable, List, Sequence, Tuple, Union

import numpy as np
import torch
from torch import Tensor

__all__ = ['PhotographStack']


class PhotographStack:
    r"""A read-only stack of :math:`V` photographs of :math:`H \times W`
    pixels that reads each from disk when indexed, in the place of the
    :math:`(V, H, W, 3)` tensor ``data.images``
    (:func:`~tg_intrinsic.io.read_capture` returns one;
    :class:`~tg_intrinsic.transforms.ProjectViews` reads a few views at a
    time from it). It answers ``shape``, ``size()``, ``dim()``,
    ``dtype``, ``device`` and ``len()`` as the tensor would; indexing with
    an integer gives a view's :math:`(H, W, 3)` float32 tensor, with a
    slice or a sequence of views their stack (a tuple indexes the views,
    then the pixels). :meth:`tensor` reads them
    all into one tensor.

    Args:
        read (callable): ``read(v)`` returns view :math:`v` as a float32
            :math:`(H, W, 3)` array or tensor.
        num_views (int): :math:`V`.
        size (tuple): :math:`(H, W)`.
        names (list of str, optional): A name per view (for messages and
            ``repr``). (default: :obj:`None`)
    """
    dtype = torch.float32
    device = torch.device('cpu')

    def __init__(self, read: Callable[[int], Union[np.ndarray, Tensor]],
                 num_views: int, size: Tuple[int, int],
                 names: Sequence[str] = None):
        self._read = read
        self.shape = torch.Size((int(num_views), int(size[0]), int(size[1]),
                                 3))
        self.names: List[str] = list(names) if names is not None else \
            [str(v) for v in range(num_views)]

    def __len__(self) -> int:
        return self.shape[0]

    def size(self, dim: int = None):
        return self.shape if dim is None else self.shape[dim]

    def dim(self) -> int:
        return 4

    def numel(self) -> int:
        return self.shape.numel()

    def __getitem__(self, index) -> Tensor:
        if isinstance(index, tuple):  # views first, then within them
            views, rest = index[0], index[1:]
            if isinstance(views, (int, np.integer)):
                return self[views][rest]
            return self[views][(slice(None), ) + rest]
        if isinstance(index, (int, np.integer)) or (
                isinstance(index, Tensor) and index.dim() == 0):
            view = int(index)
            if not -len(self) <= view < len(self):
                raise IndexError(f"view {view} of a stack of {len(self)} "
                                 f"photographs")
            return self._view(view % len(self))
        if isinstance(index, slice):
            views = range(*index.indices(len(self)))
        else:
            views = [int(v) for v in index]
        out = torch.empty((len(views), ) + tuple(self.shape[1:]),
                          dtype=self.dtype)
        for i, view in enumerate(views):
            out[i] = self[view]
        return out

    def __iter__(self):
        for view in range(len(self)):
            yield self._view(view)

    def _view(self, view: int) -> Tensor:
        image = torch.as_tensor(self._read(view), dtype=self.dtype)
        if tuple(image.shape) != tuple(self.shape[1:]):
            raise ValueError(f"'{self.names[view]}' read as "
                             f"{list(image.shape)}, expected "
                             f"{list(self.shape[1:])}")
        return image

    def tensor(self) -> Tensor:
        """All the photographs in one :math:`(V, H, W, 3)` tensor."""
        return self[:]

    def to(self, *args, **kwargs) -> Union['PhotographStack', Tensor]:
        """Itself where the target is the CPU in float32 (it stays on
        disk), else the photographs read into a tensor there."""
        target = torch.empty(0).to(*args, **kwargs)
        if target.device.type == 'cpu' and target.dtype == self.dtype:
            return self
        return self.tensor().to(*args, **kwargs)

    def __repr__(self) -> str:
        first = osp.dirname(self.names[0]) if self.names else ''
        return (f"{self.__class__.__name__}({len(self)} photographs of "
                f"{self.shape[1]} x {self.shape[2]}"
                f"{', in ' + repr(first) if first else ''})")
