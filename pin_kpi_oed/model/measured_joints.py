"""The joint values of a measurement set, checked against the robot: the one input check shared by the
identification, its validation and every prediction of a calibrated model (rad; m for a prismatic joint)."""

from __future__ import annotations

from typing import Any

import numpy as np

from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.errors import InputError

__all__ = ["align_data"]


def align_data(robot: Any, data: MeasurementSet, need_position: bool = True) -> np.ndarray:
    """Joint values of ``data`` in the robot's joint order, checked (rad).

    Args:
        robot: the :class:`~pin_kpi_oed.model.robot.Robot`.
        data: the measurements.
        need_position: the positions must be finite (False for predictions from joint values).

    Raises:
        InputError: missing joint columns, non-finite values, degrees instead of rad,
            values outside the joint limits, non-finite positions.
    """
    src = data.source or "measurement set"
    missing = [j for j in robot.joint_names if j not in data.joint_names]
    if missing:
        raise InputError(f"{src}: missing joint column(s) {', '.join(missing)} (rad); robot joints: "
                         f"{', '.join(robot.joint_names)}; data columns: {', '.join(data.joint_names)}")
    idx = [data.joint_names.index(j) for j in robot.joint_names]
    Q = np.asarray(data.q, float)[:, idx]
    checks = [("joint values", Q), ("x, y, z", data.position_m if need_position else None),
              ("rx, ry, rz", data.rotvec_rad), ("sigma", data.sigma_m)]
    for name, arr in checks:
        if arr is None:
            continue
        bad = ~np.isfinite(arr)
        if bad.any():
            i = int(np.argwhere(bad)[0][0])
            raise InputError(f"{src}: {name} of measurement {i + 1} is not finite (NaN/inf)")
    robot.check_units(Q, src, first_row=1)
    if data.rotvec_rad is not None and np.any(np.linalg.norm(data.rotvec_rad, axis=1) > 2 * np.pi + 0.1):
        raise InputError(f"{src}: rotation vectors longer than 2π rad: looks like degrees; convert to rad")
    if data.sigma_m is not None and np.any(data.sigma_m <= 0):
        raise InputError(f"{src}: standard deviations must be > 0 m")
    return robot.check_q(Q, what=src)
