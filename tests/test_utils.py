"""Atomic writes (temporary file beside the target, then a rename):
readers see the old file or the whole new one, a failed write leaves the
old file and no temporary behind, a missing folder is named; the
clean-up of temporaries left by killed processes; machine_info."""
import json
import os
import platform

import numpy as np
import pytest
import torch

from tg_intrinsic.utils import (TEMPORARY_PREFIX, atomic_torch_save,
                                atomic_write, atomic_write_file,
                                atomic_write_json, machine_info,
                                remove_temporaries)


def temporaries(folder):
    return [n for n in os.listdir(folder) if n.startswith(TEMPORARY_PREFIX)]


def test_atomic_write_writes_the_whole_file_and_no_temporary(tmp_path):
    path = tmp_path / 'out.txt'
    atomic_write(str(path), lambda f: f.write('first'), 'w')
    assert path.read_text() == 'first'
    atomic_write(str(path), lambda f: f.write(b'\x00\x01second'), 'wb')
    assert path.read_bytes() == b'\x00\x01second'
    assert os.listdir(tmp_path) == ['out.txt']


def test_atomic_write_gives_the_usual_permissions(tmp_path):
    # the result gets 0666 minus the umask, as any new file does
    umask = os.umask(0o022)
    try:
        atomic_write(str(tmp_path / 'a.txt'), lambda f: f.write('x'), 'w')
        os.umask(0o077)
        atomic_write(str(tmp_path / 'b.txt'), lambda f: f.write('x'), 'w')
    finally:
        os.umask(umask)
    assert os.stat(tmp_path / 'a.txt').st_mode & 0o777 == 0o644
    assert os.stat(tmp_path / 'b.txt').st_mode & 0o777 == 0o600


@pytest.mark.parametrize('error', [RuntimeError('disk on fire'),
                                   KeyboardInterrupt()])
def test_a_failed_write_keeps_the_old_file_and_leaves_no_temporary(
        tmp_path, error):
    path = tmp_path / 'result.json'
    path.write_text('old')

    def half_then_fail(f):
        f.write('{"half": ')
        raise error

    with pytest.raises(type(error)):
        atomic_write(str(path), half_then_fail, 'w')
    assert path.read_text() == 'old'
    assert temporaries(tmp_path) == []


def test_the_folder_is_made_or_named(tmp_path):
    deep = tmp_path / 'a' / 'b' / 'c.txt'
    atomic_write(str(deep), lambda f: f.write('made'), 'w')
    assert deep.read_text() == 'made'
    missing = tmp_path / 'nowhere' / 'c.txt'
    with pytest.raises(FileNotFoundError) as info:
        atomic_write(str(missing), lambda f: f.write('x'), 'w',
                     make_folder=False)
    message = str(info.value)
    assert str(missing) in message and 'does not exist' in message
    assert TEMPORARY_PREFIX not in message  # the user never asked for it
    assert not (tmp_path / 'nowhere').exists()
    (tmp_path / 'plain').write_text('a file, not a folder')
    with pytest.raises(FileNotFoundError, match='is not a folder'):
        atomic_write(str(tmp_path / 'plain' / 'c.txt'),
                     lambda f: f.write('x'), 'w', make_folder=False)


@pytest.mark.parametrize('writer', ['atomic_write', 'atomic_write_file'])
def test_ctrl_c_just_after_the_temporary_is_made_leaves_none(
        tmp_path, monkeypatch, writer):
    # The signal's KeyboardInterrupt is raised at the next bytecode check,
    # which can be the instant os.open has made the file and not yet
    # returned its descriptor (CI saw precompute leave a '.tmp-*.pt' so).
    real_open = os.open

    def open_then_interrupted(*args, **kwargs):
        real_open(*args, **kwargs)
        raise KeyboardInterrupt

    path = tmp_path / 'result.txt'
    path.write_text('old')
    monkeypatch.setattr(os, 'open', open_then_interrupted)
    with pytest.raises(KeyboardInterrupt):
        if writer == 'atomic_write':
            atomic_write(str(path), lambda f: f.write('new'), 'w')
        else:
            atomic_write_file(str(path), lambda name: None)
    monkeypatch.undo()
    assert path.read_text() == 'old' and temporaries(tmp_path) == []


def test_a_temporary_name_already_taken_is_not_removed(tmp_path,
                                                        monkeypatch):
    import secrets
    taken = tmp_path / f'{TEMPORARY_PREFIX}{"ab" * 8}out.txt'
    taken.write_text("another process's")
    monkeypatch.setattr(secrets, 'token_hex', lambda n: 'ab' * n)
    with pytest.raises(FileExistsError):
        atomic_write(str(tmp_path / 'out.txt'), lambda f: f.write('x'), 'w')
    assert taken.read_text() == "another process's"


