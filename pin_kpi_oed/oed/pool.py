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
Fedorov exchange: repeatedly swap a chosen point for a pool point when it
lowers φ, with rank-3 Woodbury updates evaluated for all candidates at once.
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
from pin_kpi_oed.oed.selection_result import PoolSelection
from pin_kpi_oed.threads import limit_threads

__all__ = ["select", "detmax", "exact_phi", "block_gains", "pool_phi", "approximate_design", "efficiency",
           "ApproximateDesign", "PoolSelection"]

#: the exchange runs over the support and the max(CANDIDATES, 5m) candidates of largest d
CANDIDATES = 300
#: ... and in large pools (N > 2 · WORKING_SET) the best design is polished by an exchange over the POLISH candidates
#: of largest d
POLISH = 3000


def block_gains(s: dict, G: np.ndarray | None, N: int, nh: int) -> np.ndarray:
    """−Δφ of candidate blocks whose S_i (nh×nh) is known by its entries ``s[a, b]`` (a ≤ b, each (N,)):
    log det S_i (D-type, G None) or tr(G_iᵀ S_i⁻¹ G_i) (A-type, G (N, nh, ns)).

    For nh ≤ 3 the 3×3 (2×2, 1×1) algebra is written out on length-N arrays — NumPy's batched ``solve`` /
    ``einsum`` on tiny matrices cost more than the arithmetic — with tr(Gᵀ S⁻¹ G) = Σ_ab (S⁻¹)_ab (G Gᵀ)_ab;
    larger nh use ``np.linalg``. Shared by the exchange here and :mod:`pin_kpi_oed.oed.extended`.
    """
    if nh > 3:
        S = np.empty((N, nh, nh))
        for (a, b), v in s.items():
            S[:, a, b] = S[:, b, a] = v
        if G is None:
            return np.linalg.slogdet(S)[1]
        return np.einsum("nas,nas->n", G, np.linalg.solve(S, G))
    if nh == 1:
        adj, det = {(0, 0): np.ones(N)}, s[0, 0]
    elif nh == 2:
        adj, det = {(0, 0): s[1, 1], (0, 1): -s[0, 1], (1, 1): s[0, 0]}, s[0, 0] * s[1, 1] - s[0, 1] ** 2
    else:
        a_, b_, c_, e_, f_, i_ = s[0, 0], s[0, 1], s[0, 2], s[1, 1], s[1, 2], s[2, 2]
        adj = {(0, 0): e_ * i_ - f_ * f_, (0, 1): c_ * f_ - b_ * i_, (0, 2): b_ * f_ - c_ * e_,
               (1, 1): a_ * i_ - c_ * c_, (1, 2): b_ * c_ - a_ * f_, (2, 2): a_ * e_ - b_ * b_}
        det = a_ * adj[0, 0] + b_ * adj[0, 1] + c_ * adj[0, 2]
    if G is None:
        return np.log(det)
    out = np.zeros(N)
    for (a, b), v in adj.items():
        out += (1.0 if a == b else 2.0) * v * np.einsum("ns,ns->n", G[:, a], G[:, b])
    return out / det


def _swap_gains(V: np.ndarray, G: np.ndarray | None) -> np.ndarray:
    """For each candidate i with S_i = I + V_i V_iᵀ: tr(G_iᵀ S_i⁻¹ G_i) (A-type), or log det S_i (G None: D).

    V: (N, nh, nb), G: (N, nh, ns); see :func:`block_gains`.
    """
    nh = V.shape[1]
    s = {(a, b): np.einsum("nk,nk->n", V[:, a], V[:, b]) + (a == b) for a in range(nh) for b in range(a, nh)}
    return block_gains(s, G, V.shape[0], nh)


