r"""The one pool selector: greedy forward selection and exchange passes on any information model's low-rank updates.

Choosing m of N candidate configurations is one search whatever the criterion and the information model; what
differs is how φ of the chosen set S changes when a candidate is added or a chosen one is taken out. An information
model offers that as a :class:`PoolState` (S and, for every candidate i at once, φ(S ∪ {i})):

==========================================================  ======================================================
state                                                       information M(S), the update per candidate
==========================================================  ======================================================
:class:`InformationState` (noise only, measured poses,       M₀ + Σ_S F_iᵀF_i; adding i: S_i = I + F_i M⁻¹ F_iᵀ
extended with a prior; :mod:`~pin_kpi_oed.oed.pool`,         (Woodbury, rank nh), taking o out: a rank-nh
:mod:`~pin_kpi_oed.oed.extended`)                            correction of every candidate's blocks
:class:`~pin_kpi_oed.oed.discrepancy_pool.GreedyState`       the kernel conditioned on S (rank one per pose) and
(the GLS forms, the kriging ``kpi_gp``)                      the GLS information (rank three)
(the hedged ``kpi_gp``: one per member of the family,       φ_H = Π_k φ_k^{ω_k} of the members' updates
:class:`~pin_kpi_oed.oed.hedged_kpi.HedgedDesignCriterion`)
:class:`ValueState` (an objective of configurations          none: φ(S ∪ {i}) from scratch for every candidate
without updates of its own)
==========================================================  ======================================================

The criterion enters only through the state's values: the A form tr(K M⁻¹ Kᵀ) when the criterion has a pool matrix K
(:meth:`~pin_kpi_oed.oed.criteria.Criterion.pool_form`: E for the KPI, I for A on C_p), else the D form −log det M
(the fallback of every other criterion of the information matrix), or the criterion of the configurations itself.

The search (:func:`greedy`, :func:`exchange`, :func:`greedy_exchange`):

* greedy: m times, add the candidate of least φ(S ∪ {i});
* exchange (Fedorov; DETMAX from a random start, :func:`~pin_kpi_oed.oed.pool.detmax`): each chosen pose in turn
  taken out and replaced by the candidate of least φ, when that lowers φ below cur·(1 − rel_tol) − abs_tol; passes
  until none swaps (or ``passes``), the state rebuilt from scratch after a pass with swaps.

The noise-only selection starts the exchange from the rounded relaxation (its certificate,
:mod:`~pin_kpi_oed.oed.relaxation`) instead of the greedy; no certificate exists where the kernel couples the poses.
"""

from __future__ import annotations

import copy
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np

from pin_kpi_oed.errors import IdentifiabilityError

__all__ = ["PoolState", "ValueState", "InformationState", "Search", "greedy", "exchange", "greedy_exchange",
           "block_gains", "information_exchange"]


class PoolState(ABC):
    """A chosen set S of a pool's candidates and φ(S ∪ {i}) of every candidate i: the low-rank update interface an
    information model offers the one pool selector.

    Attributes:
        chosen: S, candidate indices.
    """

    chosen: list[int]

    @property
    @abstractmethod
    def n_candidates(self) -> int:
        """N, the candidates (chosen ones included)."""

    @abstractmethod
    def values(self, exclude: np.ndarray) -> np.ndarray:
        """φ(S ∪ {i}) for every candidate (N,), ``inf`` where ``exclude`` (N,) bool is set."""

    @abstractmethod
    def add(self, i: int) -> None:
        """Add candidate i to S (in place).

        Raises:
            IdentifiabilityError: the information is no longer positive definite.
        """

    @abstractmethod
    def without(self, i: int) -> PoolState | None:
        """A new state with the chosen i taken out (this one unchanged), or None if S without i is singular."""

    def rebuild(self, chosen: Sequence[int]) -> PoolState:
        """A state of the set ``chosen`` from scratch (after a pass with swaps: no drift of the updates);
        default: this state (its updates are exact)."""
        return self

    def after_greedy(self) -> PoolState:
        """The state the exchange starts from once the greedy has chosen S (e.g. the greedy's ridge removed)."""
        return self

    def settled(self, predicted: float) -> float:
        """φ(S) after an accepted swap: ``predicted`` (the update's value) unless the state knows it afresh."""
        return predicted

    def pick(self, phi: np.ndarray, exclude: np.ndarray) -> int:
        """The candidate a greedy step adds: the least φ (the first of equal ones); while no addition gives a finite
        φ (S does not yet determine the parameters), the first candidate not excluded."""
        j = int(np.argmin(phi))
        return j if np.isfinite(phi[j]) else int(np.flatnonzero(~exclude)[0])


