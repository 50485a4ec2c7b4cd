r"""Recursive re-registration of the set-up during work: a Kalman filter on the tracker pose whose drift level is
estimated from the rows themselves.

A tracker stand settles, the hall warms up, the robot's base grows with the temperature: over a day the set-up
drifts by tens of µm, which a model calibrated in the morning does not know. The state is the set-up correction
x = δ_t (the tracker pose twist of :class:`~pin_kpi_oed.model.parameters.ParameterLayout`:
``tracker_T_base ← T₀ · exp6(δ_t)``), a random walk in time,

.. math::  x_i = x_{i-1} + w_i,\qquad w_i \sim N(0,\ q^2\,Δt_i\,D),\qquad D = \mathrm{diag}(1, 1, 1, L^{-2}, L^{-2},
           L^{-2}),

(Δt the time since the previous row, s — one second per row without a time column —, L the rows' typical distance
from the tracker, m: the level q is a displacement rate in m/√s), observed through each new row

.. math::  y_i = Y_0(q_i) + G_i x_i + e_i,\qquad e_i \sim N(0, \mathrm{diag}(σ_i^2)),

Y₀ and σ the calibrated model's prediction and honest σ, G_i the prediction's set-up Jacobian (tracker frame). Each
row is *predicted before it is used*: the innovation r_i = y_i − Y₀ − G_i x̂ with covariance S_i = G_i P G_iᵀ +
diag(σ_i²), then the Kalman update x̂ += K r, P = (I − KG) P (Joseph form), K = P Gᵀ S⁻¹.

The level q is not a tuning constant: a bank of filters, one per level of :data:`LEVELS_M_PER_SQRT_S` (0 — a set-up
that does not move — up to 10 µm/√s), each scores its innovations by their Gaussian log-likelihood with a
forgetting factor λ (memory ≈ 1/(1 − λ) rows); the prediction is the mixture of the filters weighted by
softmax(log-likelihood) — the posterior over the levels —, its covariance the mixture's (the spread of the filters'
means included). A row whose innovation is beyond χ²₃ at 1 − 10⁻⁴ against the mixture is an outlier: predicted and
counted, not used.

Every filter of the bank starts from the same prior on the set-up correction, P₀ = s₀² D (s₀ =
:data:`SETUP_PRIOR_M`): the set-up the rows are measured in is not exactly the model's (its registration's own error,
a tracker set up again), and a constant offset must be absorbed alike by every level — with P₀ = 0 only a level
whose walk accumulates that offset over the memory could follow it, and a set-up that does not move would be scored
as drifting (about 1 µm/√row for an offset of tens of µm over a few hundred rows).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["SetupFilter", "LEVELS_M_PER_SQRT_S"]

#: Random-walk levels of the set-up's drift the bank holds (m/√s): none, then 1 nm/√s .. 10 µm/√s.
LEVELS_M_PER_SQRT_S = (0.0, 1e-9, 1e-8, 3e-8, 1e-7, 3e-7, 1e-6, 1e-5)
#: σ of the set-up's prior offset at the rows (m): every level's starting covariance s₀² D (module docstring).
SETUP_PRIOR_M = 1e-4
#: Innovations beyond this χ²₃ value (1 − 10⁻⁴) are outliers: not used for the update.
OUTLIER_CHI2 = 21.108


@dataclass
class SetupFilter:
    """A bank of Kalman filters on the set-up correction (module docstring).

    Attributes:
        lever_m: L, the rows' typical distance from the tracker (m): rotation noise q/L.
        forgetting: λ of the levels' log-likelihoods, in (0, 1].
        levels: the random-walk levels (m/√s).
        prior_m: s₀, the σ of the set-up's offset before the first row (m; rotations s₀/L).
        x: per level the state (k, 6); P: per level its covariance (k, 6, 6); loglik: per level (k,).
        outliers: rows not used for the update; rows: rows seen.
    """

    lever_m: float
    forgetting: float = 0.995
    levels: tuple = LEVELS_M_PER_SQRT_S
    prior_m: float = SETUP_PRIOR_M
    x: np.ndarray = field(init=False)
    P: np.ndarray = field(init=False)
    loglik: np.ndarray = field(init=False)
    outliers: int = 0
    rows: int = 0
    _t: float | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        k = len(self.levels)
        self.x = np.zeros((k, 6))
        self.loglik = np.zeros(k)
        self.D = np.diag([1.0, 1.0, 1.0] + [1.0 / self.lever_m ** 2] * 3)
        self.P = np.repeat((self.prior_m ** 2 * self.D)[None], k, axis=0)
        self.q2 = np.asarray(self.levels, float) ** 2

    @property
    def weights(self) -> np.ndarray:
        """Posterior weights of the levels (k,)."""
        w = np.exp(self.loglik - self.loglik.max())
        return w / w.sum()

    @property
    def level_m_per_sqrt_s(self) -> float:
        """The most probable level (m/√s)."""
        return float(self.levels[int(np.argmax(self.loglik))])

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        """The mixture's set-up correction (6,) and its covariance (6, 6)."""
        w = self.weights
        mu = w @ self.x
        d = self.x - mu
        return mu, np.einsum("k,kij->ij", w, self.P) + np.einsum("k,ki,kj->ij", w, d, d)

    def predict(self, G: np.ndarray, sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The mixture's correction of a row's prediction (3,) and the covariance (3, 3) of measured − predicted.

        Args:
            G: the row's set-up Jacobian (3, 6) (tracker frame, per unit of the twist); sigma: its honest σ (3,) m.
        """
        mus = self.x @ G.T
        S = np.einsum("ia,kab,jb->kij", G, self.P, G) + np.diag(sigma ** 2)
        w = self.weights
        mu = w @ mus
        d = mus - mu
        return mu, np.einsum("k,kij->ij", w, S) + np.einsum("k,ki,kj->ij", w, d, d)

    def advance(self, t_s: float | None) -> None:
        """The random walk up to time ``t_s`` (s; None: one second after the previous row)."""
        dt = 1.0 if (t_s is None or self._t is None) else max(float(t_s) - self._t, 0.0)
        if t_s is not None:
            self._t = float(t_s)
        self.P = self.P + (self.q2 * dt)[:, None, None] * self.D

    def update(self, r0: np.ndarray, G: np.ndarray, sigma: np.ndarray) -> bool:
        """Use a row: r0 = measured − Y₀ (3,) m. Returns False when it is an outlier (not used)."""
        self.rows += 1
        mu, C = self.predict(G, sigma)
        e = r0 - mu
        if float(e @ np.linalg.solve(C, e)) > OUTLIER_CHI2:
            self.outliers += 1
            return False
        R = np.diag(sigma ** 2)                                  # every level at once, (k, ...) stacks
        P = self.P
        PGt = P @ G.T                                            # (k, 6, 3)
        S = G @ PGt + R
        r = r0 - self.x @ G.T                                    # (k, 3)
        Si = np.linalg.inv(S)
        K = PGt @ Si                                             # (k, 6, 3)
        self.x = self.x + np.einsum("kab,kb->ka", K, r)
        A = np.eye(6) - K @ G
        self.P = A @ P @ np.swapaxes(A, 1, 2) + K @ R @ np.swapaxes(K, 1, 2)
        _, logdet = np.linalg.slogdet(S)
        self.loglik = self.forgetting * self.loglik - 0.5 * (np.einsum("ka,kab,kb->k", r, Si, r) + logdet
                                                             + 3 * np.log(2 * np.pi))
        return True
