r"""Pool selection of the discrepancy-aware criteria: greedy forward selection with rank-one kernel updates of every
candidate's conditional quantities (the kernel conditioned on the selected set S, noisy) and rank-three information
updates, then exchange passes with exact downdates (:class:`GreedyState`, :func:`select_pool_gp` for ``kpi_gp``; the
GLS forms subclass the state). No equivalence-theorem certificate exists: the kernel couples the poses.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np
from scipy.linalg import solve_triangular

from pin_kpi_oed.discrepancy.prior import DiscrepancyPrior
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.oed.kriging import kpi_gp_value_and_grad, pad_rows
from pin_kpi_oed.oed.pool_search import PoolState, greedy_exchange
from pin_kpi_oed.oed.selection_result import PoolSelection

__all__ = ["GreedyState", "GlsState", "greedy_ridge", "after_given", "select_pool_gp", "NO_CERTIFICATE"]

#: One line the design output prints for this criterion.
NO_CERTIFICATE = ("kpi_gp: no optimality certificate exists for the discrepancy-aware criterion (the kernel couples "
                  "the poses; the equivalence theorem of the noise-only criteria does not apply)")


def sym3_trace_solve(S: dict, X: dict) -> np.ndarray:
    """tr(S_n⁻¹ X_n) of N symmetric 3×3 pairs given by their entries (a ≤ b, each (N,)), by the adjugate."""
    a, b, c, e, f, i = S[0, 0], S[0, 1], S[0, 2], S[1, 1], S[1, 2], S[2, 2]
    A00, A01, A02 = e * i - f * f, c * f - b * i, b * f - c * e
    A11, A12, A22 = a * i - c * c, b * c - a * f, a * e - b * b
    det = a * A00 + b * A01 + c * A02
    return (A00 * X[0, 0] + A11 * X[1, 1] + A22 * X[2, 2] + 2.0 * (A01 * X[0, 1] + A02 * X[0, 2] + A12 * X[1, 2])) / det


class GreedyState(PoolState):
    """Conditional quantities of every candidate given a chosen set S (kernel conditioned on S, noisy), the
    :class:`~pin_kpi_oed.oed.pool_search.PoolState` of the discrepancy-aware criteria: φ(S ∪ {i}) is tr C_s of
    ``kpi_gp`` here, the D or A form of the GLS information in :class:`GlsState`.

    Args:
        Jc: the candidates' base-frame Jacobians (N, 3, nb); Qc: their configurations (N, n) rad.
        E: KPI Jacobian (t, 3, nb), base frame (rows beyond Qw's: without discrepancy, :func:`pad_rows`); Qw: working
            configurations (t, n) rad.
        disc: the :class:`DiscrepancyPrior`; prior_info: Σ₀⁻¹ (nb, nb) or None; eps_info: the ridge on M of
            :meth:`values` (0: exact).
    """

    def __init__(self, Jc, Qc, E, Qw, disc, prior_info, eps_info):
        self.Jc, self.Qc, self.disc = Jc, Qc, disc
        self.s2 = disc.scale_m ** 2
        self.w = disc.noise
        N, _, nb = Jc.shape
        self.kdiag = np.full(N, 0.0) if disc.kernel is None else disc.kernel.diag(Qc)
        self.Uc = pad_rows(disc.covariance(Qw, Qc), E.shape[0])       # (t, N) conditional cross-covariance
        self.Ja = np.ascontiguousarray(np.swapaxes(Jc, 0, 1))    # (3, N, nb) the Jacobian rows, axis-major
        self.Rc = self.Ja.copy()                                 # (3, N, nb) conditional Jacobian rows
        self.H = np.moveaxis(E, 1, 0).copy()                     # (3, t, nb)
        self.T = float(np.trace(disc.covariance(Qw)))
        self.M = np.zeros((nb, nb)) if prior_info is None else np.array(prior_info, float)
        self.kdiag0, self.Kwc0, self.H0, self.T0, self.M0 = self.kdiag.copy(), self.Uc.copy(), self.H.copy(), \
            self.T, self.M.copy()
        self.eps = eps_info
        self.kcols: dict[int, np.ndarray] = {}                   # k(candidates, i), shared by the copies
        self.trig: tuple[np.ndarray, ...] | None = None
        self.V = np.zeros((0, N))                                # K_S(x, y) = k(x, y) − Σ_r sgn_r V_r(x) V_r(y)
        self.sgn = np.zeros(0)
        self.chosen: list[int] = []

    @property
    def n_candidates(self) -> int:
        return len(self.Qc)

    def kcol(self, i: int) -> np.ndarray:
        """k(candidate i, candidates) (N,), cached (the candidates' cos and sin computed once, ``features``)."""
        if i not in self.kcols:
            k = self.disc.kernel
            if k is None:
                self.kcols[i] = np.zeros(len(self.Qc))
            else:
                if self.trig is None:
                    self.trig = k.features(self.Qc)
                self.kcols[i] = k.against(self.Qc[i:i + 1], self.trig)[0]
        return self.kcols[i]

    def build(self, sel: list[int]) -> GreedyState:
        """The state given the set ``sel`` from scratch (one Cholesky factor, a few products)."""
        st = type(self).__new__(type(self))
        st.__dict__.update({k: v for k, v in self.__dict__.items()})
        S = np.asarray(sel, int)
        G = np.array([self.kcol(int(i))[S] for i in S]) + self.w * np.eye(S.size)
        L = np.linalg.cholesky(G)

        st.V = solve_triangular(L, np.array([self.kcol(int(i)) for i in S]), lower=True,
                                check_finite=False)      # (k, N)
        Wt = solve_triangular(L, self.Kwc0[:, S].T, lower=True, check_finite=False)               # (k, t)
        B = solve_triangular(L, self.Jc[S].reshape(S.size, -1), lower=True, check_finite=False)   # (k, 3 nb)
        nb = self.Jc.shape[2]
        st.sgn = np.ones(S.size)
        st.kdiag = self.kdiag0 - np.einsum("kn,kn->n", st.V, st.V)
        st.Uc = self.Kwc0 - Wt.T @ st.V
        B3 = B.reshape(S.size, 3, nb)
        st.Rc = self.Ja - np.einsum("kn,kac->anc", st.V, B3)
        st.H = self.H0 - np.einsum("kt,kac->atc", Wt, B3)
        st.T = self.T0 - float(np.sum(Wt * Wt))
        st.M = self.M0 + np.einsum("a,kac,kad->cd", 1.0 / self.s2, B3, B3)
        st.chosen = list(S)
        return st

    def rebuild(self, chosen: Sequence[int]) -> GreedyState:
        return self.build(list(chosen))

    def without(self, i: int) -> GreedyState:
        """The state with the chosen candidate ``i`` removed (exact rank-one downdate: a row of sign −1 in ``V``)."""
        st, kcol, u, r, g = self._downdated(i, slice(None))
        st.Uc[:, i] = u
        st.Rc[:, i] = r
        st.V = np.vstack([self.V, kcol / np.sqrt(g)])
        st.sgn = np.append(self.sgn, -1.0)
        st.chosen = [c for c in self.chosen if c != i]
        return st

    def values_without(self, i: int, among: np.ndarray) -> np.ndarray:
        """:meth:`values` of the candidates ``among`` (none of them chosen) for the set without the chosen ``i``:
        the downdate of :meth:`without` on those candidates' rows only (this state unchanged)."""
        st = self._downdated(i, among)[0]
        return st.values(np.zeros(len(among), bool))

    def _downdated(self, i: int, among: np.ndarray | slice
                   ) -> tuple[GreedyState, np.ndarray, np.ndarray, np.ndarray, float]:
        """A copy of this state with the chosen ``i`` taken out on the candidates ``among`` (an index array, or
        ``slice(None)``: all): their kernel diagonal and columns and the set-wide part downdated; with the downdate's
        kernel column of ``i`` on them, its u, r and g."""
        st = type(self).__new__(type(self))
        st.__dict__.update(self.__dict__)
        kap = self.kdiag[i]
        w = self.w
        g = kap * w / (w - kap) + w
        kcol = (self.kcol(i)[among] - self.V[:, among].T @ (self.sgn * self.V[:, i])) * (g / w)
        u = self.Uc[:, i] * (g / w)
        r = self.Rc[:, i] * (g / w)                              # (3, nb)
        st.kdiag = self.kdiag[among] + kcol ** 2 / g
        st.Uc = self.Uc[:, among] + np.outer(u, kcol) / g
        st.Rc = self.Rc[:, among] + kcol[None, :, None] * r[:, None, :] / g
        self._downdate_information(st, u, r, g)
        return st, kcol, u, r, g

    def _downdate_information(self, st: GreedyState, u: np.ndarray, r: np.ndarray, g: float) -> None:
        """The set-wide part of :meth:`without` (H, T, M) into ``st``."""
        st.H = self.H + np.einsum("t,ac->atc", u, r) / g
        st.T = self.T + float(u @ u) / g
        st.M = self.M - np.einsum("a,ac,ad->cd", 1.0 / self.s2, r, r) / g

    def add(self, p: int) -> None:
        g = self.kdiag[p] + self.w
        kp = (self.kcol(p) - self.V.T @ (self.sgn * self.V[:, p])) \
            if self.disc.kernel is not None else np.zeros(len(self.Qc))
        u = self.Uc[:, p].copy()
        r = self.Rc[:, p].copy()                                 # (3, nb)
        self.V = np.vstack([self.V, kp / np.sqrt(g)])
        self.sgn = np.append(self.sgn, 1.0)
        self.kdiag = self.kdiag - kp ** 2 / g
        self.Uc -= np.outer(u, kp) / g
        self.Rc -= kp[None, :, None] * r[:, None, :] / g
        self.H -= np.einsum("t,ac->atc", u, r) / g
        self.T -= float(u @ u) / g
        self.M += np.einsum("a,ac,ad->cd", 1.0 / self.s2, r, r) / g
        self.chosen.append(p)

    def whitened(self, R: np.ndarray, *more: np.ndarray) -> list[np.ndarray]:
        """Rows whitened by the information of the chosen set: X L⁻ᵀ for each (…, nb) array, L the Cholesky factor
        of M + εI (so that R C Rᵀ = R̃ R̃ᵀ without forming C = (M + εI)⁻¹ and squaring its condition)."""
        nb = self.M.shape[0]
        M = self.M + self.eps * np.eye(nb)
        L = np.linalg.cholesky(0.5 * (M + M.T))
        LiT = solve_triangular(L, np.eye(nb), lower=True, check_finite=False).T
        return [(X.reshape(-1, nb) @ LiT).reshape(X.shape) for X in (R,) + more]

    def values(self, exclude: np.ndarray, among: np.ndarray | None = None) -> np.ndarray:
        """tr C_s after adding each candidate (inf for excluded ones; ``among``: only those candidates, ``exclude``
        unused), exact rank-three information update, in rows whitened by M (:meth:`whitened`):

        tr C_s(S ∪ {i}) = σ²(T − |u|²/g) + tr CN − 2 tr(RCZ)/g + |u|² tr(RCR)/g² − tr(W X), W = (D_g + RCR)⁻¹,
        X = RDR − (RCR RCZᵀ + RCZ RCR)/g + |u|² RCR²/g², D = C N C, z_a = H_aᵀ u (per candidate), N = Σ H_aᵀH_a."""
        R, Uc, g = self.Rc, self.Uc, self.kdiag + self.w
        if among is not None:
            R, Uc, g = R[:, among], Uc[:, among], g[among]
        try:
            Rw, Hw = self.whitened(R, self.H)                    # R L⁻ᵀ (3, n, nb), H L⁻ᵀ (3, t, nb)
        except np.linalg.LinAlgError:  # a set downdated to an information not positive definite at working
            return np.full(R.shape[1], np.inf)  # precision (a point removed from too few): no swap through it
        nb = Rw.shape[2]
        Hf = Hw.reshape(-1, nb)
        Nw = Hf.T @ Hf                                           # L⁻¹ N L⁻ᵀ: R D Rᵀ = R̃ Ñ R̃ᵀ
        uu = np.einsum("tn,tn->n", Uc, Uc)
        n, t = Rw.shape[1], Hw.shape[1]
        RCR = {(a, b): np.einsum("nk,nk->n", Rw[a], Rw[b]) for a in range(3) for b in range(a, 3)}
        RCR.update({(b, a): v for (a, b), v in list(RCR.items())})
        if 3 * t < nb:  # N has rank 3t: R̃ Ñ R̃ᵀ and R̃ z̃ from Y = R̃ H̃ᵀ (3, n, 3, t)
            Y = (Rw.reshape(-1, nb) @ Hf.T).reshape(3, n, 3 * t)
            RDR = {(a, b): np.einsum("nk,nk->n", Y[a], Y[b]) for a in range(3) for b in range(a, 3)}
            Y4 = Y.reshape(3, n, 3, t)
            RCZ = {(a, b): np.einsum("nt,tn->n", Y4[a, :, b], Uc) for a in range(3) for b in range(3)}
        else:
            DR = (Rw.reshape(-1, nb) @ Nw).reshape(Rw.shape)
            Z = np.matmul(Uc.T, Hw)                              # (3, n, nb): L⁻¹ z_a
            RDR = {(a, b): np.einsum("nk,nk->n", DR[a], Rw[b]) for a in range(3) for b in range(a, 3)}
            RCZ = {(a, b): np.einsum("nk,nk->n", Rw[a], Z[b]) for a in range(3) for b in range(3)}
        gi = 1.0 / g
        c2 = uu * gi ** 2
        P = {(a, c): sum(RCR[a, b] * RCZ[c, b] for b in range(3)) for a in range(3) for c in range(3)}
        X = {(a, c): RDR[a, c] - gi * (P[a, c] + P[c, a]) + c2 * sum(RCR[a, b] * RCR[b, c] for b in range(3))
             for a in range(3) for c in range(a, 3)}
        S = {(a, b): RCR[a, b] + (g * self.s2[a] if a == b else 0.0) for a in range(3) for b in range(a, 3)}
        trCN = (float(np.trace(Nw)) - 2 * gi * sum(RCZ[a, a] for a in range(3))
                + c2 * sum(RCR[a, a] for a in range(3)))
        phi = float(self.s2.sum()) * (self.T - uu * gi) + trCN - sym3_trace_solve(S, X)
        if among is None:
            phi[exclude] = np.inf
        return phi


class GlsState(GreedyState):
    """The greedy state of the GLS information (no working configurations) scoring candidates by the A form
    tr(K M⁻¹ Kᵀ) (``K`` the criterion's pool matrix) or, K None, the D form −log det M."""

    K: np.ndarray | None = None

    def values(self, exclude: np.ndarray, among: np.ndarray | None = None) -> np.ndarray:
        """−log det M or tr(K M⁻¹ Kᵀ) after adding each candidate (inf for excluded ones; ``among``: only those),
        exact rank-three update: −log det M − log det(D_g + R C Rᵀ) + log det D_g, tr(K C Kᵀ) − tr(W (R C Kᵀ)(K C Rᵀ)),
        W = (D_g + R C Rᵀ)⁻¹, D_g = g diag(s²)."""
        nb = self.M.shape[0]
        M = 0.5 * (self.M + self.M.T) + self.eps * np.eye(nb)
        C = np.linalg.inv(M)
        R, g = self.Rc, self.kdiag + self.w
        if among is not None:
            R, g = R[:, among], g[among]
        CR = (R.reshape(-1, nb) @ C).reshape(R.shape)
        S = {(a, b): np.einsum("nk,nk->n", CR[a], R[b]) + (g * self.s2[a] if a == b else 0.0)
             for a in range(3) for b in range(a, 3)}
        if self.K is not None:
            G = (CR.reshape(-1, nb) @ self.K.T).reshape(3, R.shape[1], -1)     # R C Kᵀ per axis (3, N, ns)
            X = {(a, b): np.einsum("ns,ns->n", G[a], G[b]) for a in range(3) for b in range(a, 3)}
            phi = float(np.sum(self.K.T * (C @ self.K.T))) - sym3_trace_solve(S, X)
        else:
            a_, b_, c_, e_, f_, i_ = S[0, 0], S[0, 1], S[0, 2], S[1, 1], S[1, 2], S[2, 2]
            det = a_ * (e_ * i_ - f_ * f_) + b_ * (c_ * f_ - b_ * i_) + c_ * (b_ * f_ - c_ * e_)
            phi = (-np.linalg.slogdet(M)[1] - np.log(det) + np.log(g) * 3 + float(np.log(self.s2).sum()))
        if among is None:
            phi[exclude] = np.inf
        return phi


def greedy_ridge(J_pool: np.ndarray, discrepancy: DiscrepancyPrior) -> float:
    """The tiny ridge of the greedy start: 1e-9 of the pool's mean information per parameter."""
    s2 = discrepancy.scale_m ** 2
    return 1e-9 * float(np.mean(np.einsum("a,nac,nac->n", 1 / s2, J_pool, J_pool))) / max(J_pool.shape[2], 1) \
        / max(discrepancy.noise, 1e-12)


def after_given(J_pool: np.ndarray, Q_pool: np.ndarray, m: int, J_given: np.ndarray | None,
                 Q_given: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, int]:
    """The candidates after the measured poses: (J, Q, number measured k0).

    Raises:
        InputError: m outside 1..N.
    """
    N = len(Q_pool)
    if not (1 <= m <= N):
        raise InputError(f"pool selection: cannot choose {m} of {N} candidates")
    if Q_given is not None and len(Q_given):
        return np.concatenate([J_given, J_pool]), np.vstack([Q_given, Q_pool]), len(Q_given)
    return J_pool, Q_pool, 0


def select_pool_gp(J_pool: np.ndarray, Q_pool: np.ndarray, E: np.ndarray, Q_work: np.ndarray,
                   discrepancy: DiscrepancyPrior, m: int, prior_info: np.ndarray | None = None,
                   Q_given: np.ndarray | None = None, J_given: np.ndarray | None = None, exchange_passes: int = 1,
                   time_budget_s: float | None = None, kcols: dict | None = None) -> PoolSelection:
    """Choose m of N candidate poses minimising tr C_s under the discrepancy (greedy + exchange).

    Greedy: each step adds the candidate of lowest tr C_s, evaluated for all candidates at once by exact
    updates (the kernel conditioned on the chosen set, rank one per addition; the information, rank three);
    until the chosen set identifies the parameters, a tiny ridge (1e-9 of the pool's mean information)
    keeps M invertible. Exchange: each chosen pose in turn is removed (the state rebuilt from the others)
    and replaced by the best candidate if that lowers tr C_s. The value returned is recomputed from scratch.

    Args:
        J_pool: candidates' base-frame Jacobians (N, 3, nb); Q_pool: their configurations (N, n) rad.
        E: KPI Jacobian (t, 3, nb), base frame; Q_work: working configurations (t, n) rad.
        discrepancy: the :class:`DiscrepancyPrior`.
        m: poses to choose (≤ N).
        prior_info: Σ₀⁻¹ (nb, nb) or None.
        Q_given, J_given: poses measured before and their Jacobians (always in the set), or None.
        exchange_passes: passes of the exchange (0: greedy only).
        time_budget_s: stop the exchange when this wall time is spent (None: no limit).
        kcols: a cache of kernel columns k(candidate i, candidates) to share with other selections over the same
            candidates and kernel (:attr:`GreedyState.kcols`), or None.

    Raises:
        InputError: m larger than the pool.
        IdentifiabilityError: the chosen set does not identify the parameters.
    """
    t0 = time.perf_counter()
    Jall, Qall, k0 = after_given(J_pool, Q_pool, m, J_given, Q_given)
    st = GreedyState(Jall, Qall, E, Q_work, discrepancy, prior_info, greedy_ridge(J_pool, discrepancy))
    if kcols is not None:
        st.kcols = kcols
    found = greedy_exchange(st, m, k0, exchange_passes, deadline=None if time_budget_s is None
                            else t0 + time_budget_s)
    idx, path, swaps = found.indices, found.path, found.swaps
    rows = np.concatenate([np.arange(k0), k0 + idx])
    Jsel, Qsel = Jall[rows], Qall[rows]
    val = kpi_gp_value_and_grad(Jsel, E, discrepancy.covariance(Qsel),
                                pad_rows(discrepancy.covariance(Q_work, Qsel), E.shape[0]),
                                float(np.trace(discrepancy.covariance(Q_work))), discrepancy.scale_m, discrepancy.noise,
                                prior_info, grad=False)[0]
    return PoolSelection(indices=idx, value=float(val), path=np.array(path), nit=swaps,
                         time_s=time.perf_counter() - t0, success=True, status="selected",
                         message=f"greedy + exchange ({swaps} swaps); no certificate")
