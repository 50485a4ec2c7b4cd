"""Move times between configurations from the URDF's per-joint speed limits.

Time model (stated, deliberately simple): a synchronised joint-space move (``movej`` / ``PTP`` /
``MoveAbsJ``) from q_a to q_b takes ``t = max_j |q_b,j − q_a,j| / v_j`` seconds, v_j the joint's
URDF ``<limit velocity>`` (rad/s, m/s for prismatic joints) times a speed override (0…1]. The
URDF gives no acceleration limits, so ramps are not modelled: every time here is a lower bound of
the real move time, and the same bound is used for every ordering it compares.
"""

from __future__ import annotations

import numpy as np

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.robot import Robot


def joint_speeds(robot: Robot, override: float = 1.0) -> np.ndarray:
    """Per-joint speed limits of the robot (URDF ``<limit velocity>``) times an override.

    Args:
        robot: the robot.
        override: speed override in (0, 1].

    Returns:
        (n,) rad/s for revolute joints, m/s for prismatic ones.

    Raises:
        InputError: override outside (0, 1], or a joint without a positive speed limit.
    """
    if not (0.0 < float(override) <= 1.0):
        raise InputError(f"speed override: must be in (0, 1], got {override}")
    v = np.array([float(robot.model.velocityLimit[robot.model.joints[j].idx_v]) for j in robot.joint_ids])
    bad = [n for n, x in zip(robot.joint_names, v) if not (np.isfinite(x) and x > 0)]
    if bad:
        raise InputError(f"{robot.urdf_path}: joint(s) {', '.join(bad)} have no positive <limit velocity>")
    return v * float(override)


def move_time(qa: np.ndarray, qb: np.ndarray, speeds: np.ndarray) -> float:
    """Time of the synchronised joint move q_a → q_b: max_j |Δq_j| / v_j (s)."""
    return float(np.max(np.abs(np.asarray(qb, float) - np.asarray(qa, float)) / speeds))


def time_matrix(Q: np.ndarray, speeds: np.ndarray) -> np.ndarray:
    """Move times between every pair of configurations.

    Args:
        Q: configurations (k, n).
        speeds: (n,) joint speed limits.

    Returns:
        (k, k) s, symmetric, zero diagonal.
    """
    Q = np.atleast_2d(np.asarray(Q, float))
    return np.max(np.abs(Q[:, None, :] - Q[None, :, :]) / speeds, axis=2)


def path_time(path: np.ndarray, speeds: np.ndarray) -> float:
    """Total time of a sequence of joint moves through the rows of ``path`` (s)."""
    path = np.atleast_2d(np.asarray(path, float))
    if path.shape[0] < 2:
        return 0.0
    return float(np.sum(np.max(np.abs(np.diff(path, axis=0)) / speeds, axis=1)))
