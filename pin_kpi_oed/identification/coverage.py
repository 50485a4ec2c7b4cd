"""Joint-space coverage: which validation configurations lie within what the training data measured.

A calibration extrapolates where the validation rows leave the training's coverage; the fit-quality gate and the
diagnosis name that cause instead of "wrong robot". Whether a *row* is covered is the one joint-space measure of
every command (:class:`~pin_kpi_oed.discrepancy.coverage.JointCoverage`: the combination of the angles counts);
the per-joint shares here (:func:`coverage`, :func:`covered_rows`) only explain which joints' ranges are missing.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pin_kpi_oed.discrepancy.coverage import JointCoverage
from pin_kpi_oed.identification.problem import align_data

__all__ = ["coverage", "covered_rows", "coverage_summary", "COVERAGE_TOL_RAD"]

#: A validation angle within this of a training angle of the same joint is covered (rad).
COVERAGE_TOL_RAD = 0.05


def coverage(source_q: np.ndarray, target_q: np.ndarray, tol_rad: float = 0.05) -> tuple[np.ndarray, float]:
    """Share of target rows whose joint angle lies within ``tol_rad`` of a source angle, per joint (wrapped mod 2π).

    Args:
        source_q: training configurations (m_s, n) rad.
        target_q: validation configurations (m_t, n) rad.
        tol_rad: tolerance (rad).

    Returns:
        (fraction per joint (n,), fraction of target rows covered on every joint at once).
    """
    covered = covered_rows(source_q, target_q, tol_rad)
    return covered.mean(axis=0), float(np.all(covered, axis=1).mean())


def covered_rows(source_q: np.ndarray, target_q: np.ndarray, tol_rad: float = 0.05) -> np.ndarray:
    """Which target angles lie within ``tol_rad`` of a source angle of the same joint (wrapped mod 2π).

    Args:
        source_q: training configurations (m_s, n) rad.
        target_q: validation configurations (m_t, n) rad.
        tol_rad: tolerance (rad).

    Returns:
        (m_t, n) bool: covered per row and joint.
    """
    S = np.mod(np.asarray(source_q, float) + np.pi, 2 * np.pi) - np.pi
    T = np.mod(np.asarray(target_q, float) + np.pi, 2 * np.pi) - np.pi
    covered = np.zeros(T.shape, bool)
    for j in range(T.shape[1]):
        s = np.sort(S[:, j])
        s_ext = np.concatenate([s - 2 * np.pi, s, s + 2 * np.pi])
        i = np.clip(np.searchsorted(s_ext, T[:, j]), 1, s_ext.size - 1)
        d = np.minimum(np.abs(T[:, j] - s_ext[i - 1]), np.abs(T[:, j] - s_ext[i]))
        covered[:, j] = d <= tol_rad
    return covered


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
    per_joint, _ = coverage(Qs, Qt, tol_rad)
    return {"rows_covered": JointCoverage.from_training(Qs).share_covered(Qt),
            "per_joint": {n: float(c) for n, c in zip(robot.joint_names, per_joint)}, "tol_rad": float(tol_rad)}
