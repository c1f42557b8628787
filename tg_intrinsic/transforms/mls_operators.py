from torch_geometric.data import Data
from torch_geometric.data.datapipes import functional_transform

from tg_intrinsic.geometry.checks import (check_positive_float,
                                          check_positive_int)
from tg_intrinsic.geometry.pointcloud.mls import (MIN_MLS_NEIGHBOURS,
                                                  build_mls_operators)
from tg_intrinsic.surface_attributes import (mls_parameters,
                                             record_operator_graph,
                                             resolve_frames)
from tg_intrinsic.transforms._batching import GraphTransform


@functional_transform('mls_operators')
class MLSOperators(GraphTransform):
    r"""Builds DeltaConv's moving-least-squares gradient and divergence
    (functional name: :obj:`mls_operators`), from the `"DeltaConv"
    <https://arxiv.org/abs/2111.08799>`_ paper.

    Writes the k-nn graph with self-loops to ``data.edge_index``
    (``edge_index[0]`` the neighbour :math:`j`, ``edge_index[1]`` the centre
    :math:`i`), the per-edge weights ``data.grad_weight`` and
    ``data.div_weight`` (:math:`(E, 2)`, see
    :func:`tg_intrinsic.geometry.pointcloud.mls.mls_grad_div`), and the
    tangent frames ``data.frame`` the weights refer to, and the parameters
    they were built with, ``data.mls_parameters`` (:math:`(1, 4)`: k,
    regularizer, kernel width, normalized), which DeltaNet models compare
    with their own:

    .. math::
        (\nabla f)_i = \sum_{j} f_j \, G_{ij}, \qquad
        (\nabla \cdot X)_i = \sum_j D_{ij} \cdot X_j .

    Frames are found by :func:`~tg_intrinsic.surface_attributes.
    resolve_frames` (``data.frame``, else ``data.normal``, else normals
    estimated from 10 neighbours). Because the weights live on the edges,
    PyG batching needs nothing special.

    Args:
        k (int, optional): Neighbours, the point itself included (at least
            3). (default: :obj:`20`)
        regularizer (float, optional): Tikhonov weight :math:`\lambda`.
            (default: :obj:`1e-3`)
        kernel_width (float, optional): Gaussian width relative to the mean
            neighbour distance. (default: :obj:`1.0`)
        normalized (bool, optional): Divide by the :math:`\ell_\infty` norm of
            :math:`G`. (default: :obj:`True`)
    """
    def __init__(self, k: int = 20, regularizer: float = 1e-3,
                 kernel_width: float = 1.0, normalized: bool = True):
        self.k = check_positive_int(k, 'k', minimum=MIN_MLS_NEIGHBOURS)
        self.regularizer = check_positive_float(regularizer, 'regularizer')
        self.kernel_width = check_positive_float(kernel_width,
                                                 'kernel_width')
        self.normalized = normalized

    def forward(self, data: Data) -> Data:
        if getattr(data, 'pos', None) is None:
            raise ValueError("MLSOperators needs point positions in "
                             "'data.pos'")
        data = data.clone()
        edge_index, frame, grad_weight, div_weight = build_mls_operators(
            data.pos, self.k, getattr(data, 'batch', None),
            frame=resolve_frames(data),
            kernel_width=self.kernel_width, regularizer=self.regularizer,
            normalized=self.normalized)
        data.edge_index = edge_index
        data.frame = frame
        data.grad_weight = grad_weight
        data.div_weight = div_weight
        # A model reading these weights checks that they were built with
        # its own parameters (one row per example once batched).
        data.mls_parameters = mls_parameters(
            self.k, self.regularizer, self.kernel_width, self.normalized)
        return record_operator_graph(data)

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}(k={self.k}, '
                f'regularizer={self.regularizer}, '
                f'kernel_width={self.kernel_width}, '
                f'normalized={self.normalized})')
