"""One design run as a declaration: the frozen :class:`DesignSettings` of a run, :func:`design_run` that performs
it (the designs, their independent check in the untightened cell, the certificate, the extended model's and the
discrepancy's scores) and the :class:`DesignRun` it returns, which is all the design file holds
(:func:`~pin_kpi_oed.design.design_writer.write_design`; ``design --json`` writes it through the same call).
Units SI: margins in m and deg (display unit of the incidence limit, as the cell file), σ in m.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any
from collections.abc import Callable, Sequence

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
        distances: capsule distances of the optimiser (``geometry``: Coal; ``numpy``: the closed-form oracle).
        pool_file: select the poses from these candidates (CSV, joint columns in rad) instead of optimising; the
            selection's bound is the certificate.
        given_file: poses already measured (CSV, joint columns in rad): design ``measurements`` more on top of them.
        given_prior: with ``given_file``, an earlier calibration's parameter covariance
            (:class:`~pin_kpi_oed.design.problem_options.ParameterPrior`).
        model, model_file, model_prior: a calibrated model (read from ``model_file``): design over its geometry +
            effects with the prior ``model`` (its covariance), ``tolerances`` or ``none``, and with its discrepancy.
        discrepancy: a :class:`~pin_kpi_oed.discrepancy.prior.DiscrepancyPrior` instead of the model's (e.g. re-fitted
            on the measured poses); robot_class, hedge: the assumed discrepancy's class, and hedging it.
        work_radius_rad, work_samples: the working region of ``kpi_gp`` (None: the defaults,
            :func:`~pin_kpi_oed.design.region.default_region`).
        reregister: ``"work"`` or a CSV of configurations where the set-up is registered again before use.
        target_sigma_m: how many more poses until the predicted TCP σ ≤ this (m): with measured poses greedily, with
            the discrepancy by the poses-needed curve.
        poses_needed: compute the poses-needed curve (with the discrepancy).
        model_sigma_at_work: the model file's own σ at the working configurations as predict gives it
            (``sigma_m``, ``extrapolated``), for the design file. With ``discrepancy`` what
            :func:`~pin_kpi_oed.identification.design_discrepancy.model_design_inputs` returns for ``model``.
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
    distances: str = "geometry"
    pool_file: str | None = None
    given_file: str | None = None
    given_prior: Any = None
    model: Any = field(default=None, repr=False)
    model_file: str | None = None
    model_prior: str = "model"
    discrepancy: Any = field(default=None, repr=False)
    robot_class: str | None = None
    hedge: bool = True
    work_radius_rad: float | None = None
    work_samples: int | None = None
    reregister: str | None = None
    target_sigma_m: float | None = None
    poses_needed: bool = False
    model_sigma_at_work: dict | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        for name in ("n_starts", "max_iter", "start_pool_size", "certificate_pool_size"):
            if int(getattr(self, name)) < 1:
                raise InputError(f"{name}: must be >= 1, got {getattr(self, name)}")
        if self.measurements is not None and int(self.measurements) < 1:
            raise InputError(f"measurements: must be >= 1, got {self.measurements}")
        if self.start not in ("pool", "random"):
            raise InputError(f"start: 'pool' or 'random', got {self.start!r}")
        if self.given_prior is not None and not self.given_file:
            raise InputError("given_prior needs Q_given (the poses already measured)")
        if self.target_sigma_m is not None and not self.target_sigma_m > 0:
            raise InputError(f"target_sigma_m: must be > 0 m, got {self.target_sigma_m}")
        if self.model_prior not in ("model", "tolerances", "none"):
            raise InputError(f"model_prior: 'model', 'tolerances' or 'none', got {self.model_prior!r}")


@dataclass(frozen=True)
class DesignRun:
    """One design run: everything its design file holds (SI units).

    Attributes:
        cell: the cell the designs are checked in (the untightened one).
        problem: the :class:`~pin_kpi_oed.design.optimize.DesignProblem` (its options: measured poses, extended model,
            discrepancy, working region).
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
        answers: the lines answering ``target_sigma_m`` / the poses-needed curve (what they were taken over).
        model_sigma_at_work: the model file's own σ at the working configurations (:class:`DesignSettings`).
        nests: with a cell listing several reflector nests, every design's
            :class:`~pin_kpi_oed.oed.nests.NestDesign` (the nest of each pose by the TCP's tr C_s), else None.
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
    answers: tuple[str, ...] = ()
    model_sigma_at_work: dict | None = None
    nests: Sequence[Any] | None = None


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
               discrepancy: bool | None = None, say: Callable[[str], None] | None = None) -> DesignRun:
    """Perform a design run: the designs (:func:`~pin_kpi_oed.design.optimize.run_designs`, or the selection from the
    user's pool) in the cell tightened by the margins, their independent check in ``cell``, the certificate, the
    extended model's scores, with a discrepancy the honest scores, and the answers to ``target_sigma_m`` / the
    poses-needed curve.

    Args:
        cell: the cell (untightened).
        settings: the run's :class:`DesignSettings` (default: the defaults).
        problem: a prepared design problem on the tightened cell, else declared from the settings
            (:func:`~pin_kpi_oed.design.declare.design_problem`).
        discrepancy: score with the discrepancy (default: when the problem has one or a criterion of the
            discrepancy is designed).
        say: receives the lines worth printing while the run goes (the pool's candidates, the extended model).

    Returns:
        The :class:`DesignRun`.

    Raises:
        PinKpiOedError: bad cell, unknown criterion, infeasible cell, solver failure, an answer the settings cannot
            give (``target_sigma_m`` without measured poses or a discrepancy).
    """
    from pin_kpi_oed.design.declare import design_problem, uses_discrepancy
    from pin_kpi_oed.design.path_profile import path_profiles
    from pin_kpi_oed.design.scores import discrepancy_scores, extended_scores

    s = settings or DesignSettings()
    say = say or _silent
    margins = (float(s.clearance_margin_m), float(s.incidence_margin_deg))
    problem = problem or design_problem(cell, s)
    m = int(s.measurements or cell.measurements)
    if discrepancy is None:
        discrepancy = problem.discrepancy is not None or bool(uses_discrepancy(s.criteria))
    if s.target_sigma_m is not None and not discrepancy:
        if problem.Q_given is None:
            raise InputError("target_sigma_m needs Q_given (the poses already measured) or the discrepancy (a "
                             "discrepancy-aware criterion such as kpi_gp, or model_file with a discrepancy)")
        problem.require_identified(f"target_sigma_m: Q_given {s.given_file}")  # before any work
    if s.pool_file:
        from pin_kpi_oed.design.user_pool import select_from_file

        results, cert, checked = select_from_file(problem, s.pool_file, s.criteria, m, s.seed, say)
    else:
        results, cert, checked = _optimised(problem, s, m), None, None
        if s.certificate:
            from pin_kpi_oed.design.optimality import certify

            cert = certify(problem, m, pool_size=s.certificate_pool_size, seed=s.seed,
                           extra=[r.q_meas for r in results if r.feasible],
                           fixed_info=problem.fixed_information() if problem.F_given is not None else None)
    until, curve, answers = _answers(problem, s, m, bool(discrepancy), checked, results)
    return DesignRun(cell=cell, problem=problem, results=results, m=m, seed=s.seed, collision=s.collision,
                     margins=margins, true_checks=true_checks(cell, results) if problem.cell is not cell else None,
                     certificate=cert, extended_scores=extended_scores(problem, results, cell.q_work),
                     discrepancy_scores=discrepancy_scores(problem, results) if discrepancy else None,
                     path_profiles=path_profiles(problem, results, discrepancy=bool(discrepancy)),
                     given_file=s.given_file, pool_file=s.pool_file,
                     model_file=s.model_file, prior=s.model_prior if s.model is not None else None, until=until,
                     poses_needed=curve, answers=answers, model_sigma_at_work=s.model_sigma_at_work,
                     nests=design_nests(cell, results, s.seed))


