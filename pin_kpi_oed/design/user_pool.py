"""Designs chosen from the user's own candidate poses (``pin-kpi-oed design --pool poses.csv``).

Taught or otherwise trusted poses are read from a CSV (joint columns named as in the URDF, rad;
other columns ignored), checked against the cell's constraints (batched
:class:`~pin_kpi_oed.cell.collision.CollisionModel`, the design's margins included) and, for
every criterion, m of the feasible ones are selected by the relaxation + exchange of
:func:`pin_kpi_oed.oed.pool.select`. The heuristic reference is m of them drawn at random (seeded).
The relaxation's equivalence-theorem bound is the certificate: no m-subset of the feasible
candidates has a lower tr(C_s) than φ*/m (A-type criteria).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from pin_kpi_oed.data.measurements import read_measurements
from pin_kpi_oed.design.optimize import DesignProblem, DesignResult
from pin_kpi_oed.errors import InfeasibleError, InputError
from pin_kpi_oed.model.robot import Robot
from pin_kpi_oed.oed.certificate import Certificate
from pin_kpi_oed.oed.criteria import get_criterion
from pin_kpi_oed.oed.pool import select

#: candidates checked per batch of the collision model (bounds the memory of 100,000 candidates)
CHUNK = 5000


def read_poses(path: str | Path, robot: Robot, what: str = "--pool") -> np.ndarray:
    """Joint configurations from a CSV (joint columns named as the robot's, rad), within the robot's limits.

    Raises:
        InputError: unreadable file, missing / wrong joint columns, values in degrees, outside the limits.
    """
    try:
        ms = read_measurements(path, joint_names=list(robot.joint_names), require_position=False)
    except InputError as exc:
        raise InputError(f"{what}: {exc}") from None
    return robot.check_q(np.asarray(ms.q, float), what)


def feasible_mask(problem: DesignProblem, Q: np.ndarray) -> np.ndarray:
    """Per candidate: every constraint of the design cell holds (collision, beam, incidence, bounds), (N,) bool."""
    return np.concatenate([problem.coll_full.feasible(Q[i:i + CHUNK]) for i in range(0, len(Q), CHUNK)]) \
        if len(Q) else np.zeros(0, bool)


def design_from_pool(problem: DesignProblem, Q_candidates: np.ndarray, criteria: list[str], m: int, seed: int = 0
                     ) -> tuple[list[DesignResult], Certificate | None, int]:
    """Select m poses from user candidates for every criterion.

    Args:
        problem: the design problem of the cell.
        Q_candidates: the user's candidates (N, n) rad.
        criteria: ``random`` and registered criterion names.
        m: poses to select.
        seed: seed of the random reference and of the exchange starts.

    Returns:
        (results: ``random`` first, then the criteria; the KPI certificate over the feasible candidates
        or None without ``kpi``; number of feasible candidates).

    Raises:
        InfeasibleError: fewer than m feasible candidates.
    """
    problem.check_measurements(m)
    ok = feasible_mask(problem, Q_candidates)
    Q = Q_candidates[ok]
    if len(Q) < m:
        raise InfeasibleError(f"--pool: only {len(Q)} of {len(Q_candidates)} candidates satisfy the cell's constraints "
                              f"(collision, beam, incidence, margins); {m} needed")
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    Qr = Q[np.sort(rng.choice(len(Q), size=m, replace=False))]
    out = [problem.result("random", Qr, problem._kpi.value(Qr), time_s=time.perf_counter() - t0, status="sampled",
                          solver_status="sampled", samples=len(Q),
                          message=f"{m} of the {len(Q)} feasible user candidates at random")]
    Fp = problem.model.weighted_jacobian(problem.p0, Q)[:, :, problem.base]
    cert = None
    for c in criteria:
        if c == "random":
            continue
        K = get_criterion(c).pool_form(problem.E, problem.base.size)
        sel = select(Fp, m, K, seed=seed)
        Qs = Q[np.sort(sel.indices)]
        out.append(problem.result(c, Qs, problem.criterion(c).value(Qs), time_s=sel.time_s, nit=sel.nit,
                                  status=sel.status, solver_status="pool", samples=len(Q), message=sel.message))
        if c == "kpi":
            a = sel.approx
            cert = Certificate(lower_bound_trace_cs_m2=a.lower_bound / m, m=m, pool_size=len(Q), samples=len(Q),
                               approx=a, pool_selection=sel.indices, pool_selection_trace_cs_m2=sel.phi, Q_pool=Q,
                               success=a.success, status=a.status, nit=a.nit, time_s=sel.time_s,
                               message=f"tr(C_s) >= {a.lower_bound / m:.4g} m^2 for every {m}-pose subset of the "
                                       f"{len(Q)} feasible user candidates")
    return out, cert, int(ok.sum())
