r"""The IPOPT design over pose × nest: the poses optimised under a nest assignment, the nests reassigned at the new
poses, in turn.

A row of a design is a pose and a reflector nest (:mod:`pin_kpi_oed.oed.nests`). The assign-after design
optimises the poses at nest 0 and then chooses each pose's nest by the KPI
(:func:`~pin_kpi_oed.oed.nests.assign_nests`). :func:`alternate_nests` starts from that design and alternates:

1. IPOPT on the poses with each pose's nest fixed (:class:`~pin_kpi_oed.oed.nest_objective.NestObjective`: the TCP's
   tr C_s at the working configurations, held joint placements included, each row's Jacobian at its nest), under
   the cell's constraints;
2. every pose's nest reassigned by the KPI at the new poses (the coordinate descent of
   :func:`~pin_kpi_oed.oed.nests.assign_nests`, the current assignment one of its starts);

until the assignment does not change (at most ``max_rounds`` rounds). The best tr C_s seen among designs that pass
the independent feasibility check is returned; the start is one of them, so the result is never worse than the
assign-after design it starts from.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from pin_kpi_oed.errors import IdentifiabilityError, SolverError
from pin_kpi_oed.results import Result

from pin_kpi_oed.oed.design_objective import DesignObjective

if TYPE_CHECKING:
    from pin_kpi_oed.design.optimize import DesignProblem
    from pin_kpi_oed.model.tolerances import Tolerances

__all__ = ["NestRound", "NestIpoptDesign", "alternate_nests"]


@dataclass
class NestRound:
    """One round of the alternation.

    Attributes:
        trace_ipopt_m2: tr C_s (m²) of IPOPT's poses at the round's nests.
        trace_m2: tr C_s (m²) after the nests were reassigned at those poses.
        changed: poses whose nest the reassignment changed; feasible: the independent check passed;
        status: IPOPT's status word.
    """

    trace_ipopt_m2: float
    trace_m2: float
    changed: int
    feasible: bool
    status: str


@dataclass(kw_only=True)
class NestIpoptDesign(Result):
    """The design over pose × nest (:func:`alternate_nests`).

    Attributes:
        q_meas: the poses (m, n) rad; nest: each pose's nest (m,) int.
        trace_m2: tr C_s at the working configurations (m², held joint placements included).
        start_trace_m2: the assign-after design's tr C_s (m²), the start.
        rounds: the rounds made (:class:`NestRound`).
    """

    q_meas: np.ndarray
    nest: np.ndarray
    trace_m2: float
    start_trace_m2: float
    rounds: list[NestRound] = field(default_factory=list)


class _Shifted(DesignObjective):
    """φ − c: the same minimiser, and the solver's scale (φ at the start) the part of φ the poses change (the held
    part of the tracker's and the base's placement is a floor no design lowers, and would leave the solver's
    relative tolerance coarser than the whole identified part)."""

    def __init__(self, objective: DesignObjective, shift: float):
        self.objective, self.shift, self.crit = objective, float(shift), objective.crit

    def value(self, Q: np.ndarray) -> float:
        """φ(Q) − c."""
        return self.objective.value(Q) - self.shift

    def value_and_grad(self, Q: np.ndarray) -> tuple[float, np.ndarray]:
        """φ(Q) − c and dφ/dQ."""
        v, g = self.objective.value_and_grad(Q)
        return v - self.shift, g


class _NestIpoptProblem:
    """A design problem whose objective is a fixed :class:`NestObjective` (what :func:`solve_ipopt` reads)."""

    def __init__(self, problem: DesignProblem, objective: DesignObjective):
        self.cell, self.coll, self._cons, self.objective = problem.cell, problem.coll, problem.cons, objective

    @property
    def cons(self) -> Any:
        """The problem's constraints."""
        return self._cons

    def criterion(self, name: str) -> DesignObjective:
        """The nest objective (whatever the name)."""
        return self.objective


def alternate_nests(problem: DesignProblem, Q_start: np.ndarray, seed: int = 0, max_rounds: int = 4,
                    options: dict | None = None, tolerances: Tolerances | None = None) -> NestIpoptDesign:
    """The alternating design over pose × nest from the assign-after design's poses (module docstring).

    Args:
        problem: the cell's design problem (its cell lists the nests, ``nests_m``, and working configurations).
        Q_start: the assign-after design's poses (m, n) rad (e.g. the ``kpi`` IPOPT design at nest 0); their nests
            are chosen here by :func:`~pin_kpi_oed.oed.nests.assign_nests`.
        seed: the structural analysis's excitation; max_rounds: rounds at most (IPOPT, then reassignment);
        options: IPOPT options (default :func:`~pin_kpi_oed.design.ipopt.ipopt_options`);
        tolerances: the held parameters' prior (default :class:`~pin_kpi_oed.model.tolerances.Tolerances`).

    Returns:
        The :class:`NestIpoptDesign` (``success``: the returned poses pass the independent check; ``nit``: rounds).

    Raises:
        IdentifiabilityError: the start's poses at nest 0 do not identify its parameters.
    """
    from pin_kpi_oed.design.ipopt import solve_ipopt
    from pin_kpi_oed.oed.nest_objective import NestObjective
    from pin_kpi_oed.oed.nests import NestStructure, assign_nests

    t0 = time.perf_counter()
    model, Q_work = problem.model, problem.cell.q_work
    st = NestStructure(model, seed)
    Q = np.array(Q_start, float)
    nest = assign_nests(model, Q, Q_work, tolerances, seed=seed).nest
    start = NestObjective(model, nest, Q_work, tolerances, seed, st).value(Q)
    best = (Q, nest, start, bool(problem.checker.check(Q).all_feasible))
    rounds: list[NestRound] = []
    for _ in range(max_rounds):
        obj = NestObjective(model, nest, Q_work, tolerances, seed, st)
        shift = 0.999 * obj.held_m2(Q)
        try:
            run = solve_ipopt(_NestIpoptProblem(problem, _Shifted(obj, shift)), obj.name, Q, options)
        except SolverError:
            break
        Q, run.value = run.Q, run.value + shift
        ok = bool(problem.checker.check(Q).all_feasible)
        try:
            new = assign_nests(model, Q, Q_work, tolerances, seed=seed, start=nest).nest
            tr = NestObjective(model, new, Q_work, tolerances, seed, st).value(Q)
        except IdentifiabilityError:  # nest 0 alone no longer identifies: keep the round's nests
            new, tr = nest, run.value
        if tr > run.value:  # the reassignment's rule (another nest must gain 1 %) can cost: keep the round's
            new, tr = nest, run.value
        rounds.append(NestRound(run.value, tr, int(np.sum(new != nest)), ok, run.status))
        if ok and tr < best[2]:
            best = (Q, new, tr, ok)
        if np.array_equal(new, nest):
            break
        nest = new
    Qb, nb, trb, okb = best
    return NestIpoptDesign(q_meas=Qb, nest=nb, trace_m2=float(trb), start_trace_m2=float(start), rounds=rounds,
                           success=okb, status="converged" if rounds and rounds[-1].changed == 0 else "max_rounds",
                           nit=len(rounds), time_s=time.perf_counter() - t0,
                           message=f"tr(C_s) {start * 1e6:.4g} -> {trb * 1e6:.4g} mm^2 in {len(rounds)} rounds")
