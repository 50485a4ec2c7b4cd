r"""Compensation keeps its branch, and says when a compensated configuration is not safe to send.

Start (reference) configuration of every target, in order of precedence:

1. the target row's joint hint (``targets.q``): the solution nearest it is wanted;
2. else the model's working configurations (``CalibratedModel.q_work``, from the cell): the one whose nominal TCP
   lies nearest the target (position in m plus ``length_m`` × orientation error in rad when the target has one);
3. else the robot's neutral configuration (then seeded random restarts).

From that start the damped least-squares IK takes minimum-norm steps, so on a redundant arm (7 joints, or a
position-only target on 6) it ends on the start's branch and near it in the null space. Checks of every
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

__all__ = ["BRANCH_STARTS", "StartConfigurations", "start_configurations", "joint_limit_rows", "collision_rows",
           "branch_step"]

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


def start_configurations(pm0: Any, q_work: np.ndarray | None, Q_hint: np.ndarray | None, pos_t: np.ndarray,
                         R_t: np.ndarray | None, aux: Any, length_m: float) -> StartConfigurations:
    """Start configurations: the hint, else the nearest working configuration, else neutral (module docstring).

    Args:
        pm0: the nominal :class:`~pin_kpi_oed.identification.compensate.PoseModel` (target frame and TCP).
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
