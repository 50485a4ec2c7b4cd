"""One design run as a declaration: the frozen :class:`DesignSettings` of a run, :func:`design_run` that performs
it (the designs, their independent check in the untightened cell, the certificate, the extended model's and the
discrepancy's scores) and the :class:`DesignRun` it returns, which is all the design file holds
(:func:`~pin_kpi_oed.design.design_writer.write_design`; ``design --json`` writes it through the same call).
Units SI: margins in m and deg (display unit of the incidence limit, as the cell file), σ in m.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any
from collections.abc import Sequence

from pin_kpi_oed.cell.cell import Cell
from pin_kpi_oed.errors import InputError

__all__ = ["DesignSettings", "DesignRun", "design_run", "true_checks"]


@dataclass(frozen=True)
class DesignSettings:
    """What a design run is asked for (frozen: a run is one declaration).

    Attributes:
        criteria: ``random`` and registered criterion names (the heuristic design is always computed first).
        measurements: poses per design (None: the cell's).
        seed: seed of the heuristic design, the pool start, the starts and the certificate's pool.
        collision: collision and line-of-sight constraints (False: joint bounds and incidence only).
        n_starts: IPOPT starts per criterion; max_iter: IPOPT iterations per start.
        start: ``pool`` (the criterion's pool selection) or ``random`` (the heuristic design).
        start_pool_size: feasible candidates of the pool start.
        certificate: compute the optimality certificate (relaxation bound of tr(C_s) over a feasible pool of
            ``certificate_pool_size`` candidates plus the designs' poses).
        clearance_margin_m, incidence_margin_deg: the margins the optimiser designs with (the checks and the
            reported clearances use the untightened cell).
    """

    criteria: tuple[str, ...] = ("random", "param", "kpi")
    measurements: int | None = None
    seed: int = 0
    collision: bool = True
    n_starts: int = 2
    max_iter: int = 500
    start: str = "pool"
    start_pool_size: int = 1000
    certificate: bool = False
    certificate_pool_size: int = 5000
    clearance_margin_m: float = 0.0
    incidence_margin_deg: float = 0.0

    def __post_init__(self) -> None:
        for name in ("n_starts", "max_iter", "start_pool_size", "certificate_pool_size"):
            if int(getattr(self, name)) < 1:
                raise InputError(f"{name}: must be >= 1, got {getattr(self, name)}")
        if self.measurements is not None and int(self.measurements) < 1:
            raise InputError(f"measurements: must be >= 1, got {self.measurements}")
        if self.start not in ("pool", "random"):
            raise InputError(f"start: 'pool' or 'random', got {self.start!r}")


@dataclass(frozen=True)
class DesignRun:
    """One design run: everything its design file holds (SI units).

    Attributes:
        cell: the cell the designs are checked in (the untightened one).
        problem: the :class:`~pin_kpi_oed.design.optimize.DesignProblem` (with measured poses a
            :class:`~pin_kpi_oed.design.sequential.SequentialProblem`).
        results: the designs, ``random`` first.
        m: measurements per design; seed: the run's seed; collision: collision avoidance was on.
        margins: clearance (m) and incidence (deg) margins the optimiser designed with.
        given_file, pool_file: the measured poses designed on top of; the user pool selected from.
        until: the "how many more poses" answer; poses_needed: the predicted σ against the number of poses.
        true_checks: the independent check of every design in ``cell`` (with margins).
        certificate: the optimality certificate; extended_scores: the extended model's scores (``model_file``,
            ``prior``: where they came from); discrepancy_scores: the honest scores with the discrepancy.
        path_profiles: σ of the TCP and of the tool orientation along the cell's working paths per design
            (:func:`~pin_kpi_oed.design.path_profile.path_profiles`), None without paths.
    """

    cell: Cell
    problem: Any
    results: Sequence[Any]
    m: int
    seed: int
    collision: bool = True
    margins: tuple[float, float] = (0.0, 0.0)
    given_file: str | None = None
    pool_file: str | None = None
    until: Any = None
    true_checks: Sequence[Any] | None = None
    certificate: Any = None
    extended_scores: Sequence[dict] | None = None
    model_file: str | None = None
    prior: str | None = None
    discrepancy_scores: Sequence[dict] | None = None
    poses_needed: Any = field(default=None)
    path_profiles: Sequence[dict] | None = None


def true_checks(cell: Cell, results: Sequence[Any]) -> list:
    """Independent check of every design in the untightened cell; the results report its true clearance and
    incidence."""
    from pin_kpi_oed.cell.feasibility import FeasibilityChecker

    checker = FeasibilityChecker(cell)
    reps = [checker.check(r.q_meas) for r in results]
    for r, rep in zip(results, reps):
        r.min_clearance_m, r.max_incidence_deg = rep.min_clearance_m, rep.max_incidence_deg
    return reps


def design_run(cell: Cell, settings: DesignSettings | None = None, problem: Any = None, *,
               discrepancy: bool | None = None) -> DesignRun:
    """Perform a design run: the designs (:func:`~pin_kpi_oed.design.optimize.run_designs`) in the cell tightened
    by the margins, their independent check in ``cell``, the certificate, the extended model's scores and, with a
    discrepancy, the honest scores.

    Args:
        cell: the cell (untightened).
        settings: the run's :class:`DesignSettings` (default: the defaults).
        problem: a prepared design problem on the tightened cell (measured poses, extended model, discrepancy,
            working region), else built from ``cell`` and the settings.
        discrepancy: score with the discrepancy (default: when the problem has one or a criterion of the
            discrepancy is designed).

    Returns:
        The :class:`DesignRun`.

    Raises:
        PinKpiOedError: bad cell, unknown criterion, infeasible cell, solver failure.
    """
    from pin_kpi_oed.design.margins import with_margins
    from pin_kpi_oed.design.optimize import DesignOptions, DesignProblem, ipopt_options, run_designs
    from pin_kpi_oed.design.path_profile import path_profiles
    from pin_kpi_oed.design.scores import discrepancy_scores, extended_scores
    from pin_kpi_oed.oed.criteria import get_criterion

    s = settings or DesignSettings()
    margins = (float(s.clearance_margin_m), float(s.incidence_margin_deg))
    tight = with_margins(cell, *margins)
    problem = problem or DesignProblem(tight, collision=s.collision)
    m = int(s.measurements or cell.measurements)
    opts = DesignOptions(collision=s.collision, n_starts=s.n_starts, ipopt=ipopt_options(max_iter=s.max_iter),
                         start=s.start, pool_size=s.start_pool_size)
    results = run_designs(problem.cell, list(s.criteria), m, s.seed, opts, problem)
    checks = true_checks(cell, results) if tight is not cell else None
    cert = None
    if s.certificate:
        from pin_kpi_oed.design.optimality import certify

        given = getattr(problem, "F_given", None) is not None
        cert = certify(problem, m, pool_size=s.certificate_pool_size, seed=s.seed,
                       extra=[r.q_meas for r in results if r.feasible],
                       fixed_info=problem.fixed_information() if given else None)
    if discrepancy is None:
        discrepancy = problem.discrepancy is not None or any(
            c != "random" and getattr(get_criterion(c), "uses_discrepancy", False) for c in s.criteria)
    return DesignRun(cell=cell, problem=problem, results=results, m=m, seed=s.seed, collision=s.collision,
                     margins=margins, true_checks=checks, certificate=cert,
                     extended_scores=extended_scores(problem, results, cell.q_work),
                     discrepancy_scores=discrepancy_scores(problem, results) if discrepancy else None,
                     path_profiles=path_profiles(problem, results, discrepancy=bool(discrepancy)))
