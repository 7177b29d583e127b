"""Writing outputs whole or not at all: the one mechanism behind every file and folder a stage writes.

A writer fills a sibling of the output with a name of its own, ``<stem>.partial-<pid>-<token><suffix>`` (two writers
of one output never share it; the suffix stays last for savers that look at it, such as torch's and SB3's), flushes
it to disk and renames it over the output: a reader, or a kill at any moment, sees the old output or the new one,
whole. What a killed writer leaves behind is deleted by the next writer of the same output.
"""

from __future__ import annotations

import errno
import glob
import os
import secrets
import shutil
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path

PARTIAL = ".partial-"  # in every temporary name (.gitignore and .dvcignore match it)
REPLACED = ".replaced-"  # a folder moved aside by a swap, deleted after it (restored if a kill cut the swap)


def partial_path(path: Path) -> Path:
    """A sibling of ``path`` that only this call names: ``<stem>.partial-<pid>-<token><suffix>``."""
    return path.with_name(f"{path.stem}{PARTIAL}{os.getpid()}-{secrets.token_hex(4)}{path.suffix}")


def process_alive(pid: int) -> bool:
    """Whether process ``pid`` exists on this machine (another user's counts)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def remove_if_orphaned(path: Path, pid: str) -> bool:
    """Delete ``path`` (a file or a folder) when this user owns it and ``pid`` (as named in it) is a process that is
    gone: what a writer killed mid-write left behind. Whether it was deleted; anything else is left alone."""
    with suppress(OSError):  # gone meanwhile, or not ours to delete
        if pid.isdigit() and path.lstat().st_uid == os.getuid() and not process_alive(int(pid)):
            if path.is_dir() and not path.is_symlink():
                shutil.rmtree(path)
            else:
                path.unlink()
            return True
    return False


def remove_stale_partials(path: Path) -> list[Path]:
    """Delete the partial siblings of ``path`` (``partial_path``) whose writers are gone; returns them."""
    prefix = f"{path.stem}{PARTIAL}"
    return [leftover for leftover in path.parent.glob(glob.escape(prefix) + "*")
            if remove_if_orphaned(leftover, leftover.name.removeprefix(prefix).split("-", 1)[0])]


def _fsync(path: Path) -> None:
    """Flush ``path`` (a file's bytes, or a folder's entries) to disk, so a crash after a rename cannot lose it; a
    file system that cannot flush folders (EINVAL) is left as it is."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    except OSError as error:
        if error.errno != errno.EINVAL:
            raise
    finally:
        os.close(fd)


@contextmanager
def atomic_output(path: Path) -> Iterator[Path]:
    """Yield a temporary sibling of ``path`` (``partial_path``: this writer's own, same suffix) to write; when the
    block succeeds it is flushed and renamed to ``path``, when it fails it is deleted, so a file with the final name
    is always complete, and two writers of one file each publish a whole file (the last rename wins)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_partials(path)
    partial = partial_path(path)
    try:
        yield partial
        _fsync(partial)
    except BaseException:
        partial.unlink(missing_ok=True)
        raise
    partial.replace(path)
    _fsync(path.parent)


@contextmanager
def atomic_folder(path: Path, keep_existing: bool = False) -> Iterator[Path]:
    """Yield a fresh temporary sibling folder of ``path`` to fill (empty, or with ``keep_existing`` a copy of the
    folder at ``path``, whose files the block may overwrite); when the block succeeds the folder replaces ``path`` as
    a whole (``_swap_in``), when it fails it is deleted and ``path`` is untouched. A reader never sees old and new
    files side by side."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    _recover(path)
    remove_stale_partials(path)
    partial = partial_path(path)
    try:
        if keep_existing and path.is_dir():
            shutil.copytree(path, partial)
        else:
            partial.mkdir()
        yield partial
        for root, _, files in os.walk(partial):
            for name in files:
                _fsync(Path(root, name))
            _fsync(Path(root))
    except BaseException:
        shutil.rmtree(partial, ignore_errors=True)
        raise
    _swap_in(partial, path)


def _aside_path(path: Path) -> Path:
    """Where ``_swap_in`` moves the folder it replaces: ``<name>.replaced-<pid>-<token>``."""
    return path.with_name(f"{path.name}{REPLACED}{os.getpid()}-{secrets.token_hex(4)}")


def _recover(path: Path) -> None:
    """Undo a swap that a kill cut between its two renames: ``path`` is missing and the folder it held waits aside
    (whole): rename that back (the newest, if several); then delete the asides whose writers are gone."""
    prefix = f"{path.name}{REPLACED}"
    asides = sorted(path.parent.glob(glob.escape(prefix) + "*"), key=lambda p: p.stat().st_mtime)
    if asides and not path.exists():
        with suppress(FileNotFoundError, OSError):  # another writer recovered it first
            asides.pop().rename(path)
    for aside in asides:
        remove_if_orphaned(aside, aside.name.removeprefix(prefix).split("-", 1)[0])


def _swap_in(folder: Path, path: Path) -> None:
    """Rename ``folder`` to ``path``; a folder already there is first renamed aside (``_aside_path``) and deleted
    after the swap. Between the two renames ``path`` is absent for an instant, never a mix; a kill in that instant
    is undone by the next writer (``_recover``)."""
    replaced = []
    while True:
        try:
            folder.rename(path)  # fails while a non-empty folder is at ``path``
            break
        except OSError as error:
            if error.errno not in (errno.ENOTEMPTY, errno.EEXIST):
                raise
        aside = _aside_path(path)
        with suppress(FileNotFoundError):  # another writer moved it aside first
            path.rename(aside)
            replaced.append(aside)
    _fsync(path.parent)
    for old in replaced:
        shutil.rmtree(old)
