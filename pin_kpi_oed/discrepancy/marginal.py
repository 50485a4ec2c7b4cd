r"""The log marginal likelihood of the discrepancy's hyper-parameters and its gradient, on the pairs of rows.

For the covariance Σ = K + (w + ε) I of n training rows (K the
:class:`~pin_kpi_oed.discrepancy.kernel.JointKernel`, w the white level, ε = 1e-10 the jitter scikit-learn's
regressor adds) and m output columns Y (n, m) sharing it,

.. math::

    \log p(Y \mid θ) = -\tfrac12 \operatorname{tr}(Y^T Σ^{-1} Y) - m \sum_i \log L_{ii} - \tfrac{m n}{2} \log 2π,
    \qquad
    \frac{\partial \log p}{\partial θ_k} = \tfrac12 \sum_{ij} W_{ij} \frac{\partial Σ_{ij}}{\partial θ_k},
    \quad W = α α^T - m Σ^{-1},\ α = Σ^{-1} Y,

with L the Cholesky factor of Σ and θ the logarithms of the hyper-parameters in scikit-learn's order (c, a_j,
ℓ_j, L_j, then w). Every derivative of the kernel is a product of its own parts with the chords
D_ij = 4 sin²(Δ_j/2) (Δ_j² for a linear joint, see the kernel's module):

.. math::

    \frac{\partial Σ}{\partial \log c} = 2P, \quad
    \frac{\partial Σ}{\partial \log a_j} = 2A_j, \quad
    \frac{\partial Σ}{\partial \log ℓ_j} = A_j \frac{D_j}{ℓ_j^2}, \quad
    \frac{\partial Σ}{\partial \log L_j} = P \frac{D_j}{L_j^2}, \quad
    \frac{\partial Σ}{\partial \log w} = w I,

so each gradient entry is one weighted sum over the pairs i < j (twice, W and Σ being symmetric) plus the
diagonal, where D = 0. Scikit-learn's regressor forms the (n, n, 2 + 3d) gradient tensor and contracts it with
an einsum per evaluation; here the chords of the pairs are formed once per training set, the one-joint
exponentials once per evaluation, and the inverse comes from the same Cholesky factor (LAPACK potri). The value
and gradient equal scikit-learn's to rounding (tested), so L-BFGS-B takes the same steps.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import linalg as sla
from scipy.optimize import minimize

from pin_kpi_oed.discrepancy.kernel import JointKernel, linear_mask

__all__ = ["MarginalLikelihood", "StartRace", "maximise_marginal_likelihood"]

#: What scikit-learn's regressor adds to the diagonal (its ``alpha``), kept so the optimum is the same.
REGRESSOR_JITTER = 1e-10
#: Pairs of rows per block of the kernel's evaluation (:meth:`MarginalLikelihood._kernel_pairs`): a block's (d,
#: PAIR_BLOCK) arrays stay in the processor's cache between the passes over them; those of all pairs of 400 rows
#: (3.8 MB each) do not.
PAIR_BLOCK = 4096
#: The iteration at which a later start's search is compared with the earlier starts' (:class:`StartRace`).
RACE_AT = 10
#: How far (nats of log marginal likelihood) a start may trail the best start and still be searched on and checked.
RACE_NATS = 100.0


@dataclass
class StartRace:
    """The starts of one fit raced on their log marginal likelihood, on the same rows.

    A start's search is stopped at iteration ``at`` when its log marginal likelihood trails the best earlier start's
    at the same iteration by more than ``nats``; a finished start is left out of the choice among the starts (the
    K-fold check, :func:`~pin_kpi_oed.discrepancy.fit.fit_discrepancy`) when its value trails the best start's by
    more than ``nats``. A difference of 100 nats is a likelihood ratio of e¹⁰⁰: such a start's hyper-parameters
    explain the residuals far worse than the leader's. On the IPA UR10's Series B (748 rows), C (1,386 and 2,773)
    and D (316) the second start of ``DiscrepancyOptions.starts`` trails the first by 330-650 nats at iteration 10
    (D: by 5, and by 123 at the end), and its K-fold held-out mean error, checked, was 12-130 % larger.

    Attributes:
        at: the iteration of the comparison (L-BFGS-B iterations); nats: the margin (log-likelihood units).
        lead: the best log marginal likelihood after each iteration over the starts searched so far (iterations
            1..``at``). finals: each start's final value (None: stopped).
    """

    at: int = RACE_AT
    nats: float = RACE_NATS
    lead: list = field(default_factory=list)
    finals: list = field(default_factory=list)

    def behind(self, iteration: int, lml: float) -> bool:
        """Whether a start at ``iteration`` with log marginal likelihood ``lml`` trails the best earlier start at
        the same iteration by more than :attr:`nats` (checked at :attr:`at` only)."""
        return iteration == self.at and len(self.lead) >= iteration and lml < self.lead[iteration - 1] - self.nats

    def record(self, history: list, final: float | None) -> None:
        """Add a start's values after each iteration (``history``) and its final value (None: stopped)."""
        for i, v in enumerate(history[:self.at]):
            if i < len(self.lead):
                self.lead[i] = max(self.lead[i], v)
            else:
                self.lead.append(v)
        self.finals.append(final)

    def contenders(self) -> list[bool]:
        """Per start searched: whether it finished within :attr:`nats` of the best final value."""
        done = [v for v in self.finals if v is not None]
        top = max(done) if done else -np.inf
        return [v is not None and v >= top - self.nats for v in self.finals]


