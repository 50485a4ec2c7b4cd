"""The optimality certificate of a design problem: a feasible pool sampled on its cell, then the relaxation.

The bound itself (equivalence theorem on the capped simplex) is :func:`pin_kpi_oed.oed.certificate.certify_pool`.
"""

from __future__ import annotations

import time

import numpy as np

from pin_kpi_oed.design.optimize import DesignProblem
from pin_kpi_oed.oed.certificate import Certificate, certify_pool

__all__ = ["certify"]


def certify(problem: DesignProblem, m: int, pool_size: int = 5000, seed: int = 0,
            max_tries_per_candidate: int = 200, extra: list[np.ndarray] | None = None,
            fixed_info: np.ndarray | None = None) -> Certificate:
    """Sample a feasible pool for a design problem, solve the relaxation, select m poses.

    Args:
        problem: the design problem (model, identifiable set, E, constraints).
        m: number of measurements.
        pool_size: feasible candidates to sample.
        seed: seed of the sampling.
        max_tries_per_candidate: sampling budget per candidate.
        extra: further feasible configurations to add to the pool, e.g. the poses of the optimised
            designs: the bound then also covers every design built from them (and an optimised
            design can no longer exceed 100 % efficiency by using poses the random pool missed).
        fixed_info: information every design already has (poses measured before, a prior), (nb, nb):
            the bound is then of tr(C_s) with it (:func:`pin_kpi_oed.oed.pool.approximate_design`).

    Returns:
        The certificate (bound of tr(C_s), m², for the KPI criterion, eq. 24a).

    Raises:
        InfeasibleError: not enough feasible poses found (from the sampler).
    """
    t0 = time.perf_counter()
    Q, samples = problem.random_design(pool_size, seed=seed, max_tries=max(problem.cell.max_random_tries,
                                                                          max_tries_per_candidate * pool_size))
    if extra:
        Q = np.vstack([Q] + [np.atleast_2d(x) for x in extra])
    Fp = problem.model.weighted_jacobian(problem.p0, Q)[:, :, problem.base]
    return certify_pool(Fp, m, problem.E, Q, samples, fixed_info=fixed_info, t0=t0)
