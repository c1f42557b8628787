"""Result folders that never mix two runs and never damage a user's files.

Every command writes its results the same way:

1. the output folder may not be, or hold, one of the command's inputs;
2. a folder that holds files the command did not write (by the record
   :data:`RECORD` that every run leaves) is written into only with
   ``--overwrite``, and even then those files are kept;
3. a run writes into a temporary folder beside the output folder and puts
   its results in place only when all of them are written: a failed or
   interrupted run leaves the earlier results as they were.
"""
import json
import os
import shutil
import tempfile
from contextlib import contextmanager
from typing import Iterable, Iterator, List, Optional, Set

from tg_intrinsic.utils import atomic_write_json

# The record of the files a run wrote, in every result folder.
RECORD = '.tg-intrinsic.json'
_STAGING = '.partial-'
_PREVIOUS = '.previous-'


def check_output_path(path: str, inputs: Iterable[str] = (),
                      option: str = '--out') -> None:
    """Raises a :class:`ValueError` naming ``option`` when ``path`` is
    empty (an unset shell variable, not the current folder), an existing
    file, cannot be created (a file where a folder above it belongs, a
    folder that is not writable), or is (or holds) one of ``inputs``,
    which writing the results there would replace or delete."""
    if not str(path).strip():
        raise ValueError(f"{option} is empty; give a folder")
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
    ``option`` otherwise; puts back a folder that a run killed while
    replacing it left aside."""
    check_output_path(path, inputs, option)
    _restore_previous(path)
    foreign = foreign_files(path, command)
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
    parent, name = os.path.split(os.path.abspath(path))
    prefix = f'.{name}{kind}'
    try:
        return sorted(os.path.join(parent, entry)
                      for entry in os.listdir(parent)
                      if entry.startswith(prefix))
    except FileNotFoundError:
        return []


def _restore_previous(path: str) -> None:
    """A run killed between moving the old results aside and moving the
    new ones in leaves no ``path`` but ``.NAME.previous-*``: put it back."""
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
        parent, name = os.path.split(os.path.abspath(path))
        aside = tempfile.mkdtemp(prefix=f'.{name}{_PREVIOUS}', dir=parent)
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
    :func:`commit_folder` only renames); removes those of killed runs."""
    parent, name = os.path.split(os.path.abspath(path))
    os.makedirs(parent, exist_ok=True)
    for leftover in _siblings(path, _STAGING):
        shutil.rmtree(leftover, ignore_errors=True)
    return tempfile.mkdtemp(prefix=f'.{name}{_STAGING}', dir=parent)


@contextmanager
def result_folder(path: str, command: str, overwrite: bool = False,
                  inputs: Iterable[str] = (), option: str = '--out'
                  ) -> Iterator[str]:
    """Yields a temporary folder to write all results of ``command`` into;
    when the block ends without an error they replace those in ``path``
    (:func:`commit_folder`), else they are deleted and ``path`` is left as
    it was. Checks ``path`` first (:func:`claim_folder`).

    Example::

        with result_folder(args.out, 'solve', args.overwrite,
                           inputs=[args.mesh]) as out:
            write_ply(os.path.join(out, 'result.ply'), ...)
    """
    claim_folder(path, command, overwrite, inputs, option)
    staging = new_staging_folder(path)
    try:
        yield staging
        commit_folder(staging, path, command)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
