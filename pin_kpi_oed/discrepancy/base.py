r"""The discrepancy as a prior: what an assumed one (:class:`~pin_kpi_oed.discrepancy.prior.DiscrepancyPrior`) and a
fitted one (:class:`~pin_kpi_oed.discrepancy.gp.Discrepancy`) have in common.

Both describe the measurement residual of the parametric model in the robot base frame as

.. math::  \delta \sim \mathcal{GP}(0, S\,k(q, q')\,S), \qquad \varepsilon \sim \mathcal N(0, w S^2),

k a normalised :class:`~pin_kpi_oed.discrepancy.kernel.JointKernel` (None: k ≡ 0, a white discrepancy), S = diag(s)
the per-axis scale (m) and w the white level (normalised). One vocabulary for both:

* :meth:`DiscrepancyModel.covariance` — k(Q_a, Q_b), normalised (× s_a² for axis a, m²);
* :attr:`DiscrepancyModel.delta_sigma_m` — σ of δ per axis, s·sqrt(k(q, q)) (m);
* :attr:`DiscrepancyModel.white_sigma_m` — σ of the white term per axis, s·sqrt(w) (m); its square
  :attr:`DiscrepancyModel.noise_var_m2`;
* :attr:`DiscrepancyModel.prior_sigma_m` — σ of the residual of the parametric model alone before any data,
  sqrt(delta² + white²) per axis (m).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["DiscrepancyModel"]


class DiscrepancyModel:
    """The prior of a discrepancy: kernel, per-axis scale and white level (see the module docstring).

    Subclasses hold ``kernel`` (a :class:`~pin_kpi_oed.discrepancy.kernel.JointKernel` or None), ``scale_m`` (3,) m
    and ``noise`` (w, normalised) and may override :attr:`n_joints`.
    """

    kernel: Any
    scale_m: np.ndarray
    noise: float

    @property
    def n_joints(self) -> int:
        """Joints of the configurations the kernel takes (from its per-joint parameters)."""
        k = self.kernel
        return 1 if k is None else int(max(np.size(k.length_scale), np.size(k.joint_amplitude)))

    def covariance(self, Qa: np.ndarray, Qb: np.ndarray | None = None) -> np.ndarray:
        """Prior covariance k(Qa, Qb) (normalised; multiply by s_a² for axis a, m²; zeros for a white discrepancy).

        Args:
            Qa: configurations (m, n) rad; Qb: configurations (p, n) rad, or None for Qa.
        """
        Qa = np.atleast_2d(Qa)
        if self.kernel is None:
            return np.zeros((len(Qa), len(Qa) if Qb is None else len(np.atleast_2d(Qb))))
        return self.kernel(Qa, None if Qb is None else np.atleast_2d(Qb))

    def grad_x(self, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
        """∂k(x_i, y_k)/∂x_i, (n, m, d) per rad (zeros for a white discrepancy)."""
        X, Y = np.atleast_2d(X), np.atleast_2d(Y)
        if self.kernel is None:
            return np.zeros((len(X), len(Y), X.shape[1]))
        return self.kernel.grad_x(X, Y)

    @property
    def delta_sigma_m(self) -> np.ndarray:
        """Prior σ of δ per axis (m): s_a·sqrt(k(q, q)) (zeros for a white discrepancy)."""
        if self.kernel is None:
            return np.zeros(3)
        kqq = float(self.kernel.diag(np.zeros((1, self.n_joints)))[0])
        return np.asarray(self.scale_m, float) * np.sqrt(kqq)

    @property
    def noise_var_m2(self) -> np.ndarray:
        """Variance per axis (m²) of what repeats from pose to pose only (tracker noise, repeatability): w·s²."""
        return self.noise * np.asarray(self.scale_m, float) ** 2

    @property
    def white_sigma_m(self) -> np.ndarray:
        """σ per axis (m) of the white term: s·sqrt(w)."""
        return np.sqrt(self.noise_var_m2)

    @property
    def prior_sigma_m(self) -> np.ndarray:
        """σ per axis (m) of the residuals of the parametric model alone: the prior variance of δ plus the white
        level, sqrt(delta_sigma_m² + white_sigma_m²)."""
        return np.sqrt(self.delta_sigma_m ** 2 + self.noise_var_m2)
