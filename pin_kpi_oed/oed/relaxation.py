"""The approximate design of a pool and its certificate (the relaxation of pool selection).

For a design *measure* w on the pool (w ≥ 0, Σw = 1), M(w) = Σ_i w_i F_iᵀ F_i (+ fixed information M₀) and
φ(w) = tr(K M(w)⁻¹ Kᵀ) (A-type) or −log det M(w) (D). φ is convex on the simplex. :func:`approximate_design`
solves it by a primal–dual interior-point (Newton) method with the exact Hessian on a working set of candidates,
grown by column generation (the equivalence condition is checked on the whole pool after each solve, so dropping
the other candidates is exact); the classical multiplicative algorithm (Silvey–Titterington–Torsney / Yu 2010,
w_i ← w_i (d_i/φ)^½, d_i = ‖K M⁻¹F_iᵀ‖²_F = −∂φ/∂w_i) is kept as ``method="multiplicative"``.
**Equivalence theorem** (Kiefer–Wolfowitz, A-optimality): w is optimal iff max_i d_i ≤ φ(w), with equality on the
support. For any w, homogeneity (φ(t w) = φ(w)/t) and convexity give the certified bound φ* ≥ φ(w)²/max_i d_i;
with weights capped at 1/m (m distinct candidates) φ* ≥ φ(w)²/mean_top_m(d), never looser, and every exact
m-point design of distinct candidates has **tr C_s ≥ φ*/m** (:func:`efficiency`). (D: φ* ≥ φ(w) − (mean_top_m(d)
− nb), and an exact design's −log det is ≥ φ* − nb log m.)
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from pin_kpi_oed.errors import IdentifiabilityError, InputError
from pin_kpi_oed.oed.covariance import check_pivots, weakest_direction
from pin_kpi_oed.results import Result

__all__ = ["ApproximateDesign", "approximate_design", "check_pool", "directional_derivatives", "efficiency",
           "pool_phi", "WORKING_SET"]


def pool_phi(M: np.ndarray, K: np.ndarray | None) -> float:
    """φ for information M: tr(K M⁻¹ Kᵀ) (A-type) or −log det M (K is None)."""
    try:
        L = np.linalg.cholesky(M)
    except np.linalg.LinAlgError:
        return np.inf
    if K is None:
        return float(-2.0 * np.sum(np.log(np.diag(L))))
    X = np.linalg.solve(L, K.T)
    return float(np.sum(X * X))


def check_pool(M: np.ndarray, names: list[str] | None = None) -> None:
    """Refuse a candidate pool whose information M (uniform weights, with the fixed part) is singular on the scaled
    basis, naming the parameters its poses cannot tell apart.

    Raises:
        IdentifiabilityError: "the candidate pool does not identify the parameters: 'a' and 'b' move the
            measurements alike in every pose of the pool (...)" and what to change.
    """
    where = "every pose of the pool"
    try:
        L = np.linalg.cholesky(M)
        check_pivots(M, np.diag(L), names, where)
    except (np.linalg.LinAlgError, IdentifiabilityError):
        raise IdentifiabilityError(
            f"the candidate pool does not identify the parameters: {weakest_direction(M, names, where)}; "
            "sample more, or more varied, feasible configurations (the cell's obstacles, the line of sight and the "
            "incidence limit may keep the pool from the joint ranges that tell them apart), or fix one of them as "
            "known") from None


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
    ``max_iter`` otherwise (the bound is valid either way, only looser). ``nit``: Newton steps (or
    multiplicative iterations with ``method="multiplicative"``).

    Attributes:
        weights: optimal measure on the pool, (N,), sums to 1.
        phi: φ(w) of the (normalised) measure.
        lower_bound: certified φ* ≥ φ(w)²/top (A-type) or φ(w) − (top − nb) (D), per unit measure; top = max_i d_i,
            or with the cap 1/m the mean of the m largest d_i.
        max_d_ratio: top / φ(w) (A) or top / nb (D): 1 at the optimum (equivalence theorem).
        support: indices with weight > 1e-4 / N.
    """

    weights: np.ndarray
    phi: float
    lower_bound: float
    max_d_ratio: float
    support: np.ndarray = field(default_factory=lambda: np.zeros(0, int))

    def to_dict(self) -> dict:
        """Plain JSON-able dict (the common result keys and the certificate's figures)."""
        return {**self.result_dict(), "phi": self.phi, "lower_bound": self.lower_bound,
                "equivalence_max_d_ratio": self.max_d_ratio, "iterations": self.nit,
                "support_size": int(self.support.size)}