def design_nests(cell: Cell, results: Sequence[Any], seed: int = 0) -> list | None:
    """Each design's nests (:func:`~pin_kpi_oed.oed.nests.assign_nests` on its poses at the cell's working
    configurations) when the cell lists several reflector nests, else None.

    Args:
        cell: the cell (``nests_m``, TCP, working configurations); results: the designs (``q_meas`` (m, n) rad);
        seed: the structural analysis's excitation.

    Returns:
        One :class:`~pin_kpi_oed.oed.nests.NestDesign` per design (None for a design whose poses do not identify
        the parameters of nest 0: it measures nest 0), or None.
    """
    if cell.nests_m is None or len(cell.nests_m) < 2 or cell.q_work.shape[0] == 0:
        return None
    from pin_kpi_oed.errors import IdentifiabilityError
    from pin_kpi_oed.oed.nests import assign_nests

    model, out = cell.tracker_model(), []
    for r in results:
        try:
            out.append(assign_nests(model, r.q_meas, cell.q_work, seed=seed))
        except IdentifiabilityError:
            out.append(None)
    return out


def _silent(line: str) -> None:
    """Say nothing."""


def _optimised(problem: Any, s: DesignSettings, m: int) -> list:
    """The heuristic and the optimised designs (IPOPT from the pool start) of the settings."""
    from pin_kpi_oed.design.optimize import DesignOptions, ipopt_options, run_designs

    opts = DesignOptions(collision=s.collision, n_starts=s.n_starts, ipopt=ipopt_options(max_iter=s.max_iter),
                         start=s.start, pool_size=s.start_pool_size)
    return run_designs(problem.cell, list(s.criteria), m, s.seed, opts, problem)


