"""Atomic file writes: readers see the old or the new file, never a partial one.

Every file the package writes (CSV, JSON, URDF, PNG, HTML) goes through :func:`atomic_write_bytes`:
a temporary file in the same directory, flushed and fsync-ed, then renamed over the target.

Concurrent writers: a command's output check (:func:`pin_kpi_oed.validation.paths.check_outputs`)
remembers each output file's state (:func:`~pin_kpi_oed.validation.paths.claim_output`); a write that finds the file
changed since
then — another process wrote it while the command ran — is refused with a message naming the file,
instead of the last writer silently replacing the other's output. The comparison and the rename happen
under a lock of the folder (``flock``, where the system has it), so two writers finishing at once are
ordered and the second one is refused.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.validation.paths import claim_output, claimed_state, output_signature


# --------------------------------------------------------------------------- #
# Atomic writes
# --------------------------------------------------------------------------- #
def _fsync_dir(directory: Path) -> None:
    """Best-effort fsync of a directory so a rename survives a crash (POSIX)."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


@contextlib.contextmanager
def _folder_lock(directory: Path):
    """An exclusive ``flock`` of the folder while held (nothing where the system has no ``flock``)."""
    try:
        import fcntl

        fd = os.open(directory, os.O_RDONLY)
    except (ImportError, OSError):
        yield
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # closing releases the lock


def check_writable(path: str | os.PathLike[str]) -> Path:
    """Check that ``path`` can be written: its directory exists and it is not a directory.

    Raises:
        InputError: naming the path and what is wrong.
    """
    target = Path(path)
    directory = target.parent if str(target.parent) else Path(".")
    if not directory.is_dir():
        raise InputError(f"cannot write '{target}': directory '{directory}' does not exist")
    if target.is_dir():
        raise InputError(f"cannot write '{target}': it is a directory")
    return target


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (the one atomic writer of the package).

    The bytes go to a new temporary file in the same directory (created with the
    usual umask-dependent permissions, or the old file's mode when it exists),
    are flushed and fsync-ed, then renamed over ``path`` with :func:`os.replace`:
    readers see the old or the new file, never a partial one. If anything fails,
    the temporary file is removed and ``path`` is left as it was.

    Args:
        path: Target file.
        data: Full content.

    Raises:
        InputError: If the target directory does not exist, ``path`` is a directory, or another process
            wrote ``path`` after this process claimed it (:func:`~pin_kpi_oed.validation.paths.claim_output`).
        OSError: On other file-system failures (disk full, permissions).
    """
    target = check_writable(path)
    directory = target.parent if str(target.parent) else Path(".")
    while True:
        tmp = directory / f".{target.name}.{os.urandom(6).hex()}.tmp"
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
            break
        except FileExistsError:  # pragma: no cover - 48 random bits
            continue
        except OSError as exc:  # the folder takes no new file: named by the output, not the temporary file
            raise InputError(f"cannot write '{target}': folder '{directory}' takes no new file "
                             f"({exc.strerror or exc})") from None
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        if target.exists():
            try:
                os.chmod(tmp, target.stat().st_mode & 0o7777)
            except OSError:
                pass
        with _folder_lock(directory):
            claimed, before = claimed_state(target)
            if claimed and output_signature(target) != before:
                when = time.strftime("%H:%M:%S", time.localtime(target.stat().st_mtime)) if target.exists() else "?"
                raise InputError(f"cannot write '{target}': another process wrote it at {when}, while this command "
                                 "ran; its file is kept (give this command another output file, or run the two one "
                                 "after the other)")
            os.replace(tmp, target)
            if claimed:
                claim_output(target)  # its own write is no other writer
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    _fsync_dir(directory)


def atomic_write_text(path: str | os.PathLike[str], text: str, encoding: str = "utf-8") -> None:
    """Write ``text`` to ``path`` atomically (see :func:`atomic_write_bytes`); newlines as given.

    Raises:
        InputError: If the target directory does not exist or ``path`` is a directory.
        OSError: On other file-system failures (disk full, permissions).
    """
    atomic_write_bytes(path, text.encode(encoding))


def to_jsonable(obj: Any) -> Any:
    """Recursively JSON-safe copy of ``obj`` (the one JSON clean-up helper of the package).

    NumPy arrays become lists, NumPy scalars Python numbers, paths strings, sets sorted lists, and
    non-finite floats ``None`` (JSON has no NaN). An array of booleans, integers or finite floats is its
    ``tolist()`` at once (the same Python numbers the entry-by-entry walk gives).

    Args:
        obj: Nested dicts / lists / tuples of Python or NumPy values.

    Returns:
        The same structure built from ``dict``, ``list``, ``str``, ``int``, ``float``, ``bool`` and ``None``.
    """
    t = type(obj)
    if t is float:
        return obj if math.isfinite(obj) else None
    if t is str or t is int or t is bool or obj is None:
        return obj
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, set, frozenset)):
        vals = sorted(obj) if isinstance(obj, (set, frozenset)) else obj
        return [to_jsonable(v) for v in vals]
    if isinstance(obj, np.ndarray):
        if obj.dtype.kind in "biu" or (obj.dtype.kind == "f" and bool(np.isfinite(obj).all())):
            return obj.tolist()
        return to_jsonable(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        v = float(obj)
        return v if math.isfinite(v) else None
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    return obj


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    if isinstance(obj, (set, frozenset)):
        return sorted(obj)
    raise TypeError(f"Object of type {type(obj).__name__} is not JSON serializable")


def atomic_write_json(path: str | os.PathLike[str], obj: Any) -> None:
    """Write ``obj`` as indented JSON (``indent=2``, trailing newline) atomically.

    NumPy arrays become (nested) lists, NumPy scalars Python numbers, paths
    strings, sets sorted lists. Non-finite floats are written as ``NaN`` /
    ``Infinity`` (Python's :mod:`json` reads them back). Serialisation happens
    before anything is written, so a failure leaves ``path`` untouched.

    Args:
        path: Target file.
        obj: JSON-serialisable object (possibly containing NumPy values).

    Raises:
        TypeError: If ``obj`` holds a value that cannot be converted.
        InputError: As :func:`atomic_write_text`.
    """
    text = json.dumps(obj, indent=2, default=_json_default)
    atomic_write_text(path, text + "\n")
