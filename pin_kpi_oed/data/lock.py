"""An exclusive lock on an output folder, so that two runs never compute into the same folder.

:func:`folder_lock` takes a non-blocking ``flock`` on ``<folder>/.lock`` (POSIX); the operating
system releases it when the process ends, even when killed, so a stale lock never blocks a resume.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from collections.abc import Iterator

from pin_kpi_oed.errors import InputError

__all__ = ["folder_lock"]


@contextlib.contextmanager
def folder_lock(folder: str | os.PathLike[str], what: str = "folder") -> Iterator[Path]:
    """Hold an exclusive lock on ``folder`` (created if missing) for the duration of the block.

    Args:
        folder: the output folder.
        what: how to name it in the message (e.g. ``--out``).

    Yields:
        The lock file's path.

    Raises:
        InputError: another process holds the lock (naming the folder and its process id when known).
    """
    path = Path(folder)
    path.mkdir(parents=True, exist_ok=True)
    lock = path / ".lock"
    fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o666)
    try:
        try:
            import fcntl

            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except ImportError:  # pragma: no cover - not POSIX: no lock
            pass
        except BlockingIOError:
            other = os.pread(fd, 32, 0).decode(errors="replace").strip()
            raise InputError(f"{what} {path}: another run{f' (pid {other})' if other else ''} is writing to this "
                             "folder; wait for it to finish (it resumes finished tasks) or choose another folder") \
                from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, str(os.getpid()).encode(), 0)
        yield lock
    finally:
        os.close(fd)