def _answers(problem: Any, s: DesignSettings, m: int, discrepancy: bool, checked: Any, results: list
             ) -> tuple[Any, Any, tuple[str, ...]]:
    """(how many more poses until ``target_sigma_m`` on top of the measured ones, the poses-needed curve with the
    discrepancy, the lines that state them): over the user's feasible pool candidates (``checked``: (poses, their
    Jacobians)) or random feasible poses of the tightened cell."""
    import numpy as np

    until = curve = None
    lines: list[str] = []
    if discrepancy and (s.target_sigma_m is not None or s.poses_needed):
        from pin_kpi_oed.oed.discrepancy_kpi import poses_needed

        if checked is not None:
            Q_pool, what = checked[0], "feasible candidates of Q_candidates"
        else:
            size = min(s.certificate_pool_size, 2000)
            Q_pool, _ = problem.random_design(size, seed=np.random.SeedSequence([s.seed, 3]),
                                              max_tries=max(problem.cell.max_random_tries, 200 * size))
            # the optimised designs' own poses join the random ones (as in the certificate's pool): the curve and its
            # plateau never claim less than a design of the table reaches
            extra = [np.asarray(r.q_meas, float) for r in results if r.criterion != "random" and r.feasible]
            Q_pool = np.vstack([Q_pool] + extra) if extra else Q_pool
            what = "feasible candidates: random" + (" + the designs' poses" if extra else "")
        n_max = min(len(Q_pool), max(4 * m, 120))
        curve = poses_needed(problem.gp_criterion(region=False), Q_pool, n_max, target_sigma_m=s.target_sigma_m,
                             seed=s.seed)
        lines.append(curve.summary() + f" ({len(Q_pool)} {what}, {curve.time_s:.1f} s)")
    elif s.target_sigma_m is not None:
        from pin_kpi_oed.design.sequential import poses_until

        if checked is not None:
            until = poses_until(problem, float(s.target_sigma_m), checked[0], Fp=checked[1])
            lines.append(until.summary() + f" (from the {len(checked[0])} feasible candidates of Q_candidates)")
        else:
            size = s.certificate_pool_size
            Q_pool, _ = problem.random_design(size, seed=np.random.SeedSequence([s.seed, 2]),
                                              max_tries=max(problem.cell.max_random_tries, 200 * size))
            until = poses_until(problem, float(s.target_sigma_m), Q_pool)
            lines.append(until.summary())
    return until, curve, tuple(lines)
