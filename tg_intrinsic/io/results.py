"""Result folders that never mix two runs and never damage a user's files.

Every command writes its results the same way:

1. the output folder may not be, or hold, one of the command's inputs;
2. a folder that holds files the command did not write (by the record
   :data:`RECORD` that every run leaves) is written into only with
   ``--overwrite``, and even then those files are kept;
3. a run writes into a temporary folder beside the output folder and puts
   its results in place only when all of them are written: a failed or
   interrupted run leaves the earlier results as they were;
4. an output folder that is a symbolic link is written through: the
   results go into its target and the link stays;
5. one run at a time writes into an output folder: a run holds a lock
   (:func:`output_lock`) from its checks to its last file, and a second
   run into the same folder stops at once, naming it, instead of mixing
   its files with the first one's.
"""
import hashlib
import json
import os
import shutil
import tempfile
from contextlib import contextmanager
from typing import Iterable, Iterator, List, Optional, Set

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None
    import msvcrt

from tg_intrinsic.utils import (atomic_write_json, current_umask,
                                os_error_reason)

# The record of the files a run wrote, in every result folder.
RECORD = '.tg-intrinsic.json'
_STAGING = '.partial-'
_PREVIOUS = '.previous-'
_LOCK = '.lock'
# Room left in a file name for the hidden siblings' prefix and suffix.
_SIBLING_ROOM = 40


def output_path(path: str) -> str:
    """The folder results go to: ``path``, or the target of a symbolic
    link ``path`` (the results go into it and the link stays)."""
    return os.path.realpath(path) if os.path.islink(path) else path


def folder_mode() -> int:
    """The permissions a new folder gets under the user's umask
    (``tempfile.mkdtemp`` makes private, 0700, folders)."""
    return 0o777 & ~current_umask()


def _hidden(path: str, kind: str) -> str:
    """The hidden sibling ``.NAME<kind>`` of ``path`` (staging, lock),
    with a long NAME shortened (and told apart by a hash) so that the
    sibling's name still fits the file system."""
    parent, name = os.path.split(os.path.abspath(path))
    if len(name.encode()) > 255 - _SIBLING_ROOM:
        digest = hashlib.sha1(name.encode()).hexdigest()[:12]
        name = name.encode()[:100].decode(errors='ignore') + '-' + digest
    return os.path.join(parent, f'.{name}{kind}')


def _name_too_long(path: str) -> Optional[str]:
    """The first part of ``path`` longer than its file system allows."""
    folder = os.path.abspath(path)
    while not os.path.exists(folder):
        folder = os.path.dirname(folder)
    try:
        limit = os.pathconf(folder, 'PC_NAME_MAX')
    except (OSError, ValueError, AttributeError):
        limit = 255
    for part in os.path.abspath(path).split(os.sep):
        if len(part.encode()) > limit:
            return f"its name '{part[:40]}...' has {len(part.encode())} " \
                f"bytes, more than the file system allows ({limit})"
    return None


@contextmanager
def output_lock(path: str, option: str = '--out') -> Iterator[None]:
    """Holds the lock of the output ``path`` (a folder or a file) while
    the block runs, so that no other run writes there at the same time;
    raises a :class:`ValueError` naming ``option`` when another process
    holds it. The lock is the file ``.NAME.lock`` beside ``path``,
    removed when the block ends; the operating system releases it when
    its process dies, so a killed run never blocks the next one."""
    lock_path = _hidden(os.path.realpath(path), _LOCK)
    while True:
        try:
            os.makedirs(os.path.dirname(lock_path), exist_ok=True)
            fd = os.open(lock_path, os.O_RDWR | os.O_CREAT,
                         folder_mode() & 0o666)
        except OSError as error:   # the folder's, not the lock's, problem
            raise ValueError(
                f"{option} '{path}' cannot be written: its folder "
                f"'{os.path.dirname(lock_path)}' does not take new files "
                f"({os_error_reason(error)}); give another "
                f"{option}") from None
        if not _try_lock(fd):
            os.close(fd)
            raise ValueError(
                f"{option} '{path}' is being written by another run of "
                f"tg-intrinsic right now; wait for it to finish, or give "
                f"another {option}")
        try:  # the holder before may have removed the file meanwhile
            if os.path.samestat(os.fstat(fd), os.stat(lock_path)):
                break
        except FileNotFoundError:
            pass
        os.close(fd)
    try:
        yield
    finally:
        try:
            os.remove(lock_path)   # before the lock ends (see the loop)
        except FileNotFoundError:
            pass
        os.close(fd)


