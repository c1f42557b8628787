"""Result folders: the staging folder, the record, foreign files, inputs,
and a run killed while the results are put in place."""
import json
import os

import pytest

from tg_intrinsic.io.results import (RECORD, claim_folder, foreign_files,
                                     result_folder)


def write(folder, name, text='x'):
    path = os.path.join(folder, name)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, 'w') as f:
        f.write(text)


def test_results_appear_together_and_replace_the_earlier_run(tmp_path):
    out = str(tmp_path / 'out')
    with result_folder(out, 'cmd') as staging:
        write(staging, 'a.txt')
        write(staging, 'sub/b.txt')
        assert not os.path.exists(out)  # nothing until all are written
    with open(os.path.join(out, RECORD)) as f:
        assert json.load(f) == {'command': 'cmd',
                                'files': ['a.txt', 'sub/b.txt']}
    with result_folder(out, 'cmd') as staging:
        write(staging, 'c.txt')
    assert sorted(os.listdir(out)) == [RECORD, 'c.txt']
    assert sorted(os.listdir(tmp_path)) == ['out']


def test_a_failed_run_changes_nothing(tmp_path):
    out = str(tmp_path / 'out')
    with result_folder(out, 'cmd') as staging:
        write(staging, 'a.txt', 'first')
    with pytest.raises(KeyboardInterrupt):
        with result_folder(out, 'cmd') as staging:
            write(staging, 'a.txt', 'second')
            raise KeyboardInterrupt
    assert open(os.path.join(out, 'a.txt')).read() == 'first'
    assert sorted(os.listdir(tmp_path)) == ['out']


def test_foreign_files_and_inputs(tmp_path):
    out = tmp_path / 'out'
    write(out, 'mine.txt')
    # another command's results are foreign too
    with pytest.raises(ValueError, match=r"--out '.*out' holds files that "
                       r"tg-intrinsic cmd did not write \(mine.txt\)"):
        claim_folder(str(out), 'cmd')
    with result_folder(str(out), 'cmd', overwrite=True) as staging:
        write(staging, 'a.txt')
    assert foreign_files(str(out), 'cmd') == ['mine.txt']
    assert foreign_files(str(out), 'other') == ['a.txt', 'mine.txt']
    with pytest.raises(ValueError, match='holds the input'):
        claim_folder(str(out), 'cmd', True, inputs=[str(out / 'mine.txt')])
    with pytest.raises(ValueError, match="--write-example is empty"):
        claim_folder('', 'cmd', option='--write-example')
    with pytest.raises(ValueError, match=r"is a file; give a folder"):
        claim_folder(str(out / 'a.txt'), 'cmd')
    with pytest.raises(ValueError, match=r"cannot be created: .*a.txt' is "
                                         r"a file, not a folder"):
        claim_folder(str(out / 'a.txt' / 'deeper'), 'cmd')


def test_a_run_killed_between_the_two_renames_is_put_back(tmp_path):
    out = tmp_path / 'out'
    with result_folder(str(out), 'cmd') as staging:
        write(staging, 'a.txt', 'kept')
    # the earlier results moved aside, the new ones not yet in place
    os.rename(out, tmp_path / '.out.previous-abc')
    claim_folder(str(out), 'cmd')
    assert (out / 'a.txt').read_text() == 'kept'
    assert sorted(os.listdir(tmp_path)) == ['out']


def test_the_working_directory_is_never_moved(tmp_path, monkeypatch):
    out = tmp_path / 'out'
    with result_folder(str(out), 'cmd') as staging:
        write(staging, 'a.txt', 'first')
    inode = os.stat(out).st_ino
    monkeypatch.chdir(out)
    with result_folder('.', 'cmd') as staging:
        write(staging, 'b.txt', 'second')
    assert os.stat(out).st_ino == inode  # the same folder, updated
    assert sorted(os.listdir(out)) == [RECORD, 'b.txt']
    assert sorted(os.listdir(tmp_path)) == ['out']


def test_a_folder_in_the_way_is_not_deleted(tmp_path):
    out = tmp_path / 'out'
    write(out, 'mine.txt')
    write(out, 'a.txt/inside.txt', 'a folder of the user')
    with pytest.raises(ValueError, match="a folder of that name is in the "
                                         "way"):
        with result_folder(str(out), 'cmd', overwrite=True) as staging:
            write(staging, 'a.txt')
    assert (out / 'a.txt' / 'inside.txt').read_text() == \
        'a folder of the user'
    assert not (out / RECORD).exists() and sorted(os.listdir(out)) == [
        'a.txt', 'mine.txt']  # and nothing else moved in


@pytest.mark.skipif(not hasattr(os, 'geteuid') or os.geteuid() == 0,
                    reason='root may write into any folder')
def test_a_read_only_output_folder_is_rejected(tmp_path):
    locked = tmp_path / 'locked'
    locked.mkdir()
    locked.chmod(0o500)
    try:
        for path in (locked, locked / 'new'):
            with pytest.raises(ValueError, match="is not writable"):
                claim_folder(str(path), 'cmd')
    finally:
        locked.chmod(0o700)
