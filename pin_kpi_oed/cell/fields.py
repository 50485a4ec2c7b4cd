"""Field readers of the cell file: vectors, angles in rad or deg, poses (file, key and value named on error)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pinocchio as pin

from pin_kpi_oed.errors import InputError

__all__ = ["where", "read_vec", "read_angles", "read_pose"]


def where(src: str, key: str) -> str:
    """``<file>: <key>`` (or the key alone when there is no file) for messages."""
    return f"{src}: {key}" if src else key


def read_vec(v: Any, n: int, what: str) -> np.ndarray:
    """``n`` finite numbers as a float array.

    Raises:
        InputError: not n finite numbers, naming ``what``.
    """
    try:
        a = np.asarray(v, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise InputError(f"{what}: expected {n} numbers, got {v!r}") from None
    if a.size != n or not np.all(np.isfinite(a)):
        raise InputError(f"{what}: expected {n} finite numbers, got {v!r}")
    return a


def read_angles(d: dict, stem: str, n: int | None, what: str, required: bool = True) -> np.ndarray | None:
    """Read ``<stem>_rad`` or ``<stem>_deg`` (converted to rad)."""
    if f"{stem}_rad" in d and f"{stem}_deg" in d:
        raise InputError(f"{what}: give either '{stem}_rad' or '{stem}_deg', not both")
    for key, scale in ((f"{stem}_rad", 1.0), (f"{stem}_deg", math.pi / 180.0)):
        if key in d:
            try:
                a = np.asarray(d[key], dtype=float)
            except (TypeError, ValueError):
                raise InputError(f"{what}.{key}: expected numbers, got {d[key]!r}") from None
            if not np.all(np.isfinite(a)) or (n is not None and a.shape[-1:] != (n,)):
                raise InputError(f"{what}.{key}: expected {n} finite numbers per entry, got {d[key]!r}")
            return a * scale
    if required:
        raise InputError(f"{what}: missing '{stem}_rad' (or '{stem}_deg')")
    return None


def read_pose(d: Any, what: str) -> pin.SE3:
    """A pose mapping ``{xyz_m, rpy_rad | rpy_deg}`` (None: identity) as ``pin.SE3`` (m, rad).

    Raises:
        InputError: not a mapping, unknown fields, or bad numbers, naming ``what``.
    """
    if d is None:
        return pin.SE3.Identity()
    if not isinstance(d, dict):
        raise InputError(f"{what}: expected a mapping with xyz_m and rpy_rad/rpy_deg, got {d!r}")
    unknown = set(d) - {"xyz_m", "rpy_rad", "rpy_deg"}
    if unknown:
        raise InputError(f"{what}: unknown field(s) {', '.join(sorted(unknown))} (expected xyz_m, rpy_rad or rpy_deg)")
    xyz = read_vec(d.get("xyz_m", [0, 0, 0]), 3, f"{what}.xyz_m")
    rpy = read_angles(d, "rpy", 3, what, required=False)
    rpy = np.zeros(3) if rpy is None else rpy
    return pin.SE3(pin.rpy.rpyToMatrix(*rpy), xyz)
