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

import time
from dataclasses import dataclass, field
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
from pin_kpi_oed.oed.objective import DesignCriterion, DesignObjective
from pin_kpi_oed.oed.path_kpi import PathKpi  # noqa: F401  (registers kpi_path)
from pin_kpi_oed.oed.pose_kpi import PoseKpi  # noqa: F401  (registers kpi6)
from pin_kpi_oed.oed.path_kpi_gp import PathDiscrepancyKpi  # noqa: F401  (registers kpi_path_gp)
from pin_kpi_oed.oed.path_kpi_max import PathMaxKpi  # noqa: F401  (registers kpi_path_max)
from pin_kpi_oed.oed.identifiability import analyse, check_kpi
from pin_kpi_oed.results import Result
from pin_kpi_oed.threads import limit_threads


__all__ = ["DesignResult", "DesignOptions", "DesignProblem", "IpoptRun", "ipopt_options", "solve_ipopt",
           "design_random", "design_ipopt", "run_designs"]


@dataclass(kw_only=True)
class DesignResult(Result):
    """One measurement design and its scores (a :class:`~pin_kpi_oed.results.Result`).

    The common result fields:

    * ``success``: every pose collision-free, visible and within bounds by the independent check
      (also readable as ``feasible``);
    * ``status``: ``sampled`` (heuristic design) or, for the returned Ipopt start, ``converged``,
      ``acceptable``, ``stalled``, ``max_iter``, ``max_time`` or ``failed``;
    * ``message``: Ipopt's status, the best-feasible-iterate fallback, violations of the independent check;
    * ``nit``: Ipopt iterations of the returned start, 0 for random (also ``iterations``);
    * ``nfev``: objective evaluations of the returned start;
    * ``time_s``: wall time (s), Ipopt over all starts or the rejection sampling (also ``solve_time_s``).

    Attributes:
        criterion: ``random`` (heuristic) or a registered criterion name (:data:`~pin_kpi_oed.oed.criteria.CRITERIA`).
        q_meas: configurations (m, n) rad.
        trace_cs_m2: tr(C_s) at the working configurations (m²).
        tcp_sigma_m: sqrt(tr(C_s)/t), RMS 3-D TCP standard deviation per working configuration (m).
        trace_cp: tr(C_p) over the identifiable parameters (mixed m², rad²).
        value: the criterion's own value (tr(C_s) for random), in its unit.
        min_clearance_m: smallest clearance over every pair checked by the independent check (m).
        max_incidence_deg: largest incidence angle (deg).
        share_colliding: share of poses in collision (0…1).
        share_infeasible: share of poses failing any check (0…1).
        solver_status: Ipopt's status name of the returned start (``sampled`` for random), suffixed
            with ``; best feasible iterate`` when the fallback was used.
        collision_avoidance: whether the collision constraints were imposed.
        samples: random poses drawn (heuristic design) or None.
        n_constraints: constraint rows of the NLP (0 for random).
        starts: per start: :meth:`IpoptRun.start_dict`.
        check: the independent check (plain dict).
    """

    criterion: str
    q_meas: np.ndarray
    trace_cs_m2: float
    tcp_sigma_m: float
    trace_cp: float
    value: float
    min_clearance_m: float
    max_incidence_deg: float
    share_colliding: float
    share_infeasible: float
    solver_status: str = ""
    collision_avoidance: bool = True
    samples: int | None = None
    n_constraints: int = 0
    starts: list[dict] = field(default_factory=list)
    check: dict = field(default_factory=dict)

    @property
    def feasible(self) -> bool:
        """Every pose passes the independent check (= ``success``)."""
        return self.success

    def improvement_over(self, reference: DesignResult) -> float:
        """Relative reduction of tr(C_s) w.r.t. ``reference`` (%)."""
        return 100.0 * (1.0 - self.trace_cs_m2 / reference.trace_cs_m2)

    def to_dict(self) -> dict:
        """Plain JSON-able dict (SI units): the common result keys, the scores, and the keys of earlier
        versions (``feasible``, ``iterations``, ``solve_time_s``)."""
        return {**self.result_dict(), "criterion": self.criterion, "q_meas": self.q_meas.tolist(),
                "trace_cs_m2": self.trace_cs_m2, "tcp_sigma_m": self.tcp_sigma_m, "trace_cp": self.trace_cp,
                "value": self.value, "min_clearance_m": self.min_clearance_m,
                "max_incidence_deg": self.max_incidence_deg, "feasible": self.feasible,
                "share_colliding": self.share_colliding, "share_infeasible": self.share_infeasible,
                "solve_time_s": self.time_s, "iterations": self.nit, "solver_status": self.solver_status,
                "collision_avoidance": self.collision_avoidance, "samples": self.samples,
                "n_constraints": self.n_constraints, "starts": self.starts, "check": self.check}

    def summary(self) -> str:
        """One readable line."""
        extra = f", {self.samples} samples" if self.samples is not None else f", {self.nit} iterations"
        return (f"{self.criterion}: tr(C_s) = {self.trace_cs_m2 * 1e6:.4g} mm^2, TCP sigma = "
                f"{self.tcp_sigma_m * 1e6:.3f} um, min clearance {self.min_clearance_m * 1e3:.1f} mm, "
                f"max incidence {self.max_incidence_deg:.1f} deg, {'feasible' if self.feasible else 'INFEASIBLE'} "
                f"({100 * self.share_colliding:.0f} % colliding){extra}, {self.time_s:.2f} s, {self.status} "
                f"({self.solver_status})")


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
            (:meth:`DesignProblem.set_region`): None = the command line's default with ``kpi_gp``
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
    """Everything fixed across designs of one cell: model, identifiable set, KPI sensitivity, constraints.

    Args:
        cell: the measurement cell.
        collision: impose the collision and line-of-sight constraints (False: joint bounds and
            incidence only, the paper's "without collision avoidance").
        prune: drop constraint rows that can never be active.
        aggregate: per-configuration aggregation of the distance rows for the optimiser: ``"ks"``
            (smooth, conservative, exact gradient), ``"min"`` or ``"none"`` (every row; the naive formulation).
        ks_length_m: KS smoothing length (m).
        distances: capsule distances of the constraints: ``"geometry"`` (default: Coal through
            a Pinocchio GeometryModel, :class:`~pin_kpi_oed.cell.coal_distances.GeometryDistances`) or ``"numpy"``
            (the closed-form segment distances, kept as the test oracle; equal to 1e-15 m).

    Raises:
        IdentifiabilityError: the TCP at the working configurations is not estimable.
        InputError: invalid cell geometry (see :class:`~pin_kpi_oed.cell.collision.CollisionModel`).
    """

    @limit_threads  # the identifiability analysis (QR, lstsq) ran with every BLAS thread on a busy machine
    def __init__(self, cell: Cell, collision: bool = True, prune: bool = True, aggregate: str = "ks",
                 ks_length_m: float = 2e-3, distances: str = "geometry"):
        self.cell = cell
        self.collision = collision
        self.model = cell.tracker_model()
        self.p0 = np.zeros(self.model.n_params)
        self.ident = analyse(self.model)
        E_full = self.model.kpi_jacobian(self.p0, cell.q_work)
        check_kpi(self.ident, self.model, E_full, f"{cell.name}: the TCP at the working configuration")
        self.base = self.ident.base
        self.E = E_full[:, self.base]
        self.coll = CollisionModel(cell, collision=collision, prune=prune, model=self.model)
        self.cons = AggregatedConstraints(self.coll, aggregate, ks_length_m, backend=distances)
        # the heuristic design is always collision-free (it is the practical baseline and every start)
        self.coll_full = self.coll if collision else CollisionModel(cell, collision=True, prune=prune,
                                                                     model=self.model)
        self.checker = FeasibilityChecker(cell)
        self.kpi_criterion = DesignCriterion(self.model, self.base, "kpi", self.E)
        self._param = DesignCriterion(self.model, self.base, "param", self.E)

    def fixed_information(self) -> np.ndarray | None:
        """Information every design of this problem already has, (nb, nb) over the identifiable parameters:
        the layout's prior diag(1/σ²) (1/m², 1/rad²); None without a prior."""
        prior = self.kpi_criterion.prior
        return None if prior is None else np.diag(1.0 / np.asarray(prior, float) ** 2)

    @property
    def n(self) -> int:
        """Joints per configuration."""
        return self.cell.robot.nq

    @property
    def q_work(self) -> np.ndarray:
        """The working configurations (t, n) rad of the KPI (the cell's)."""
        return self.cell.q_work

    #: Optional :class:`~pin_kpi_oed.oed.extended.ExtendedModel`: design over geometry + effects with a prior.
    extended: Any = None
    #: Optional :class:`~pin_kpi_oed.oed.discrepancy_kpi.DiscrepancyPrior` of the ``kpi_gp`` criterion and of the
    #: honest TCP σ (None: the documented default of the robot's class,
    #: :func:`~pin_kpi_oed.oed.discrepancy_defaults.class_discrepancy`).
    discrepancy: Any = None
    #: Optional robot class of that default (a key of :data:`~pin_kpi_oed.oed.discrepancy_defaults.ROBOT_CLASSES`;
    #: None: from the robot's name).
    robot_class: str | None = None

    def discrepancy_prior(self) -> Any:
        """The discrepancy of this problem (:attr:`discrepancy`, else the documented default of the robot's class)."""
        from pin_kpi_oed.oed.discrepancy_defaults import class_discrepancy

        if self.discrepancy is None:
            self.discrepancy = class_discrepancy(self.cell.robot, self.robot_class)
            self.discrepancy_assumed = True
        return self.discrepancy

    #: The discrepancy is an assumption (the class default, nothing measured): the ``kpi_gp`` design hedges over a
    #: family of priors around it (:mod:`pin_kpi_oed.oed.hedged_kpi`) unless :attr:`hedge` is False.
    discrepancy_assumed: bool = False
    #: Hedge an assumed discrepancy (False: design for the assumed prior alone).
    hedge: bool = True

    #: Optional configurations (r, n) rad where the set-up is registered again before the calibration is used (another
    #: session): ``kpi_gp`` and the honest σ score the TCP error after that registration
    #: (:mod:`pin_kpi_oed.oed.reregistration`); None: used in the set-up it is measured in.
    Q_register: Any = None

    #: Optional :class:`~pin_kpi_oed.design.region.WorkingRegion`: ``kpi_gp`` takes its KPI over W and the region's
    #: configurations (None: W alone; :meth:`set_region`).
    region: Any = None

    def set_region(self, radius_rad: float, samples: int, seed: int = 0, joints: int = 5, cell: Cell | None = None
                   ) -> Any:
        """Draw the working region of ``kpi_gp`` (:func:`~pin_kpi_oed.design.region.working_region`): ``samples``
        seeded configurations within ``radius_rad`` of the working configurations, those outside the joint bounds or
        in collision (the independent check of ``cell``, default this problem's) dropped; R = 0 leaves W alone.
        The tracker's line of sight and incidence are not required: the region is where the robot works, not where
        it is measured (the working configurations themselves usually face away from the tracker). Returns it."""
        from pin_kpi_oed.design.region import working_region

        checker = self.checker if cell is None else FeasibilityChecker(cell)

        def reachable(Q: np.ndarray) -> np.ndarray:
            rep = checker.check(Q)
            return rep.within_bounds & rep.collision_free

        self.region = working_region(self.cell.q_work, radius_rad, samples, seed, joints=joints, feasible=reachable)
        return self.region

    def gp_criterion(self, region: bool = True, name: str = "kpi_gp", Q_work: np.ndarray | None = None) -> Any:
        """The discrepancy-aware KPI criterion (``kpi_gp``) of this problem's geometry (identifiable geometry +
        set-up, the layout's prior) at the working configurations, and over the :attr:`region` when one is set
        and ``region`` (or at ``Q_work`` when given: the working paths' samples of ``kpi_path_gp``); another
        discrepancy-aware ``name`` (``D_gp``, ``param_gp``, …): its
        :class:`~pin_kpi_oed.oed.discrepancy_criteria.GlsDesignCriterion` (no working configurations)."""
        from pin_kpi_oed.oed.discrepancy_kpi import DiscrepancyDesignCriterion

        if name != "kpi_gp":
            from pin_kpi_oed.oed.discrepancy_criteria import GlsDesignCriterion

            return GlsDesignCriterion(self.model, self.base, self.discrepancy_prior(), name,
                                      Q_given=getattr(self, "Q_given", None), p=self.p0)
        if Q_work is None:
            Q_work = self.region.configurations() if region and self.region is not None else self.cell.q_work
        return DiscrepancyDesignCriterion(self.model, self.base, self.discrepancy_prior(), Q_work,
                                          Q_given=getattr(self, "Q_given", None), p=self.p0,
                                          Q_register=self.Q_register)

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
        """A criterion of the information matrix on this problem's information (noise only)."""
        return DesignCriterion(self.model, self.base, crit, self.E)

    def min_measurements(self) -> int:
        """Fewest configurations that can identify the base parameters."""
        return int(np.ceil(self.base.size / self.model.nh))

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
        try:
            cs = self.kpi_criterion.value(Q)
            cp = self._param.value(Q)
        except IdentifiabilityError:
            cs = cp = float("inf")
        rep = report or self.checker.check(Q)
        t = self.cell.q_work.shape[0]
        message = solver.pop("message", "")
        if not rep.all_feasible:
            message = (message + "; " if message else "") + "independent check: " + ", ".join(rep.violations(3))
        return DesignResult(criterion=criterion, q_meas=np.array(Q), trace_cs_m2=float(cs),
                            tcp_sigma_m=float(np.sqrt(cs / t)), trace_cp=float(cp), value=float(value),
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
        problem = DesignProblem(cell, collision=opts.collision)
        _default_region(problem, criteria, opts, seed)
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


def _default_region(problem: DesignProblem, criteria: list[str], opts: DesignOptions, seed: int) -> None:
    """The working region of ``kpi_gp`` as the command line draws it (``design --work-radius/--work-samples``):
    the same defaults, seed and cell, so that the API and the command line design the same poses."""
    from pin_kpi_oed.design.region import DEFAULT_WORK_RADIUS_RAD, DEFAULT_WORK_SAMPLES

    radius = opts.work_radius if opts.work_radius is not None else (
        DEFAULT_WORK_RADIUS_RAD if "kpi_gp" in criteria else 0.0)
    samples = DEFAULT_WORK_SAMPLES if opts.work_samples is None else int(opts.work_samples)
    if radius < 0 or samples < 0:
        raise InputError(f"work_radius ({radius:g}) and work_samples ({samples}) must be >= 0")
    if radius > 0 and samples > 0:
        problem.set_region(radius, samples, seed, cell=problem.cell)


def _start_pool(problem: DesignProblem, m: int, seed: int, pool_size: int) -> tuple[np.ndarray, np.ndarray]:
    """Feasible random candidates for the pool start (seeded from ``seed``) and their weighted Jacobians."""
    Q_pool, _ = problem.random_design(max(pool_size, 2 * m), seed=np.random.SeedSequence([seed, 1]),
                                      max_tries=max(problem.cell.max_random_tries, 200 * pool_size))
    return Q_pool, problem.model.weighted_jacobian(problem.p0, Q_pool)[:, :, problem.base]
