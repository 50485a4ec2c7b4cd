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

from dataclasses import dataclass, field

import numpy as np

from pin_kpi_oed.errors import IdentifiabilityError, InputError


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


@dataclass
class ApproximateDesign:
    """Result of the relaxation.

    Attributes:
        weights: optimal measure on the pool, (N,), sums to 1.
        phi: φ(w) of the (normalised) measure.
        lower_bound: certified φ* ≥ φ(w)²/max d (A-type) or φ(w) − (max d − nb) (D) — per unit measure.
        max_d_ratio: max_i d_i / φ(w) (A) or max_i d_i / nb (D): 1 at the optimum (equivalence theorem).
        iterations: multiplicative iterations.
        support: indices with weight > 1e-4 / N.
    """

    weights: np.ndarray
    phi: float
    lower_bound: float
    max_d_ratio: float
    iterations: int
    support: np.ndarray = field(default_factory=lambda: np.zeros(0, int))

    def to_dict(self) -> dict:
        """Plain JSON-able dict."""
        return {"phi": self.phi, "lower_bound": self.lower_bound, "equivalence_max_d_ratio": self.max_d_ratio,
                "iterations": self.iterations, "support_size": int(self.support.size)}


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
    return ApproximateDesign(w, phi, bound, float(ratio), total, np.flatnonzero(w > 1e-4 / N))


def _exchange(Fp: np.ndarray, chosen: np.ndarray, K: np.ndarray | None, ridge: float, max_sweeps: int = 50
              ) -> np.ndarray:
    """Fedorov exchange with Woodbury updates: swap points while φ decreases. Returns chosen indices."""
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
    for _ in range(max_sweeps):
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
    return np.array(chosen)


def select(Fp: np.ndarray, m: int, K: np.ndarray | None = None, tol: float = 1e-3, n_starts: int = 2,
           seed: int = 0) -> tuple[np.ndarray, ApproximateDesign]:
    """Choose m distinct candidates: relaxation, rounding to the largest weights, exchange.

    The exchange runs from the rounded relaxation and from ``n_starts`` seeded subsets of the
    candidates the relaxation favours; the best exact design is returned.

    Returns:
        (indices of the chosen candidates, the approximate design with its certificate).

    Raises:
        InputError: m larger than the pool.
    """
    N = Fp.shape[0]
    if m > N:
        raise InputError(f"cannot choose {m} measurements from a pool of {N} candidates")
    approx = approximate_design(Fp, K, tol=tol)
    # exchange among the informative candidates: the support and the largest directional derivatives
    M = _info_w(Fp, approx.weights)
    d = _d(Fp, M, K)
    cand = np.union1d(np.argsort(-d)[:max(2000, 4 * m)], approx.support)
    start = np.searchsorted(cand, np.argsort(-approx.weights)[:m])
    sub = Fp[cand]
    # the rounded start, and a few seeded starts drawn from the candidates the relaxation favours
    rng = np.random.default_rng(seed)
    favoured = np.argsort(-(approx.weights[cand] + 1e-12 * d[cand]))[:min(cand.size, 3 * m)]
    starts = [start] + [rng.choice(favoured, size=m, replace=False) for _ in range(n_starts)]
    best, best_phi = start, np.inf
    for s0 in starts:
        ridge = 0.0 if np.isfinite(_phi(_info(sub, s0), K)) else 1e-12
        idx = _exchange(sub, s0, K, ridge)
        val = _phi(_info(sub, idx), K)
        if val < best_phi:
            best, best_phi = idx, val
    return cand[best], approx


def _info(Fp: np.ndarray, idx: np.ndarray) -> np.ndarray:
    F = Fp[idx].reshape(-1, Fp.shape[-1])
    return F.T @ F


def detmax(Fp: np.ndarray, m: int, K: np.ndarray | None = None, seed: int = 0) -> np.ndarray:
    """DETMAX-style baseline: exchange from a random m-subset (seeded)."""
    rng = np.random.default_rng(seed)
    start = rng.choice(Fp.shape[0], size=m, replace=False)
    ridge = 0.0 if np.isfinite(_phi(_info(Fp, start), K)) else 1e-12
    return _exchange(Fp, start, K, ridge)


def exact_phi(Fp: np.ndarray, idx: np.ndarray, K: np.ndarray | None = None) -> float:
    """φ of an exact design (the chosen candidates, information not normalised)."""
    return _phi(_info(Fp, np.asarray(idx)), K)


def efficiency(phi_exact: float, approx: ApproximateDesign, m: int) -> float:
    """Efficiency of an exact m-point A-type design against the certificate: (φ*_bound/m) / φ(ξ) ≤ 1."""
    return float(approx.lower_bound / m / phi_exact)
