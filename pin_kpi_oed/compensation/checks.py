r"""Compensation keeps its branch, and says when a compensated configuration is not safe to send.

Start (reference) configuration of every target, in order of precedence:

1. the target row's joint hint (``targets.q``): the solution nearest it is wanted;
2. else the model's working configurations (``CalibratedModel.q_work``, from the cell): the one whose nominal TCP
   lies nearest the target (position in m plus ``length_m`` × orientation error in rad when the target has one);
3. else the robot's neutral configuration (then seeded random restarts).

From that start the damped least-squares IK takes minimum-norm steps, so on a redundant arm (7 joints, or a
position-only target on 6) it ends on the start's branch; :func:`nearest_to_reference` then slides the solution along
its self-motion manifold to the configuration nearest the start (null-space steps N(q_ref − q), N = I − J⁺J, each
followed by Gauss–Newton steps back onto the target), so the solution is the one nearest the hint. Checks of every
compensated configuration q (and the reason it is not ``ok``):

* ``off_branch``: the nominal IK needed a random restart although a hint or a working configuration gave the branch
  (the target is not reachable on that branch); or q lies more than ``max_branch_step_rad`` from the nominal
  solution q⁰ in some joint (compensation is a small correction: a larger step is another branch);
* ``joint_limit``: a joint of q within ``limit_margin`` (rad / m) of its limit, where the IK's clipping may have
  stopped it (the solution is then not the calibrated model's);
* ``collision``: with a cell, q not collision-free in the cell's independent check (Pinocchio + Coal).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

__all__ = ["BRANCH_STARTS", "StartConfigurations", "start_configurations", "nearest_to_reference", "joint_limit_rows",
           "collision_rows", "branch_step", "rotation_errors"]

#: Where a target's start configuration came from.
BRANCH_STARTS = ("hint", "working", "neutral")


@dataclass
class StartConfigurations:
    """Start (reference) configuration of every target.

    Attributes:
        Q: (m, n) configurations (rad / m).
        kind: per target ``hint``, ``working`` or ``neutral``.
        index: per target, the working configuration used (-1 otherwise).
    """

    Q: np.ndarray
    kind: list[str]
    index: np.ndarray


def rotation_errors(R_target: np.ndarray, R: np.ndarray) -> np.ndarray:
    """ω with exp(ω)·R = R_target for every row, (m, 3) rad."""
    return np.array([pin.log3(Rt @ Ri.T) for Rt, Ri in zip(R_target, R)]).reshape(-1, 3)


def start_configurations(pm0: Any, q_work: np.ndarray | None, Q_hint: np.ndarray | None, pos_t: np.ndarray,
                         R_t: np.ndarray | None, aux: Any, length_m: float) -> StartConfigurations:
    """Start configurations: the hint, else the nearest working configuration, else neutral (module docstring).

    Args:
        pm0: the nominal :class:`~pin_kpi_oed.compensation.compensator.PoseModel` (target frame and TCP).
        q_work: the model's working configurations (k, n), or None.
        Q_hint: joint hints of the targets (m, n), or None.
        pos_t: target positions (m, 3) m; R_t: target rotations (m, 3, 3) or None.
        aux: the targets' auxiliary columns (effects).
        length_m: weight of the orientation error (m per rad).

    Returns:
        The :class:`StartConfigurations`.
    """
    robot = pm0.robot
    m = len(pos_t)
    Q = np.tile(robot.neutral(), (m, 1))
    kind = ["neutral"] * m
    index = np.full(m, -1)
    if q_work is not None and len(q_work):
        W = np.clip(np.asarray(q_work, float), robot.q_lower, robot.q_upper)
        pos_w, R_w = pm0.pose(W, None)
        D = np.linalg.norm(pos_t[:, None, :] - pos_w[None, :, :], axis=2)
        if R_t is not None:
            D = D + length_m * np.array([[np.linalg.norm(pin.log3(Rt @ Rw.T)) for Rw in R_w] for Rt in R_t])
        index = np.argmin(D, axis=1)
        Q = W[index].copy()
        kind = ["working"] * m
    if Q_hint is not None:
        Q = np.clip(np.asarray(Q_hint, float), robot.q_lower, robot.q_upper)
        kind = ["hint"] * m
        index = np.full(m, -1)
    return StartConfigurations(Q, kind, index)


def nearest_to_reference(pm: Any, Q: np.ndarray, Q_ref: np.ndarray, pos_t: np.ndarray, R_t: np.ndarray | None,
                         weights: np.ndarray, tol_m: float, iters: int = 30) -> np.ndarray:
    """Each redundant row of Q moved along its self-motion manifold to the solution nearest Q_ref (module docstring).

    Args:
        pm: the :class:`~pin_kpi_oed.compensation.compensator.PoseModel` the rows solve (the nominal one).
        Q: converged solutions (m, n); Q_ref: their references (m, n) (rad / m).
        pos_t, R_t: the targets (m, 3) and rotations (m, 3, 3) or None (position only).
        weights: the task rows' weights (3 or 6), orientation rows in m/rad.
        tol_m: a moved row must still reach its target within this (m; rad × weight for orientation).
        iters: null-space steps per row.

    Returns:
        (m, n): each row at least as near its reference as before (rows without redundancy unchanged).
    """
    robot = pm.robot
    nr = len(weights)
    if robot.nq <= nr:
        return Q
    Q = np.array(Q, float)
    lo, hi = robot.q_lower, robot.q_upper

    def task_errors(Qr: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """The weighted task errors of configurations Qr (k, n) solving targets ``rows``: one pose evaluation."""
        pos, R = pm.pose(Qr, None)
        e = pos_t[rows] - pos
        if R_t is not None:
            e = np.hstack([e, rotation_errors(R_t[rows], R)])
        return e * weights

    def norms(X: np.ndarray) -> np.ndarray:
        """Each row's norm as ``np.linalg.norm`` of that row alone (the same rounding as one row at a time: the
        tests below compare near-equal norms)."""
        return np.array([np.linalg.norm(x) for x in X])

    def gauss_newton_step(q: np.ndarray, e: np.ndarray) -> np.ndarray:
        return np.clip(q + np.linalg.pinv(pm.jacobian(q)[:nr] * weights[:, None]) @ e, lo, hi)

    # every row takes the steps it took alone; the rows still moving share each pose evaluation
    active = np.ones(len(Q), bool)
    for _ in range(iters):
        rows = np.flatnonzero(active)
        if not rows.size:
            break
        D = np.empty((rows.size, robot.nq))
        for k, i in enumerate(rows):
            J = pm.jacobian(Q[i])[:nr] * weights[:, None]
            D[k] = (np.eye(robot.nq) - np.linalg.pinv(J) @ J) @ (Q_ref[i] - Q[i])
        still = norms(D) < 1e-9
        active[rows[still]] = False
        rows, D = rows[~still], D[~still]
        if not rows.size:
            break
        Q1 = np.clip(Q[rows] + D, lo, hi)
        back = np.ones(rows.size, bool)  # back onto the target (the null-space step leaves a second-order error)
        for _ in range(5):
            moving = np.flatnonzero(back)
            if not moving.size:
                break
            E = task_errors(Q1[moving], rows[moving])
            done = norms(E) <= 1e-10
            back[moving[done]] = False
            for k, e in zip(moving[~done], E[~done]):
                Q1[k] = gauss_newton_step(Q1[k], e)
        worse = norms(task_errors(Q1, rows)) > tol_m
        worse |= norms(Q1 - Q_ref[rows]) >= norms(Q[rows] - Q_ref[rows])
        active[rows[worse]] = False
        Q[rows[~worse]] = Q1[~worse]
    return Q


def joint_limit_rows(robot: Any, Q: np.ndarray, margin: float) -> np.ndarray:
    """Per row of Q, whether a joint lies within ``margin`` (rad / m) of its limit."""
    Q = np.atleast_2d(Q)
    return np.any((Q <= robot.q_lower + margin) | (Q >= robot.q_upper - margin), axis=1)


def collision_rows(cell: Any, Q: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """(per row, not collision-free in the cell's independent check; the pair nearest to colliding per row)."""
    from pin_kpi_oed.cell.feasibility import FeasibilityChecker

    rep = FeasibilityChecker(cell).check(np.atleast_2d(Q))
    return ~rep.collision_free, list(rep.worst)


def branch_step(Q: np.ndarray, Q_ref: np.ndarray) -> np.ndarray:
    """Largest joint difference of every row from its reference, (m,) rad / m."""
    return np.abs(np.atleast_2d(Q) - np.atleast_2d(Q_ref)).max(axis=1)