def _multiplicative(Fp: np.ndarray, w: np.ndarray, K: np.ndarray | None, tol: float, max_iter: int,
                    M0: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """Multiplicative iterations on a (sub)pool until the equivalence gap < tol. Returns (w, iterations).

    With a fixed part M0 the target Σ w_i d_i replaces φ (A) / nb (D): a heuristic warm start only."""
    nb = Fp.shape[-1]
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 (the count is read after the loop)
        M = _info_w(Fp, w, M0)
        d = _d(Fp, M, K)
        target = (pool_phi(M, K) if K is not None else nb) if M0 is None else float(w @ d)
        if d.max() / target - 1.0 < tol:
            break
        w = w * np.sqrt(d / target) if K is not None else w * (d / nb)
        w /= w.sum()
    return w, it


def _info_w(Fp: np.ndarray, w: np.ndarray, M0: np.ndarray | None = None) -> np.ndarray:
    """M(w) = M0 + Σ w_i F_iᵀF_i (M0: the fixed part per unit measure, or None)."""
    Fw = (Fp * np.sqrt(w)[:, None, None]).reshape(-1, Fp.shape[-1])
    return Fw.T @ Fw if M0 is None else Fw.T @ Fw + M0


def newton_parts(F2: np.ndarray, k: int, nh: int, w: np.ndarray, K: np.ndarray | None,
                  M0: np.ndarray | None = None) -> tuple[float, np.ndarray, np.ndarray]:
    """φ(w), its gradient (−d) and a factor B of its Hessian H = B Bᵀ on a (sub)pool; F2 the stacked candidates
    (k·nh, nb).

    With M = L Lᵀ, G_i = F_i L⁻ᵀ (nh, nb) and Ã_i = G_iᵀG_i = L⁻¹A_iL⁻ᵀ (A_i = F_iᵀF_i):
    A-type, R = K L⁻ᵀ: φ = ‖R‖²_F, d_i = ‖G_i Rᵀ‖²_F = ‖F_i M⁻¹Kᵀ‖²_F and
    ∂²φ/∂w_i∂w_j = 2 tr(K M⁻¹A_iM⁻¹A_jM⁻¹Kᵀ) = 2 tr(P Ã_i Ã_j), P = RᵀR = V Λ Vᵀ. In P's eigenbasis
    (X_i = Vᵀ Ã_i V, symmetric) 2 tr(P Ã_i Ã_j) = Σ_{a≤b} c_ab X_i,ab X_j,ab with c_ab = 2(λ_a + λ_b)/(1 + δ_ab),
    so B_i = (√c_ab X_i,ab) over the pairs a ≤ b with c_ab > 0: rank r ≤ nb(nb+1)/2, and for a KPI with ns
    rows r ≤ ns·nb − ns(ns−1)/2 (pairs inside P's null space drop out; ns = 3: 78 of 378).
    D: φ = −log det M, d_i = ‖G_i‖²_F, ∂²φ/∂w_i∂w_j = tr(M⁻¹A_iM⁻¹A_j) = tr(Ã_i Ã_j): the same with V = I,
    λ_a = ½. The Newton system then costs O(k·r²) (Woodbury, :func:`solve_diag_lowrank`) instead of O(k³).
    A fixed part M0 (M = M0 + Σ w_i A_i) changes only M.

    Returns:
        (φ, g (k,), B (k, r)).
    """
    nb = F2.shape[1]
    Fw = F2 * np.repeat(np.sqrt(w), nh)[:, None]
    L = np.linalg.cholesky(Fw.T @ Fw if M0 is None else Fw.T @ Fw + M0)
    Linv = np.linalg.solve(L, np.eye(nb))
    G = (F2 @ Linv.T).reshape(k, nh, nb)
    if K is None:
        phi = float(-2.0 * np.log(np.diag(L)).sum())
        g = -np.einsum("iab,iab->i", G, G)
        lam = np.full(nb, 0.5)
    else:
        R = K @ Linv.T
        phi = float(np.sum(R * R))
        g = -np.einsum("ias,ias->i", *(2 * [G @ R.T]))
        lam, V = np.linalg.eigh(R.T @ R)
        lam = np.where(lam > 1e-13 * lam.max(), lam, 0.0)  # P has rank ns: the rest is rounding
        G = G @ V
    ia, ib = np.triu_indices(nb)
    c = 2.0 * (lam[ia] + lam[ib]) / np.where(ia == ib, 2.0, 1.0)
    keep = c > 0
    if keep.all():  # Vᵀ Ã_i V = Σ_h (G_i V)_h,a (G_i V)_h,b whole (k, nb, nb), then its upper triangle: the same sums
        P = G[:, 0, :, None] * G[:, 0, None, :]
        for h in range(1, nh):
            P += G[:, h, :, None] * G[:, h, None, :]
        X = P.reshape(k, nb * nb)[:, ia * nb + ib]
    else:  # a KPI's few kept pairs, entry by entry
        ia, ib = ia[keep], ib[keep]
        X = G[:, 0, ia] * G[:, 0, ib]  # the kept entries of Vᵀ Ã_i V, (k, r)
        for h in range(1, nh):
            X += G[:, h, ia] * G[:, h, ib]
    X *= np.sqrt(c[keep])
    return phi, g, X


def solve_diag_lowrank(D: np.ndarray, B: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve (diag(D) + B Bᵀ) X = rhs for D > 0: Woodbury with the r×r capacitance matrix I + BᵀD⁻¹B
    (Cholesky) when B has fewer columns than rows, the dense k×k system otherwise.

    Args:
        D: (k,) positive diagonal; B: (k, r); rhs: (k,) or (k, c).

    Returns:
        X, shaped as rhs.
    """
    k, r = B.shape
    if r >= k:
        A = B @ B.T
        A[np.diag_indices(k)] += D
        return np.linalg.solve(A, rhs)
    Di = 1.0 / D
    X = rhs * (Di if rhs.ndim == 1 else Di[:, None])
    BD = B * Di[:, None]
    C = B.T @ BD
    C[np.diag_indices(r)] += 1.0
    L = np.linalg.cholesky(C)
    Y = np.linalg.solve(L.T, np.linalg.solve(L, B.T @ X))
    return X - BD @ Y


def _gap(d: np.ndarray, w: np.ndarray, scale: float, m: int, fixed: bool) -> float:
    """Equivalence-theorem gap: mean_top_m(d)/scale − 1 (scale = φ (A) or nb (D) = Σ w_i d_i without a fixed
    part), or with a fixed part (mean_top_m(d) − Σ w_i d_i)/scale."""
    top = _top_mean(d, m)
    return top / scale - 1.0 if not fixed else (top - float(w @ d) / float(w.sum())) / abs(scale)


def _top_mean(d: np.ndarray, m: int) -> float:
    """Mean of the m largest entries of d (m = 1: the maximum)."""
    return float(d.max()) if m <= 1 else float(np.mean(np.partition(d, d.size - m)[d.size - m:]))


def onto_capped(w: np.ndarray, cap: float) -> np.ndarray:
    """A measure of the capped simplex {v ≥ 0, Σv = 1, v ≤ cap} from w: weights above the cap are cut to it and
    the excess is spread over the others in proportion (repeated until none exceeds; the warm start's projection).

    Args:
        w: weights ≥ 0 summing to 1, (k,).
        cap: the cap 1/m, with cap·k ≥ 1.

    Returns:
        v, (k,): Σv = 1, 0 ≤ v ≤ cap; v = w if w is already capped.
    """
    v = w.copy()
    for _ in range(v.size):
        over = v > cap
        if not over.any():
            break
        excess = float(np.sum(v[over] - cap))
        v[over] = cap
        free = v < cap
        v[free] += excess * (v[free] / v[free].sum() if v[free].sum() > 0 else 1.0 / free.sum())
    return v


def _newton_simplex(Fa: np.ndarray, w: np.ndarray, K: np.ndarray | None, tol: float, m: int = 1,
                    max_iter: int = 60, M0: np.ndarray | None = None, warm: bool = False) -> tuple[np.ndarray, int]:
    """Primal–dual interior-point (Newton) method for min φ(w) over {w ≥ 0, Σw = 1, w ≤ 1/m}.

    KKT conditions: ∇φ + ν1 − z + y = 0, w∘z = μ, (1/m − w)∘y = μ, μ → 0 (the cap and its dual y
    only for m > 1). Each step solves the (k+1)-dimensional Newton system with the exact Hessian
    (:func:`newton_parts`: H = B Bᵀ of rank r ≤ nb(nb+1)/2, solved by Woodbury in O(k·r²)) and keeps the
    iterates interior (fraction to the boundary 0.99). It converges
    in 15–40 steps, where the multiplicative algorithm needs thousands of iterations.

    Args:
        Fa: the candidates' weighted Jacobians, (k, nh, nb), k ≥ m; together they must identify the parameters.
        w: starting weights, (k,) (pulled into the interior and renormalised).
        K: A-type criterion matrix; None = D-optimality.
        tol: stop when the gap on the subpool, mean of the m largest d / φ − 1 (A) or / nb − 1 (D), < tol.
        m: the cap 1/m on each weight (distinct points of an m-point design); 1 = no cap.
        max_iter: cap on Newton steps.
        M0: fixed information per unit measure (M = M0 + Σ w_i A_i), or None; the gap is then
            (mean of the m largest d − Σ w_i d_i) / (φ (A) or nb (D)).
        warm: w is a previous solution: start from it mixed 10 % (not 50 %) with the uniform measure.

    Returns:
        (weights, Newton steps).

    Raises:
        numpy.linalg.LinAlgError: the subpool does not identify the parameters.
    """
    k, nh, nb = Fa.shape
    F2 = Fa.reshape(k * nh, nb)
    cap = 1.0 / m if m > 1 else np.inf
    w = np.clip(w, 1e-6 / k, None)
    w = w / w.sum()
    if m > 1:  # strictly inside the cap: mix with the uniform measure (1/k < 1/m)
        if warm:  # the previous round's weights, 10 % toward the uniform measure (strictly inside: ≤ 0.9 cap + 0.1/k)
            w = 0.9 * onto_capped(w, cap) + 0.1 / k
        else:
            w = 0.5 * np.minimum(w, cap) / np.minimum(w, cap).sum() + 0.5 / k
    phi, g, B = newton_parts(F2, k, nh, w, K, M0)
    nu = float(-g.min())
    z = np.maximum(nu + g, 1e-3 * abs(nu))
    y = np.full(k, 1e-3 * abs(nu)) if m > 1 else np.zeros(k)
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 (the count is read after the loop)
        if _gap(-g, w, phi if K is not None else nb, m, M0 is not None) < tol:
            break
        s = cap - w
        mu = 0.1 * (float(w @ z) + (float(s @ y) if m > 1 else 0.0)) / k
        rcz = w * z - mu
        D = z / w
        rhs = -(g + nu - z + y) - rcz / w
        if m > 1:
            rcy = s * y - mu
            D = D + y / s
            rhs += rcy / s
        # [[H + diag(D), 1], [1ᵀ, 0]] [dw; dnu] = [rhs; 1 − Σw], H = B Bᵀ: two solves with H + diag(D)
        X = solve_diag_lowrank(D, B, np.stack([rhs, np.ones(k)], axis=1))
        dnu = (X[:, 0].sum() - (1.0 - w.sum())) / X[:, 1].sum()
        dw = X[:, 0] - dnu * X[:, 1]
        dz = (-rcz - z * dw) / w
        pairs = [(w, dw), (z, dz)]
        if m > 1:
            dy = (-rcy + y * dw) / s
            pairs += [(s, -dw), (y, dy)]
        step = 1.0
        for x, dx in pairs:
            neg = dx < 0
            if neg.any():
                step = min(step, 0.99 * float(np.min(-x[neg] / dx[neg])))
        w, z, nu = w + step * dw, z + step * dz, nu + step * dnu
        if m > 1:
            y = y + step * dy
        phi, g, B = newton_parts(F2, k, nh, w, K, M0)
    return w / w.sum(), it


def directional_derivatives(Fp: np.ndarray, w: np.ndarray, K: np.ndarray | None, chunk: int = 20000,
                            M0: np.ndarray | None = None) -> tuple[float, np.ndarray]:
    """φ(w) and the directional derivatives d_i for every candidate, in chunks (bounded memory)."""
    M = _info_w(Fp, w, M0) if np.count_nonzero(w) == w.size else _info_w(Fp[w > 0], w[w > 0], M0)
    phi = pool_phi(M, K)
    L = np.linalg.cholesky(M)
    nb = Fp.shape[-1]
    R = np.linalg.solve(L.T, np.linalg.solve(L, K.T)) if K is not None else np.linalg.inv(L).T  # (nb, ns | nb)
    d = np.empty(Fp.shape[0])
    for a in range(0, Fp.shape[0], chunk):
        U = Fp[a:a + chunk].reshape(-1, nb) @ R
        d[a:a + chunk] = (U * U).reshape(min(chunk, Fp.shape[0] - a), -1).sum(axis=1)
    return phi, d


def approximate_design(Fp: np.ndarray, K: np.ndarray | None = None, tol: float = 1e-3, max_iter: int = 20000,
                       method: str = "newton", m: int | None = None, fixed_info: np.ndarray | None = None,
                       names: list[str] | None = None) -> ApproximateDesign:
    """Optimal approximate design on a candidate pool, with its certificate.

    ``method="newton"`` (default): candidate reduction by the equivalence theorem and an
    interior-point Newton method on the simplex. Five multiplicative iterations on the whole pool
    pick a working set (the candidates carrying weight and those with the largest d_i; pools of more
    than 4,000 candidates start from 2,000 drawn at random, seeded, see :func:`_relax_newton`); the
    interior-point method (:func:`_newton_simplex`) solves the relaxation on it to tol/10; then d_i is
    evaluated on the whole pool: every candidate outside the m largest d_i satisfies the
    equivalence condition and stays out, the others join the working set, and the loop repeats
    until the gap holds on the whole pool (column generation: the reduction is exact because the
    check is on all N candidates). ``method="multiplicative"``: the previous active-set
    multiplicative algorithm (Silvey–Titterington–Torsney), kept as the reference (no cap).

    With ``m`` the weights are capped at 1/m — an m-point design of *distinct* candidates is such a
    measure — and the bound uses the mean of the m largest d_i instead of the maximum:
    φ(v) ≥ φ(w)²/Σ v_i d_i ≥ φ(w)²/mean_top_m(d) (A-type, by convexity and homogeneity) or
    φ(v) ≥ φ(w) − (mean_top_m(d) − nb) (D), for every capped v. This is never looser than the
    uncapped bound (the maximum) and removes the gap that comes from replicated points.

    **Fixed information** (``fixed_info`` = M₀, e.g. poses already measured and a prior: sequential
    design): an exact design S of m candidates has M = M₀ + Σ_S A_i = m·(M₀/m + Σ_i v_i A_i), v = 1_S/m
    in the capped simplex, so the relaxation is solved for M(w) = M₀/m + Σ w_i A_i and, φ being convex
    in w, φ(v) ≥ φ(w) + ∇φ(w)ᵀ(v − w) ≥ φ(w) − (mean_top_m(d) − Σ w_i d_i) for every capped v (the
    equivalence-theorem bound with a fixed part; homogeneity no longer holds). As without it, an exact
    design's tr C_s ≥ lower_bound/m (A) and −log det M ≥ lower_bound − nb log m (D); the gap is
    (mean_top_m(d) − Σ w_i d_i)/φ (A) or /nb (D), and ``max_d_ratio`` is 1 + that gap.

    Args:
        Fp: weighted Jacobians of the candidates over the identifiable parameters, (N, nh, nb).
        K: A-type criterion matrix (E for tr C_s, identity for tr C_p); None = D-optimality.
        tol: stop when the gap top/φ − 1 (A) or top/nb − 1 (D) < tol, top = max_i d_i or the mean of
            the m largest.
        max_iter: cap on the total number of iterations (multiplicative, or Newton steps).
        method: ``newton`` or ``multiplicative``.
        m: cap the weights at 1/m (distinct-point designs of m candidates); None = no cap.
        fixed_info: information M₀ every design already has (nb, nb), same weighting as Fp; needs ``m``
            and the Newton method.
        names: the identifiable parameters' names, for the refusal.

    Raises:
        IdentifiabilityError: the whole pool (with M₀) does not identify the parameters (its information, scaled to
            a unit diagonal, singular: :func:`~pin_kpi_oed.oed.covariance.check_pivots`), naming the parameters
            that move the measurements alike in every pose of the pool.
        InputError: unknown method, m larger than the pool, ``fixed_info`` without m or of the wrong shape.
    """
    t0 = time.perf_counter()
    N, nh, nb = Fp.shape
    mc, M0 = _relaxation_setup(N, nb, method, m, fixed_info)
    w = np.full(N, 1.0 / N)
    check_pool(_info_w(Fp, w, M0), names)
    phi0 = pool_phi(_info_w(Fp, w, M0), K)
    if method == "newton":
        w, total = _relax_newton(Fp, K, tol, max_iter, phi0, mc, M0)
    else:
        w, total = _relax_multiplicative(Fp, w, K, tol, max_iter)
    phi, d = directional_derivatives(Fp, w, K, M0=M0)
    bound, ratio = _equivalence_bound(phi, d, w, K, nb, mc, M0)
    ok = bool(ratio - 1.0 < tol)
    unit = "Newton steps" if method == "newton" else "iterations"
    what = "max d" if mc == 1 else f"mean of the {mc} largest d"
    scale = "phi" if K is not None else "nb"
    what = f"{what} / {scale}" if M0 is None else f"1 + ({what} - sum w d) / {scale} (fixed information)"
    return ApproximateDesign(weights=w, phi=phi, lower_bound=bound, max_d_ratio=float(ratio),
                             support=np.flatnonzero(w > 1e-4 / N), nit=total, success=ok,
                             status="converged" if ok else "max_iter",
                             message=f"equivalence theorem: {what} = "
                                     f"{ratio:.5f} after {total} {unit}",
                             time_s=time.perf_counter() - t0)


def _relaxation_setup(N: int, nb: int, method: str, m: int | None, fixed_info: np.ndarray | None
                      ) -> tuple[int, np.ndarray | None]:
    """The weight cap's m and the fixed information per measurement M₀/m of :func:`approximate_design`.

    Returns:
        (mc: 1 without a cap, else m; M₀/m (nb, nb) or None).

    Raises:
        InputError: unknown method, m larger than the pool, ``fixed_info`` without m or of the wrong shape.
    """
    if method not in ("newton", "multiplicative"):
        raise InputError(f"approximate design method: expected 'newton' or 'multiplicative', got {method!r}")
    mc = 1 if m is None or method == "multiplicative" else int(m)
    if mc > N:
        raise InputError(f"cannot choose {mc} measurements from a pool of {N} candidates")
    if fixed_info is None:
        return mc, None
    if m is None or method != "newton":
        raise InputError("approximate design with fixed information needs m and the Newton method")
    if np.shape(fixed_info) != (nb, nb):
        raise InputError(f"fixed information must be {nb}x{nb}, got {np.shape(fixed_info)}")
    return mc, np.asarray(fixed_info, float) / mc


def _equivalence_bound(phi: float, d: np.ndarray, w: np.ndarray, K: np.ndarray | None, nb: int, mc: int,
                       M0: np.ndarray | None) -> tuple[float, float]:
    """The equivalence-theorem lower bound on φ of every (capped) design and the d-ratio (see
    :func:`approximate_design`): A-type φ²/top or φ − (top − Σ w d) with fixed information, D-type φ − (top − nb).

    Returns:
        (lower bound on φ, max_d_ratio: 1 at the optimum).
    """
    top = _top_mean(d, mc)
    if M0 is not None:
        bound = phi - (top - float(w @ d))
        ratio = 1.0 + _gap(d, w, phi if K is not None else nb, mc, True)
        return (max(bound, 0.0) if K is not None else bound), ratio
    if K is not None:
        return phi ** 2 / top, top / phi
    return phi - (top - nb), top / nb


#: pools larger than twice this start the working set from this many candidates drawn at random (seeded), not
#: from multiplicative iterations on the whole pool (a far better first working set for large pools)
WORKING_SET = 2000
#: per round the working set grows by at most this fraction (and at least by m + k candidates)
_GROW = 0.5
#: candidates whose weight fell below this fraction of the largest leave the working set
_PRUNE = 1e-3
#: violators whose d exceeds the working set's m-th largest d by more than this · tol · φ join first (the others
#: only if none does: near-duplicates of the support within the tolerance would otherwise flood the working set)
_MARGIN = 0.5


def _relax_newton(Fp: np.ndarray, K: np.ndarray | None, tol: float, max_iter: int, phi0: float, m: int,
                  M0: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """Working-set interior-point relaxation (see :func:`approximate_design`). Returns (w, Newton steps).

    Small pools (N ≤ 2·:data:`WORKING_SET`): round 1 on the candidates five multiplicative iterations favour; later
    rounds keep the candidates with weight ≥ 1e-4 of the largest and add those of the m + k largest d_i above
    the working set's m-th largest d. Large pools (the 100,000-pose user pools, where near-duplicate candidates
    made that working set grow by ~150 per round over ~30 rounds): round 1 on :data:`WORKING_SET` random candidates
    (seeded); later rounds keep the weights ≥ :data:`_PRUNE` of the largest, add the violators (d_i above the
    working set's m-th largest d) whose excess is > :data:`_MARGIN` · tol · φ first — at most :data:`_GROW` × the
    working set — and warm-start the interior-point method from the previous weights. Each round is solved to
    tol/10; the loop ends when the gap over **all** candidates is < tol (or no candidate violates), so the
    reduction is exact in both cases.
    """
    N, nh, nb = Fp.shape
    Ks = None if K is None else K / np.sqrt(phi0)  # φ ≈ 1 at the start: well-scaled Newton systems
    k = min(N, max(6 * nb, 150, 2 * m))
    large = N > 2 * WORKING_SET
    if large:
        work = np.sort(np.random.default_rng(0).choice(N, WORKING_SET, replace=False))  # seeded: reproducible
        w = np.zeros(N)
        w[work] = 1.0 / work.size
    else:
        w, _ = _multiplicative(Fp, np.full(N, 1.0 / N), Ks, tol, 5, M0)
        work = np.union1d(np.argsort(-w)[:k], np.argsort(-directional_derivatives(Fp, w, Ks, M0=M0)[1])[:k // 3 + m])
    total, warm = 0, False
    while True:
        wa = w[work] + 1e-3 / work.size
        try:
            wa, it = _newton_simplex(Fp[work], wa / wa.sum(), Ks, tol / 10, m,
                                     max(1, min(60, max_iter - total)), M0, warm)
        except np.linalg.LinAlgError:  # the working set does not identify: enlarge it
            if work.size == N:
                raise
            work = np.union1d(work, np.argsort(-w)[:2 * work.size])
            continue
        total += it
        w = np.zeros(N)
        w[work] = wa
        w[w < 1e-9 * wa.max()] = 0.0  # interior-point dust; the certificate is computed for this w
        w /= w.sum()
        phi, d = directional_derivatives(Fp, w, Ks, M0=M0)
        target = phi if K is not None else nb
        thr = np.partition(d[work], work.size - m)[work.size - m]
        viol = np.setdiff1d(np.flatnonzero(d > thr) if large else np.argsort(-d)[:m + k], work)
        viol = viol[d[viol] > thr]
        if _gap(d, w, target, m, M0 is not None) < tol or total >= max_iter or viol.size == 0:
            return w, total
        if large:
            strong = viol[d[viol] > thr + _MARGIN * tol * abs(target)]
            viol = strong if strong.size else viol
            viol = viol[np.argsort(-d[viol])[:max(m + k, int(_GROW * work.size))]]
        work = np.union1d(work[wa > (_PRUNE if large else 1e-4) * wa.max()], viol)
        warm = large


def _relax_multiplicative(Fp: np.ndarray, w: np.ndarray, K: np.ndarray | None, tol: float, max_iter: int
                          ) -> tuple[np.ndarray, int]:
    """The previous relaxation: multiplicative iterations with an active set. Returns (w, iterations)."""
    N, nh, nb = Fp.shape
    w, total = _multiplicative(Fp, w, K, tol, min(50, max_iter))
    k = min(N, max(20 * nb, 500))
    while total < max_iter:
        M = _info_w(Fp, w)
        d = _d(Fp, M, K)
        target = pool_phi(M, K) if K is not None else nb
        if d.max() / target - 1.0 < tol:
            break
        active = np.union1d(np.argsort(-w)[:k], np.argsort(-d)[:k // 5])
        wa = w[active] + 1e-3 / active.size  # give violators some weight
        wa /= wa.sum()
        wa, it = _multiplicative(Fp[active], wa, K, tol / 2, max_iter - total)
        total += it
        w = np.zeros(N)
        w[active] = wa
    return w, total


def efficiency(phi_exact: float, approx: ApproximateDesign, m: int) -> float:
    """Efficiency of an exact m-point A-type design against the certificate: (φ*_bound/m) / φ(ξ) ≤ 1."""
    return float(approx.lower_bound / m / phi_exact)