class MarginalLikelihood:
    """−log p(Y | θ) and its gradient for one training set (see the module).

    Args:
        Q: training configurations (n, d) rad (m for a linear joint).
        Y: normalised residuals (n, m).
        linear: (d,) bool, the kernel's linear joints (``JointKernel.linear``); None: none.
    """

    def __init__(self, Q: np.ndarray, Y: np.ndarray, linear: np.ndarray | None = None) -> None:
        Q = np.atleast_2d(np.asarray(Q, float))
        self.Y = np.asarray(Y, float).reshape(len(Q), -1)
        self.n, self.d = Q.shape
        i, j = np.triu_indices(self.n, 1)
        self.flat = i + j * self.n                                       # (i, j), i < j, in column-major order
        self.flat_c = i * self.n + j                                     # the same pairs in row-major order
        self.D = 2.0 - 2.0 * np.cos(Q.T[:, i] - Q.T[:, j])                 # (d, pairs) chords 4 sin²(Δ/2)
        lin = linear_mask(linear, self.d)
        if lin is not None:
            self.D[lin] = (Q.T[lin][:, i] - Q.T[lin][:, j]) ** 2             # a linear joint's Δ²
        self.S = np.zeros((self.n, self.n), order="F")                    # Σ's upper triangle, factored in place
        # work arrays of every evaluation, allocated once (a new array of this size costs its page faults each time)
        self._A = np.empty_like(self.D)
        self._pairs = np.empty((3, self.D.shape[1]))
        self._Sp = np.empty(self.D.shape[1])
        self._W = np.empty((self.n, self.n))
        self.nfev = 0

    def split(self, theta: np.ndarray) -> tuple[float, np.ndarray, np.ndarray, np.ndarray, float]:
        """(c, a, ℓ, L, w) from θ (logarithms, scikit-learn's order)."""
        d = self.d
        v = np.exp(np.asarray(theta, float))
        return float(v[0]), v[1:1 + d], v[1 + d:1 + 2 * d], v[1 + 2 * d:1 + 3 * d], float(v[1 + 3 * d])

    def _kernel_pairs(self, c: float, a: np.ndarray, ell: np.ndarray, L: np.ndarray) -> None:
        """The kernel of every pair i < j: its product part c² exp(−Σ_j D_j / 2L_j²) into ``_pairs[0]``, the one-joint
        parts a_j² exp(−D_j / 2ℓ_j²) into ``_A`` and their sum into ``_pairs[1]``, :data:`PAIR_BLOCK` pairs at a time
        (a block's arrays stay in the processor's cache between the passes over them). Every value is formed by the
        same operations in the same order as over the whole arrays at once (element by element; the joints summed in
        their order), so the result is the same to the last bit: the optimiser's path depends on it."""
        P, K, _ = self._pairs
        sP, sA, a2 = -0.5 / L ** 2, (-0.5 / ell ** 2)[:, None], (a ** 2)[:, None]
        for b in range(0, self.D.shape[1], PAIR_BLOCK):
            cut = slice(b, b + PAIR_BLOCK)
            Db, Ab, Pb, Kb = self.D[:, cut], self._A[:, cut], P[cut], K[cut]
            np.matmul(sP, Db, out=Pb)
            np.exp(Pb, out=Pb)                                            # c² not yet applied
            Pb *= c ** 2
            np.multiply(Db, sA, out=Ab)
            np.exp(Ab, out=Ab)
            Ab *= a2
            np.copyto(Kb, Ab[0])
            for j in range(1, self.d):
                Kb += Ab[j]
            Kb += Pb

    def __call__(self, theta: np.ndarray) -> tuple[float, np.ndarray]:
        """(−log p, −∂ log p/∂θ); (inf, 0) where Σ is not positive definite (as scikit-learn)."""
        self.nfev += 1
        c, a, ell, L, w = self.split(theta)
        n, m, d = self.n, self.Y.shape[1], self.d
        P, K, Wp = self._pairs                                            # (pairs,) each, reused
        A = self._A                                                       # (d, pairs)
        self._kernel_pairs(c, a, ell, L)
        S = self.S
        Sf = S.reshape(-1, order="F")                                    # a view (column-major)
        Sf[self.flat] = K
        Sf[::n + 1] = c ** 2 + float((a ** 2).sum()) + w + REGRESSOR_JITTER
        Lc, info = sla.lapack.dpotrf(S, lower=0, clean=0, overwrite_a=1)   # Σ = UᵀU
        if info != 0:
            return np.inf, np.zeros(len(theta))
        alpha, info = sla.lapack.dpotrs(Lc, self.Y, lower=0)
        lml = -0.5 * float((self.Y * alpha).sum()) - m * float(np.log(Lc.diagonal()).sum()) \
            - 0.5 * m * n * np.log(2.0 * np.pi)
        Si, info = sla.lapack.dpotri(Lc, lower=0, overwrite_c=1)               # Σ⁻¹ (upper triangle)
        if info != 0:
            return np.inf, np.zeros(len(theta))
        W = np.matmul(alpha, alpha.T, out=self._W)
        Wd = float(W.trace() - m * Si.trace())                            # the diagonal's sum
        # W − mΣ⁻¹ at the pairs i < j only: the same operations on each pair as over the whole matrices
        W.reshape(-1).take(self.flat_c, out=Wp)                           # (ααᵀ)_ij, W row-major
        Sp = Si.reshape(-1, order="F").take(self.flat, out=self._Sp)      # (Σ⁻¹)_ij, i < j: its upper triangle
        Sp *= m
        Wp -= Sp
        Wp *= 2.0                                                             # counted for both triangles
        WP = np.multiply(Wp, P, out=K)
        g = np.empty(len(theta))
        g[0] = float(WP.sum()) + c ** 2 * Wd
        g[1:1 + d] = A @ Wp + a ** 2 * Wd
        g[1 + d:1 + 2 * d] = 0.5 * np.einsum("p,jp,jp->j", Wp, A, self.D) / ell ** 2
        g[1 + 2 * d:1 + 3 * d] = 0.5 * (self.D @ WP) / L ** 2
        g[1 + 3 * d] = 0.5 * w * Wd
        return -lml, -g


