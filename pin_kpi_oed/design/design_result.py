"""The result of one measurement design (:class:`DesignResult`, a :class:`~pin_kpi_oed.results.Result`): the poses,
tr(C_s), the TCP σ, tr(C_p), the criterion's value and the independent check's clearance and incidence. SI units
(rad, m², m); the incidence in degrees (its display unit, as the cell file)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pin_kpi_oed.results import Result

__all__ = ["DesignResult"]


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
        trace_cs_m2: tr(C_s) at the working configurations (m²): the identified parameters' part, what the criteria
            compare and improvements are stated on.
        tcp_sigma_m: sqrt((tr(C_s) + held_trace_m2)/t), RMS 3-D TCP standard deviation per working configuration
            (m), with the joint-placement parameters held at nominal under their tolerance.
        held_trace_m2: the held parameters' part of tr(C_s) (m²), which no measurement of the reflector removes
            (:func:`~pin_kpi_oed.oed.held.design_held`; the same for every design of a problem); held_line: what it
            is from and what removes it ("" when nothing is held).
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
    held_trace_m2: float = 0.0
    held_line: str = ""

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
                "n_constraints": self.n_constraints, "starts": self.starts, "check": self.check,
                "held_trace_m2": self.held_trace_m2, "held_line": self.held_line}

    def summary(self) -> str:
        """One readable line."""
        extra = f", {self.samples} samples" if self.samples is not None else f", {self.nit} iterations"
        return (f"{self.criterion}: tr(C_s) = {self.trace_cs_m2 * 1e6:.4g} mm^2, TCP sigma = "
                f"{self.tcp_sigma_m * 1e6:.3f} um, min clearance {self.min_clearance_m * 1e3:.1f} mm, "
                f"max incidence {self.max_incidence_deg:.1f} deg, {'feasible' if self.feasible else 'INFEASIBLE'} "
                f"({100 * self.share_colliding:.0f} % colliding){extra}, {self.time_s:.2f} s, {self.status} "
                f"({self.solver_status})")
