"""Designs chosen from the user's own candidate poses (``pin-kpi-oed design --pool poses.csv``).

Taught or otherwise trusted poses are read from a CSV (joint columns named as in the URDF, rad;
other columns ignored) and checked against the design cell's constraints (the margins included):
the feasible set is **the independent Coal check's** (:class:`~pin_kpi_oed.cell.feasibility.FeasibilityChecker`,
its tolerances), obtained fast: the optimiser's batched capsule model
(:meth:`~pin_kpi_oed.cell.collision.CollisionModel.row_minima`) decides every candidate whose smallest
clearance row and incidence row are farther than :data:`BAND_M` / :data:`BAND_COS` from the
checker's thresholds (both compute the same capsule distances, to ~1e-15 m), and Coal decides the
few within the band. For every criterion, m of the feasible ones are selected by the relaxation +
exchange of :func:`pin_kpi_oed.oed.pool.select`; the heuristic reference is m of them drawn at
random (seeded). The relaxation's equivalence-theorem bound is the certificate: no m-subset of the
feasible candidates has a lower tr(C_s) than φ*/m (A-type criteria).

With poses already measured (a problem declared with ``Q_given``, ``--pool`` with
``--given``) their information F_gᵀF_g (+ a prior) is the fixed part M₀ of every selection and of
the certificate (:func:`pin_kpi_oed.oed.pool.select` with ``fixed_info``).
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from pin_kpi_oed.data.measurements import read_measurements
from pin_kpi_oed.design.optimize import DesignProblem, DesignResult
from pin_kpi_oed.errors import IdentifiabilityError, InfeasibleError, InputError
from pin_kpi_oed.model.robot import Robot
from pin_kpi_oed.oed.certificate import Certificate
from pin_kpi_oed.oed.objective import DesignCriterion
from pin_kpi_oed.oed.selection_result import PoolSelection
from pin_kpi_oed.threads import limited_threads

#: candidates checked per batch (bounds the memory of 100,000 candidates; Jacobians of 5,000 at a time are
#: also twice as fast as of 100,000: cache)
CHUNK = 5000
#: the independent check's tolerances (:meth:`FeasibilityChecker.check`): clearance (m), joint bounds (rad / m)
CHECK_TOL_M = 1e-7
#: ... and on cos(incidence) − cos(limit)
CHECK_TOL_COS = 1e-9
#: candidates whose smallest clearance row lies within this of the check's threshold go to Coal (m)
BAND_M = 1e-6
#: the same for the incidence row (cosine)
BAND_COS = 1e-8


def _data_lines(path: str | Path) -> list[int]:
    """File line numbers (from 1) of the data rows of a CSV (read again only for a message)."""
    from pin_kpi_oed.data.table import read_text_table

    return list(read_text_table(path, str(path), "pose file")[3])


def read_poses(path: str | Path, robot: Robot, what: str = "Q_candidates") -> np.ndarray:
    """Joint configurations from a CSV (joint columns named as the robot's, rad), within the robot's limits.

    Values within the 1e-9 rad (m) reading tolerance beyond a limit are put on the limit.

    Raises:
        InputError: unreadable file, missing / wrong joint columns, values in degrees, outside the limits.
    """
    try:
        ms = read_measurements(path, joint_names=list(robot.joint_names), require_position=False)
    except InputError as exc:  # advice about options design does not have becomes what to do with the file
        msg = str(exc).replace(" or declare the units (units='mm,deg')", " in the file")
        msg = re.sub(r"map other names with columns='[^']*'", "rename the file's columns to the robot's joint names",
                     msg)
        raise InputError(f"{what}: {msg}") from None
    Q = robot.check_q(np.asarray(ms.q, float), f"{what} {path}", line_of=lambda i: _data_lines(path)[i])
    return np.clip(Q, robot.q_lower, robot.q_upper)


def read_pool(path: str | Path, robot: Robot, what: str = "Q_candidates") -> tuple[np.ndarray, np.ndarray]:
    """Candidate configurations from a CSV (joint columns named as the robot's, rad): those outside the joint bounds
    are dropped (and returned by row), not refused; values within 1e-9 rad (m) beyond a bound are put on it.

    Args:
        path: the pose file.
        robot: the robot (its bounds are the cell's).
        what: the option, for messages.

    Returns:
        (the candidates within the bounds (N, n) rad, 1-based data-row numbers of those outside).

    Raises:
        InputError: unreadable file, missing / wrong joint columns, values in degrees or not finite, or no
            candidate within the bounds.
    """
    try:
        ms = read_measurements(path, joint_names=list(robot.joint_names), require_position=False)
    except InputError as exc:
        raise InputError(f"{what}: {exc}") from None
    Q = np.asarray(ms.q, float)
    if not np.all(np.isfinite(Q)):
        robot.check_q(Q, f"{what} {path}")  # names the first non-finite value
    tol = 1e-9
    inside = np.all((Q >= robot.q_lower - tol) & (Q <= robot.q_upper + tol), axis=1)
    if not inside.any():
        raise InputError(f"{what} {path}: none of its {len(Q)} candidates lies within the cell's joint bounds")
    return np.clip(Q[inside], robot.q_lower, robot.q_upper), np.flatnonzero(~inside) + 1


def pool_line(path: str | Path, n_read: int, outside_rows: np.ndarray, n_feasible: int, reasons: dict) -> str:
    """One line: how many candidates the pool file held, how many are feasible, how many were dropped and why."""
    dropped = n_read - n_feasible
    why = []
    if len(outside_rows):
        rows = ", ".join(map(str, outside_rows[:5])) + (" ..." if len(outside_rows) > 5 else "")
        why.append(f"{len(outside_rows)} outside the cell's joint bounds (rows {rows})")
    why += [f"{n} {what}" for what, n in reasons.items() if n]
    return (f"Q_candidates: {n_read} candidates in {path}: {n_feasible} feasible" +
            (f", {dropped} dropped ({'; '.join(why)})" if dropped else ""))


#: candidates closer than this in every joint (rad, m) are one pose for :func:`near_duplicates`
DUPLICATE_TOL = 1e-6


def near_duplicates(Q: np.ndarray, tol: float = DUPLICATE_TOL) -> list[np.ndarray]:
    """Groups of candidates that are the same pose up to ``tol`` in every joint (rad, m), largest first.

    Args:
        Q: candidates (N, n).
        tol: joint tolerance.

    Returns:
        The groups of two or more (0-based indices into Q, ascending), largest group first.
    """
    Q = np.atleast_2d(np.asarray(Q, float))
    if len(Q) < 2:
        return []
    _, inverse, counts = np.unique(np.floor(Q / tol + 0.5).astype(np.int64), axis=0, return_inverse=True,
                                   return_counts=True)
    inverse = inverse.reshape(-1)
    groups = [np.flatnonzero(inverse == g) for g in np.flatnonzero(counts > 1)]
    return sorted(groups, key=lambda g: (-len(g), g[0]))


def duplicates_line(path: str | Path, Q: np.ndarray, rows: np.ndarray) -> str | None:
    """One line naming the near-duplicate candidates (by their 1-based data rows ``rows``), None when there are none."""
    groups = near_duplicates(Q)
    if not groups:
        return None
    distinct = len(Q) - sum(len(g) - 1 for g in groups)
    shown = "; ".join("rows " + ", ".join(map(str, rows[g[:5]])) + (f" (+{len(g) - 5} more)" if len(g) > 5 else "")
                      for g in groups[:3])
    more = f"; {len(groups) - 3} more group{'s' if len(groups) > 4 else ''}" if len(groups) > 3 else ""
    return (f"Q_candidates {path}: the {len(Q)} feasible candidates are only {distinct} distinct poses (the same pose "
            f"within {DUPLICATE_TOL:g} rad: {shown}{more}), too few varied ones to identify the parameters; "
            "give more varied candidates")


def check_candidates(problem: DesignProblem, Q: np.ndarray, with_jacobians: bool = True,
                     timings: dict | None = None, reasons: dict | None = None
                     ) -> tuple[np.ndarray, np.ndarray | None, int]:
    """The candidates the independent check accepts in the design cell, and their weighted Jacobians.

    Per chunk of :data:`CHUNK`: the batched rows decide the candidates clear of the check's
    thresholds by more than the band; :meth:`FeasibilityChecker.check` (Coal) decides the others (in a
    cell with environment files, every candidate the rows do not clear: their capsules enclose meshes);
    then the weighted Jacobians of the feasible ones over the identifiable parameters.

    Args:
        problem: the design problem (its ``coll_full`` and ``checker`` are of the design cell).
        Q: candidates (N, n) rad.
        with_jacobians: also return the feasible candidates' weighted Jacobians.
        timings: if given, ``check_s`` and ``jacobians_s`` (s) are added to it.
        reasons: if given, the rejected candidates are counted into it by reason: ``outside the joint bounds``,
            ``beyond the incidence limit``, ``in collision or blocking the beam`` (clearance, margins included).

    Returns:
        (feasible mask (N,), Jacobians (n_feasible, nh, nb) or None, candidates decided by Coal).
    """
    cm, cell = problem.coll_full, problem.cell
    N = len(Q)
    ok = np.zeros(N, bool)
    F, n_coal, t_chk, t_jac = [], 0, 0.0, 0.0
    with limited_threads():
        for a in range(0, N, CHUNK):
            t0 = time.perf_counter()
            q = Q[a:a + CHUNK]
            inb = np.all((q >= cell.q_lower - CHECK_TOL_M) & (q <= cell.q_upper + CHECK_TOL_M), axis=1)
            dmin, inc = cm.row_minima(q, exact_below=-CHECK_TOL_M + BAND_M)
            sure = inb & (dmin >= -CHECK_TOL_M + BAND_M) & (inc >= -CHECK_TOL_COS + BAND_COS)
            near = inb & ~sure & (inc >= -CHECK_TOL_COS - BAND_COS)
            if not cell.environment:  # else the rows hold enclosing capsules of meshes Coal checks as they are:
                near &= dmin >= -CHECK_TOL_M - BAND_M  # a row violation there is no verdict, Coal decides
            if near.any():
                sure[near] = problem.checker.check(q[near], tol=CHECK_TOL_M).feasible
                n_coal += int(near.sum())
            ok[a:a + CHUNK] = sure
            if reasons is not None:
                _count_reasons(reasons, ~sure, inb, inc)
            t1 = time.perf_counter()
            if with_jacobians and sure.any():
                F.append(problem.model.weighted_jacobian(problem.p0, q[sure])[:, :, problem.base])
            t_chk += t1 - t0
            t_jac += time.perf_counter() - t1
    if timings is not None:
        timings["check_s"] = timings.get("check_s", 0.0) + t_chk
        timings["jacobians_s"] = timings.get("jacobians_s", 0.0) + t_jac
    Fp = None
    if with_jacobians:
        Fp = np.concatenate(F) if F else np.zeros((0, problem.model.nh, problem.base.size))
    return ok, Fp, n_coal


def _count_reasons(reasons: dict, rejected: np.ndarray, inb: np.ndarray, inc: np.ndarray) -> None:
    """Add the rejected candidates of a chunk to ``reasons`` (bounds, incidence row, else clearance / beam)."""
    bad_inc = rejected & inb & (inc < -CHECK_TOL_COS)
    for what, n in (("outside the joint bounds", rejected & ~inb), ("beyond the incidence limit", bad_inc),
                    ("in collision or blocking the beam", rejected & inb & ~bad_inc)):
        reasons[what] = reasons.get(what, 0) + int(n.sum())


def feasible_mask(problem: DesignProblem, Q: np.ndarray) -> np.ndarray:
    """Per candidate: the independent check accepts it in the design cell (collision, beam, incidence, bounds), (N,)
    bool."""
    return check_candidates(problem, Q, with_jacobians=False)[0]


def selection_efficiency(sel: PoolSelection, m: int, nb: int | None = None) -> float:
    """Efficiency of a pool selection against its relaxation's certificate (≤ 1).

    A-type: (φ*/m) / φ(ξ) (:meth:`PoolSelection.efficiency`). D-type (−log det): the D-efficiency
    (det M(ξ) / det M*)^(1/nb) ≥ exp(−(φ(ξ) − (φ* − nb log m)) / nb), φ* the certified bound per unit measure.

    Args:
        sel: the selection (its ``phi`` and ``approx.lower_bound``).
        m: selected poses.
        nb: the number of parameters if the criterion's pool form is −log det M (K None); None for A-type.

    Returns:
        The efficiency's lower bound, in (0, 1].
    """
    if nb is None:
        return sel.efficiency()
    return float(np.exp(-(sel.value - (sel.approx.lower_bound - nb * np.log(m))) / nb))


def design_from_pool(problem: DesignProblem, Q_candidates: np.ndarray, criteria: list[str], m: int, seed: int = 0,
                     timings: dict | None = None, checked: tuple[np.ndarray, np.ndarray] | None = None
                     ) -> tuple[list[DesignResult], Certificate | None, int]:
    """Select m poses from user candidates for every criterion.

    With measured poses (a problem declared with ``Q_given``) their information
    (and its prior) is the fixed part of every selection, of every score and of the certificate.

    Args:
        problem: the design problem of the cell (with or without measured poses).
        Q_candidates: the user's candidates (N, n) rad.
        criteria: ``random`` and registered criterion names.
        m: poses to select.
        seed: seed of the random reference and of the exchange starts.
        timings: if given, filled with the time per stage (s): ``check_s``, ``jacobians_s``, ``select_<criterion>_s``
            (and its CPU time ``select_<criterion>_cpu_s``), and each selection's efficiency against its certificate,
            ``efficiency_<criterion>``
            (:func:`selection_efficiency`).
        checked: (feasible mask, their Jacobians) of :func:`check_candidates` if already computed.

    Returns:
        (results: ``random`` first, then the criteria; the KPI certificate over the feasible candidates
        or None without ``kpi``; number of feasible candidates).

    Raises:
        InfeasibleError: fewer than m feasible candidates.
    """
    problem.check_measurements(m)
    ok, Fp = checked if checked is not None else check_candidates(problem, Q_candidates, timings=timings)[:2]
    Q = Q_candidates[ok]
    if len(Q) < m:
        raise InfeasibleError(f"Q_candidates: only {len(Q)} of {len(Q_candidates)} "
                              f"candidates satisfy the cell's constraints "
                              f"(collision, beam, incidence, margins); {m} needed")
    on_top = f" on top of the {len(problem.Q_given)} measured poses" if problem.Q_given is not None else ""
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    Qr = Q[np.sort(rng.choice(len(Q), size=m, replace=False))]
    out = [problem.result("random", Qr, problem.kpi_criterion.value(Qr), time_s=time.perf_counter() - t0,
                          status="sampled",
                          solver_status="sampled", samples=len(Q),
                          message=f"{m} of the {len(Q)} feasible user candidates at random{on_top}")]
    cert = None
    for c in criteria:
        if c == "random":
            continue
        obj = problem.criterion(c)
        t0, c0 = time.perf_counter(), time.process_time()
        # the noise-only information: relaxation + certificate over the checked candidates' Jacobians; every other
        # information model or criterion of the configurations: its own greedy + exchange (no certificate exists)
        sel = obj.select(Q, m, seed=seed, Fp=Fp) if isinstance(obj, DesignCriterion) else obj.select(Q, m, seed=seed)
        if timings is not None:
            timings[f"select_{c}_s"] = time.perf_counter() - t0
            timings[f"select_{c}_cpu_s"] = time.process_time() - c0
            if sel.approx is not None:
                K = obj.crit.pool_form(problem.E, problem.base.size) if isinstance(obj, DesignCriterion) else None
                timings[f"efficiency_{c}"] = selection_efficiency(sel, m, problem.base.size if K is None else None)
        Qs = Q[np.sort(sel.indices)]
        out.append(problem.result(c, Qs, obj.value(Qs), time_s=sel.time_s, nit=sel.nit, status=sel.status,
                                  solver_status="pool", samples=len(Q), message=sel.message))
        if c == "kpi" and sel.approx is not None:
            a = sel.approx
            cert = Certificate(lower_bound_trace_cs_m2=a.lower_bound / m, m=m, pool_size=len(Q), samples=len(Q),
                               approx=a, pool_selection=sel.indices, pool_selection_trace_cs_m2=sel.value, Q_pool=Q,
                               success=a.success, status=a.status, nit=a.nit, time_s=sel.time_s,
                               message=f"tr(C_s) >= {a.lower_bound / m:.4g} m^2 for every {m}-pose subset of the "
                                       f"{len(Q)} feasible user candidates{on_top}")
    return out, cert, int(ok.sum())


def select_from_file(problem: DesignProblem, path: str, criteria: Sequence[str], m: int, seed: int = 0,
                     say: Callable[[str], None] | None = None
                     ) -> tuple[list[DesignResult], Certificate | None, tuple[np.ndarray, np.ndarray]]:
    """The designs of a user's pool file (``design --pool``): the candidates read (:func:`read_pool`), checked
    (:func:`check_candidates`; ``say`` gets :func:`pool_line`) and selected from (:func:`design_from_pool`).

    Returns:
        (the designs, the certificate or None, (the feasible candidates (N, n) rad, their weighted Jacobians)).

    Raises:
        InputError: an unreadable file; InfeasibleError: fewer than m feasible candidates; IdentifiabilityError:
            the feasible candidates are too few distinct poses (their rows named, :func:`duplicates_line`).
    """
    Qc, outside = read_pool(path, problem.cell.robot)
    reasons: dict[str, int] = {}
    ok, Fp, _ = check_candidates(problem, Qc, reasons=reasons)
    if say is not None:
        say(pool_line(path, len(Qc) + len(outside), outside, int(ok.sum()), reasons))
    assert Fp is not None  # with_jacobians
    try:
        results, cert, _ = design_from_pool(problem, Qc, list(criteria), m, seed, checked=(ok, Fp))
    except IdentifiabilityError as exc:  # near-duplicate candidates: name their rows
        rows = np.setdiff1d(np.arange(1, len(Qc) + len(outside) + 1), outside)[ok]
        raise IdentifiabilityError(duplicates_line(path, Qc[ok], rows) or f"Q_candidates {path}: {exc}") from None
    return results, cert, (Qc[ok], Fp)
