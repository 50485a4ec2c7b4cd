r"""Pool selection of the discrepancy-aware criteria: greedy forward selection with rank-one kernel updates of every
candidate's conditional quantities (the kernel conditioned on the selected set S, noisy) and rank-three information
updates, then exchange passes with exact downdates (:class:`GreedyState`, :func:`select_pool_gp` for ``kpi_gp``; the
GLS forms subclass the state). No equivalence-theorem certificate exists: the kernel couples the poses.
"""

from __future__ import annotations

import time

import numpy as np
from scipy.linalg import solve_triangular

from pin_kpi_oed.discrepancy.prior import DiscrepancyPrior
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.oed.kriging import kpi_gp_value_and_grad
from pin_kpi_oed.oed.selection_result import PoolSelection

__all__ = ["GreedyState", "greedy_ridge", "after_given", "greedy_exchange", "select_pool_gp", "NO_CERTIFICATE"]

#: One line the design output prints for this criterion.
NO_CERTIFICATE = ("kpi_gp: no optimality certificate exists for the discrepancy-aware criterion (the kernel couples "
                  "the poses; the equivalence theorem of the noise-only criteria does not apply)")


class GreedyState:
    """Conditional quantities of every candidate given a selected set S (kernel conditioned on S, noisy)."""

    def __init__(self, Jc, Qc, E, Qw, disc, prior_info, eps_info):
        self.Jc, self.Qc, self.disc = Jc, Qc, disc
        self.s2 = disc.scale_m ** 2
        self.w = disc.noise
        N, _, nb = Jc.shape
        self.kdiag = np.full(N, 0.0) if disc.kernel is None else disc.kernel.diag(Qc)
        self.Uc = disc.cov(Qw, Qc)                              # (t, N) conditional cross-covariance
        self.Rc = Jc.copy()                                      # (N, 3, nb) conditional Jacobian rows
        self.H = np.moveaxis(E, 1, 0).copy()                     # (3, t, nb)
        self.T = float(np.trace(disc.cov(Qw)))
        self.M = np.zeros((nb, nb)) if prior_info is None else np.array(prior_info, float)
        self.kdiag0, self.Kwc0, self.H0, self.T0, self.M0 = self.kdiag.copy(), self.Uc.copy(), self.H.copy(), \
            self.T, self.M.copy()
        self.eps = eps_info
        self.kcols: dict[int, np.ndarray] = {}                   # k(candidates, i), shared by the copies
        self.V = np.zeros((0, N))                                # K_S(x, y) = k(x, y) − Σ_r sgn_r V_r(x) V_r(y)
        self.sgn = np.zeros(0)
        self.chosen: list[int] = []

    def kcol(self, i: int) -> np.ndarray:
        """k(candidates, candidate i) (N,), cached."""
        if i not in self.kcols:
            self.kcols[i] = self.disc.cov(self.Qc, self.Qc[i:i + 1])[:, 0]
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
        st.Rc = self.Jc - (st.V.T @ B).reshape(self.Jc.shape)
        B3 = B.reshape(S.size, 3, nb)
        st.H = self.H0 - np.einsum("kt,kac->atc", Wt, B3)
        st.T = self.T0 - float(np.sum(Wt * Wt))
        st.M = self.M0 + np.einsum("a,kac,kad->cd", 1.0 / self.s2, B3, B3)
        st.chosen = list(S)
        return st

    def without(self, i: int) -> GreedyState:
        """The state with the chosen candidate ``i`` removed (exact rank-one downdate: a row of sign −1 in ``V``)."""
        st = type(self).__new__(type(self))
        st.__dict__.update(self.__dict__)
        kap = self.kdiag[i]
        w = self.w
        g = kap * w / (w - kap) + w
        kcol = (self.kcol(i) - self.V.T @ (self.sgn * self.V[:, i])) * (g / w)
        u = self.Uc[:, i] * (g / w)
        r = self.Rc[i] * (g / w)
        st.kdiag = self.kdiag + kcol ** 2 / g
        st.Uc = self.Uc + np.outer(u, kcol) / g
        st.Uc[:, i] = u
        st.Rc = self.Rc + kcol[:, None, None] * r[None] / g
        st.Rc[i] = r
        st.H = self.H + np.einsum("t,ac->atc", u, r) / g
        st.T = self.T + float(u @ u) / g
        st.M = self.M - np.einsum("a,ac,ad->cd", 1.0 / self.s2, r, r) / g
        st.V = np.vstack([self.V, kcol / np.sqrt(g)])
        st.sgn = np.append(self.sgn, -1.0)
        st.chosen = [c for c in self.chosen if c != i]
        return st

    def add(self, p: int) -> None:
        g = self.kdiag[p] + self.w
        kp = (self.kcol(p) - self.V.T @ (self.sgn * self.V[:, p])) \
            if self.disc.kernel is not None else np.zeros(len(self.Qc))
        u = self.Uc[:, p].copy()
        r = self.Rc[p].copy()                                    # (3, nb)
        self.V = np.vstack([self.V, kp / np.sqrt(g)])
        self.sgn = np.append(self.sgn, 1.0)
        self.kdiag = self.kdiag - kp ** 2 / g
        self.Uc -= np.outer(u, kp) / g
        self.Rc -= kp[:, None, None] * r[None] / g
        self.H -= np.einsum("t,ac->atc", u, r) / g
        self.T -= float(u @ u) / g
        self.M += np.einsum("a,ac,ad->cd", 1.0 / self.s2, r, r) / g
        self.chosen.append(p)

    def values(self, exclude: np.ndarray) -> np.ndarray:
        """tr C_s after adding each candidate (inf for excluded ones), exact rank-three information update."""
        nb = self.M.shape[0]
        M = self.M + self.eps * np.eye(nb)
        C = np.linalg.inv(0.5 * (M + M.T))
        N = np.einsum("atc,atd->cd", self.H, self.H)
        Dm = C @ N @ C
        g = self.kdiag + self.w                                  # (N,)
        uu = np.einsum("tn,tn->n", self.Uc, self.Uc)
        R = self.Rc                                              # (N, 3, nb)
        Rt = np.swapaxes(R, 1, 2)
        CR = R @ C                                               # (N, 3, nb): rows (C r_a)ᵀ
        RCR = CR @ Rt                                            # (N, 3, 3)
        RDR = (R @ Dm) @ Rt
        Z = np.swapaxes(self.H, 1, 2) @ self.Uc                  # (3, nb, N): z_a = H_aᵀ u
        RCZ = np.einsum("nac,bcn->nab", CR, Z, optimize=True)
        Dinv = np.zeros_like(RCR)
        idx = np.arange(3)
        Dinv[:, idx, idx] = (g[:, None] * self.s2[None, :])
        W = np.linalg.inv(Dinv + RCR)
        gi = 1.0 / g
        trCN = (np.sum(C * N) - 2 * gi * np.einsum("naa->n", RCZ) + uu * gi ** 2 * np.einsum("naa->n", RCR))
        X = (RDR - gi[:, None, None] * (RCR @ np.swapaxes(RCZ, 1, 2) + RCZ @ RCR)
             + (uu * gi ** 2)[:, None, None] * (RCR @ RCR))
        phi = float(self.s2.sum()) * (self.T - uu * gi) + trCN - np.einsum("nab,nba->n", W, X)
        phi[exclude] = np.inf
        return phi


