"""One writer at a time per output: a stage holds its output's lock while it writes, and a second writer of the same
output stops at once with one line naming the first.

The lock is the kernel's (``flock`` on ``<output>.lock``, which records the holder's pid and command): it ends with
its holder however that ends, so a lock file that a killed writer left behind blocks no one.
"""

from __future__ import annotations

import fcntl
import json
import os
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from mor.errors import MorError

HOLDER_WAIT_S = 1.0  # how long a refused writer waits for the holder to record itself (it does so right after flock)


def lock_path(output: Path) -> Path:
    """The lock file of ``output``: ``<output>.lock`` beside it."""
    return output.with_name(output.name + ".lock")


@contextmanager
def writer_lock(output: Path, command: str) -> Iterator[None]:
    """Hold the lock of ``output`` for the block, recording this process and ``command`` (as a user would type it,
    e.g. ``mor eval run --method M``) in it; MorError naming the holder when another process holds it."""
    output = Path(output)
    path = lock_path(output)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = _acquire(path, output)
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, (json.dumps({"pid": os.getpid(), "command": command}) + "\n").encode(), 0)
        yield
    finally:
        path.unlink(missing_ok=True)  # while still held: whoever comes next locks a new file
        os.close(fd)


def _acquire(path: Path, output: Path) -> int:
    """An open descriptor of the lock file ``path``, locked by this process; MorError when another holds it."""
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _holder(fd)
            os.close(fd)
            raise MorError(f"another `{holder.get('command', 'mor')}` is writing {output} "
                           f"(pid {holder.get('pid', 'unknown')}); wait for it or stop it") from None
        if _same_file(fd, path):
            return fd
        os.close(fd)  # its holder let go and deleted it between our open and flock: try the new one


def _same_file(fd: int, path: Path) -> bool:
    """Whether ``fd`` is still the file named ``path`` (not one deleted since it was opened)."""
    try:
        named = os.stat(path)
    except FileNotFoundError:
        return False
    opened = os.fstat(fd)
    return (named.st_dev, named.st_ino) == (opened.st_dev, opened.st_ino)


def _holder(fd: int) -> dict:
    """What the holder of the lock file ``fd`` recorded (pid, command); {} if it records nothing in time."""
    deadline = time.monotonic() + HOLDER_WAIT_S
    while True:
        try:
            return json.loads(os.pread(fd, 4096, 0))
        except ValueError:  # not written yet, or half written
            if time.monotonic() > deadline:
                return {}
            time.sleep(0.02)
