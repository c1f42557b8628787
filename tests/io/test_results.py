"""Result folders: the staging folder, the record, foreign files, inputs,
a run killed while the results are put in place, links, concurrent runs
(processes), permissions and long names."""
import json
import multiprocessing
import os
import signal
import stat
import time

import pytest

from tg_intrinsic.io.results import (RECORD, claim_folder, foreign_files,
                                     output_lock, result_folder)


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
    with pytest.raises(KeyboardInterrupt):   # the next run puts it back
        with result_folder(str(out), 'cmd'):
            raise KeyboardInterrupt
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


def test_a_linked_output_folder_is_written_through(tmp_path):
    target = tmp_path / 'scratch' / 'runs'
    target.mkdir(parents=True)
    link = tmp_path / 'runs'
    link.symlink_to(target)
    for run in ('first', 'second'):   # new, then over an earlier result
        with result_folder(str(link), 'cmd') as staging:
            write(staging, 'a.txt', run)
        assert link.is_symlink() and os.readlink(link) == str(target)
        assert (target / 'a.txt').read_text() == run
    assert sorted(os.listdir(tmp_path)) == ['runs', 'scratch']
    assert sorted(os.listdir(tmp_path / 'scratch')) == ['runs']


def _write_slowly(out, name, started, results):
    started.wait()
    try:
        with result_folder(out, 'cmd') as staging:
            for index in range(20):
                write(staging, f'{index}.txt', name)
                time.sleep(0.01)
        results.put((name, 'done'))
    except ValueError as error:
        results.put((name, str(error)))


def test_concurrent_runs_never_mix_or_lose_files(tmp_path):
    out = str(tmp_path / 'out')
    context = multiprocessing.get_context('fork')
    results = context.Queue()
    for trial in range(2):
        started = context.Event()
        runs = [context.Process(target=_write_slowly,
                                args=(out, f'run{trial}{k}', started,
                                      results)) for k in range(4)]
        for run in runs:
            run.start()
        started.set()
        for run in runs:
            run.join(60)
            assert run.exitcode == 0
        outcomes = dict(results.get(timeout=5) for _ in runs)
        done = [name for name, said in outcomes.items() if said == 'done']
        assert done, outcomes
        for name, said in outcomes.items():
            assert said == 'done' or 'is being written by another run' \
                in said, said
        # the folder holds one whole run: every file its record lists
        with open(os.path.join(out, RECORD)) as f:
            listed = json.load(f)['files']
        assert len(listed) == 20
        texts = {open(os.path.join(out, name)).read() for name in listed}
        assert len(texts) == 1 and texts <= set(done)
        assert sorted(os.listdir(tmp_path)) == ['out']   # no staging left


def _hold_the_lock(out, ready):
    with output_lock(out):
        ready.set()
        time.sleep(60)


def test_a_killed_run_does_not_block_the_next(tmp_path):
    out = str(tmp_path / 'out')
    context = multiprocessing.get_context('fork')
    ready = context.Event()
    holder = context.Process(target=_hold_the_lock, args=(out, ready))
    holder.start()
    assert ready.wait(30)
    with pytest.raises(ValueError, match="'.*out' is being written by "
                       "another run of tg-intrinsic right now"):
        with result_folder(out, 'cmd'):
            pass
    os.kill(holder.pid, signal.SIGKILL)
    holder.join()
    with result_folder(out, 'cmd') as staging:
        write(staging, 'a.txt')
    assert sorted(os.listdir(tmp_path)) == ['out']


def test_result_folders_follow_the_umask(tmp_path):
    previous = os.umask(0o022)
    try:
        with result_folder(str(tmp_path / 'out'), 'cmd') as staging:
            write(staging, 'a.txt')
    finally:
        os.umask(previous)
    assert stat.S_IMODE(os.stat(tmp_path / 'out').st_mode) == 0o755


def test_long_output_names(tmp_path):
    with pytest.raises(ValueError, match=r"has 300 bytes, more than the "
                       r"file system allows \(255\); give a shorter name"):
        with result_folder(str(tmp_path / ('x' * 300)), 'cmd'):
            pass
    # a name that fits, whose hidden siblings would not: shortened
    out = tmp_path / ('y' * 250)
    for run in range(2):
        with result_folder(str(out), 'cmd') as staging:
            write(staging, 'a.txt', str(run))
    assert (out / 'a.txt').read_text() == '1'
    assert os.listdir(tmp_path) == [out.name]