def _exchange(st: GreedyState, sel: list[int], excl: np.ndarray, k0: int, cur: float, passes: int, t0: float,
              budget: float | None) -> tuple[list[int], float, int]:
    """Exchange passes of :func:`select_pool_gp`: each chosen pose in turn removed (exact downdate) and replaced by the
    best candidate if that lowers tr C_s; a fresh factor after each pass with swaps. Returns (set, value, swaps)."""
    m = len(sel)
    swaps = 0
    for _ in range(passes):
        changed = False
        for pos in range(m):
            if budget is not None and time.perf_counter() - t0 > budget:
                break
            i = k0 + sel[pos]
            down = st.without(i)
            ex = excl.copy()
            ex[i] = False
            phi = down.values(ex)
            j = int(np.argmin(phi))
            if j != i and phi[j] < cur * (1 - 1e-9):
                excl[i], excl[j] = False, True
                sel[pos] = j - k0
                cur = float(phi[j])
                swaps += 1
                changed = True
                st = down
                st.add(j)
        if not changed:
            break
        st = st.build(list(range(k0)) + [k0 + x for x in sel])   # fresh factor after a pass with swaps
    return sel, cur, swaps


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


def greedy_exchange(st: GreedyState, m: int, k0: int, passes: int, t0: float, budget: float | None
                     ) -> tuple[np.ndarray, list[float], int]:
    """Greedy additions of m candidates to a state holding k0 measured poses first, then the exchange passes
    (:func:`_exchange`); the criterion is the state's :meth:`values`. Returns (pool indices, greedy path, swaps)."""
    for i in range(k0):
        st.add(i)
    excl = np.zeros(len(st.Qc), bool)
    excl[:k0] = True
    path = []
    for _ in range(m):
        phi = st.values(excl)
        j = int(np.argmin(phi))
        path.append(float(phi[j]))
        st.add(j)
        excl[j] = True
    sel = [j - k0 for j in st.chosen[k0:]]
    sel, _, swaps = _exchange(st, sel, excl, k0, path[-1], passes, t0, budget)
    return np.array(sel, int), path, swaps


def select_pool_gp(J_pool: np.ndarray, Q_pool: np.ndarray, E: np.ndarray, Q_work: np.ndarray,
                   discrepancy: DiscrepancyPrior, m: int, prior_info: np.ndarray | None = None,
                   Q_given: np.ndarray | None = None, J_given: np.ndarray | None = None, exchange_passes: int = 1,
                   time_budget_s: float | None = None) -> PoolSelection:
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

    Raises:
        InputError: m larger than the pool.
        IdentifiabilityError: the chosen set does not identify the parameters.
    """
    t0 = time.perf_counter()
    Jall, Qall, k0 = after_given(J_pool, Q_pool, m, J_given, Q_given)
    st = GreedyState(Jall, Qall, E, Q_work, discrepancy, prior_info, greedy_ridge(J_pool, discrepancy))
    idx, path, swaps = greedy_exchange(st, m, k0, exchange_passes, t0, time_budget_s)
    rows = np.concatenate([np.arange(k0), k0 + idx])
    Jsel, Qsel = Jall[rows], Qall[rows]
    val = kpi_gp_value_and_grad(Jsel, E, discrepancy.cov(Qsel), discrepancy.cov(Q_work, Qsel),
                                float(np.trace(discrepancy.cov(Q_work))), discrepancy.scale_m, discrepancy.noise,
                                prior_info, grad=False)[0]
    return PoolSelection(indices=idx, value=float(val), path=np.array(path), nit=swaps,
                         time_s=time.perf_counter() - t0, success=True, status="selected",
                         message=f"greedy + exchange ({swaps} swaps); no certificate")