class ValueState(PoolState):
    """φ(S ∪ {i}) evaluated from scratch for every candidate: the state of an objective without low-rank updates
    (a criterion of the configurations without a pool form of its own; N evaluations of φ per step).

    Args:
        phi: φ of a list of candidate indices (``inf`` when they do not determine the parameters).
        n: candidates; seed: seed of the candidates' order in each greedy step (ties and steps without a finite φ
            take the first in it).
    """

    def __init__(self, phi: Callable[[list[int]], float], n: int, seed: int = 0) -> None:
        self.phi, self.N, self.rng = phi, int(n), np.random.default_rng(seed)
        self.chosen: list[int] = []

    @property
    def n_candidates(self) -> int:
        return self.N

    def values(self, exclude: np.ndarray) -> np.ndarray:
        out = np.full(self.N, np.inf)
        for i in np.flatnonzero(~exclude):
            out[i] = self.phi(self.chosen + [int(i)])
        return out

    def add(self, i: int) -> None:
        self.chosen.append(int(i))

    def without(self, i: int) -> ValueState:
        st = copy.copy(self)
        st.chosen = [c for c in self.chosen if c != i]
        return st

    def pick(self, phi: np.ndarray, exclude: np.ndarray) -> int:
        order = np.array([i for i in self.rng.permutation(self.N) if not exclude[i]], int)
        k = int(np.argmin(phi[order]))
        return int(order[k]) if np.isfinite(phi[order[k]]) else int(order[0])


def greedy(st: PoolState, m: int, exclude: np.ndarray) -> list[float]:
    """Add m candidates to ``st``, each the one of least φ (``exclude`` updated in place); φ after each addition."""
    path = []
    for _ in range(m):
        phi = st.values(exclude)
        j = st.pick(phi, exclude)
        path.append(float(phi[j]))
        st.add(j)
        exclude[j] = True
    return path


def exchange(st: PoolState, sel: list[int], exclude: np.ndarray, cur: float, passes: int, rel_tol: float = 1e-9,
             abs_tol: float = 0.0, fixed: Sequence[int] = (), deadline: float | None = None
             ) -> tuple[PoolState, list[int], float, int, int]:
    """Exchange passes: each chosen candidate of ``sel`` in turn taken out and replaced by the one of least φ when that
    is below cur·(1 − rel_tol) − abs_tol.

    Once every position has been tried on the same state (the positions after a pass's last swap and the next
    pass's up to it) the search ends: trying a position again on that state repeats its answer (no swap), so the
    passes a full run would go on with change nothing.

    Args:
        st: the state of ``fixed`` + ``sel``; sel: the swappable chosen candidates (updated in place).
        exclude: (N,) bool, the chosen ones (and any never to choose), updated in place.
        cur: φ of the chosen set; passes: at most this many passes (stops after a pass without a swap).
        rel_tol, abs_tol: the improvement a swap needs.
        fixed: chosen candidates never swapped (measured poses); deadline: ``time.perf_counter()`` after which no
            further position is tried.

    Returns:
        (state, sel, φ, swaps, passes run).
    """
    swaps = sweeps = 0
    calm = 0  # positions tried in a row on the same state without a swap
    for sweeps in range(1, int(passes) + 1):  # noqa: B007 (the count is read after the loop)
        changed = False
        for pos in range(len(sel)):
            if calm >= len(sel):  # every position was tried on this state: trying one again repeats its answer
                break
            if deadline is not None and time.perf_counter() > deadline:
                break
            calm += 1
            i = sel[pos]
            down = st.without(i)
            if down is None:
                continue
            ex = exclude.copy()
            ex[i] = False
            phi = down.values(ex)
            j = int(np.argmin(phi))
            if j != i and phi[j] < cur * (1 - rel_tol) - abs_tol:
                exclude[i], exclude[j] = False, True
                sel[pos] = j
                down.add(j)
                st = down
                cur = st.settled(float(phi[j]))
                swaps += 1
                changed, calm = True, 0
        if not changed:
            break
        rebuilt = st.rebuild(list(fixed) + sel)
        if rebuilt is not st:  # a state from scratch may differ from the updated one in its last digits
            st, calm = rebuilt, 0
    return st, sel, cur, swaps, sweeps


