"""Pool selection and optimality certificates for measurement designs.

Choose m configurations out of a pool of N feasible candidates (sampled, or
the poses of a measured data set). Each candidate i contributes the
information F_iᵀF_i (F_i: its weighted Jacobian rows over the identifiable
parameters). For a design *measure* w on the pool (w ≥ 0, Σw = 1)

    M(w) = Σ_i w_i F_iᵀ F_i,     φ(w) = tr(K M(w)⁻¹ Kᵀ)   (A-type: K = E for the KPI, K = I for A on C_p)
    or φ(w) = −log det M(w)                                 (D-optimality).

**Approximate design (relaxation).** φ is convex on the simplex; the
multiplicative algorithm (Silvey–Titterington–Torsney / Yu 2010)

    w_i ← w_i · (d_i / φ(w))^ρ ,    d_i = ‖K M⁻¹ F_iᵀ‖²_F   (= −∂φ/∂w_i),   ρ = 1/2

converges monotonically to the optimum w*. **Equivalence theorem**
(Kiefer–Wolfowitz, A-optimality): w is optimal iff max_i d_i ≤ φ(w), with
equality on the support. For any w, homogeneity (φ(t w) = φ(w)/t) and
convexity give the certified bound

    φ* ≥ φ(w)² / max_i d_i ,

and since an exact m-point design ξ has M = m·M(ξ/m), every exact design
over the same feasible set satisfies **tr C_s ≥ φ*/m**: the lower bound
against which :func:`efficiency` reports each design's efficiency
(φ*/m)/φ(ξ). (For D: eff = exp((−φ* + φ(ξ/m))/nb)... we report the A-type
bound only where the criterion is A-type; D uses max_i d_i ≤ nb.)

**Rounding and exchange.** The m largest-weight candidates (distinct) start a
Fedorov exchange: repeatedly swap a chosen point for a pool point when it
lowers φ, with rank-3 Woodbury updates evaluated for all candidates at once.
:func:`detmax` is the classical DETMAX-style exchange from a random start,
the baseline the relaxation must match or beat.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from pin_kpi_oed.errors import IdentifiabilityError, InputError
from pin_kpi_oed.results import Result
from pin_kpi_oed.threads import limit_threads


def _phi(M: np.ndarray, K: np.ndarray | None) -> float:
    """φ for information M: tr(K M⁻¹ Kᵀ) (A-type) or −log det M (K is None)."""
    try:
        L = np.linalg.cholesky(M)
    except np.linalg.LinAlgError:
        return np.inf
    if K is None:
        return float(-2.0 * np.sum(np.log(np.diag(L))))
    X = np.linalg.solve(L, K.T)
    return float(np.sum(X * X))


def _d(Fp: np.ndarray, M: np.ndarray, K: np.ndarray | None) -> np.ndarray:
    """Directional derivatives d_i = −∂φ/∂w_i for all candidates, (N,)."""
    Minv = np.linalg.inv(M)
    if K is None:
        B = Fp @ Minv  # (N, nh, nb)
        return np.einsum("nab,nab->n", B, Fp)
    G = Fp @ (Minv @ K.T)  # (N, nh, ns)
    return np.einsum("nas,nas->n", G, G)


@dataclass(kw_only=True)
class ApproximateDesign(Result):
    """Result of the relaxation (a :class:`~pin_kpi_oed.results.Result`).

    ``success`` / ``status`` ``converged``: the equivalence-theorem gap is below the tolerance;
    ``max_iter`` otherwise (the bound is valid either way, only looser). ``nit``: multiplicative
    iterations.

    Attributes:
        weights: optimal measure on the pool, (N,), sums to 1.
        phi: φ(w) of the (normalised) measure.
        lower_bound: certified φ* ≥ φ(w)²/max d (A-type) or φ(w) − (max d − nb) (D) — per unit measure.
        max_d_ratio: max_i d_i / φ(w) (A) or max_i d_i / nb (D): 1 at the optimum (equivalence theorem).
        support: indices with weight > 1e-4 / N.
    """

    weights: np.ndarray
    phi: float
    lower_bound: float
    max_d_ratio: float
    support: np.ndarray = field(default_factory=lambda: np.zeros(0, int))

    @property
    def iterations(self) -> int:
        """Multiplicative iterations (= ``nit``)."""
        return self.nit

    def to_dict(self) -> dict:
        """Plain JSON-able dict (the common result keys and the certificate's figures)."""
        return {**self.result_dict(), "phi": self.phi, "lower_bound": self.lower_bound,
                "equivalence_max_d_ratio": self.max_d_ratio, "iterations": self.nit,
                "support_size": int(self.support.size)}


@dataclass(kw_only=True)
class PoolSelection(Result):
    """m candidates chosen from a pool (a :class:`~pin_kpi_oed.results.Result`; ``nit``: exchange sweeps).

    Attributes:
        indices: the chosen candidates, (m,) distinct.
        phi: φ of the exact design (information not normalised): tr(K M⁻¹ Kᵀ) or −log det M.
        approx: the relaxation with its certificate.
    """

    indices: np.ndarray
    phi: float
    approx: ApproximateDesign

    def efficiency(self) -> float:
        """Efficiency of the selection against the relaxation's certificate (A-type, ≤ 1)."""
        return efficiency(self.phi, self.approx, self.indices.size)

    def to_dict(self) -> dict:
        """Plain JSON-able dict."""
        return {**self.result_dict(), "indices": self.indices.tolist(), "phi": self.phi,
                "relaxation": self.approx.to_dict()}


def _multiplicative(Fp: np.ndarray, w: np.ndarray, K: np.ndarray | None, tol: float, max_iter: int
                    ) -> tuple[np.ndarray, int]:
    """Multiplicative iterations on a (sub)pool until the equivalence gap < tol. Returns (w, iterations)."""
    nb = Fp.shape[-1]
    it = 0
    for it in range(1, max_iter + 1):
        M = _info_w(Fp, w)
        d = _d(Fp, M, K)
        target = _phi(M, K) if K is not None else nb
        if d.max() / target - 1.0 < tol:
            break
        w = w * np.sqrt(d / target) if K is not None else w * (d / nb)
        w /= w.sum()
    return w, it


def _info_w(Fp: np.ndarray, w: np.ndarray) -> np.ndarray:
    Fw = (Fp * np.sqrt(w)[:, None, None]).reshape(-1, Fp.shape[-1])
    return Fw.T @ Fw


def approximate_design(Fp: np.ndarray, K: np.ndarray | None = None, tol: float = 1e-3, max_iter: int = 20000
                       ) -> ApproximateDesign:
    """Optimal approximate design on a candidate pool by the multiplicative algorithm.

    An active-set strategy keeps it fast on large pools: a few iterations on the whole pool, then
    iterations on the candidates carrying weight plus every candidate that violates the equivalence
    condition, re-checked on the whole pool until it holds to ``tol``. The certificate is always
    computed on the whole pool.

    Args:
        Fp: weighted Jacobians of the candidates over the identifiable parameters, (N, nh, nb).
        K: A-type criterion matrix (E for tr C_s, identity for tr C_p); None = D-optimality.
        tol: stop when the equivalence-theorem gap max_i d_i/φ − 1 (A) or max d_i/nb − 1 (D) < tol.
        max_iter: cap on the total number of multiplicative iterations.

    Raises:
        IdentifiabilityError: the whole pool does not identify the parameters.
    """
    t0 = time.perf_counter()
    N, nh, nb = Fp.shape
    w = np.full(N, 1.0 / N)
    if not np.isfinite(_phi(_info_w(Fp, w), K)):
        raise IdentifiabilityError("the candidate pool does not identify the parameters: sample more, or more "
                                   "varied, feasible configurations")
    w, total = _multiplicative(Fp, w, K, tol, min(50, max_iter))
    k = min(N, max(20 * nb, 500))
    while total < max_iter:
        M = _info_w(Fp, w)
        d = _d(Fp, M, K)
        target = _phi(M, K) if K is not None else nb
        if d.max() / target - 1.0 < tol:
            break
        active = np.union1d(np.argsort(-w)[:k], np.argsort(-d)[:k // 5])
        wa = w[active] + 1e-3 / active.size  # give violators some weight
        wa /= wa.sum()
        wa, it = _multiplicative(Fp[active], wa, K, tol / 2, max_iter - total)
        total += it
        w = np.zeros(N)
        w[active] = wa
    M = _info_w(Fp, w)
    d = _d(Fp, M, K)
    phi = _phi(M, K)
    if K is not None:
        bound, ratio = phi ** 2 / d.max(), d.max() / phi
    else:
        bound, ratio = phi - (d.max() - nb), d.max() / nb
    ok = bool(ratio - 1.0 < tol)
    return ApproximateDesign(weights=w, phi=phi, lower_bound=bound, max_d_ratio=float(ratio),
                             support=np.flatnonzero(w > 1e-4 / N), nit=total, success=ok,
                             status="converged" if ok else "max_iter",
                             message=f"equivalence theorem: max d/phi = {ratio:.5f} after {total} iterations",
                             time_s=time.perf_counter() - t0)


def _exchange(Fp: np.ndarray, chosen: np.ndarray, K: np.ndarray | None, ridge: float, max_sweeps: int = 50
              ) -> tuple[np.ndarray, int]:
    """Fedorov exchange with Woodbury updates: swap points while φ decreases. Returns (chosen indices, sweeps)."""
    N, nh, nb = Fp.shape
    chosen = list(chosen)
    in_set = np.zeros(N, bool)
    in_set[chosen] = True
    reg = ridge * np.eye(nb)

    def info_of(idx):
        F = Fp[idx].reshape(-1, nb)
        return F.T @ F + reg

    M = info_of(chosen)
    cur = _phi(M, K)
    sweeps = 0
    for sweeps in range(1, max_sweeps + 1):
        improved = False
        for pos in range(len(chosen)):
            out = chosen[pos]
            M_minus = M - Fp[out].T @ Fp[out]
            phi_minus = _phi(M_minus, K)
            if not np.isfinite(phi_minus):
                continue
            Minv = np.linalg.inv(M_minus)
            B = Fp @ Minv  # (N, nh, nb)
            S = np.eye(nh) + np.einsum("nab,ncb->nac", B, Fp)  # (N, nh, nh)
            if K is None:
                gain = np.linalg.slogdet(S)[1]  # −Δφ
            else:
                G = B @ K.T  # (N, nh, ns)
                X = np.linalg.solve(S, G)
                gain = np.einsum("nas,nas->n", G, X)  # tr reduction
            gain = np.where(in_set, -np.inf, gain)
            best = int(np.argmax(gain))
            new_phi = phi_minus - gain[best]
            if new_phi < cur * (1 - 1e-10) - 1e-300:
                in_set[out], in_set[best] = False, True
                chosen[pos] = best
                M = M_minus + Fp[best].T @ Fp[best]
                cur = _phi(M, K)
                improved = True
        if not improved:
            break
    return np.array(chosen), sweeps


@limit_threads
def select(Fp: np.ndarray, m: int, K: np.ndarray | None = None, tol: float = 1e-3, n_starts: int = 2,
           seed: int = 0) -> PoolSelection:
    """Choose m distinct candidates: relaxation, rounding to the largest weights, exchange.

    The exchange runs from the rounded relaxation and from ``n_starts`` seeded subsets of the
    candidates the relaxation favours; the best exact design is returned.

    Args:
        Fp: weighted Jacobians of the candidates over the identifiable parameters, (N, nh, nb).
        m: number of candidates to choose.
        K: A-type criterion matrix (:meth:`~pin_kpi_oed.oed.criteria.Criterion.pool_form`); None = D-optimality.
        tol: equivalence-theorem tolerance of the relaxation.
        n_starts: seeded exchange starts besides the rounded relaxation.
        seed: seed of those starts.

    Returns:
        The selection (``indices``, exact ``phi``) with the approximate design and its certificate;
        ``success`` is the relaxation's.

    Raises:
        InputError: m larger than the pool.
        IdentifiabilityError: the pool does not identify the parameters.
    """
    t0 = time.perf_counter()
    N = Fp.shape[0]
    if m > N:
        raise InputError(f"cannot choose {m} measurements from a pool of {N} candidates")
    approx = approximate_design(Fp, K, tol=tol)
    cand, starts = _exchange_starts(Fp, m, K, approx, n_starts, seed)
    sub = Fp[cand]
    best, best_phi, sweeps = starts[0], np.inf, 0
    for s0 in starts:
        ridge = 0.0 if np.isfinite(_phi(_info(sub, s0), K)) else 1e-12
        idx, nsw = _exchange(sub, s0, K, ridge)
        sweeps += nsw
        val = _phi(_info(sub, idx), K)
        if val < best_phi:
            best, best_phi = idx, val
    return PoolSelection(indices=cand[best], phi=float(best_phi), approx=approx, success=approx.success,
                         status=approx.status, nit=sweeps, time_s=time.perf_counter() - t0,
                         message=f"{m} of {N} candidates; {approx.message}")


def _exchange_starts(Fp: np.ndarray, m: int, K: np.ndarray | None, approx: ApproximateDesign, n_starts: int,
                     seed: int) -> tuple[np.ndarray, list[np.ndarray]]:
    """The exchange's candidate subset (support + largest directional derivatives) and its starts in it:
    the rounded relaxation and ``n_starts`` seeded subsets of the candidates the relaxation favours."""
    M = _info_w(Fp, approx.weights)
    d = _d(Fp, M, K)
    cand = np.union1d(np.argsort(-d)[:max(2000, 4 * m)], approx.support)
    start = np.searchsorted(cand, np.argsort(-approx.weights)[:m])
    rng = np.random.default_rng(seed)
    favoured = np.argsort(-(approx.weights[cand] + 1e-12 * d[cand]))[:min(cand.size, 3 * m)]
    return cand, [start] + [rng.choice(favoured, size=m, replace=False) for _ in range(n_starts)]


def _info(Fp: np.ndarray, idx: np.ndarray) -> np.ndarray:
    F = Fp[idx].reshape(-1, Fp.shape[-1])
    return F.T @ F


def detmax(Fp: np.ndarray, m: int, K: np.ndarray | None = None, seed: int = 0) -> np.ndarray:
    """DETMAX-style baseline: exchange from a random m-subset (seeded)."""
    rng = np.random.default_rng(seed)
    start = rng.choice(Fp.shape[0], size=m, replace=False)
    ridge = 0.0 if np.isfinite(_phi(_info(Fp, start), K)) else 1e-12
    return _exchange(Fp, start, K, ridge)[0]


def exact_phi(Fp: np.ndarray, idx: np.ndarray, K: np.ndarray | None = None) -> float:
    """φ of an exact design (the chosen candidates, information not normalised)."""
    return _phi(_info(Fp, np.asarray(idx)), K)


def efficiency(phi_exact: float, approx: ApproximateDesign, m: int) -> float:
    """Efficiency of an exact m-point A-type design against the certificate: (φ*_bound/m) / φ(ξ) ≤ 1."""
    return float(approx.lower_bound / m / phi_exact)
