"""Optimality certificates of measurement designs on a candidate pool.

The sampling of the pool on a cell: :mod:`pin_kpi_oed.design.optimality`.

The design problem (24) is non-convex and IPOPT finds a local optimum. Its
*approximate-design relaxation* over a large pool of feasible poses (random
configurations rejection-sampled against every constraint of the cell) is
convex: :func:`pin_kpi_oed.oed.pool.approximate_design` solves it (weights capped at 1/m) and certifies

    tr C_s(ξ) ≥ φ*/m        for every m-point design ξ of distinct poses drawn from the pool,

with φ* ≥ φ(w)²/mean_top_m(d) (equivalence theorem on the capped simplex; the mean of the m largest
directional derivatives, never looser than the uncapped bound φ(w)²/max_i d_i). The *efficiency* of a design
is (φ*/m)/tr C_s(ξ). The pool is a finite sample of the feasible set, so a
continuous (IPOPT) design can exceed 100 % by the margin by which the pool
misses the best poses; with 10,000 candidates that margin is small, and the
report states it rather than hiding it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
import numpy as np

from pin_kpi_oed.oed.pool import ApproximateDesign, select
from pin_kpi_oed.results import Result

__all__ = ["Certificate", "certify_pool"]


@dataclass(kw_only=True)
class Certificate(Result):
    """A lower bound of tr(C_s) for m-point designs of a cell (a :class:`~pin_kpi_oed.results.Result`).

    ``success`` / ``status`` / ``nit`` are the relaxation's (equivalence-theorem gap below the
    tolerance; Newton steps of the relaxation); ``time_s`` covers sampling, relaxation and selection.

    Attributes:
        lower_bound_trace_cs_m2: φ*/m, the certified bound (m²).
        m: number of measurements the bound is for.
        pool_size: feasible candidates in the pool; samples: random configurations drawn.
        approx: the relaxation (weights, equivalence-theorem ratio).
        pool_selection: indices of the m-point pool selection; pool_selection_trace_cs_m2 its tr(C_s).
        Q_pool: the candidate configurations (N, n) rad.
    """

    lower_bound_trace_cs_m2: float
    m: int
    pool_size: int
    samples: int
    approx: ApproximateDesign
    pool_selection: np.ndarray
    pool_selection_trace_cs_m2: float
    Q_pool: np.ndarray

    def efficiency(self, trace_cs_m2: float) -> float:
        """Efficiency (φ*/m)/tr(C_s) of a design with the given tr(C_s) (1 = certified optimal)."""
        return float(self.lower_bound_trace_cs_m2 / trace_cs_m2)

    def to_dict(self) -> dict:
        """Plain JSON-able dict (SI units): the common result keys and the certificate's figures."""
        return {**self.result_dict(), "lower_bound_trace_cs_m2": self.lower_bound_trace_cs_m2, "m": self.m,
                "pool_size": self.pool_size, "samples": self.samples, "relaxation": self.approx.to_dict(),
                "pool_selection_trace_cs_m2": self.pool_selection_trace_cs_m2,
                "pool_selection_efficiency": self.efficiency(self.pool_selection_trace_cs_m2)}


def certify_pool(Fp: np.ndarray, m: int, E: np.ndarray | None, Q: np.ndarray, samples: int,
                 fixed_info: np.ndarray | None = None, t0: float | None = None) -> Certificate:
    """The certificate of a feasible candidate pool: solve the relaxation, select m poses, bound tr(C_s).

    Args:
        Fp: weighted Jacobians of the candidates over the identifiable parameters, (N, nh, nb).
        m: number of measurements.
        E: KPI Jacobian of the working configurations (criterion matrix of tr C_s), or None (D-optimality).
        Q: the candidate configurations, (N, n) rad.
        samples: random configurations drawn to find them.
        fixed_info: information every design already has (poses measured before, a prior), (nb, nb):
            the bound is then of tr(C_s) with it (:func:`pin_kpi_oed.oed.pool.approximate_design`).
        t0: ``time.perf_counter()`` when the work began (default: now).

    Returns:
        The certificate (bound of tr(C_s), m², for the KPI criterion, eq. 24a).
    """
    t0 = time.perf_counter() if t0 is None else t0
    sel = select(Fp, m, E, fixed_info=fixed_info)
    approx = sel.approx
    return Certificate(lower_bound_trace_cs_m2=approx.lower_bound / m, m=m, pool_size=Q.shape[0], samples=samples,
                       approx=approx, pool_selection=sel.indices, pool_selection_trace_cs_m2=sel.value, Q_pool=Q,
                       success=approx.success, status=approx.status, nit=approx.nit,
                       message=f"tr(C_s) >= {approx.lower_bound / m:.4g} m^2 for every {m}-pose design from "
                               f"{Q.shape[0]} feasible candidates ({approx.message})",
                       time_s=time.perf_counter() - t0)
