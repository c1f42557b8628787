"""Checkpoints: what --allow-changes accepts, and files that are not a
readable checkpoint of a run, refused in words."""
import pytest
import torch

from tg_intrinsic.errors import UsageError
from tg_intrinsic.training.checkpoints import allowed_changes, read_checkpoint


def test_allowed_changes():
    assert allowed_changes('epochs, --eval-every,,dataset') == [
        'epochs', 'eval_every', 'mesh_root']
    with pytest.raises(ValueError, match=r"--allow-changes lr: only "
                       r"epochs, .* may change when resuming"):
        allowed_changes('epochs,lr')


def test_a_file_that_is_no_checkpoint_is_refused(tmp_path):
    truncated = tmp_path / 'truncated.pt'
    truncated.write_bytes(b'PK\x03\x04 and then nothing')
    with pytest.raises(UsageError, match="is not a readable checkpoint"):
        read_checkpoint(str(truncated))
    other = tmp_path / 'weights.pt'
    torch.save({'model': {}}, other)
    with pytest.raises(UsageError, match="is not a checkpoint of "
                       "tg-intrinsic train"):
        read_checkpoint(str(other))