def _try_lock(fd: int) -> bool:
    try:
        if fcntl is not None:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        else:  # pragma: no cover - Windows
            msvcrt.locking(fd, msvcrt.LK_NBLCK, 1)
        return True
    except OSError:
        return False


def check_output_path(path: str, inputs: Iterable[str] = (),
                      option: str = '--out') -> None:
    """Raises a :class:`ValueError` naming ``option`` when ``path`` is
    empty (an unset shell variable, not the current folder), an existing
    file, cannot be created (a file where a folder above it belongs, a
    folder that is not writable), or is (or holds) one of ``inputs``,
    which writing the results there would replace or delete."""
    if not str(path).strip():
        raise ValueError(f"{option} is empty; give a folder")
    too_long = _name_too_long(path)
    if too_long:
        raise ValueError(f"{option} '{path[:60]}...' cannot be created: "
                         f"{too_long}; give a shorter name")
    if os.path.exists(path) and not os.path.isdir(path):
        raise ValueError(f"{option} '{path}' is a file; give a folder")
    parent = os.path.dirname(os.path.abspath(path))
    while not os.path.exists(parent):
        parent = os.path.dirname(parent)
    if not os.path.isdir(parent):
        raise ValueError(f"{option} '{path}' cannot be created: '{parent}' "
                         f"is a file, not a folder; give another {option}")
    for folder in (parent, path):
        if os.path.isdir(folder) and not os.access(folder, os.W_OK):
            raise ValueError(f"{option} '{path}' cannot be written: the "
                             f"folder '{folder}' is not writable; give "
                             f"another {option}")
    folder = os.path.realpath(path)
    for source in inputs:
        if source is None:
            continue
        real = os.path.realpath(source)
        if real == folder or real.startswith(folder + os.sep):
            raise ValueError(
                f"{option} '{path}' holds the input '{source}', which writing "
                f"the results there could replace or remove; give another "
                f"{option}")


def recorded_files(path: str, command: str) -> Optional[Set[str]]:
    """The files (relative paths) that the last run of ``command`` wrote
    into ``path`` by its record, or :obj:`None` when there is no readable
    record of that command."""
    try:
        with open(os.path.join(path, RECORD)) as f:
            record = json.load(f)
        if record.get('command') != command:
            return None
        return {str(name) for name in record['files']}
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None


def files_under(path: str) -> List[str]:
    """Every file and link under ``path`` as relative paths, sorted
    (empty for a missing folder)."""
    found = []
    for root, dirs, files in os.walk(path):
        dirs.sort()
        for name in files + [d for d in dirs
                             if os.path.islink(os.path.join(root, d))]:
            found.append(os.path.relpath(os.path.join(root, name), path))
    return sorted(found)


def foreign_files(path: str, command: str) -> List[str]:
    """The files under ``path`` that no run of ``command`` wrote there
    (empty for a missing or empty folder)."""
    if not os.path.isdir(path):
        return []
    own = recorded_files(path, command) or set()
    return [name for name in files_under(path)
            if name not in own and name != RECORD]


def claim_folder(path: str, command: str, overwrite: bool = False,
                 inputs: Iterable[str] = (), option: str = '--out'
                 ) -> List[str]:
    """Checks that ``command`` may write its results into ``path`` (see
    the module docstring) and returns the foreign files it holds (empty
    unless ``overwrite``). Raises a :class:`ValueError` naming
    ``option`` otherwise."""
    check_output_path(path, inputs, option)
    foreign = foreign_files(output_path(path), command)
    if foreign and not overwrite:
        shown = ', '.join(foreign[:5]) + (f' and {len(foreign) - 5} more'
                                          if len(foreign) > 5 else '')
        raise ValueError(
            f"{option} '{path}' holds files that tg-intrinsic {command} did "
            f"not write ({shown}); give a new or empty folder, or "
            f"--overwrite to write there anyway (those files are kept, "
            f"files of the same name replaced)")
    return foreign


def write_record(path: str, command: str, files: Iterable[str]) -> None:
    """Records in ``path`` that ``command`` wrote ``files`` there."""
    atomic_write_json(os.path.join(path, RECORD),
                      {'command': command, 'files': sorted(set(files))})