class Search(NamedTuple):
    """What :func:`greedy_exchange` found: the chosen candidates (minus the measured ones, in order of addition, then
    swapped), φ after each greedy addition, swaps, exchange passes run, φ of the set, the final state."""

    indices: np.ndarray
    path: list
    swaps: int
    passes: int
    value: float
    state: PoolState


def greedy_exchange(st: PoolState, m: int, k0: int = 0, passes: int = 1, rel_tol: float = 1e-9,
                    abs_tol: float = 0.0, deadline: float | None = None) -> Search:
    """Candidates 0..k0−1 (measured poses) into the state, m greedy additions, then :func:`exchange`."""
    for i in range(k0):
        st.add(i)
    excl = np.zeros(st.n_candidates, bool)
    excl[:k0] = True
    path = greedy(st, m, excl)
    sel = list(st.chosen[k0:])
    st = st.after_greedy()
    cur = st.settled(path[-1] if path else np.inf)
    st, sel, cur, swaps, sweeps = exchange(st, sel, excl, cur, passes, rel_tol, abs_tol, fixed=range(k0),
                                           deadline=deadline)
    return Search(np.array(sel, int) - k0, path, swaps, sweeps, cur, st)


# ---------------------------------------------------------------------- the information model M₀ + Σ F_iᵀF_i
def block_gains(s: dict, G: np.ndarray | None, N: int, nh: int) -> np.ndarray:
    """−Δφ of candidate blocks whose S_i (nh×nh) is known by its entries ``s[a, b]`` (a ≤ b, each (N,)):
    log det S_i (D-type, G None) or tr(G_iᵀ S_i⁻¹ G_i) (A-type, G (N, nh, ns)).

    For nh ≤ 3 the 3×3 (2×2, 1×1) algebra is written out on length-N arrays — NumPy's batched ``solve`` /
    ``einsum`` on tiny matrices cost more than the arithmetic — with tr(Gᵀ S⁻¹ G) = Σ_ab (S⁻¹)_ab (G Gᵀ)_ab;
    larger nh use ``np.linalg``.
    """
    if nh > 3:
        S = np.empty((N, nh, nh))
        for (a, b), v in s.items():
            S[:, a, b] = S[:, b, a] = v
        if G is None:
            return np.linalg.slogdet(S)[1]
        return np.einsum("nas,nas->n", G, np.linalg.solve(S, G))
    if G is None:
        return np.log(_adjugate(s, N, nh)[1])
    return _gram_gains(s, {(a, b): np.einsum("ns,ns->n", G[:, a], G[:, b]) for a, b in s}, N, nh)


def _adjugate(s: dict, N: int, nh: int) -> tuple[dict, np.ndarray]:
    """The adjugate's entries (a ≤ b, each (N,)) and the determinant (N,) of blocks S_i (nh ≤ 3) given by their
    entries ``s[a, b]`` (a ≤ b), written out on length-N arrays."""
    if nh == 1:
        return {(0, 0): np.ones(N)}, s[0, 0]
    if nh == 2:
        return {(0, 0): s[1, 1], (0, 1): -s[0, 1], (1, 1): s[0, 0]}, s[0, 0] * s[1, 1] - s[0, 1] ** 2
    a_, b_, c_, e_, f_, i_ = s[0, 0], s[0, 1], s[0, 2], s[1, 1], s[1, 2], s[2, 2]
    adj = {(0, 0): e_ * i_ - f_ * f_, (0, 1): c_ * f_ - b_ * i_, (0, 2): b_ * f_ - c_ * e_,
           (1, 1): a_ * i_ - c_ * c_, (1, 2): b_ * c_ - a_ * f_, (2, 2): a_ * e_ - b_ * b_}
    return adj, a_ * adj[0, 0] + b_ * adj[0, 1] + c_ * adj[0, 2]


def _gram_gains(s: dict, P: np.ndarray | dict, N: int, nh: int) -> np.ndarray:
    """tr(S_i⁻¹ P_i) of blocks S_i (nh ≤ 3, entries ``s[a, b]``) and symmetric P_i = G_i G_iᵀ, P indexed ``P[a, b]``
    for a ≤ b ((nh, nh, N), or a dict of the entries (N,)): the A-type gains of :func:`block_gains` from the nh×nh
    Gram matrices instead of G (nh, ns) itself."""
    adj, det = _adjugate(s, N, nh)
    out = np.zeros(N)
    for (a, b), v in adj.items():
        out += (1.0 if a == b else 2.0) * v * P[a, b]
    return out / det