def _search(f: MarginalLikelihood, theta0: np.ndarray, bounds: np.ndarray, max_iter: int,
            race: StartRace | None) -> Any:
    """One L-BFGS-B search of −log p from ``theta0`` (at most ``max_iter`` iterations), raced in ``race`` and recorded
    there: the optimiser's result, its ``fun`` inf when the race stopped it."""
    history: list[float] = []
    stopped = False

    def watch(intermediate_result: Any) -> None:
        nonlocal stopped
        history.append(-float(intermediate_result.fun))
        if race is not None and race.behind(len(history), history[-1]):
            stopped = True
            raise StopIteration                                       # L-BFGS-B ends with the last iterate
    res = minimize(f, theta0, method="L-BFGS-B", jac=True, bounds=bounds, callback=watch,
                   options={"maxiter": int(max_iter)})
    if race is not None:
        race.record(history, None if stopped else -float(res.fun))
    if stopped:
        res.fun = np.inf
    return res


def maximise_marginal_likelihood(Q: np.ndarray, Y: np.ndarray, kernel0: JointKernel, noise0: float,
                                 noise_bounds: tuple[float, float], max_iter: int, restarts: int = 0,
                                 seed: int = 0, race: StartRace | None = None) -> tuple[JointKernel, float, float]:
    """The kernel and white level of largest marginal likelihood: L-BFGS-B from ``kernel0`` and ``noise0`` (at most
    ``max_iter`` iterations), and from ``restarts`` starts drawn uniformly over the log bounds (seeded with ``seed``,
    as scikit-learn's regressor draws them).

    Args:
        race: the starts of the fit so far (:class:`StartRace`): each search here is raced against them (stopped
            at ``race.at`` iterations when it trails by more than ``race.nats``) and recorded in it. None: no race.

    Returns:
        (kernel, white level w (normalised variance), log marginal likelihood at it); the log marginal likelihood
        is -inf when every search was stopped by the race (the kernel is then the last one reached).
    """
    f = MarginalLikelihood(Q, Y, kernel0.linear)
    d = f.d
    c, L0, a0, ell0 = kernel0.parts(d)
    theta0 = np.log(np.concatenate([[c], a0, ell0, L0, [noise0]]))

    def rows(b: Any) -> np.ndarray:                                       # (2,) or per joint (d, 2)
        return np.broadcast_to(np.asarray(b, float).reshape(-1, 2), (d, 2))
    b = np.vstack([np.asarray(kernel0.amplitude_bounds, float).reshape(1, 2), rows(kernel0.joint_amplitude_bounds),
                   rows(kernel0.joint_length_scale_bounds), rows(kernel0.length_scale_bounds),
                   np.asarray(noise_bounds, float).reshape(1, 2)])
    bounds = np.log(b)
    starts = [theta0]
    rng = np.random.RandomState(int(seed))
    starts += [rng.uniform(bounds[:, 0], bounds[:, 1]) for _ in range(int(restarts))]
    best: Any = None
    for t0 in starts:
        res = _search(f, t0, bounds, max_iter, race)
        if best is None or res.fun < best.fun:
            best = res
    c, a, ell, L, w = f.split(best.x)
    kernel = JointKernel(c, L, a, ell, kernel0.amplitude_bounds, kernel0.length_scale_bounds,
                         kernel0.joint_amplitude_bounds, kernel0.joint_length_scale_bounds, kernel0.linear)
    return kernel, w, -float(best.fun)
