"""Output paths checked before any work: never a lost input, never a late failure.

:func:`check_outputs` refuses, in milliseconds and before anything is read or computed, an output
that is a folder, whose folder is missing or read-only, that names one of the command's inputs,
or that names another output of the same command (without it ``import-ipa x.csv --out x.csv`` would
replace raw tracker data, and ``diagnose`` would fail on a missing folder after minutes of work). It also
claims every output file (:func:`claim_output`; the package's one atomic writer,
:func:`pin_kpi_oed.data.atomic.atomic_write_bytes`, compares): if another process writes one of
them while the command runs, the command's write is refused instead of silently replacing it.
"""

from __future__ import annotations

import os
from pathlib import Path
from collections.abc import Iterable

from pin_kpi_oed.errors import InputError

__all__ = ["check_outputs", "same_file", "claim_output", "claimed_state", "output_signature",
           "release_outputs", "FIGURE_SUFFIXES", "check_figure_suffix"]

#: file name endings a figure output may have; the figure is written in the format its name says
FIGURE_SUFFIXES = (".png", ".pdf", ".svg")


def check_figure_suffix(opt: str, path: str | os.PathLike[str] | None) -> None:
    """A figure output's name ends in a format the package writes (:data:`FIGURE_SUFFIXES`).

    Raises:
        InputError: naming the option, the path and the endings allowed (a ``.jpg`` name would hold PNG bytes).
    """
    if not path:
        return
    suffix = Path(path).suffix.lower()
    if suffix not in FIGURE_SUFFIXES:
        raise InputError(f"{opt} {path}: a figure is written as {', '.join(FIGURE_SUFFIXES)}; "
                         f"end the file name with one of them (got '{suffix or 'no ending'}')")


def _key(path: str | os.PathLike[str]) -> str:
    return os.path.normcase(os.path.realpath(os.path.abspath(os.fspath(path))))


def same_file(a: str | os.PathLike[str], b: str | os.PathLike[str]) -> bool:
    """True when ``a`` and ``b`` name the same file (symlinks, hard links and ``./`` resolved)."""
    if _key(a) == _key(b):
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


#: the state of each claimed output file when its command checked it (path key -> (inode, size, mtime ns),
#: None when the file did not exist)
_CLAIMED: dict[str, tuple[int, int, int] | None] = {}


def output_signature(path: str | os.PathLike[str]) -> tuple[int, int, int] | None:
    """(inode, size, mtime ns) of a file, None when there is none: any write (an atomic one makes a new inode)
    changes it."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return (st.st_ino, st.st_size, st.st_mtime_ns)


def claim_output(path: str | os.PathLike[str]) -> None:
    """Remember an output file's state now (a command's start, or its own write): the atomic writer refuses to
    replace the file if another process has written it in between."""
    _CLAIMED[_key(path)] = output_signature(path)


def release_outputs() -> None:
    """Forget every claim (the command that made them has ended)."""
    _CLAIMED.clear()


def claimed_state(path: str | os.PathLike[str]) -> tuple[bool, tuple[int, int, int] | None]:
    """(whether ``path`` is claimed, its state when claimed)."""
    key = _key(path)
    return key in _CLAIMED, _CLAIMED.get(key)


def _check_file_target(opt: str, path: Path) -> None:
    if path.is_dir():
        raise InputError(f"{opt} {path}: is a folder; give a file name")
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise InputError(f"{opt} {path}: folder '{folder}' does not exist (create it first: mkdir -p {folder})")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InputError(f"{opt} {path}: folder '{folder}' is not writable")
    if path.exists() and not os.access(path, os.W_OK):
        raise InputError(f"{opt} {path}: the file exists and is read-only")
    _probe_folder(opt, path, folder)


def _probe_folder(opt: str, path: Path, folder: Path) -> None:
    """Create and remove a file in ``folder``: the writer's temporary file must be possible there (permission bits
    do not tell for ``/proc``, a read-only mount or a full quota; a root user passes every ``os.access``).

    Raises:
        InputError: naming the option, the output path and the system's reason.
    """
    import tempfile  # here, not at the top: a command that writes nothing does not load it

    try:
        fd, probe = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".probe", dir=folder)
    except OSError as exc:
        raise InputError(f"{opt} {path}: cannot create a file in folder '{folder}' ({exc.strerror or exc}); "
                         "choose a writable folder") from None
    os.close(fd)
    try:
        os.unlink(probe)
    except OSError:
        pass


def _check_dir_target(opt: str, path: Path) -> None:
    if path.exists():
        if not path.is_dir():
            raise InputError(f"{opt} {path}: exists and is not a folder")
        if not os.access(path, os.W_OK | os.X_OK):
            raise InputError(f"{opt} {path}: folder is not writable")
        return
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise InputError(f"{opt} {path}: parent folder '{parent}' does not exist (create it first: mkdir -p {parent}; "
                         "the command creates only the last folder)")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise InputError(f"{opt} {path}: parent folder '{parent}' is not writable")


def check_outputs(outputs: Iterable[tuple[str, str | os.PathLike[str] | None]],
                  inputs: Iterable[tuple[str, str | os.PathLike[str] | None]] = (),
                  folders: Iterable[tuple[str, str | os.PathLike[str] | None]] = ()) -> None:
    """Refuse unusable output paths before any work.

    Args:
        outputs: (option, file path or None) of every output file.
        inputs: (option, path or None) of every input file or folder (a folder's files count as inputs).
        folders: (option, folder path or None) of output folders (created by the command if missing).

    Raises:
        InputError: naming the option and the path: a folder given as a file, a missing or read-only
            folder, an output equal to an input or to another output.
    """
    ins: list[tuple[str, Path]] = []
    for opt, p in inputs:
        if not p:
            continue
        q = Path(p)
        ins.append((opt, q))
        if q.is_dir():
            ins += [(f"{opt} ({f.name})", f) for f in sorted(q.iterdir()) if f.is_file()]
    seen: list[tuple[str, Path]] = []
    for kind, items in (("file", outputs), ("folder", folders)):
        for opt, p in items:
            if not p:
                continue
            path = Path(p)
            (_check_file_target if kind == "file" else _check_dir_target)(opt, path)
            for iopt, ip in ins:
                if same_file(path, ip):
                    raise InputError(f"{opt} {path}: is the input {iopt} {ip}; writing it would destroy the input "
                                     "(choose another file name)")
            for oopt, op in seen:
                if same_file(path, op):
                    raise InputError(f"{opt} {path}: is also {oopt}; give each output its own file")
            seen.append((opt, path))
    for _, path in seen:
        if not path.is_dir():
            claim_output(path)  # a write finding it changed by another process meanwhile is refused