def _pair_dots(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """P (nh, nh, N) of X, Y (nh, N, k): P[a, b] = P[b, a] = Σ_k X[a, :, k] Y[b, :, k] for a ≤ b, one call per a
    (the same sums as ``np.einsum("nk,nk->n", X[a], Y[b])`` entry by entry)."""
    nh = X.shape[0]
    P = np.empty((nh, nh, X.shape[1]))
    for a in range(nh):
        P[a, a:] = np.einsum("nk,bnk->bn", X[a], Y[a:])
    lo, up = np.tril_indices(nh, -1)
    P[lo, up] = P[up, lo]
    return P


def _full_gains(S: np.ndarray, G: np.ndarray | None) -> np.ndarray:
    """:func:`block_gains` (nh > 3) of the blocks S_i given whole, S (nh, nh, N) symmetric, G (nh, N, ns) or None:
    the same numbers as S_i's entries passed one by one."""
    S = np.ascontiguousarray(S.transpose(2, 0, 1))
    if G is None:
        return np.linalg.slogdet(S)[1]
    Gn = G.transpose(1, 0, 2)
    return np.einsum("nas,nas->n", Gn, np.linalg.solve(S, Gn))


def _block_gains(s: dict, G: np.ndarray | None, N: int, nh: int) -> np.ndarray:
    """:func:`block_gains` with G laid out (nh, N, ns)."""
    return block_gains(s, None if G is None else G.transpose(1, 0, 2), N, nh)


class InformationState(PoolState):
    """The information M = M₀ + Σ_S F_iᵀF_i of blocks F_i (nh, nx) with φ the A form tr(K M⁻¹ Kᵀ) or (K None) the D
    form −log det M; every candidate scored at once by Woodbury.

    With B_i = F_i M⁻¹: A_i = F_i M⁻¹ F_iᵀ and H_i = F_i M⁻¹ Kᵀ, computed with one GEMM over the stacked
    blocks (layout (nh, N, ·), contiguous per measurement axis). Adding candidate i: S_i = I + A_i,
    G_i = H_i. Taking out a chosen o (M₋ = M − F_oᵀF_o, S_o = I − A_o = L_o L_oᵀ):
    F_i M₋⁻¹ F_iᵀ = A_i + D_i D_iᵀ and F_i M₋⁻¹ Kᵀ = H_i + D_i L_o⁻¹ H_o with D_i = B_i F_oᵀ L_o⁻ᵀ —
    O(N·nh·nx·nh) per position instead of a new O(N·nh·nx²) product. Where K has more rows than a block (A on C_p:
    ns = nx) a swap's gains come from the nh×nh Gram matrices G_iG_iᵀ, not G_i itself (:meth:`_gram_swap`). φ is
    recomputed from M after every addition.

    Args:
        Fp: the candidates' blocks (N, nh, nx); K: the A-form matrix (ns, nx) or None (D form).
        M0: information every set has (nx, nx) (a prior, measured poses), or None.
        chosen: the starting set S.
        ridge: ε I added to M until :meth:`after_greedy` (the greedy's ridge while S does not yet determine the
            parameters).

    Raises:
        IdentifiabilityError: M₀ + Σ_S F_iᵀF_i is not positive definite.
    """

    def __init__(self, Fp: np.ndarray, K: np.ndarray | None, M0: np.ndarray | None = None,
                 chosen: Sequence[int] | np.ndarray = (), ridge: float = 0.0) -> None:
        self.N, self.nh, self.nx = Fp.shape
        self.Fp = Fp
        self.Fa = np.ascontiguousarray(Fp.transpose(1, 0, 2))  # (nh, N, nx)
        self.K = K
        #: K is the identity (A on C_p): H_i = F_i M⁻¹ Kᵀ is B_i itself, no product
        self.K_eye = K is not None and K.shape == (self.nx, self.nx) and bool(np.array_equal(K, np.eye(self.nx)))
        #: a swap's A-form gains from the Gram matrices G_i G_iᵀ (nh×nh) instead of G_i (nh×ns) when K has more rows
        #: than a block (A on C_p: ns = nx), blocks of at most 3 rows
        self.gram = K is not None and K.shape[0] > self.nh and self.nh <= 3
        self.HH: np.ndarray | None = None  # H_i H_iᵀ of every candidate, (nh, nh, N), when ``gram``: made once per M
        self.chosen = [int(i) for i in chosen]
        F = Fp[self.chosen].reshape(-1, self.nx)
        M = F.T @ F
        self.pending: tuple | None = None
        #: work arrays of :meth:`swap_gains` (shared by the states :meth:`without` copies: never kept by one): a
        #: fresh (nh, N, ns) product a call costs more than the product itself (new pages of memory every time)
        self.scratch: dict[str, np.ndarray] = {}
        self.ridge = float(ridge)
        if ridge:
            M = M + self.ridge * np.eye(self.nx)
        if not self.at(M if M0 is None else M + M0):
            raise IdentifiabilityError("pool selection: the information of the starting set is not positive definite")

    @property
    def n_candidates(self) -> int:
        return self.N

    def at(self, M: np.ndarray) -> bool:
        """Set M; False if M is not positive definite."""
        try:
            L = np.linalg.cholesky(M)
        except np.linalg.LinAlgError:
            return False
        nh, N, nx = self.nh, self.N, self.nx
        self.M = M
        Minv = np.linalg.inv(M)
        Minv = 0.5 * (Minv + Minv.T)
        self.B = (self.Fa.reshape(nh * N, nx) @ Minv).reshape(nh, N, nx)
        if nh > 3:  # the entries a row at a time, not one by one
            self.A = {}
            self.A_full = _pair_dots(self.B, self.Fa)
        else:
            self.A = {(a, b): np.einsum("nk,nk->n", self.B[a], self.Fa[b]) for a in range(nh) for b in range(a, nh)}
        if self.K is None:
            self.H = None
            self.phi = float(-2.0 * np.sum(np.log(np.diag(L))))
        else:
            self.H = self.B if self.K_eye else (self.B.reshape(nh * N, nx) @ self.K.T).reshape(nh, N, -1)
            self.HH = None  # made by the first swap on this M (:meth:`_gram_swap`)
            X = np.linalg.solve(L, self.K.T)
            self.phi = float(np.sum(X * X))
        return True

    def add_gains(self) -> np.ndarray:
        """−Δφ of adding each candidate to M, (N,)."""
        if self.nh > 3:
            return _full_gains(self.A_full + np.eye(self.nh)[:, :, None], self.H)
        s = {k: v + (1.0 if k[0] == k[1] else 0.0) for k, v in self.A.items()}
        return _block_gains(s, self.H, self.N, self.nh)

    def swap_gains(self, o: int) -> tuple[float, np.ndarray] | None:
        """(φ of M − F_oᵀF_o, −Δφ of adding each candidate to it), or None if it is singular."""
        nh = self.nh
        if nh > 3:
            So = np.eye(nh) - self.A_full[:, :, o]
        else:
            So = np.eye(nh) - np.array([[self.A[min(a, b), max(a, b)][o] for b in range(nh)] for a in range(nh)])
        try:
            Lo = np.linalg.cholesky(So)
        except np.linalg.LinAlgError:
            return None
        LoiT = np.linalg.inv(Lo).T
        X = self.Fp[o].T @ LoiT  # D_i = B_i X
        if self.gram:
            return self._gram_swap(o, X, LoiT)
        D = np.matmul(self.B.reshape(nh * self.N, self.nx), X,
                      out=self._work("D", (nh * self.N, nh))).reshape(nh, self.N, nh)
        if nh > 3:  # S_i of every candidate at once, (nh, nh, N): the same sums as the entries' own calls below
            S = self.A_full + np.eye(nh)[:, :, None] + _pair_dots(D, D)
            gains: Callable[[np.ndarray | None], np.ndarray] = lambda G: _full_gains(S, G)  # noqa: E731
        else:
            s = {(a, b): v + (1.0 if a == b else 0.0) + np.einsum("nc,nc->n", D[a], D[b])
                 for (a, b), v in self.A.items()}
            gains = lambda G: _block_gains(s, G, self.N, nh)  # noqa: E731
        if self.H is None:
            return self.phi - 2.0 * float(np.sum(np.log(np.diag(Lo)))), gains(None)
        W = LoiT.T @ self.H[:, o, :]  # L_o⁻¹ H_o, (nh, ns)
        G = np.matmul(D.reshape(nh * self.N, nh), W, out=self._work("G", (nh * self.N, W.shape[1])))
        G += self.H.reshape(G.shape)  # H + D W
        return self.phi + float(np.sum(W * W)), gains(G.reshape(self.H.shape))

    def _gram_swap(self, o: int, X: np.ndarray, LoiT: np.ndarray) -> tuple[float, np.ndarray]:
        """:meth:`swap_gains` of the A form when K has more rows than a block (``gram``), by the Gram matrices
        G_i G_iᵀ = H_i H_iᵀ + Y_i D_iᵀ + D_i Y_iᵀ of G_i = H_i + D_i W (W = L_o⁻¹ H_o), Y_i = H_i Wᵀ + ½ D_i W Wᵀ:
        D_i = B_i X and Y_i = B_i (Kᵀ Wᵀ + ½ X W Wᵀ) in one product with B, and H_i H_iᵀ kept by the state, instead
        of G (nh, N, ns) and its products: the same gains within rounding (a few 1e-16 relative).

        Args:
            o: the chosen candidate taken out; X: F_oᵀ L_o⁻ᵀ, (nx, nh); LoiT: L_o⁻ᵀ, (nh, nh).

        Returns:
            (φ of M − F_oᵀF_o, −Δφ of adding each candidate to it).
        """
        nh, N = self.nh, self.N
        assert self.H is not None and self.K is not None
        if self.HH is None:
            self.HH = _pair_dots(self.H, self.H)
        W = LoiT.T @ self.H[:, o, :]  # (nh, ns)
        KW = W.T if self.K_eye else self.K.T @ W.T
        R = np.hstack([X, KW + X @ (0.5 * (W @ W.T))])  # (nx, 2 nh)
        DY = np.matmul(self.B.reshape(nh * N, self.nx), R, out=self._work("DY", (nh * N, 2 * nh)))
        DY3 = DY.reshape(nh, N, 2 * nh)
        D, Y = DY3[:, :, :nh], DY3[:, :, nh:]
        s = {(a, b): v + (1.0 if a == b else 0.0) + np.einsum("nc,nc->n", D[a], D[b]) for (a, b), v in self.A.items()}
        Z = np.empty((nh, nh, N))
        for a in range(nh):
            Z[a] = np.einsum("nk,bnk->bn", Y[a], D)  # Z[a, b] = Y_a · D_b
        return self.phi + float(np.sum(W * W)), _gram_gains(s, self.HH + Z + Z.transpose(1, 0, 2), N, nh)

    def _work(self, name: str, shape: tuple[int, ...]) -> np.ndarray:
        """The work array ``name`` of :meth:`swap_gains` of that shape (made on the first call)."""
        a = self.scratch.get(name)
        if a is None or a.shape != shape:
            a = self.scratch[name] = np.empty(shape)
        return a

    def values(self, exclude: np.ndarray) -> np.ndarray:
        if self.pending is None:
            phi = self.phi - self.add_gains()
        else:
            _, phi_m, g = self.pending
            phi = phi_m - g
        return np.where(exclude, np.inf, phi)

    def add(self, i: int) -> None:
        F = self.Fp[i].T @ self.Fp[i]
        if self.pending is not None:
            o = self.pending[0]
            M = self.M - self.Fp[o].T @ self.Fp[o] + F
            self.pending = None
        else:
            M = self.M + F
        if not self.at(M):
            raise IdentifiabilityError("pool selection: the information lost positive definiteness")
        self.chosen.append(int(i))

    def without(self, i: int) -> InformationState | None:
        sw = self.swap_gains(i)
        if sw is None:
            return None
        st = copy.copy(self)
        st.pending = (i, sw[0], sw[1])
        st.chosen = [c for c in self.chosen if c != i]
        return st

    def after_greedy(self) -> InformationState:
        if self.ridge:
            M, self.ridge = self.M - self.ridge * np.eye(self.nx), 0.0
            if not self.at(M):
                raise IdentifiabilityError("pool selection: the chosen candidates with the prior do not determine "
                                           "the parameters")
        return self

    def settled(self, predicted: float) -> float:
        return self.phi


def information_exchange(Fp: np.ndarray, start: Sequence[int] | np.ndarray, K: np.ndarray | None, M0: np.ndarray | None,
                         passes: int, rel_tol: float, abs_tol: float) -> tuple[np.ndarray, int]:
    """:func:`exchange` on :class:`InformationState` from the set ``start`` (the noise-only selection's rounded
    relaxation, DETMAX's random start). Returns (chosen, swaps)."""
    try:
        st = InformationState(Fp, K, M0, start)
    except IdentifiabilityError:  # no position can be swapped out of a singular start
        return np.asarray(start, int), 0
    excl = np.zeros(st.N, bool)
    excl[st.chosen] = True
    _, sel, _, swaps, _ = exchange(st, list(st.chosen), excl, st.phi, passes, rel_tol, abs_tol)
    return np.array(sel, int), swaps
