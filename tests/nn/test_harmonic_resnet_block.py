import pytest
import torch

from tg_intrinsic.geometry.geodesics.harmonic import (HarmonicOperator,
                                                      harmonic_terms)
from tg_intrinsic.nn import HarmonicResNetBlock
from tg_intrinsic.nn.harmonic_resnet_block import harmonic_operators
from tests.nn.conftest import C128, no_sparse_kernel, random_discs


def test_features_must_have_one_row_per_graph_node(monkeypatch):
    edge_index, logmap, transport, weight, radius = random_discs()
    harmonic = harmonic_terms(edge_index, logmap, weight, radius, 3, 1)
    short = torch.randn(40, 2, 2, dtype=C128)
    operator = HarmonicOperator(edge_index, harmonic, transport, 60, 2, 2)
    no_sparse_kernel(monkeypatch)
    block = HarmonicResNetBlock(2, 2, max_order=1, rings=3, prev_order=1)
    ops = {(2, 2): operator}
    with pytest.raises(ValueError, match=r"'z' has 40 rows but there are "
                                         r"60 nodes in 'operators'"):
        block(short, ops)
    with pytest.raises(ValueError, match=r'order pairs \[\(1, 2\)\]'):
        HarmonicResNetBlock(2, 2, 1, 3, prev_order=0)(short[:, :1], ops)


def test_harmonic_operators_reject_bad_graphs():
    edge_index, logmap, transport, weight, radius = random_discs()
    harmonic = harmonic_terms(edge_index, logmap, weight, radius, 3, 1)
    negative = edge_index.clone()
    negative[0, 0] = -1
    with pytest.raises(ValueError, match='outside'):
        harmonic_operators(negative, harmonic, transport, 60, [(2, 2)])


def test_constructor_needs_positive_channel_counts():
    with pytest.raises(ValueError, match="'out_channels' must be at least"):
        HarmonicResNetBlock(2, 0)
