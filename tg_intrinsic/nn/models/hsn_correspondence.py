from typing import Optional, Sequence

import torch
import torch.nn.functional as F
from torch import Tensor
from torch_geometric.data import Data

from tg_intrinsic.geometry.checks import check_positive_int
from tg_intrinsic.nn.harmonic_resnet_block import (DEFAULT_COMPLEX_NORM,
                                                   norm_repr)
from tg_intrinsic.nn.models.hsn_u_resnet import HSNUResNet


class HSNCorrespondence(torch.nn.Module):
    r"""Dense shape correspondence with Harmonic Surface Networks, from the
    `"CNNs on Surfaces using Rotation-Equivariant Features"
    <https://doi.org/10.1145/3386569.3392437>`_ paper (its FAUST
    experiment): an :class:`HSNUResNet` whose gauge-invariant features of
    every vertex go through two fully connected layers that classify the
    vertex as one of the :math:`T` vertices of a template. It computes

    .. math::
        \hat{\mathbf{y}}_i = W_2\, \mathrm{dropout}\big(\mathrm{ReLU}(
        W_1 \mathbf{h}_i + \mathbf{b}_1)\big) + \mathbf{b}_2, \qquad
        \mathbf{h}_i = \sum_M |\mathbf{d}_{0, i}^M|,

    trained with cross entropy against the index of the matching template
    vertex; the prediction is :math:`\arg\max_t \hat{y}_{it}`.

    Args:
        in_channels (int): Input features per point (``data.x``, else
            ``data.pos``).
        num_template_vertices (int): Vertices :math:`T` of the template
            (classes).
        channels (Sequence[int], optional): Features per level of the
            U-ResNet. (default: :obj:`(16, 32)`)
        max_order (int, optional): Highest rotation order.
            (default: :obj:`1`)
        rings (int, optional): Rings of the radial profiles.
            (default: :obj:`6`)
        hidden (int, optional): Width of the first fully connected layer.
            (default: :obj:`256`, as in the paper)
        dropout (float, optional): Dropout before the last layer.
            (default: :obj:`0.5`)
        norm (str, optional): The U-ResNet's normalisation, see
            :class:`HarmonicResNetBlock`. (default: :obj:`'instance'`)

    Shapes:
        - **input:** a (batched) :class:`~tg_intrinsic.data.IntrinsicData`
        - **output:** logits :math:`(N, T)`
    """
    def __init__(self, in_channels: int, num_template_vertices: int,
                 channels: Sequence[int] = (16, 32), max_order: int = 1,
                 rings: int = 6, hidden: int = 256, dropout: float = 0.5,
                 norm: Optional[str] = DEFAULT_COMPLEX_NORM):
        super().__init__()
        self.num_template_vertices = check_positive_int(
            num_template_vertices, 'num_template_vertices')
        self.hidden = check_positive_int(hidden, 'hidden')
        if not 0.0 <= float(dropout) < 1.0:
            raise ValueError(f"'dropout' must be in [0, 1), got {dropout!r}")
        self.dropout = float(dropout)
        self.backbone = HSNUResNet(in_channels, None, channels, max_order,
                                   rings, norm=norm)
        self.lin1 = torch.nn.Linear(self.backbone.channels[0], hidden)
        self.lin2 = torch.nn.Linear(hidden, self.num_template_vertices)

    def reset_parameters(self):
        self.backbone.reset_parameters()
        self.lin1.reset_parameters()
        self.lin2.reset_parameters()

    def forward(self, data: Data) -> Tensor:
        r"""Scores every vertex against every template vertex.

        Args:
            data (torch_geometric.data.Data): The shapes, as for
                :class:`HSNUResNet`: ``x`` :math:`(N, C_{in})` (else
                ``pos``), optionally ``batch`` :math:`(N)`, and the disc
                graphs of every level and the pooling between them.

        Returns:
            torch.Tensor: Logits :math:`(N, T)`, one row per vertex.
        """
        h = F.relu(self.lin1(self.backbone(data)))
        h = F.dropout(h, p=self.dropout, training=self.training)
        return self.lin2(h)

    def __repr__(self) -> str:
        b = self.backbone
        return (f'{self.__class__.__name__}({b.in_channels}, '
                f'{self.num_template_vertices}, channels={b.channels}, '
                f'max_order={b.max_order}, rings={b.rings}, '
                f'hidden={self.hidden}, dropout={self.dropout}'
                + norm_repr(b.norm) + ')')
