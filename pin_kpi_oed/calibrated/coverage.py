"""Joint-space coverage: which validation configurations lie within what the training data measured.

A calibration extrapolates where the validation rows leave the training's coverage; the fit-quality gate and the
diagnosis name that cause instead of "wrong robot". Whether a *row* is covered is the one joint-space measure of
every command (:class:`~pin_kpi_oed.discrepancy.coverage.JointCoverage`: the combination of the angles counts);
the per-joint shares here (:func:`coverage`, :func:`covered_rows`) only explain which joints' ranges are missing.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pin_kpi_oed.discrepancy.coverage import JointCoverage, joint_distance
from pin_kpi_oed.model.measured_joints import align_data

__all__ = ["coverage", "covered_rows", "coverage_summary", "COVERAGE_TOL_RAD"]

#: A validation angle within this of a training angle of the same joint is covered (rad).
COVERAGE_TOL_RAD = 0.05


def coverage(source_q: np.ndarray, target_q: np.ndarray, tol_rad: float = 0.05,
             periodic: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """Share of target rows whose joint value lies within ``tol_rad`` of a source value, per joint
    (:func:`covered_rows`).

    Args:
        source_q: training configurations (m_s, n) rad / m.
        target_q: validation configurations (m_t, n) rad / m.
        tol_rad: tolerance (rad; m for a prismatic joint).
        periodic: (n,) bool, the joints compared modulo 2π (the robot's
            :attr:`~pin_kpi_oed.model.robot.Robot.periodic_joints`); None: every joint.

    Returns:
        (fraction per joint (n,), fraction of target rows covered on every joint at once).
    """
    covered = covered_rows(source_q, target_q, tol_rad, periodic)
    return covered.mean(axis=0), float(np.all(covered, axis=1).mean())


def covered_rows(source_q: np.ndarray, target_q: np.ndarray, tol_rad: float = 0.05,
                 periodic: np.ndarray | None = None) -> np.ndarray:
    """Which target values lie within ``tol_rad`` of a source value of the same joint
    (:func:`~pin_kpi_oed.discrepancy.coverage.joint_distance`: wrapped mod 2π for a ``periodic`` joint only).

    Args:
        source_q: training configurations (m_s, n) rad / m.
        target_q: validation configurations (m_t, n) rad / m.
        tol_rad: tolerance (rad; m for a prismatic joint).
        periodic: (n,) bool, the joints compared modulo 2π; None: every joint.

    Returns:
        (m_t, n) bool: covered per row and joint.
    """
    return joint_distance(source_q, target_q, periodic) <= tol_rad


def coverage_summary(robot: Any, train: Any, test: Any, tol_rad: float = COVERAGE_TOL_RAD) -> dict:
    """How much of ``test`` lies within the joint angles of ``train`` (the robot's joints, wrapped mod 2π).

    Args:
        robot: the robot (its joint names pick the columns).
        train, test: measurement sets (training, validation).
        tol_rad: tolerance (rad).

    Returns:
        ``rows_covered`` (share of validation rows within the training's joint-space coverage,
        :class:`~pin_kpi_oed.discrepancy.coverage.JointCoverage`), ``per_joint`` (name -> share of validation
        angles within ``tol_rad`` of a training angle of that joint), ``tol_rad``.
    """
    Qs = align_data(robot, train, need_position=False)
    Qt = align_data(robot, test, need_position=False)
    per_joint, _ = coverage(Qs, Qt, tol_rad, robot.periodic_joints)
    return {"rows_covered": JointCoverage.from_training(Qs, periodic=robot.periodic_joints).share_covered(Qt),
            "per_joint": {n: float(c) for n, c in zip(robot.joint_names, per_joint)}, "tol_rad": float(tol_rad)}