def test_atomic_write_file_hands_a_temporary_with_the_same_extension(
        tmp_path):
    path = tmp_path / 'image.png'
    seen = []

    def write_to(name):
        seen.append(name)
        with open(name, 'wb') as f:
            f.write(b'png bytes')

    atomic_write_file(str(path), write_to)
    assert path.read_bytes() == b'png bytes'
    (name, ) = seen
    assert os.path.dirname(name) == str(tmp_path)  # beside: one rename
    assert os.path.basename(name).startswith(TEMPORARY_PREFIX)
    assert name.endswith('image.png') and name != str(path)
    assert os.listdir(tmp_path) == ['image.png']

    def fail(name):
        with open(name, 'wb') as f:
            f.write(b'half')
        raise OSError('no space left')

    with pytest.raises(OSError, match='no space'):
        atomic_write_file(str(path), fail)
    assert path.read_bytes() == b'png bytes' and temporaries(tmp_path) == []


def test_json_and_torch_round_trip(tmp_path):
    obj = {'zeta': 1, 'alpha': [1.5, None, 'x'], 'nested': {'b': 2, 'a': 1}}
    atomic_write_json(str(tmp_path / 'm.json'), obj)
    text = (tmp_path / 'm.json').read_text()
    assert json.loads(text) == obj
    assert text.index('zeta') < text.index('alpha')  # order kept
    assert '\n  "alpha"' in text  # indented
    state = {'w': torch.arange(6.).reshape(2, 3), 'step': 7,
             'rng': np.random.default_rng(3).bit_generator.state}
    atomic_torch_save(state, str(tmp_path / 'ck.pt'))
    back = torch.load(tmp_path / 'ck.pt', weights_only=False)
    assert torch.equal(back['w'], state['w']) and back['step'] == 7
    assert back['rng'] == state['rng']
    assert temporaries(tmp_path) == []


def test_remove_temporaries_removes_only_left_over_temporaries(tmp_path):
    (tmp_path / '.tmp-k2j4h8checkpoint.pt').write_bytes(b'half')
    (tmp_path / '.tmp-a1metrics.csv').write_text('epoch,')
    (tmp_path / 'checkpoint.pt').write_bytes(b'whole')
    (tmp_path / '.hidden').write_text('keep')
    (tmp_path / 'x.tmp-not-a-prefix').write_text('keep')
    (tmp_path / '.tmp-folder').mkdir()  # not a file: kept
    assert remove_temporaries(str(tmp_path)) == ['.tmp-a1metrics.csv',
                                                 '.tmp-k2j4h8checkpoint.pt']
    assert sorted(os.listdir(tmp_path)) == [
        '.hidden', '.tmp-folder', 'checkpoint.pt', 'x.tmp-not-a-prefix']
    assert remove_temporaries(str(tmp_path)) == []
    assert remove_temporaries(str(tmp_path / 'missing')) == []


def test_machine_info_reports_this_machine():
    import scipy
    import torch_geometric
    info = machine_info()
    assert info['python'] == platform.python_version()
    assert info['torch'] == torch.__version__
    assert info['torch_geometric'] == torch_geometric.__version__
    assert info['numpy'] == np.__version__
    assert info['scipy'] == scipy.__version__
    assert info['cpu_count'] == os.cpu_count()
    assert info['torch_threads'] == torch.get_num_threads()
    assert info['platform'] == platform.platform()
    expected_cuda = torch.cuda.get_device_name(0) \
        if torch.cuda.is_available() else None
    assert info['cuda'] == expected_cuda
    json.dumps(info)  # recorded next to every benchmark: serialisable


@pytest.mark.parametrize('calls', [1, 2, 3, 5])
def test_a_ctrl_c_while_saving_stays_a_ctrl_c(tmp_path, monkeypatch, calls):
    """Ctrl-C arrives during the ``calls``-th write: a KeyboardInterrupt
    (the command stops), not torch's RuntimeError from inside its writer
    (the command took it for a bad file and went on); no file is left."""
    real_fdopen = os.fdopen

    class Interrupted:
        def __init__(self, f):
            self.f, self.calls = f, 0

        def write(self, data):
            self.calls += 1
            if self.calls == calls:   # Ctrl-C pressed during this write
                raise KeyboardInterrupt
            return self.f.write(data)

        def __getattr__(self, name):
            return getattr(self.f, name)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.f.close()

    monkeypatch.setattr(os, 'fdopen',
                        lambda *a, **k: Interrupted(real_fdopen(*a, **k)))
    saved = {'x': torch.zeros(1000), 'y': torch.ones(9)}
    try:
        atomic_torch_save(saved, str(tmp_path / 'a.pt'))
    except KeyboardInterrupt:
        assert os.listdir(tmp_path) == []
    else:   # fewer writes than ``calls``: no Ctrl-C came
        loaded = torch.load(tmp_path / 'a.pt')
        assert all(torch.equal(loaded[k], saved[k]) for k in saved)