def _siblings(path: str, kind: str) -> List[str]:
    parent, prefix = os.path.split(_hidden(path, kind))
    try:
        return sorted(os.path.join(parent, entry)
                      for entry in os.listdir(parent)
                      if entry.startswith(prefix))
    except FileNotFoundError:
        return []


def restore_previous(path: str) -> None:
    """A run killed between moving the old results aside and moving the
    new ones in leaves no ``path`` but ``.NAME.previous-*``: put it back
    (only while holding :func:`output_lock`)."""
    previous = _siblings(path, _PREVIOUS)
    if previous and not os.path.exists(path):
        os.rename(previous[-1], path)
        previous = previous[:-1]
    for leftover in previous:
        shutil.rmtree(leftover, ignore_errors=True)


def commit_folder(staging: str, path: str, command: str) -> None:
    """Puts the results in ``staging`` in place at ``path``: by renaming
    the whole folder when ``path`` is missing or holds only results of
    ``command`` (so readers see the old results or the new ones), else
    (foreign files, or the working directory inside) file by file,
    keeping the foreign files and removing the files of the earlier run
    that this one did not write again."""
    files = [name for name in files_under(staging) if name != RECORD]
    write_record(staging, command, files)
    if not os.path.exists(path):
        os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
        os.rename(staging, path)
        return
    real, here = os.path.realpath(path), os.path.realpath(os.getcwd())
    holds_cwd = here == real or here.startswith(real + os.sep)
    # (a folder holding the working directory stays: renaming it away
    # would leave the user's shell in a deleted folder)
    if not foreign_files(path, command) and not holds_cwd:
        parent, prefix = os.path.split(_hidden(path, _PREVIOUS))
        aside = tempfile.mkdtemp(prefix=prefix, dir=parent)
        os.rmdir(aside)
        os.rename(path, aside)
        os.rename(staging, path)
        shutil.rmtree(aside, ignore_errors=True)
        return
    old = recorded_files(path, command) or set()
    for name in files:  # all checked before anything moves
        target = os.path.join(path, name)
        if os.path.isdir(target) and not os.path.islink(target):
            raise ValueError(f"cannot write '{target}': a folder of that "
                             f"name is in the way; move it, or give "
                             f"another output folder")
    for name in files:
        target = os.path.join(path, name)
        os.makedirs(os.path.dirname(target), exist_ok=True)
        os.replace(os.path.join(staging, name), target)
    for name in sorted(old - set(files)):
        try:
            os.remove(os.path.join(path, name))
        except (FileNotFoundError, IsADirectoryError):
            pass
    os.replace(os.path.join(staging, RECORD), os.path.join(path, RECORD))
    shutil.rmtree(staging, ignore_errors=True)


def new_staging_folder(path: str) -> str:
    """An empty temporary folder beside ``path`` (same file system, so
    :func:`commit_folder` only renames), with the permissions of a new
    folder; removes those of killed runs (only while holding
    :func:`output_lock`)."""
    parent, prefix = os.path.split(_hidden(path, _STAGING))
    os.makedirs(parent, exist_ok=True)
    for leftover in _siblings(path, _STAGING):
        shutil.rmtree(leftover, ignore_errors=True)
    staging = tempfile.mkdtemp(prefix=prefix, dir=parent)
    os.chmod(staging, folder_mode())
    return staging


@contextmanager
def result_folder(path: str, command: str, overwrite: bool = False,
                  inputs: Iterable[str] = (), option: str = '--out'
                  ) -> Iterator[str]:
    """Yields a temporary folder to write all results of ``command`` into;
    when the block ends without an error they replace those in ``path``
    (:func:`commit_folder`), else they are deleted and ``path`` is left as
    it was. Checks ``path`` first (:func:`claim_folder`) and holds its
    lock (:func:`output_lock`) until the end; a link ``path`` is written
    through (:func:`output_path`).

    Example::

        with result_folder(args.out, 'solve', args.overwrite,
                           inputs=[args.mesh]) as out:
            write_ply(os.path.join(out, 'result.ply'), ...)
    """
    check_output_path(path, inputs, option)
    path = output_path(path)
    with output_lock(path, option):
        restore_previous(path)
        claim_folder(path, command, overwrite, inputs, option)
        staging = new_staging_folder(path)
        try:
            yield staging
            commit_folder(staging, path, command)
        except BaseException:
            shutil.rmtree(staging, ignore_errors=True)
            raise
