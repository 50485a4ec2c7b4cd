r"""The KPI after re-registration: what a calibration is worth in another session, once the tracker is registered again.

A calibration is used later, in another set-up: the tracker stands elsewhere (or the robot was moved) and its pose
(with the reflector) is registered again on a few rows R measured there, the robot held
(:func:`~pin_kpi_oed.upkeep.transfer.register_setup`). The registration fits the set-up s by least
squares to the residuals at R, so it absorbs the part of the robot's error that looks like a set-up change there
(locally a rigid motion of the workspace). To first order, with Δθ the error of the calibrated parameters,
J_R the measured point's Jacobian at R, G_R = J_R[:, s] its set-up columns and E the KPI Jacobian at the working
configurations W (set-up columns E_s),

.. math::  \Delta s = -(G_R^T \Omega G_R)^{-1} G_R^T \Omega\, J_R \Delta\theta,\qquad
           e_W = \tilde E\,\Delta\theta,\qquad
           \tilde E = E - E_s\,(G_R^T \Omega G_R)^{-1} G_R^T \Omega\, J_R,

with Ω = diag(1/s_a²) the per-axis weights. Ẽ replaces E in the discrepancy-aware KPI (its set-up columns are
zero: the old set-up does not matter any more). The registration's own noise adds a constant, design-independent
term (white level w per axis at the r registration rows),

.. math::  C_{\mathrm{reg}} = E_s P\,N_R\,P^T E_s^T,\qquad P = (G_R^T \Omega G_R)^{-1} G_R^T \Omega,\qquad
           N_R = \operatorname{blkdiag}_a\, s_a^2 w I_r.

**The kriging error at R.** The registration fits the set-up to the residuals at R, which hold the calibrated
prediction's error there: its parametric part J_R Δθ (in Ẽ above) and the discrepancy's kriging error k_R, which is
correlated with the kriging error k_W at W. Exactly (to first order), with e = [e_W; e_R] the calibrated
prediction's errors at W and R and C_WR their universal-kriging covariance (the KPI of W ∪ R with E' = [E; J_R]),

.. math::  e_W' = L\,e - B\,\varepsilon_R,\qquad L = [\,I,\; -B\,],\qquad B = E_s P,\qquad
           C_s' = L\,C_{WR}\,L^T + C_{\mathrm{reg}}

(:func:`reregistered_covariance`).

The design criterion and every σ ``design`` reports keep Ẽ (the registration credited with the parametric part of
the error at R only, k_W counted as before): their pool updates and IPOPT gradient are those of a plain trace,
where L C_WR Lᵀ would need a weighted one. The exact form is
:meth:`~pin_kpi_oed.oed.discrepancy_kpi.DiscrepancyDesignCriterion.reregistered_covariance`: Monte-Carlo exact
where the criterion's form is 7 % low in a correlated case (tests/test_reregistration.py), and 1.3–4.5 % below it on the
real UR10
pairs, whose observed errors differ from both by more (docs/results.md).

The discrepancy is taken as carried to the new session with the model (what the calibrated model assumes: its
posterior mean is predicted there, and its kriging error at W is counted as before). A discrepancy that belongs to
the session is not in this prediction: ``register`` measures it on the registration rows and scales the station's
σ by their standardised errors, before any other row is measured.

Without it a design for another session scores the parameter uncertainty extrapolated to W in the old set-up:
on the real UR10 (Series D → C) that number is 40–500 mm for every set while the re-registered error is
0.5–0.7 mm, and the discrepancy-aware KPI minimising it was 59 % worse than random at 30 poses (−11 % with Ẽ).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pin_kpi_oed.errors import InputError

__all__ = ["Reregistration", "reregistration", "reregistered_covariance"]


@dataclass
class Reregistration:
    """The KPI Jacobian after re-registration and the registration's own covariance.

    Attributes:
        E: Ẽ (t, 3, nb), base frame (set-up columns zero).
        E_before: the KPI Jacobian E it was computed from (t, 3, nb).
        cov_m2: C_reg (3t, 3t) m², rows per working configuration then axis.
        Q_register: the registration configurations R (r, n) rad.
        setup: mask of the set-up columns among the nb identifiable parameters.
        gain: B = E_s P (3t, 3r): how the registration moves the working configurations' prediction per residual at
            R (rows per configuration then axis).
    """

    E: np.ndarray
    E_before: np.ndarray
    cov_m2: np.ndarray
    Q_register: np.ndarray
    setup: np.ndarray
    gain: np.ndarray

    @property
    def trace_m2(self) -> float:
        """tr C_reg (m²)."""
        return float(np.trace(self.cov_m2))


def reregistration(E: np.ndarray, J_register: np.ndarray, setup: np.ndarray, scale_m: np.ndarray, noise: float,
                   Q_register: np.ndarray) -> Reregistration:
    """Ẽ and C_reg of the module formulas.

    Args:
        E: KPI Jacobian at the working configurations, base frame (t, 3, nb).
        J_register: the measured point's Jacobian at the registration configurations, base frame (r, 3, nb).
        setup: boolean mask (nb,) of the set-up parameters (what the registration re-fits).
        scale_m: the discrepancy's per-axis scale S (3,) m; noise: its white level w (normalised).
        Q_register: R (r, n) rad (kept in the result).

    Raises:
        InputError: no set-up parameter, or registration configurations that do not determine the set-up.
    """
    E, J_register = np.asarray(E, float), np.asarray(J_register, float)
    setup = np.asarray(setup, bool)
    if not setup.any():
        raise InputError("re-registration: the model has no identifiable set-up parameter to register")
    r = J_register.shape[0]
    s2 = np.asarray(scale_m, float) ** 2
    omega = np.tile(1.0 / s2, r)                                # per row (configuration, axis)
    G = J_register[:, :, setup].reshape(3 * r, -1)
    A = G.T @ (omega[:, None] * G)
    sv = np.linalg.svd(A, compute_uv=False)
    if sv[-1] <= 1e-10 * sv[0]:
        raise InputError(f"re-registration: the {r} registration configuration(s) do not determine the set-up "
                         f"({int(setup.sum())} parameters); use at least 3 configurations spread over the workspace")
    P = np.linalg.solve(A, G.T * omega[None, :])                # (k, 3r)
    Jr = J_register.reshape(3 * r, -1)
    Es = E[:, :, setup]                                         # (t, 3, k)
    Et = E - np.einsum("tak,kp->tap", Es, P @ Jr)
    Et[:, :, setup] = 0.0                                       # exactly: the old set-up does not matter
    N = np.kron(noise * np.eye(r), np.diag(s2))                 # rows (configuration, axis)
    B = Es.reshape(-1, Es.shape[2]) @ P                         # (3t, 3r)
    return Reregistration(Et, E, B @ N @ B.T, np.atleast_2d(np.asarray(Q_register, float)), setup, B)


def reregistered_covariance(rr: Reregistration, C_WR: np.ndarray) -> np.ndarray:
    """The exact re-registered C_s' = L C_WR Lᵀ + C_reg of the module formulas, (3t, 3t) m², base frame.

    Args:
        rr: the :func:`reregistration` of the working configurations W and the registration configurations R.
        C_WR: the universal-kriging covariance of the calibrated prediction's errors at W ∪ R (W first; rows per
            configuration then axis), (3(t + r), 3(t + r)) m²: the KPI covariance with E' = [E; J_R]
            (:func:`~pin_kpi_oed.oed.kriging.kpi_gp_covariance`).

    Raises:
        InputError: C_WR of another size than W ∪ R.
    """
    n_w, n_r = rr.gain.shape
    if np.shape(C_WR) != (n_w + n_r, n_w + n_r):
        raise InputError(f"re-registration: C_WR must be {n_w + n_r} x {n_w + n_r} (W then R), got {np.shape(C_WR)}")
    L = np.hstack([np.eye(n_w), -rr.gain])
    return L @ np.asarray(C_WR, float) @ L.T + rr.cov_m2
