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