def _exchange(Fp: np.ndarray, chosen: Sequence[int] | np.ndarray, K: np.ndarray | None, ridge: float,
              max_sweeps: int = 50, M0: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """Fedorov exchange with Woodbury updates: swap points while φ decreases (information M0 + Σ_chosen F_iᵀF_i).
    Returns (chosen indices, sweeps)."""
    N, nh, nb = Fp.shape
    chosen = list(chosen)
    in_set = np.zeros(N, bool)
    in_set[chosen] = True
    reg = ridge * np.eye(nb) if M0 is None else ridge * np.eye(nb) + M0

    def info_of(idx):
        F = Fp[idx].reshape(-1, nb)
        return F.T @ F + reg

    M = info_of(chosen)
    cur = pool_phi(M, K)
    FpT = np.ascontiguousarray(Fp.transpose(0, 2, 1))
    F2 = Fp.reshape(N * nh, nb)
    sweeps = 0
    for sweeps in range(1, max_sweeps + 1):  # noqa: B007 (the count is read after the loop)
        improved = False
        for pos in range(len(chosen)):
            out = chosen[pos]
            M_minus = M - FpT[out] @ Fp[out]
            try:
                L = np.linalg.cholesky(M_minus)
            except np.linalg.LinAlgError:
                continue
            Linv = np.linalg.solve(L, np.eye(nb))
            V = (F2 @ Linv.T).reshape(N, nh, nb)  # F_i L⁻ᵀ: S_i = I + V_i V_iᵀ = I + F_i M⁻¹ F_iᵀ
            if K is None:
                phi_minus = float(-2.0 * np.sum(np.log(np.diag(L))))
                gain = _swap_gains(V, None)  # −Δφ = log det S_i
            else:
                R = K @ Linv.T  # (ns, nb): K M⁻¹ Kᵀ = R Rᵀ
                phi_minus = float(np.sum(R * R))
                G = (F2 @ (Linv.T @ R.T)).reshape(N, nh, -1)  # F_i M⁻¹ Kᵀ, (N, nh, ns)
                gain = _swap_gains(V, G)  # tr reduction
            gain[in_set] = -np.inf
            best = int(np.argmax(gain))
            new_phi = phi_minus - gain[best]
            if new_phi < cur * (1 - 1e-10) - 1e-300:
                in_set[out], in_set[best] = False, True
                chosen[pos] = best
                M = M_minus + FpT[best] @ Fp[best]
                cur = pool_phi(M, K)
                improved = True
        if not improved:
            break
    return np.array(chosen), sweeps


@limit_threads
def select(Fp: np.ndarray, m: int, K: np.ndarray | None = None, tol: float = 1e-3, n_starts: int = 2,
           seed: int = 0, fixed_info: np.ndarray | None = None) -> PoolSelection:
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

    Returns:
        The selection (``indices``, exact ``value`` φ) with the approximate design and its certificate;
        ``success`` is the relaxation's.

    Raises:
        InputError: m larger than the pool.
        IdentifiabilityError: the pool does not identify the parameters.
    """
    t0 = time.perf_counter()
    N = Fp.shape[0]
    if m > N:
        raise InputError(f"cannot choose {m} measurements from a pool of {N} candidates")
    approx = approximate_design(Fp, K, tol=tol, m=m, fixed_info=fixed_info)
    M0 = None if fixed_info is None else np.asarray(fixed_info, float)
    cand, starts, d = _exchange_starts(Fp, m, K, approx, n_starts, seed, None if M0 is None else M0 / m)
    sub = Fp[cand]
    best, best_phi, sweeps = starts[0], np.inf, 0
    for s0 in starts:
        ridge = 0.0 if np.isfinite(pool_phi(_info(sub, s0, M0), K)) else 1e-12
        idx, nsw = _exchange(sub, s0, K, ridge, M0=M0)
        sweeps += nsw
        val = pool_phi(_info(sub, idx, M0), K)
        if val < best_phi:
            best, best_phi = idx, val
    best = cand[best]
    wide = np.union1d(cand, np.argsort(-d)[:POLISH]) if N > 2 * WORKING_SET else cand
    if wide.size > cand.size:  # polish: the best design, exchanged over a wider set (can only lower φ)
        pos = np.searchsorted(wide, best)
        idx, nsw = _exchange(Fp[wide], pos, K, 0.0 if np.isfinite(best_phi) else 1e-12, M0=M0)
        sweeps += nsw
        val = pool_phi(_info(Fp, wide[idx], M0), K)
        if val < best_phi:
            best, best_phi = wide[idx], val
    return PoolSelection(indices=best, value=float(best_phi), approx=approx, success=approx.success,
                         status=approx.status, nit=sweeps, time_s=time.perf_counter() - t0,
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
