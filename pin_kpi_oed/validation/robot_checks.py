"""Plausibility checks of a URDF before and after Pinocchio reads it (shared by every command).

Before: a joint axis of zero length, a ``<limit>`` with lower > upper, an un-expanded xacro file.
After: a robot whose reach is kilometres (a URDF written in mm).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pin_kpi_oed.errors import RobotLoadError

__all__ = ["check_urdf_tree", "check_robot_scale", "MAX_REACH_M"]

#: the largest plausible reach of an arm (m); a URDF in mm gives ~1000x its real reach
MAX_REACH_M = 100.0


def check_urdf_tree(root: Any, path: Any, text: str = "") -> None:
    """Check the parsed URDF XML (``xml.etree`` root) of ``path``.

    Raises:
        RobotLoadError: naming the file, the joint and the value: a xacro file, a zero joint axis,
            reversed limits.
    """
    if "<xacro:" in text or "${" in text:  # un-expanded macros or properties (an expanded file keeps only xmlns)
        raise RobotLoadError(f"{path}: a xacro file, not plain URDF: expand it first "
                             f"(e.g. 'xacro {path} > robot.urdf') and pass the .urdf")
    for j in root.iter("joint"):
        name, kind = j.get("name", "?"), j.get("type", "")
        if kind not in ("revolute", "continuous", "prismatic"):
            continue
        ax = j.find("axis")
        if ax is not None and ax.get("xyz") is not None:
            try:
                v = np.array([float(x) for x in ax.get("xyz").split()], float)
            except ValueError:
                raise RobotLoadError(f"{path}: joint '{name}': axis xyz='{ax.get('xyz')}' is not 3 numbers") from None
            if v.size != 3 or not np.all(np.isfinite(v)) or np.linalg.norm(v) < 1e-12:
                raise RobotLoadError(f"{path}: joint '{name}': axis xyz='{ax.get('xyz')}' has zero length (or is not "
                                     "3 finite numbers); give the unit direction of the joint axis")
        lim = j.find("limit")
        if lim is not None and kind != "continuous" and lim.get("lower") is not None and lim.get("upper") is not None:
            try:
                lo, hi = float(lim.get("lower")), float(lim.get("upper"))
            except ValueError:
                raise RobotLoadError(f"{path}: joint '{name}': limit lower/upper are not numbers") from None
            if lo > hi:
                unit = "m" if kind == "prismatic" else "rad"
                raise RobotLoadError(f"{path}: joint '{name}': limit lower={lo:g} > upper={hi:g} {unit} (reversed)")


def check_robot_scale(reach_m: float, path: Any) -> None:
    """Refuse a robot whose reach (m) is implausible for an arm (a URDF in mm).

    Raises:
        RobotLoadError: naming the file and the reach.
    """
    if not math.isfinite(reach_m) or reach_m > MAX_REACH_M:
        raise RobotLoadError(f"{path}: the robot reaches {reach_m:.4g} m, more than {MAX_REACH_M:g} m: the URDF looks "
                             "like mm (URDF lengths are in m)")


class captured_stderr:
    """Capture what C/C++ code writes to file descriptor 2 (urdfdom's parser) instead of printing it.

    Usage: ``with captured_stderr() as cap: ...``; then ``cap.text`` holds the captured text and
    ``cap.first_line()`` its first meaningful line (e.g. urdfdom's reason for a refusal).
    """

    def __enter__(self) -> "captured_stderr":
        import os
        import sys
        import tempfile

        self.text = ""
        try:
            sys.stderr.flush()
            self._fd = sys.stderr.fileno() if hasattr(sys.stderr, "fileno") else 2
        except (OSError, ValueError, AttributeError):
            self._fd = 2
        self._tmp = tempfile.TemporaryFile()
        try:
            self._saved = os.dup(2)
            os.dup2(self._tmp.fileno(), 2)
        except OSError:  # pragma: no cover - no fd 2
            self._saved = None
        return self

    def __exit__(self, *exc: Any) -> None:
        import os

        if self._saved is not None:
            os.dup2(self._saved, 2)
            os.close(self._saved)
        self._tmp.seek(0)
        self.text = self._tmp.read().decode(errors="replace")
        self._tmp.close()

    def first_line(self) -> str:
        """The first non-empty captured line without urdfdom's ``Error:`` prefix ('' when none)."""
        for ln in self.text.splitlines():
            ln = ln.strip()
            if ln:
                return ln.removeprefix("Error:").strip()
        return ""
