r"""ISO 9283 pose figures against the commanded poses, as the standard defines them.

When the rows carry the commanded poses (``goal_x, goal_y, goal_z`` in the robot's base frame, m, and optionally
``goal_roll, goal_pitch, goal_yaw``, rad, the commanded TCP's orientation as roll-pitch-yaw about the fixed x, y, z
axes: R = R_z(yaw) R_y(pitch) R_x(roll)), the measured point's commanded position in the tracker frame is

    x_c = T_tb · (p_goal + R_goal (r − c)),

T_tb the base frame registered in the tracker frame (the set-up of the station that scored the rows: the base
frame established by measurement, as ISO 9283 assumes), r the measured point (the station's reflector, tool
frame) and c the point the goals command (``commanded_tcp``, tool frame; default r: the goals command the
measured point itself). Per commanded position (rows whose goals lie within the stated distance of its first goal,
:func:`~pin_kpi_oed.report.iso9283.goal_groups`) with attained positions x_j:

* AP = ‖x̄ − x̄_c‖ (x̄_c the mean commanded position of its rows: one commanded pose per cycle), per axis x̄ − x̄_c;
* vAP = the largest distance between the barycentres of the rows x_j − x_c,j of its directions (distinct
  configurations, joints within 1 mrad);
* RP = l̄ + 3 S_l, l_j = ‖x_j − x̄‖, over the rows of one commanded position reached in one direction (≥ 3 rows);
* drift (rows with a ``time`` column): dAP = |AP_last − AP_first| between the first and the last row in time of a
  commanded position, with the time between them.

These figures need no model of the robot: the robot as its controller drives it, measured against what it was
told. The certificate labels the model-prediction variant (:mod:`pin_kpi_oed.report.iso9283`) as such.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pin_kpi_oed.errors import InputError

__all__ = ["GOAL_ORIENTATION", "commanded_positions", "commanded_figures", "drift"]

#: The data's commanded-orientation columns (rad; roll, pitch, yaw about the fixed x, y, z axes).
GOAL_ORIENTATION = ("goal_roll", "goal_pitch", "goal_yaw")


def _rpy(rpy: np.ndarray) -> np.ndarray:
    """R = R_z(yaw) R_y(pitch) R_x(roll) per row, (m, 3, 3)."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_euler("xyz", np.asarray(rpy, float)).as_matrix()


def commanded_positions(data: Any, tracker_T_base: np.ndarray, reflector_m: np.ndarray,
                        commanded_tcp_m: np.ndarray | None = None) -> np.ndarray | None:
    """The measured point's commanded position per row in the tracker frame (module docstring), m; None when the rows
    carry no goal positions.

    Args:
        data: the rows (``extra`` goal columns, base frame).
        tracker_T_base: 4 × 4 pose of the base in the tracker frame (m).
        reflector_m: the measured point in the tool frame (m).
        commanded_tcp_m: the point the goals command, tool frame (m); None: the measured point.

    Raises:
        InputError: a commanded TCP other than the measured point without the goal orientation columns.
    """
    from pin_kpi_oed.report.iso9283 import GOAL_POSITION

    if not all(k in data.extra for k in GOAL_POSITION):
        return None
    P = np.column_stack([np.asarray(data.extra[k], float) for k in GOAL_POSITION])
    r = np.asarray(reflector_m, float).reshape(3)
    if commanded_tcp_m is not None and not np.allclose(commanded_tcp_m, r, rtol=0, atol=1e-12):
        if not all(k in data.extra for k in GOAL_ORIENTATION):
            raise InputError("commanded_tcp: the rows carry no goal_roll, goal_pitch, goal_yaw columns, so a commanded "
                             "TCP other than the measured point cannot be moved to it")
        R = _rpy(np.column_stack([np.asarray(data.extra[k], float) for k in GOAL_ORIENTATION]))
        P = P + R @ (r - np.asarray(commanded_tcp_m, float).reshape(3))
    T = np.asarray(tracker_T_base, float)
    return P @ T[:3, :3].T + T[:3, 3]


def drift(time_s: np.ndarray | None, err_m: np.ndarray, groups: list[np.ndarray]) -> dict | None:
    """dAP = |‖e_last‖ − ‖e_first‖| per commanded position, the first and last row in time (m), with the time between
    them (s); None without times.

    Args:
        time_s: the rows' times (s) or None.
        err_m: attained − commanded per row (m, 3) m.
        groups: rows of each commanded position.
    """
    if time_s is None:
        return None
    t = np.asarray(time_s, float)
    rows = []
    for g in groups:
        o = g[np.argsort(t[g], kind="stable")]
        if t[o[-1]] > t[o[0]]:
            rows.append({"dAP_m": float(abs(np.linalg.norm(err_m[o[-1]]) - np.linalg.norm(err_m[o[0]]))),
                         "dt_s": float(t[o[-1]] - t[o[0]])})
    if not rows:
        return None
    d = np.array([r["dAP_m"] for r in rows])
    return {"n_positions": len(rows), "max_m": float(d.max()), "mean_m": float(d.mean()),
            "span_s": float(max(r["dt_s"] for r in rows)), "per_position": rows}


def commanded_figures(data: Any, measured_m: np.ndarray, x_c: np.ndarray, Q: np.ndarray, groups: list[np.ndarray],
                      q_tol_rad: float = 1e-3, frame: str = "") -> dict:
    """AP, vAP, RP and drift against the commanded poses (module docstring), m.

    Args:
        data: the rows (for their ``time_s``).
        measured_m: attained positions (m, 3), tracker frame (m).
        x_c: their commanded positions in the same frame (:func:`commanded_positions`), m.
        Q: configurations (rad) naming the directions.
        groups: rows per commanded position (:func:`~pin_kpi_oed.report.iso9283.goal_groups`).
        q_tol_rad: joint tolerance of one direction (rad).
        frame: where the base frame came from (printed).

    Returns:
        ``AP_vAP`` (:func:`~pin_kpi_oed.report.iso9283.pose_accuracy` of x_j − x_c,j), ``RP``
        (:func:`~pin_kpi_oed.report.iso9283.repeatability` per commanded position and direction with ≥ 3 rows, or
        None), ``drift`` (:func:`drift` or None), ``statements``, ``frame``.
    """
    from pin_kpi_oed.report.iso9283 import direction_keys, pose_accuracy, repeatability

    err = np.asarray(measured_m, float) - np.asarray(x_c, float)
    keys = direction_keys(Q, q_tol_rad)
    out: dict = {"frame": frame, "statements": [], "AP_vAP": pose_accuracy(err, groups, keys)}
    cycles = [g[keys[g] == k] for g in groups for k in np.unique(keys[g])]
    cycles = [c for c in cycles if c.size >= 3]
    out["RP"] = repeatability(np.asarray(measured_m, float), cycles) if cycles else None
    if not cycles:
        out["statements"].append("no commanded position was reached 3 times or more in one direction: no RP")
    out["drift"] = drift(getattr(data, "time_s", None), err, groups)
    if out["drift"] is None:
        out["statements"].append("the rows carry no times (or one time per position): no drift")
    return out
