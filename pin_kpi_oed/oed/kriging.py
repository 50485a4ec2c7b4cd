r"""The universal-kriging TCP covariance of the discrepancy-aware KPI (``kpi_gp``) and its exact gradient.

The paper's C_s = E C_p Eᵀ counts tracker noise only. With the discrepancy of
:mod:`pin_kpi_oed.discrepancy` the measurement of pose q (robot base frame) is

.. math::  y = J(q)\,\theta + \delta(q) + \varepsilon,\qquad
           \operatorname{cov}(\delta_a(q) + \varepsilon_a, \delta_b(q') + \varepsilon_b)
           = \delta_{ab}\, s_a^2\,(k(q, q') + w\,[q = q']),

with J the parameter Jacobian of the reflector position (rows rotated from the tracker frame to the
robot base by the tracker pose's rotation: one rotation for the whole set), S = diag(s_x, s_y, s_z) the
discrepancy's per-axis scale (m), k its :class:`~pin_kpi_oed.discrepancy.kernel.JointKernel` and w its
white level (normalised). The calibrated TCP prediction at the working configurations W is the
GLS / MAP parameter estimate plus the kriged discrepancy; its error covariance is (universal kriging)

.. math::  C_s = K_{WW} - K_{WQ}\Sigma^{-1}K_{QW}
           + (E - K_{WQ}\Sigma^{-1}F)\,(F^T\Sigma^{-1}F + \Sigma_0^{-1})^{-1}\,(E - K_{WQ}\Sigma^{-1}F)^T,

per axis a: Σ_a = s_a² G, G = K_QQ + wI (the same correlation for the three axes), so with
A = G⁻¹, U = A K_QW, V_a = A J_a, H_a = E_a − Uᵀ J_a and M = Σ_a s_a⁻² J_aᵀ V_a + Σ₀⁻¹:

    tr C_s = Σ_a s_a² (tr K_WW − tr K_WQ U) + tr(M⁻¹ Σ_a H_aᵀ H_a).

With k ≡ 0 it is the paper's C_s with the noise σ_a² = w s_a² (tested). The value is tr C_s (m²; the
KPI trace in the base frame equals the tracker-frame one: a rotation keeps the trace).

Exact gradient (D = M⁻¹ N M⁻¹, N = Σ H_aᵀH_a, C = M⁻¹, σ² = Σ s_a²):

* ∂φ/∂J_a = −2 s_a⁻² V_a D − 2 U H_a C, chained with ∂J/∂q (:meth:`MeasurementModel.jacobian_dq`);
* ∂φ/∂K_WQ = −2σ² Uᵀ − 2 Σ_a H_a C V_aᵀ, chained with ∂k(q, w)/∂q (:meth:`JointKernel.grad_x`);
* ∂φ/∂G = σ² U Uᵀ + Σ_a s_a⁻² V_a D V_aᵀ + 2 Σ_a U H_a C V_aᵀ, chained through both arguments of K_QQ.
"""

from __future__ import annotations

import numpy as np

from pin_kpi_oed.discrepancy.cholesky import jitter_cholesky
from pin_kpi_oed.errors import IdentifiabilityError

__all__ = ["kpi_gp_covariance", "kpi_gp_value_and_grad", "pad_rows"]


def pad_rows(K: np.ndarray, rows: int) -> np.ndarray:
    """K (t, …) with zero rows appended up to ``rows``: the kernel of KPI rows that carry no discrepancy (rows of E
    beyond the t working configurations, e.g. the tool orientation of ``kpi6_gp``: H = E − UᵀJ is E there and they add
    nothing to the kriging term)."""
    K = np.asarray(K, float)
    if K.shape[0] == rows:
        return K
    return np.concatenate([K, np.zeros((rows - K.shape[0],) + K.shape[1:])])


