"""Provenance of a result: the files it came from (path, rows, SHA-256), the software that made it, the command.

A calibration certificate must say what was calibrated with what: :func:`file_record` fingerprints a data file
(SHA-256 of its bytes, so any change to it shows), :func:`software_versions` names the package and the
libraries that shape the numbers, :func:`command_line` writes the command that reproduces a run.
"""

from __future__ import annotations

import hashlib
import os
import platform
import shlex
from importlib import metadata
from pathlib import Path
from collections.abc import Sequence

__all__ = ["sha256_of", "file_record", "software_versions", "command_line", "DEPENDENCIES"]

#: Distributions whose versions a certificate lists (the package first).
DEPENDENCIES = ("pin_kpi_oed", "pin", "coal", "numpy", "scipy", "scikit-learn", "pandas", "matplotlib",
                "example-robot-data", "cyipopt-wheels")


def sha256_of(path: str | os.PathLike) -> str:
    """SHA-256 (hex) of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def file_record(path: str | os.PathLike, rows: int | None = None) -> dict:
    """``{"path", "name", "bytes", "sha256", "rows"}`` of a data file (``rows``: the measurements read from it)."""
    p = Path(path)
    return {"path": str(p), "name": p.name, "bytes": int(p.stat().st_size), "sha256": sha256_of(p),
            "rows": None if rows is None else int(rows)}


def software_versions() -> dict:
    """Python and the versions of :data:`DEPENDENCIES` (``"not installed"`` where one is missing)."""
    out = {"python": platform.python_version()}
    for name in DEPENDENCIES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def command_line(argv: Sequence[str], program: str = "pin-kpi-oed") -> str:
    """The shell command of a run (``argv`` without the program name), quoted for a POSIX shell."""
    return " ".join([program] + [shlex.quote(str(a)) for a in argv])
