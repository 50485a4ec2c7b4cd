"""Optimum experimental design with collision avoidance, solved by IPOPT (paper eqs. 7a–7b, 24a–24e).

The general OED problem min φ(C(q)) s.t. ψ(q) ≥ 0 (eq. 7) with the paper's choices (eq. 24).

The design problem for m measurement configurations Q = (q₁ … q_m) is::

    min_Q   φ(C(Q)) / φ(C(Q₀))                          (24a; e.g. φ = tr C_s, the KPI criterion)
    s.t.    q_lo ≤ q_i ≤ q_hi                           (joint bounds, as variable bounds)
            g(q_i) ≥ δ            for every i           (24b: capsule pairs, half-spaces, laser beam,
                                                         incidence; :mod:`pin_kpi_oed.cell.collision`)

with C_p = (FᵀF)⁻¹ over the identifiable parameters, F = Σ⁻¹ ∂h/∂p (24d), C_s = E C_p Eᵀ with
E = ∂TCP/∂p at the working configurations (24c, 24e), and δ a small buffer (0.1 mm, 1e-5 in cos β)
so that Ipopt's constraint tolerance can never turn into a collision of the final check.

Formulation choices that make it fast (``benchmarks/bench_design.py`` measures them). A naive
formulation — one Ipopt row per capsule pair and configuration (60 rows × 60 configurations for the
KR 15 cell) — spends ~90 % of its time inside Ipopt: with a limited-memory Hessian each iteration
factorises the KKT system and back-solves it for every quasi-Newton correction pair, so the cost
per iteration grows with the number of rows (≈ 60 ms at 3,600 rows against ≈ 10 ms at 120), and
the barrier terms of thousands of nearly-active rows slow the progress. Here:

* **pruning**: rows that can never be active (distance bounds over the whole joint range) are dropped;
* **aggregation per configuration with exact gradients**: each configuration keeps one smooth
  Kreisselmeier–Steinhauser row over its distance rows, c = d_min − ℓ log Σ exp(−(d_p − d_min)/ℓ)
  (ℓ = 2 mm), whose gradient is the exact softmax-weighted sum of the pairs' exact gradients, plus
  its incidence row; c ≤ min_p d_p, so c ≥ 0 never admits a collision (conservative by < ℓ·ln N,
  typically < 1 mm); 2 rows per configuration instead of ~60;
* **sparse, block-diagonal Jacobian**: each row depends on one configuration only;
* **one batched call** evaluates all rows of all configurations (and one the criterion), cached by x:
  Ipopt asks for the constraints and then the Jacobian at the same point;
* **objective scaled by its value at the start** (tr C_s ≈ 1e-12 m²; log criteria shifted instead),
  exact gradient dφ/dQ from :class:`~pin_kpi_oed.oed.criteria.DesignCriterion`;
* **feasible start**: the heuristic design (uniform random, rejection-sampled), so Ipopt starts
  interior; **multi-start** from further seeded random feasible designs;
* limited-memory Hessian (6 pairs, yᵀy/sᵀy initialisation), adaptive barrier update, tolerances
  relative to the scaled objective (:func:`ipopt_options`), one BLAS/OpenMP thread (:mod:`pin_kpi_oed.threads`).

The run also stops when the lowest objective of all iterates has improved by less than 0.1 % over
50 iterations (status ``stalled``); on the KR 15 cell the result is within ~3 % of a run to
tol = 1e-6 that takes ten times longer. If Ipopt stops without success (or stalls), the best
feasible iterate seen (tracked in the ``intermediate`` callback from Ipopt's current iterate and
constraint values) is returned with the status. Every returned design is re-checked by the
independent dense :class:`~pin_kpi_oed.cell.feasibility.FeasibilityChecker`.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from pin_kpi_oed.cell.cell import Cell
from pin_kpi_oed.cell.aggregate import AggregatedConstraints
from pin_kpi_oed.cell.collision import CollisionModel
from pin_kpi_oed.cell.sampling import random_feasible
from pin_kpi_oed.design.ipopt import IpoptRun, ipopt_options, solve_ipopt
from pin_kpi_oed.progress import progress
from pin_kpi_oed.cell.feasibility import FeasibilityChecker, FeasibilityReport
from pin_kpi_oed.errors import IdentifiabilityError, InputError
from pin_kpi_oed.oed.criteria import ConfigurationCriterion, Criterion, check_names, get_criterion
from pin_kpi_oed.oed.covariance import prior_square_root
from pin_kpi_oed.oed.design_objective import DesignObjective
from pin_kpi_oed.oed.held import HeldShare, design_held
from pin_kpi_oed.oed.objective import DesignCriterion, information_criterion
from pin_kpi_oed.oed.path_kpi import PathKpi  # noqa: F401  (registers kpi_path)
from pin_kpi_oed.oed.pose_kpi import PoseKpi  # noqa: F401  (registers kpi6)
from pin_kpi_oed.oed.path_kpi_gp import PathDiscrepancyKpi  # noqa: F401  (registers kpi_path_gp)
from pin_kpi_oed.oed.pose_kpi_gp import PoseDiscrepancyKpi  # noqa: F401  (registers kpi6_gp)
from pin_kpi_oed.oed.path_kpi_max import PathMaxKpi  # noqa: F401  (registers kpi_path_max)
from pin_kpi_oed.oed.identifiability import analyse, check_kpi
from pin_kpi_oed.oed.nests import nests_identifiability
from pin_kpi_oed.design.design_result import DesignResult
from pin_kpi_oed.design.problem_options import ParameterPrior, ProblemOptions, prior_information
from pin_kpi_oed.threads import limit_threads


__all__ = ["DesignResult", "DesignOptions", "DesignProblem", "IpoptRun", "ipopt_options", "solve_ipopt",
           "design_random", "design_ipopt", "run_designs"]


@dataclass
class DesignOptions:
    """Knobs of :func:`run_designs`.

    Attributes:
        collision: impose the collision constraints (used when no prepared problem is given).
        n_starts: Ipopt starts per optimised criterion.
        ipopt: Ipopt options (default :func:`ipopt_options`).
        start: first start of every optimisation: ``pool`` = the pool selection of m poses for the
            criterion (:meth:`~pin_kpi_oed.oed.criteria.Criterion.pool_form`; criteria without one
            select by D-optimality) from ``pool_size`` feasible random candidates, or ``random`` =
            the heuristic design. Further starts are random.
        pool_size: feasible candidates of the pool start.
        work_radius: radius (rad) of the working region ``kpi_gp`` takes its KPI over, as ``design --work-radius``
            (:func:`~pin_kpi_oed.design.region.default_region`): None = the command line's default with ``kpi_gp``
            (:data:`~pin_kpi_oed.design.region.DEFAULT_WORK_RADIUS_RAD`), 0 = the working configurations alone.
            Used when :func:`run_designs` builds the problem (a given problem keeps its own region).
        work_samples: seeded samples of the working region (None: the command line's default).
    """

    collision: bool = True
    n_starts: int = 1
    ipopt: dict | None = None
    start: str = "pool"
    pool_size: int = 1000
    work_radius: float | None = None
    work_samples: int | None = None

    def __post_init__(self) -> None:
        if self.start not in ("pool", "random"):
            raise InputError(f"start must be 'pool' or 'random', got '{self.start}'")
        if self.n_starts < 1 or self.pool_size < 1:
            raise InputError(f"n_starts ({self.n_starts}) and pool_size ({self.pool_size}) must be >= 1")


class DesignProblem:
    """Everything fixed across designs of one cell: model, identifiable set, KPI sensitivity, constraints, and what
    the problem is declared with (:class:`~pin_kpi_oed.design.problem_options.ProblemOptions`, frozen: measured
    poses and their prior, an extended model, the discrepancy, the working region, re-registration). Nothing is set
    on a problem after construction; :meth:`replaced` declares another.

    Args:
        cell: the measurement cell (the one the optimiser designs in: tightened by margins, if any).
        options: the declaration (default: the defaults).
        **changes: fields of :class:`~pin_kpi_oed.design.problem_options.ProblemOptions` that override ``options``
            (``DesignProblem(cell, collision=False)``, ``DesignProblem(cell, Q_given=Q)``).

    Raises:
        IdentifiabilityError: the TCP at the working configurations is not estimable.
        InputError: invalid cell geometry (see :class:`~pin_kpi_oed.cell.collision.CollisionModel`), measured poses
            of the wrong width or outside the joint limits (named ``Q_given``), a prior of the wrong shape.
    """

    @limit_threads  # the identifiability analysis (QR, lstsq) ran with every BLAS thread on a busy machine
    def __init__(self, cell: Cell, options: ProblemOptions | None = None, **changes: Any):
        o = options or ProblemOptions()
        self.options = o = dataclasses.replace(o, **changes) if changes else o
        self.cell = cell
        self.collision = o.collision
        self.model = cell.tracker_model()
        self.p0 = np.zeros(self.model.n_params)
        self.ident = analyse(self.model)
        E_full = self.model.kpi_jacobian(self.p0, cell.q_work)
        # several nests: the TCP need be estimable with all of them (nest 0 alone may leave part of it held)
        check_kpi(self.ident if self.model.n_nests < 2 else nests_identifiability(self.model), self.model, E_full,
                  f"{cell.name}: the TCP at the working configuration")
        self.base = self.ident.base
        self.E = E_full[:, self.base]
        self.coll = CollisionModel(cell, collision=o.collision, prune=o.prune, model=self.model)
        self.cons = AggregatedConstraints(self.coll, o.aggregate, o.ks_length_m, backend=o.distances)
        # the heuristic design is always collision-free (it is the practical baseline and every start)
        self.coll_full = self.coll if o.collision else CollisionModel(cell, collision=True, prune=o.prune,
                                                                       model=self.model)
        self.checker = FeasibilityChecker(cell)
        self.Q_given, self.F_given, self.prior_info = self._given(o)
        self.kpi_criterion = self.information_objective(information_criterion("kpi"))
        self.param_criterion = self.information_objective(information_criterion("param"))
        self._assumed: Any = None  # the class default discrepancy, drawn on first use

    def _given(self, o: ProblemOptions) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray | None]:
        """(Q_given checked, [F(Q_given); R₀] over the identifiable parameters, Σ₀⁻¹), or Nones without measured
        poses."""
        if o.Q_given is None:
            return None, None, None
        if o.Q_given.shape[1] != self.n:
            raise InputError(f"Q_given: expected {self.n} joint values per pose, got {o.Q_given.shape[1]}")
        Q = self.cell.robot.check_q(o.Q_given, "Q_given")
        F = self.model.weighted_jacobian(self.p0, Q)[:, :, self.base].reshape(-1, self.base.size)
        P = o.given_prior
        if isinstance(P, ParameterPrior):
            P = prior_information(self, P.names, P.covariance, f"given_prior {P.source}")
        if P is not None:
            if np.shape(P) != (self.base.size, self.base.size):
                raise InputError(f"given_prior: the information must be {self.base.size}x{self.base.size}, "
                                 f"got {np.shape(P)}")
            P = np.asarray(P, float)
            F = np.vstack([F, prior_square_root(P)])
        return Q, F, P

    def replaced(self, **changes: Any) -> DesignProblem:
        """The problem of the same cell declared with ``changes`` to its options (a new problem)."""
        return type(self)(self.cell, self.options, **changes)

    @property
    def extended(self) -> Any:
        """The :class:`~pin_kpi_oed.oed.extended.ExtendedModel` the criteria of the information matrix are taken on,
        or None."""
        return self.options.extended

    @property
    def discrepancy(self) -> Any:
        """The given discrepancy (a :class:`~pin_kpi_oed.discrepancy.prior.DiscrepancyPrior`), None when assumed."""
        return self.options.discrepancy

    @property
    def discrepancy_assumed(self) -> bool:
        """No discrepancy given: the robot class's default is assumed (``kpi_gp`` hedges around it)."""
        return self.options.discrepancy is None

    @property
    def hedge(self) -> bool:
        """Hedge ``kpi_gp`` under an assumed discrepancy."""
        return self.options.hedge

    @property
    def region(self) -> Any:
        """The :class:`~pin_kpi_oed.design.region.WorkingRegion` of ``kpi_gp``, or None."""
        return self.options.region

    @property
    def Q_register(self) -> np.ndarray | None:
        """Configurations of the re-registration before use in another session (rad), or None."""
        return self.options.Q_register

    @property
    def prior_file(self) -> str | None:
        """The file of the measured poses' prior (:class:`~pin_kpi_oed.design.problem_options.ParameterPrior`), or
        None."""
        P = self.options.given_prior
        return P.source if isinstance(P, ParameterPrior) else None

    def fixed_information(self) -> np.ndarray | None:
        """Information every design of this problem already has, (nb, nb) over the identifiable parameters: the
        measured poses' F_gᵀF_g (their prior rows included) plus the layout's prior diag(1/σ²) (1/m², 1/rad²); None
        without either."""
        prior = self.kpi_criterion.prior
        P = None if prior is None else np.diag(1.0 / np.asarray(prior, float) ** 2)
        if self.F_given is None:
            return P
        M0 = self.F_given.T @ self.F_given
        return M0 if P is None else M0 + P

    @property
    def n(self) -> int:
        """Joints per configuration."""
        return self.cell.robot.nq

    @property
    def q_work(self) -> np.ndarray:
        """The working configurations (t, n) rad of the KPI (the cell's)."""
        return self.cell.q_work

    def discrepancy_prior(self) -> Any:
        """The discrepancy of this problem (:attr:`discrepancy`, else the documented default of the robot's class,
        :func:`~pin_kpi_oed.oed.discrepancy_defaults.class_discrepancy`)."""
        if self.options.discrepancy is not None:
            return self.options.discrepancy
        if self._assumed is None:
            from pin_kpi_oed.oed.discrepancy_defaults import class_discrepancy

            self._assumed = class_discrepancy(self.cell.robot, self.options.robot_class)
        return self._assumed

    def gp_criterion(self, region: bool = True, name: str = "kpi_gp", Q_work: np.ndarray | None = None) -> Any:
        """The discrepancy-aware KPI criterion (``kpi_gp``) of this problem's geometry (identifiable geometry +
        set-up, the layout's prior) at the working configurations, and over the :attr:`region` when one is set
        and ``region`` (or at ``Q_work`` when given: the working paths' samples of ``kpi_path_gp``); another
        discrepancy-aware ``name`` (``D_gp``, ``param_gp``, …): its
        :class:`~pin_kpi_oed.oed.discrepancy_criteria.GlsDesignCriterion` (no working configurations)."""
        from pin_kpi_oed.oed.discrepancy_kpi import DiscrepancyDesignCriterion

        if name != "kpi_gp":
            from pin_kpi_oed.oed.discrepancy_criteria import GlsDesignCriterion

            return GlsDesignCriterion(self.model, self.base, self.discrepancy_prior(), name, Q_given=self.Q_given,
                                      p=self.p0)
        if Q_work is None:
            Q_work = self.region.configurations() if region and self.region is not None else self.cell.q_work
        return DiscrepancyDesignCriterion(self.model, self.base, self.discrepancy_prior(), Q_work,
                                          Q_given=self.Q_given, p=self.p0, Q_register=self.Q_register)

    def gp_objective(self, name: str = "kpi_gp", Q_work: np.ndarray | None = None) -> DesignObjective:
        """The design objective of a discrepancy-aware criterion (:meth:`gp_criterion`); ``kpi_gp`` under an assumed
        discrepancy (:attr:`discrepancy_assumed`, nothing measured) hedges over a family of priors around it
        (:class:`~pin_kpi_oed.oed.hedged_kpi.HedgedDesignCriterion`) unless :attr:`hedge` is False. The scores (the
        honest σ) take :meth:`gp_criterion` itself; ``Q_work`` as there."""
        crit = self.gp_criterion(name=name, Q_work=Q_work)
        if name == "kpi_gp" and self.hedge and self.discrepancy_assumed:
            from pin_kpi_oed.oed.hedged_kpi import HedgedDesignCriterion

            return HedgedDesignCriterion.around(crit)
        return crit

    def criterion(self, name: str) -> DesignObjective:
        """The design objective of the registered criterion ``name`` on this problem: a criterion of the
        configurations builds its own (:meth:`ConfigurationCriterion.objective
        <pin_kpi_oed.oed.criteria.ConfigurationCriterion.objective>`), a criterion of the information matrix is taken
        on :attr:`extended` when set, else on :meth:`information_objective`.

        Raises:
            InputError: unknown name.
        """
        crit = get_criterion(name)
        if isinstance(crit, ConfigurationCriterion):
            return crit.objective(self)
        if self.extended is not None:
            from pin_kpi_oed.oed.extended import ExtendedDesignCriterion

            return ExtendedDesignCriterion(self.extended, crit, self.cell.q_work)
        return self.information_objective(crit)

    def information_objective(self, crit: Criterion) -> DesignCriterion:
        """A criterion of the information matrix on this problem's information: noise only, plus the measured poses'
        rows (and their prior's) when given."""
        return DesignCriterion(self.model, self.base, crit, self.E, F_given=self.F_given)

    def identifies(self) -> bool:
        """Whether the measured poses alone identify the base parameters (False without measured poses)."""
        return bool(self.F_given is not None and self.F_given.size
                    and np.linalg.matrix_rank(self.F_given) == self.base.size)

    def require_identified(self, what: str = "Q_given") -> None:
        """Refuse a step that needs M⁻¹ of the measured poses alone (the "how many more" answer).

        Raises:
            IdentifiabilityError: the measured poses do not identify the parameters (names ``what`` and how
                many poses to design first).
        """
        if not self.identifies():
            raise IdentifiabilityError(f"{what}: the measured poses do not identify the parameters; design "
                                       f"at least {self.min_measurements()} more first")

    def sigma_tcp(self, Q_new: np.ndarray | None = None) -> float:
        """Predicted TCP σ = sqrt(tr C_s / t) (m) of the measured poses plus ``Q_new`` (eq. 19)."""
        t = self.cell.q_work.shape[0]
        if Q_new is None or len(Q_new) == 0:
            F = self.F_given if self.F_given is not None else np.zeros((0, self.base.size))
            tr = self.kpi_criterion.crit.value(F, self.E, self.kpi_criterion.prior)
        else:
            tr = self.kpi_criterion.value(np.atleast_2d(Q_new))
        return float(np.sqrt(tr / t))

    def min_measurements(self) -> int:
        """Fewest (new) configurations that can identify the base parameters (with the measured ones)."""
        if self.F_given is None:
            return int(np.ceil(self.base.size / self.model.nh))
        if self.identifies():
            return 1
        return max(1, int(np.ceil((self.base.size - np.linalg.matrix_rank(self.F_given)) / self.model.nh)))

    def check_measurements(self, m: int) -> None:
        """Raise InputError when m configurations cannot identify the base parameters."""
        if m < self.min_measurements():
            raise InputError(f"{m} measurements cannot identify {self.base.size} parameters: use at least "
                             f"{self.min_measurements()}")

    def random_design(self, m: int, seed: int | np.random.SeedSequence = 0, max_tries: int | None = None
                      ) -> tuple[np.ndarray, int]:
        """Heuristic design: m uniform random configurations rejection-sampled until feasible (all
        constraints, also when the optimiser runs without collision avoidance).

        Returns:
            (Q (m, n) rad, samples drawn).

        Raises:
            InfeasibleError: no (or too few) feasible poses in ``max_tries`` samples.
        """
        rng = np.random.default_rng(seed)
        return random_feasible(self.coll_full, m, rng, max_tries or self.cell.max_random_tries)

    def result(self, criterion: str, Q: np.ndarray, value: float, report: FeasibilityReport | None = None,
               **solver: Any) -> DesignResult:
        """Score a design (tr C_s, tr C_p) and run the independent check.

        Args:
            criterion: ``random`` or the criterion name.
            Q: the configurations (m, n) rad.
            value: the criterion's value.
            report: the independent check if already run (else run here).
            **solver: further :class:`DesignResult` fields from the solver (``status``, ``message``,
                ``nit``, ``nfev``, ``time_s``, ``solver_status``, ``samples``, ``n_constraints``, ``starts``).
        """
        held = HeldShare()
        try:
            cs = self.kpi_criterion.value(Q)
            cp = self.param_criterion.value(Q)
            held = design_held(self.model, self.base, Q, self.cell.q_work, p=self.p0)
        except IdentifiabilityError:
            cs = cp = float("inf")
        rep = report or self.checker.check(Q)
        t = self.cell.q_work.shape[0]
        message = solver.pop("message", "")
        if not rep.all_feasible:
            message = (message + "; " if message else "") + "independent check: " + ", ".join(rep.violations(3))
        return DesignResult(criterion=criterion, q_meas=np.array(Q), trace_cs_m2=float(cs),
                            tcp_sigma_m=float(np.sqrt((cs + held.trace_m2) / t)), trace_cp=float(cp),
                            value=float(value), held_trace_m2=held.trace_m2, held_line=held.line(cs, t),
                            min_clearance_m=rep.min_clearance_m, max_incidence_deg=rep.max_incidence_deg,
                            success=rep.all_feasible, share_colliding=rep.share_colliding,
                            share_infeasible=rep.share_infeasible, collision_avoidance=self.collision,
                            check=rep.to_dict(), message=message, **solver)


def design_random(problem: DesignProblem, m: int, seed: int = 0) -> DesignResult:
    """The heuristic design (uniform random, rejection-sampled) as a :class:`DesignResult`."""
    t0 = time.perf_counter()
    Q, ns = problem.random_design(m, seed)
    dt = time.perf_counter() - t0
    return problem.result("random", Q, problem.kpi_criterion.value(Q), time_s=dt, status="sampled",
                          solver_status="sampled",
                          samples=ns, message=f"{ns} uniform random poses drawn for {m} feasible ones")


def design_ipopt(problem: DesignProblem, criterion: str, m: int, seed: int = 0, n_starts: int = 1,
                 start: np.ndarray | None = None, options: dict | None = None) -> DesignResult:
    """Optimum design for ``criterion`` by Ipopt, multi-start, re-checked independently.

    Args:
        problem: the cell's design problem.
        criterion: a registered criterion name (``kpi`` = A on C_s, ``param`` = A on C_p, ...).
        m: number of measurement configurations.
        seed: seed of the starts; start 0 is the heuristic design of this seed (or ``start``).
        n_starts: number of starts (further starts: random feasible designs of seeds spawned from ``seed``).
        start: explicit first start (m, n) rad, e.g. the heuristic design already computed.
        options: Ipopt options (default :func:`ipopt_options`).

    Returns:
        The best design over the starts that passes the independent check (else the best design,
        flagged infeasible).

    Raises:
        InputError: unknown criterion or too few measurements.
        InfeasibleError: no feasible random start found.
    """
    get_criterion(criterion)
    problem.check_measurements(m)
    seeds = np.random.SeedSequence(seed).spawn(max(n_starts, 1))
    runs: list[IpoptRun] = []
    for k in progress(range(max(n_starts, 1)), desc=f"{criterion} starts", disable=n_starts <= 1):
        if k == 0:
            Q0 = start if start is not None else problem.random_design(m, seed)[0]
        else:
            Q0 = problem.random_design(m, seeds[k])[0]
        runs.append(solve_ipopt(problem, criterion, Q0, options))
    r, report = _best_checked_run(problem, runs)
    return problem.result(criterion, r.Q, r.value, report=report, time_s=sum(x.time_s for x in runs), nit=r.nit,
                          nfev=r.nfev, status=r.status, solver_status=r.solver_status, message=r.message,
                          n_constraints=r.n_constraints, starts=[x.start_dict() for x in runs])


def _best_checked_run(problem: DesignProblem, runs: list[IpoptRun]) -> tuple[IpoptRun, FeasibilityReport | None]:
    """The best run (by value) that passes the independent check, with its report; else the best run and None."""
    order = sorted(range(len(runs)), key=lambda i: (not runs[i].success, runs[i].value))
    for i in order:
        rep = problem.checker.check(runs[i].Q)
        if rep.all_feasible:
            return runs[i], rep
    return runs[order[0]], None


@limit_threads
def run_designs(cell: Cell, criteria: list[str], m: int | None = None, seed: int = 0,
                options: DesignOptions | None = None, problem: DesignProblem | None = None) -> list[DesignResult]:
    """Compute the heuristic and optimum designs of a cell.

    Args:
        cell: the measurement cell.
        criteria: ``random`` and/or registered criterion names; the heuristic design is always computed
            (it is the start of every optimisation and the reference of the improvements).
        m: measurements (default the cell's).
        seed: seed of the heuristic design, the pool and the starts.
        options: the knobs (:class:`DesignOptions`: collision, starts, Ipopt options, first start, pool size).
        problem: a prepared :class:`DesignProblem` (else built).

    Returns:
        The results, ``random`` first, then the criteria in the given order.

    Raises:
        InputError: unknown criterion or too few measurements.
    """
    opts = options or DesignOptions()
    check_names(criteria)
    m = m or cell.measurements
    if problem is None:
        from pin_kpi_oed.design.region import default_region

        problem = DesignProblem(cell, collision=opts.collision,
                                region=default_region(cell, criteria, opts.work_radius, opts.work_samples, seed))
    problem.check_measurements(m)
    rnd = design_random(problem, m, seed)
    out = [rnd]
    pool = None
    if opts.start == "pool" and any(c != "random" for c in criteria):
        pool = _start_pool(problem, m, seed, opts.pool_size)
    for c in criteria:
        if c == "random":
            continue
        Q0 = rnd.q_meas
        if pool is not None:
            Q_pool, Fp = pool
            obj = problem.criterion(c)
            sel = obj.select(Q_pool, m, Fp=Fp) if isinstance(obj, DesignCriterion) else obj.select(Q_pool, m, seed)
            Q0 = Q_pool[sel.indices]
        out.append(design_ipopt(problem, c, m, seed, opts.n_starts, start=Q0, options=opts.ipopt))
    return out


def _start_pool(problem: DesignProblem, m: int, seed: int, pool_size: int) -> tuple[np.ndarray, np.ndarray]:
    """Feasible random candidates for the pool start (seeded from ``seed``) and their weighted Jacobians."""
    Q_pool, _ = problem.random_design(max(pool_size, 2 * m), seed=np.random.SeedSequence([seed, 1]),
                                      max_tries=max(problem.cell.max_random_tries, 200 * pool_size))
    return Q_pool, problem.model.weighted_jacobian(problem.p0, Q_pool)[:, :, problem.base]