def _prep(J, E, Kqq, Kwq, scale, w, P):
    """A = G⁻¹, U, V_a, H_a (axis-major), C = M⁻¹ and s² (matrix products only: this runs at every IPOPT step)."""
    J = np.asarray(J, float)
    E = np.asarray(E, float)
    m, _, nb = J.shape
    G = Kqq + w * np.eye(m)
    L = jitter_cholesky(G, what="K_QQ + wI")
    Li = np.linalg.solve(L, np.eye(m))
    A = Li.T @ Li
    U = A @ Kwq.T                                           # (m, t)
    Ja = np.ascontiguousarray(np.swapaxes(J, 0, 1))         # (3, m, nb)
    V = A @ Ja                                              # (3, m, nb)
    s2 = scale ** 2
    M = sum(Ja[a].T @ V[a] / s2[a] for a in range(3))
    if P is not None:
        M = M + P
    H = np.swapaxes(E, 0, 1) - U.T @ Ja                     # (3, t, nb)
    try:
        Lm = np.linalg.cholesky(0.5 * (M + M.T))
    except np.linalg.LinAlgError:
        raise IdentifiabilityError("singular information matrix: the design does not identify the parameters "
                                   "under the discrepancy; use more or more varied configurations") from None
    Lmi = np.linalg.solve(Lm, np.eye(nb))
    C = Lmi.T @ Lmi
    return A, U, V, H, C, s2


def kpi_gp_covariance(J: np.ndarray, E: np.ndarray, Kqq: np.ndarray, Kwq: np.ndarray, Kww: np.ndarray,
                      scale_m: np.ndarray, noise: float, prior_info: np.ndarray | None = None) -> np.ndarray:
    """C_s under the discrepancy (module formula), (3t, 3t) m², rows per working configuration then axis.

    Args:
        J: parameter Jacobian at the measured poses in the base frame, (m, 3, nb) (m per parameter unit).
        E: KPI Jacobian at the working configurations in the base frame, (t, 3, nb).
        Kqq, Kwq, Kww: normalised kernel matrices (m, m), (t, m), (t, t).
        scale_m: S (3,) m; noise: w.
        prior_info: Σ₀⁻¹ (nb, nb) or None.

    Raises:
        IdentifiabilityError: singular information.
    """
    scale = np.asarray(scale_m, float)
    A, U, V, H, C, s2 = _prep(J, E, Kqq, Kwq, scale, noise, prior_info)
    t = Kww.shape[0]
    Kc = Kww - Kwq @ U
    HC = H @ C
    Cs = np.zeros((t, 3, t, 3))
    for a in range(3):
        for b in range(3):
            Cs[:, a, :, b] = HC[a] @ H[b].T + (s2[a] * Kc if a == b else 0.0)
    return Cs.reshape(3 * t, 3 * t)


def kpi_gp_value_and_grad(J: np.ndarray, E: np.ndarray, Kqq: np.ndarray, Kwq: np.ndarray, tr_kww: float,
                          scale_m: np.ndarray, noise: float, prior_info: np.ndarray | None = None,
                          grad: bool = True) -> tuple[float, dict | None]:
    """tr C_s (m²) and its gradient w.r.t. J (m, 3, nb), K_WQ (t, m) and G = K_QQ + wI (m, m) (module formulas).

    Returns:
        (φ, {"J": ∂φ/∂J, "Kwq": ∂φ/∂K_WQ, "G": ∂φ/∂G (entries treated as independent)} or None).
    """
    scale = np.asarray(scale_m, float)
    A, U, V, H, C, s2 = _prep(J, E, Kqq, Kwq, scale, noise, prior_info)
    sig2 = float(s2.sum())
    N = sum(H[a].T @ H[a] for a in range(3))
    phi = sig2 * (tr_kww - float(np.sum(Kwq * U.T))) + float(np.sum(C * N))
    if not grad:
        return phi, None
    D = C @ N @ C
    HC = H @ C                                              # (3, t, nb)
    VD = V @ D                                              # (3, m, nb)
    gJ = np.stack([-2.0 / s2[a] * VD[a] - 2.0 * U @ HC[a] for a in range(3)], axis=1)   # (m, 3, nb)
    HCV = HC @ np.swapaxes(V, 1, 2)                         # (3, t, m)
    gK = -2.0 * sig2 * U.T - 2.0 * HCV.sum(0)
    gG = sig2 * U @ U.T + sum(VD[a] @ V[a].T / s2[a] for a in range(3)) + 2.0 * U @ HCV.sum(0)
    return phi, {"J": gJ, "Kwq": gK, "G": gG}
