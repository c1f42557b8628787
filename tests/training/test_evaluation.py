"""Evaluation: batches for batch statistics, instance mIoU and the gap
that eval-mode inference shows."""
import torch

from tg_intrinsic.training.evaluation import (instance_miou,
                                              statistics_gap, whole_batches)


def test_batches_for_batch_statistics_never_hold_a_lone_shape():
    assert whole_batches(5, 4) == [[0, 1, 2, 3, 4]]
    assert whole_batches(9, 4) == [[0, 1, 2, 3], [4, 5, 6, 7, 8]]
    assert whole_batches(8, 4) == [[0, 1, 2, 3], [4, 5, 6, 7]]
    assert whole_batches(3, 8) == [[0, 1, 2]]
    assert whole_batches(3, 1) == [[0], [1], [2]]


def test_instance_miou_against_a_hand_count():
    # one shape of a category with parts 0, 1, 2 (and a label 3 it lacks)
    pred = torch.tensor([0, 1, 1])
    y = torch.tensor([0, 0, 1])
    parts = torch.tensor([True, True, True, False])
    # part 0: {0} / {0, 1} = 1/2; part 1: {2} / {1, 2} = 1/2; part 2 is
    # absent from both and counts as 1 (ShapeNet-Part's convention)
    assert instance_miou(pred, y, parts) == (0.5 + 0.5 + 1.0) / 3
    assert instance_miou(y, y, parts) == 1.0


def test_statistics_gap_names_a_difference_above_the_threshold():
    assert statistics_gap({'test_accuracy': 0.5,
                           'test_accuracy_batch_statistics': 0.5}) == ''
    said = statistics_gap({'test_accuracy': 0.5,
                           'test_accuracy_batch_statistics': 0.6})
    assert '0.600' in said
