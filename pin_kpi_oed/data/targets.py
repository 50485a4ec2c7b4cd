"""Target files for compensation: Cartesian TCP targets, or a joint-space program (CSV).

A **targets** file has one row per TCP target:

==============================  ========  ============================================
column                          unit      meaning
==============================  ========  ============================================
``x``, ``y``, ``z``             m         TCP position (required), in the frame chosen
                                          at compensation (cell = tracker frame of a
                                          station, or the robot base frame)
``rx``, ``ry``, ``rz``          rad       optional: tool orientation as a rotation
                                          vector (axis × angle), all three or none
``name``                        (text)    optional: the target's label (default 1..m)
one per actuated joint          rad / m   optional: a start configuration near the
                                          wanted solution (e.g. the taught pose)
``temperature``, ``payload``,   °C, kg,   optional: what the calibrated effects read
``time``                        s
==============================  ========  ============================================

A **program** file has the joint columns (the nominal program, rad / m) and optionally
``name``, ``temperature``, ``payload``, ``time``. Numbers are SI unless declared with ``units``
(e.g. ``"mm,deg"``); other column names are mapped with ``columns`` (``"joint_a1=A1,x=X"``, see
:mod:`pin_kpi_oed.data.table`). Undeclared files in mm or degrees are refused with one line.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from collections.abc import Mapping, Sequence

import numpy as np

from pin_kpi_oed.data.measurements import (ANGLE_LIMIT_RAD, MAX_MEDIAN_DISTANCE_M, MeasurementSet,
                                           parse_numeric_table)
from pin_kpi_oed.data.table import Units, parse_columns, parse_units, read_text_table, rename_header
from pin_kpi_oed.errors import InputError

__all__ = ["TargetSet", "read_targets"]

_NAME = "name"
_AUX = ("temperature", "payload", "time")


@dataclass
class TargetSet:
    """TCP targets or program poses (SI units).

    Attributes:
        names: label of every row.
        position_m: TCP positions (m, 3) m, or None (a program).
        rotvec_rad: tool orientations as rotation vectors (m, 3) rad, or None.
        q: joint values (m, n) rad / m in ``joint_names`` order, or None.
        joint_names: names of the columns of ``q``.
        aux: temperature, payload, time of every row (a :class:`MeasurementSet` the effects read).
        source: the file.
    """

    names: list[str]
    position_m: np.ndarray | None
    rotvec_rad: np.ndarray | None
    q: np.ndarray | None
    joint_names: list[str]
    aux: MeasurementSet
    source: str = ""

    def __len__(self) -> int:
        return len(self.names)


def read_targets(path: str | os.PathLike, joint_names: Sequence[str], *, program: bool = False,
                 revolute: Sequence[bool] | np.ndarray | None = None, units: str | Units | None = None,
                 columns: str | Mapping[str, str] | None = None,
                 joint_guard: Sequence[float] | None = None) -> TargetSet:
    """Read a targets file (``program=False``) or a joint-space program (``program=True``).

    Args:
        path: the CSV file.
        joint_names: the robot's actuated joints (the joint columns, if present).
        program: joint columns required, positions not read.
        revolute: revolute mask of the joints (prismatic joint values are lengths); default all revolute.
        units: declared units of the file (``"mm,deg"``); None: SI, mm/degrees refused.
        columns: mapping of the package's column names to the file's (``"joint_a1=A1,x=X"``).
        joint_guard: per joint, the largest magnitude of an undeclared value (rad / m; default 2π + 0.1 rad):
            :attr:`pin_kpi_oed.model.robot.Robot.unit_guard`, a joint of a few turns keeps its range.

    Returns:
        The :class:`TargetSet` (SI units).

    Raises:
        InputError: missing file or columns, a bad cell (file, column, row and value named), an
            incomplete rx/ry/rz group, values that look like mm or degrees without ``units``.
    """
    src = str(Path(path))
    u = parse_units(units)
    mapping = parse_columns(columns)
    kind = "program file" if program else "targets file"
    header, _, rows, lines = read_text_table(path, src, kind)
    if not header:
        raise InputError(f"{src}: empty file, expected a header row")
    if not rows:
        raise InputError(f"{src}: no rows after the header")
    header = rename_header(header, mapping, src)
    seen = {}
    for i, h in enumerate(header):
        if not h:
            raise InputError(f"{src}: header column {i + 1} has an empty name")
        if h in seen:
            raise InputError(f"{src}: column '{h}' appears twice in the header")
        seen[h] = i
    joints = list(joint_names)
    has_q = [j for j in joints if j in seen]
    if program and len(has_q) != len(joints):
        missing = [j for j in joints if j not in seen]
        raise InputError(f"{src}: missing joint column(s) {', '.join(missing)} of the program; columns found: "
                         f"{', '.join(header)} (map other names with parameter 'columns')")
    if has_q and len(has_q) != len(joints):
        raise InputError(f"{src}: joint columns must be all of {', '.join(joints)} or none; found only "
                         f"{', '.join(has_q)}")
    if not program:
        miss = [c for c in "xyz" if c not in seen]
        if miss:
            raise InputError(f"{src}: missing position column(s) {', '.join(miss)} of the TCP targets; columns "
                             f"found: {', '.join(header)} (map other names with parameter 'columns')")
    rot = [c for c in ("rx", "ry", "rz") if c in seen]
    if rot and len(rot) != 3:
        raise InputError(f"{src}: orientation needs all of rx, ry, rz (rotation vector); found only {', '.join(rot)}")
    known = set(joints) | set("xyz") | {"rx", "ry", "rz"} | set(_AUX)
    data = parse_numeric_table(rows, lines, header, src, lambda c: float(c.strip()), ", ".join(header),
                               skip=tuple(h for h in header if h not in known))  # name and other columns: text

    def block(names: Sequence[str]) -> np.ndarray:
        return data[:, [seen[n] for n in names]].copy()

    rev = np.ones(len(joints), bool) if revolute is None else np.asarray(revolute, bool)
    q = None
    if has_q:
        q = block(joints) * np.where(rev, u.angle_rad, u.length_m)
    pos = None if program else block(list("xyz")) * u.length_m
    rv = block(["rx", "ry", "rz"]) * u.angle_rad if rot and not program else None
    if not u.declared:
        _sniff(src, pos, rv, q, joints, rev, lines, joint_guard)
    names = ([rows[r][seen[_NAME]].strip() for r in range(len(rows))] if _NAME in seen
             else [str(r + 1) for r in range(len(rows))])
    m = len(rows)
    aux = MeasurementSet(joints, q if q is not None else np.zeros((m, len(joints))), np.full((m, 3), np.nan),
                         temperature_c=block(["temperature"])[:, 0] if "temperature" in seen else None,
                         payload_kg=block(["payload"])[:, 0] if "payload" in seen else None,
                         time_s=block(["time"])[:, 0] if "time" in seen else None, source=src)
    return TargetSet(names, pos, rv, q, joints, aux, src)


def _sniff(src: str, pos: np.ndarray | None, rv: np.ndarray | None, q: np.ndarray | None, joints: list[str],
           rev: np.ndarray, lines: list[int], joint_guard: Sequence[float] | None = None) -> None:
    """Refuse undeclared files whose numbers look like mm or degrees (one line, naming the column); a joint's values
    against its own ``joint_guard`` (rad) when given and larger than 2π + 0.1 rad."""
    if pos is not None:
        med = float(np.median(np.linalg.norm(pos, axis=1)))
        if med > MAX_MEDIAN_DISTANCE_M:
            raise InputError(f"{src}: columns x, y, z: median distance {med:.6g} m exceeds {MAX_MEDIAN_DISTANCE_M:g} m;"
                             " looks like mm; declare the units (units='mm,deg') or convert to m/rad")
    guard = (np.maximum(np.asarray(joint_guard, float), ANGLE_LIMIT_RAD) if joint_guard is not None
             and np.size(joint_guard) == len(joints) else np.full(len(joints), ANGLE_LIMIT_RAD))
    for arr, names, mask, lim in ((q, joints, rev, guard), (rv, ["rx", "ry", "rz"], np.ones(3, bool),
                                                            np.full(3, ANGLE_LIMIT_RAD))):
        if arr is None:
            continue
        big = (np.abs(arr) > lim[None, :]) & mask[None, :]
        if big.any():
            r, c = np.argwhere(big)[0]
            what = "2π+0.1 rad" if lim[c] == ANGLE_LIMIT_RAD else f"{lim[c]:.4g} rad (the joint's own limit + 0.1)"
            raise InputError(f"{src}: column '{names[c]}', row {r + 1} (line {lines[r]}): "
                             f"value {float(arr[r, c]):.6g} exceeds "
                             f"{what}; looks like degrees; declare the units (units='mm,deg') or convert to rad")
