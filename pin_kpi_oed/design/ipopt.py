"""The IPOPT run of a design problem (paper eq. 24): the scaled criterion, the batched constraints with their
block-sparse Jacobian (cyipopt), the options (limited-memory Hessian, adaptive barrier, tolerances relative to the
scaled objective), the stagnation stop and the best feasible iterate (see :mod:`pin_kpi_oed.design.optimize`)."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from pin_kpi_oed.errors import IdentifiabilityError, SolverError
from pin_kpi_oed.oed.design_objective import DesignObjective
from pin_kpi_oed.results import Result

__all__ = ["ConstraintSet", "IpoptProblem", "IpoptRun", "ipopt_options", "solve_ipopt", "STALL_WINDOW", "STALL_TOL",
           "CLEARANCE_BUFFER_M", "COS_BUFFER"]


class ConstraintSet(Protocol):
    """The batched constraints g(q) ≥ 0 the IPOPT run reads: the cell's
    (:class:`~pin_kpi_oed.cell.aggregate.AggregatedConstraints`) or a device's added to them (a camera's,
    :class:`~pin_kpi_oed.design.camera_design.CameraConstraints`).

    Attributes:
        n: joints per configuration; n_rows: rows per configuration; units: each row's unit (``m`` for distances:
            the clearance buffer, else the cosine buffer); jac_rows, jac_cols: the structural non-zeros of one
            configuration's Jacobian.
    """

    @property
    def n(self) -> int: ...
    @property
    def n_rows(self) -> int: ...
    @property
    def units(self) -> list[str]: ...
    @property
    def jac_rows(self) -> np.ndarray: ...
    @property
    def jac_cols(self) -> np.ndarray: ...

    def evaluate(self, Q: np.ndarray, with_grad: bool = True) -> Any:
        """Rows (m, n_rows) and, with ``with_grad``, their gradients (m, n_rows, n)."""


class IpoptProblem(Protocol):
    """What the IPOPT run reads of a design problem (:class:`~pin_kpi_oed.design.optimize.DesignProblem`).

    Attributes:
        cell: the cell (joint bounds ``q_lower`` / ``q_upper``, rad / m).
        cons: the batched constraints (:class:`ConstraintSet`).
        coll: the full collision model (``feasible(Q)``: the independent feasibility of each configuration).
    """

    cell: Any
    @property
    def cons(self) -> ConstraintSet:
        """The batched constraints (read-only: a problem's own constraint set, of any :class:`ConstraintSet` type)."""
    coll: Any

    def criterion(self, name: str) -> DesignObjective:
        """The objective φ(Q) of criterion ``name``."""


#: Stagnation test: stop when the lowest (scaled) objective of all iterates improved by less than
#: STALL_TOL (0.1 % of the start value for ratio criteria, 1e-3 in log units otherwise) over
#: STALL_WINDOW iterations; the best feasible iterate is then returned.
STALL_WINDOW = 50
STALL_TOL = 1e-3

#: Buffers of the optimiser's constraints above the feasibility threshold (m for distances, cos β).
CLEARANCE_BUFFER_M = 1e-4
COS_BUFFER = 1e-5

_IPOPT_STATUS = {0: "Solve_Succeeded", 1: "Solved_To_Acceptable_Level", 2: "Infeasible_Problem_Detected",
                 3: "Search_Direction_Becomes_Too_Small", 4: "Diverging_Iterates", 5: "User_Requested_Stop",
                 6: "Feasible_Point_Found", -1: "Maximum_Iterations_Exceeded", -2: "Restoration_Failed",
                 -3: "Error_In_Step_Computation", -4: "Maximum_CpuTime_Exceeded", -5: "Maximum_WallTime_Exceeded",
                 -10: "Not_Enough_Degrees_Of_Freedom", -11: "Invalid_Problem_Definition",
                 -12: "Invalid_Option", -13: "Invalid_Number_Detected", -100: "Unrecoverable_Exception",
                 -101: "NonIpopt_Exception_Thrown", -102: "Insufficient_Memory", -199: "Internal_Error"}

#: Ipopt return codes in the package's status words (anything else: ``failed``).
_STATUS_WORD = {0: "converged", 1: "acceptable", -1: "max_iter", -4: "max_time", -5: "max_time"}


@dataclass(kw_only=True)
class IpoptRun(Result):
    """One Ipopt run of the design problem (a :class:`~pin_kpi_oed.results.Result`).

    ``success``: the returned design satisfies every optimiser row (fast path; the independent check
    comes later); ``status``: ``converged``, ``acceptable``, ``stalled``, ``max_iter``, ``max_time`` or
    ``failed``; ``nit``: Ipopt iterations; ``nfev``: objective evaluations; ``time_s``: wall time (s).

    Attributes:
        Q: the returned configurations (m, n) rad.
        f: scaled objective (φ/φ₀ for ratio criteria, φ − φ₀ otherwise).
        value: the criterion φ.
        eval_time_s: time spent in our callbacks (s).
        n_constraints: constraint rows of the NLP.
        n_constraint_evals: constraint (and Jacobian) evaluations.
        solver_status: Ipopt's status name (``Stalled`` for the stagnation stop), with
            ``; best feasible iterate`` appended when the fallback was used.
        fallback: the best feasible iterate was returned instead of Ipopt's last one.
    """

    Q: np.ndarray
    f: float
    value: float
    eval_time_s: float = 0.0
    n_constraints: int = 0
    n_constraint_evals: int = 0
    solver_status: str = ""
    fallback: bool = False

    def start_dict(self) -> dict:
        """The per-start record of :attr:`DesignResult.starts` (common keys + the figures of one start)."""
        return {**self.result_dict(), "value": self.value, "objective_scaled": self.f, "iterations": self.nit,
                "eval_time_s": self.eval_time_s, "solver_status": self.solver_status,
                "feasible_fast_path": self.success,
                "evaluations": {"objective": self.nfev, "constraints": self.n_constraint_evals}}

    def to_dict(self) -> dict:
        """Plain JSON-able dict (SI units)."""
        return {**self.start_dict(), "q_meas": self.Q.tolist(), "n_constraints": self.n_constraints,
                "fallback": self.fallback}


class DesignNLP:
    """cyipopt problem: scaled criterion, batched cached constraints, block-sparse Jacobian."""

    def __init__(self, crit: DesignObjective, cons: ConstraintSet, m: int, f0: float):
        self.crit, self.cons, self.m, self.n = crit, cons, m, cons.n
        self.ratio = crit.is_ratio
        self.f0 = f0
        R = cons.n_rows
        off_r = (np.arange(m) * R)[:, None]
        off_c = (np.arange(m) * self.n)[:, None]
        self.jr = (off_r + cons.jac_rows[None, :]).ravel()
        self.jc = (off_c + cons.jac_cols[None, :]).ravel()
        self._gkey: bytes | None = None
        self._fkey: bytes | None = None
        self.best_x: np.ndarray | None = None
        self.best_f = np.inf
        self.iterations = 0
        self.problem = None
        self.n_f = self.n_g = 0
        self.t_f = self.t_g = 0.0
        self.history: list[float] = []
        self.obj_low = np.inf
        self.stall_window, self.stall_tol, self.stalled = STALL_WINDOW, STALL_TOL, False

    def _Q(self, x: np.ndarray) -> np.ndarray:
        return x.reshape(self.m, self.n)

    def _eval_f(self, x: np.ndarray) -> None:
        key = x.tobytes()
        if key != self._fkey:
            t0 = time.perf_counter()
            v, G = self.crit.value_and_grad(self._Q(x))
            if self.ratio:
                self._f, self._df = v / self.f0, G.ravel() / self.f0
            else:
                self._f, self._df = v - self.f0, G.ravel()
            self._fkey = key
            self.n_f += 1
            self.t_f += time.perf_counter() - t0

    def _eval_g(self, x: np.ndarray) -> None:
        key = x.tobytes()
        if key != self._gkey:
            t0 = time.perf_counter()
            g, G = self.cons.evaluate(self._Q(x), with_grad=True)
            self._g = g.ravel()
            self._J = G[:, self.cons.jac_rows, self.cons.jac_cols].ravel()
            self._gkey = key
            self.n_g += 1
            self.t_g += time.perf_counter() - t0

    def objective(self, x: np.ndarray) -> float:
        try:
            self._eval_f(x)
        except IdentifiabilityError:
            return 1e20  # singular information matrix: Ipopt backtracks
        return self._f

    def gradient(self, x: np.ndarray) -> np.ndarray:
        self._eval_f(x)
        return self._df

    def constraints(self, x: np.ndarray) -> np.ndarray:
        self._eval_g(x)
        return self._g

    def jacobianstructure(self) -> tuple[np.ndarray, np.ndarray]:
        return self.jr, self.jc

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        self._eval_g(x)
        return self._J

    def intermediate(self, alg_mod, iter_count, obj_value, inf_pr, inf_du, mu, d_norm, regularization_size,
                     alpha_du, alpha_pr, ls_trials) -> bool:
        self.iterations = int(iter_count)
        if alg_mod == 0 and self.problem is not None:
            it = self.problem.get_current_iterate()
            gmin = float(it["g"].min()) if it is not None and it["g"].size else 0.0
            # aggregated rows are conservative: g >= 0 implies every pair and the incidence are feasible
            if it is not None and gmin >= 0.0 and obj_value < self.best_f:
                self.best_f = float(obj_value)
                self.best_x = np.array(it["x"], float)
            self.obj_low = min(self.obj_low, float(obj_value))
        self.history.append(self.obj_low)
        w = self.stall_window
        if w and len(self.history) > w and np.isfinite(self.history[-w - 1]):
            if self.history[-w - 1] - self.obj_low < self.stall_tol * max(1.0, abs(self.obj_low)):
                self.stalled = True
                return False  # stagnation: stop (Ipopt status User_Requested_Stop)
        return True


def ipopt_options(max_iter: int = 500, tol: float = 1e-3, acceptable_tol: float = 1e-2, acceptable_iter: int = 10,
                  acceptable_obj_change_tol: float = 1e-3, history: int = 6) -> dict:
    """Ipopt options of the design solver.

    The objective is scaled to 1 at the start, so ``tol`` = 1e-3 on Ipopt's scaled KKT error is a
    relative criterion; "acceptable" termination needs the KKT error below ``acceptable_tol`` and a
    relative objective change below ``acceptable_obj_change_tol`` (0.1 %) for ``acceptable_iter``
    consecutive iterations. Ipopt's last iterate may then violate a constraint by up to 1 cm
    (``acceptable_constr_viol_tol``): :func:`solve_ipopt` returns the best *feasible* iterate instead.
    The quasi-Newton matrix is initialised with yᵀy/sᵀy (``scalar2``), which keeps the first steps
    short: with the default sᵀy/sᵀs, 240-configuration designs took steps of ~1 rad that left the
    feasible set for dozens of iterations. ``benchmarks/bench_design.py`` compares the result with a
    run to tol = 1e-6.
    """
    return {"hessian_approximation": "limited-memory", "limited_memory_max_history": history,
            "limited_memory_initialization": "scalar2",
            "mu_strategy": "adaptive", "tol": tol, "acceptable_tol": acceptable_tol,
            "acceptable_iter": acceptable_iter, "acceptable_obj_change_tol": acceptable_obj_change_tol,
            "acceptable_constr_viol_tol": 1e-2, "max_iter": max_iter, "print_level": 0,
            "sb": "yes", "linear_solver": "mumps"}


def solve_ipopt(problem: IpoptProblem, criterion: str, Q0: np.ndarray, options: dict | None = None,
                stall_window: int = STALL_WINDOW) -> IpoptRun:
    """One Ipopt run of the design problem from the start ``Q0``.

    Args:
        problem: the cell's design problem.
        criterion: a registered criterion name.
        Q0: start (m, n) rad, normally feasible (the heuristic design).
        options: Ipopt options (default :func:`ipopt_options`).
        stall_window: iterations of the stagnation test (0 disables it).

    Returns:
        The run (:class:`IpoptRun`): the configurations, the scaled objective and the criterion's value,
        status, iterations, evaluations, times.

    Raises:
        SolverError: the criterion cannot be scaled at the start, or Ipopt could not run.
    """
    import cyipopt

    crit = problem.criterion(criterion)
    m, n = Q0.shape
    nlp = DesignNLP(crit, problem.cons, m, ipopt_start_value(crit, Q0))
    lb, ub, cl, cu = _nlp_bounds(problem, m)
    x0 = np.clip(Q0.ravel(), lb, ub)
    t0 = time.perf_counter()
    prob = cyipopt.Problem(n=x0.size, m=cl.size, problem_obj=nlp, lb=lb, ub=ub, cl=cl, cu=cu)
    nlp.problem = prob
    nlp.stall_window = stall_window
    for k, v in (options or ipopt_options()).items():
        prob.add_option(k, v)
    if problem.coll.feasible(x0.reshape(m, n)).all():  # the (heuristic) start is the first feasible iterate
        nlp.best_x, nlp.best_f = x0.copy(), nlp.objective(x0)
    try:
        x, info = prob.solve(x0)
    except Exception as exc:  # cyipopt raises on invalid options or failing callbacks
        raise SolverError(f"Ipopt failed on the {criterion} design: {exc}") from None
    finally:
        prob.close()
    return _finish_run(problem, nlp, np.asarray(x, float), int(info["status"]), (lb, ub),
                       time.perf_counter() - t0, cl.size)


def ipopt_start_value(crit: DesignObjective, Q0: np.ndarray) -> float:
    """φ at the start (the objective's scale or shift).

    Raises:
        SolverError: the start does not identify the parameters, or a ratio criterion is not positive there.
    """
    try:
        f0 = crit.value(Q0)
    except IdentifiabilityError as exc:
        raise SolverError(f"the start design of the {crit.name} design does not identify the parameters ({exc})"
                          ) from None
    if crit.is_ratio and not (np.isfinite(f0) and f0 > 0):
        disc = getattr(crit, "discrepancy", None)
        what = (f"; it is computed with the discrepancy ({getattr(disc, 'source', '') or 'given'}): check its kernel, "
                "scale_m and noise" if disc is not None else
                "; check the cell's noise, reflector, TCP and working configurations")
        raise SolverError(f"criterion {crit.name} is {f0} at the start design: cannot scale it{what}")
    return f0


def _nlp_bounds(problem: IpoptProblem, m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Variable bounds (joint limits, rad) and constraint bounds (buffers, m or cos β) of m configurations."""
    lb = np.tile(problem.cell.q_lower, m)
    ub = np.tile(problem.cell.q_upper, m)
    cl1 = np.array([CLEARANCE_BUFFER_M if u == "m" else COS_BUFFER for u in problem.cons.units])
    cl = np.tile(cl1, m)
    return lb, ub, cl, np.full(cl.size, 2e19)


def _finish_run(problem: IpoptProblem, nlp: DesignNLP, x: np.ndarray, code: int, bounds: tuple[np.ndarray, np.ndarray],
                dt: float, n_constraints: int) -> IpoptRun:
    """Ipopt's last iterate or, if it is infeasible, stalled or worse, the best feasible iterate, as a run."""
    lb, ub = bounds
    m, n = nlp.m, nlp.n
    name = "Stalled" if nlp.stalled and code == 5 else _IPOPT_STATUS.get(code, str(code))
    word = "stalled" if nlp.stalled and code == 5 else _STATUS_WORD.get(code, "failed")
    x = np.clip(x, lb, ub)
    ok = bool(problem.coll.feasible(x.reshape(m, n)).all())
    f = nlp.objective(x)
    fallback = False
    if nlp.best_x is not None and (not ok or nlp.stalled or (code not in (0, 1) and nlp.best_f < f)):
        x, f, ok, fallback = np.clip(nlp.best_x, lb, ub), nlp.best_f, True, True
    value = f * nlp.f0 if nlp.ratio else f + nlp.f0
    solver_status = name + ("; best feasible iterate" if fallback else "")
    return IpoptRun(Q=x.reshape(m, n), f=float(f), value=float(value), eval_time_s=nlp.t_f + nlp.t_g,
                    n_constraints=int(n_constraints), n_constraint_evals=nlp.n_g, solver_status=solver_status,
                    fallback=fallback, success=ok, status=word, nit=nlp.iterations, nfev=nlp.n_f, time_s=dt,
                    message=f"Ipopt: {name}" + ("; best feasible iterate returned" if fallback else ""))
