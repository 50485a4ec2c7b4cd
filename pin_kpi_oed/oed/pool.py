"""Pool selection and optimality certificates for measurement designs.

Choose m configurations out of a pool of N feasible candidates (sampled, or
the poses of a measured data set). Each candidate i contributes the
information F_iᵀF_i (F_i: its weighted Jacobian rows over the identifiable
parameters). For a design *measure* w on the pool (w ≥ 0, Σw = 1)

    M(w) = Σ_i w_i F_iᵀ F_i,     φ(w) = tr(K M(w)⁻¹ Kᵀ)   (A-type: K = E for the KPI, K = I for A on C_p)
    or φ(w) = −log det M(w)                                 (D-optimality).

**Approximate design (relaxation)** (:mod:`pin_kpi_oed.oed.relaxation`): the convex problem over design
measures with weights capped at 1/m, solved with its equivalence-theorem certificate: every exact design of
distinct pool candidates satisfies **tr C_s ≥ φ*/m**, the bound against which each selection's efficiency
(φ*/m)/φ(ξ) is reported.

**Rounding and exchange.** The m largest-weight candidates (distinct) start a
Fedorov exchange of the one pool selector (:mod:`pin_kpi_oed.oed.pool_search`): repeatedly swap a chosen
point for a pool point when it lowers φ, with rank-nh Woodbury updates evaluated for all candidates at once.
:func:`detmax` is the classical DETMAX-style exchange from a random start,
the baseline the relaxation must match or beat.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.oed.relaxation import (WORKING_SET, ApproximateDesign, approximate_design, directional_derivatives,
                                        efficiency, pool_phi)
from pin_kpi_oed.oed.pool_search import block_gains, information_exchange
from pin_kpi_oed.oed.selection_result import PoolSelection
from pin_kpi_oed.threads import limit_threads

__all__ = ["select", "detmax", "exact_phi", "block_gains", "pool_phi", "approximate_design", "efficiency",
           "ApproximateDesign", "PoolSelection"]

#: the exchange runs over the support and the max(CANDIDATES, 5m) candidates of largest d
CANDIDATES = 300
#: ... and in large pools (N > 2 · WORKING_SET) the best design is polished by an exchange over the POLISH candidates
#: of largest d
POLISH = 3000


def _exchange(Fp: np.ndarray, chosen: Sequence[int] | np.ndarray, K: np.ndarray | None, ridge: float,
              max_sweeps: int = 50, M0: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """Fedorov exchange of the one pool selector (:func:`~pin_kpi_oed.oed.pool_search.exchange` on the information
    M0 + ridge·I + Σ_chosen F_iᵀF_i): swap points while φ decreases. Returns (chosen indices, swaps)."""
    nb = Fp.shape[2]
    reg = ridge * np.eye(nb) if M0 is None else ridge * np.eye(nb) + M0
    return information_exchange(Fp, chosen, K, reg, max_sweeps, rel_tol=1e-10, abs_tol=1e-300)


@limit_threads
def select(Fp: np.ndarray, m: int, K: np.ndarray | None = None, tol: float = 1e-3, n_starts: int = 2,
           seed: int = 0, fixed_info: np.ndarray | None = None, names: list[str] | None = None) -> PoolSelection:
    """Choose m distinct candidates: relaxation (weights capped at 1/m), rounding to the largest weights, exchange.

    The exchange runs, over the support and the max(300, 5m) candidates with the largest d_i at the
    relaxation's optimum, from the rounded relaxation and from ``n_starts`` seeded subsets of the
    candidates the relaxation favours; the best exact design is returned.

    Args:
        Fp: weighted Jacobians of the candidates over the identifiable parameters, (N, nh, nb).
        m: number of candidates to choose.
        K: A-type criterion matrix (:meth:`~pin_kpi_oed.oed.criteria.Criterion.pool_form`); None = D-optimality.
        tol: equivalence-theorem tolerance of the relaxation.
        n_starts: seeded exchange starts besides the rounded relaxation.
        seed: seed of those starts.
        fixed_info: information M₀ every design already has (poses measured before, a prior), (nb, nb):
            φ of M₀ + Σ_chosen F_iᵀF_i is minimised and certified (:func:`approximate_design`).
        names: the identifiable parameters' names, for the refusal of a pool that does not identify them.

    Returns:
        The selection (``indices``, exact ``value`` φ) with the approximate design and its certificate;
        ``success`` is the relaxation's.

    Raises:
        InputError: m larger than the pool.
        IdentifiabilityError: the pool does not identify the parameters (naming those its poses move alike).
    """
    t0 = time.perf_counter()
    N = Fp.shape[0]
    if m > N:
        raise InputError(f"cannot choose {m} measurements from a pool of {N} candidates")
    approx = approximate_design(Fp, K, tol=tol, m=m, fixed_info=fixed_info, names=names)
    M0 = None if fixed_info is None else np.asarray(fixed_info, float)
    cand, starts, d = _exchange_starts(Fp, m, K, approx, n_starts, seed, None if M0 is None else M0 / m)
    sub = Fp[cand]
    best, best_phi, swaps = starts[0], np.inf, 0
    for s0 in starts:
        ridge = 0.0 if np.isfinite(pool_phi(_info(sub, s0, M0), K)) else 1e-12
        idx, nsw = _exchange(sub, s0, K, ridge, M0=M0)
        swaps += nsw
        val = pool_phi(_info(sub, idx, M0), K)
        if val < best_phi:
            best, best_phi = idx, val
    best = cand[best]
    wide = np.union1d(cand, np.argsort(-d)[:POLISH]) if N > 2 * WORKING_SET else cand
    if wide.size > cand.size:  # polish: the best design, exchanged over a wider set (can only lower φ)
        pos = np.searchsorted(wide, best)
        idx, nsw = _exchange(Fp[wide], pos, K, 0.0 if np.isfinite(best_phi) else 1e-12, M0=M0)
        swaps += nsw
        val = pool_phi(_info(Fp, wide[idx], M0), K)
        if val < best_phi:
            best, best_phi = wide[idx], val
    return PoolSelection(indices=best, value=float(best_phi), approx=approx, success=approx.success,
                         status=approx.status, nit=swaps, time_s=time.perf_counter() - t0,
                         message=f"{m} of {N} candidates; {approx.message}")


def _exchange_starts(Fp: np.ndarray, m: int, K: np.ndarray | None, approx: ApproximateDesign, n_starts: int,
                     seed: int, M0: np.ndarray | None = None) -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
    """The exchange's candidate subset (support + largest directional derivatives) and its starts in it:
    the rounded relaxation and ``n_starts`` seeded subsets of the candidates the relaxation favours."""
    d = directional_derivatives(Fp, approx.weights, K, M0=M0)[1]
    cand = np.union1d(np.argsort(-d)[:max(CANDIDATES, 5 * m)], np.flatnonzero(approx.weights > 0))
    order = np.lexsort((-d[cand], -approx.weights[cand]))  # by weight, then by d (positions in cand)
    start = order[:m]
    rng = np.random.default_rng(seed)
    favoured = order[:min(cand.size, 3 * m)]
    return cand, [start] + [rng.choice(favoured, size=m, replace=False) for _ in range(n_starts)], d


def _info(Fp: np.ndarray, idx: np.ndarray, M0: np.ndarray | None = None) -> np.ndarray:
    F = Fp[idx].reshape(-1, Fp.shape[-1])
    return F.T @ F if M0 is None else F.T @ F + M0


def detmax(Fp: np.ndarray, m: int, K: np.ndarray | None = None, seed: int = 0) -> np.ndarray:
    """DETMAX-style baseline: exchange from a random m-subset (seeded)."""
    rng = np.random.default_rng(seed)
    start = rng.choice(Fp.shape[0], size=m, replace=False)
    ridge = 0.0 if np.isfinite(pool_phi(_info(Fp, start), K)) else 1e-12
    return _exchange(Fp, start, K, ridge)[0]


def exact_phi(Fp: np.ndarray, idx: np.ndarray, K: np.ndarray | None = None, fixed_info: np.ndarray | None = None
              ) -> float:
    """φ of an exact design (the chosen candidates, information not normalised; plus ``fixed_info`` if given)."""
    return pool_phi(_info(Fp, np.asarray(idx), None if fixed_info is None else np.asarray(fixed_info, float)), K)
