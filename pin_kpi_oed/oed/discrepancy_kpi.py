r"""The KPI criterion under model discrepancy: the universal-kriging TCP covariance (criterion ``kpi_gp``).

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

Pool selection (:func:`select_pool_gp`): greedy additions by exact rank-one (kernel) and rank-three
(information) updates of the conditional quantities of every candidate, then exchange passes; no
equivalence-theorem certificate exists for this criterion (it is not a function of an information
matrix of the design measure: the kernel couples the poses).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pin_kpi_oed.errors import IdentifiabilityError, InputError
from pin_kpi_oed.oed.covariance import prior_of
from pin_kpi_oed.oed.criteria import Criterion, KpiDiscrepancy

__all__ = ["DiscrepancyPrior", "default_discrepancy", "DEFAULT_DISCREPANCY", "kpi_gp_covariance",
           "kpi_gp_value_and_grad", "KpiDiscrepancy", "DiscrepancyDesignCriterion", "select_pool_gp",
           "GpPoolSelection", "NO_CERTIFICATE", "PosesNeeded", "poses_needed"]

#: One line the design output prints for this criterion.
NO_CERTIFICATE = ("kpi_gp: no optimality certificate exists for the discrepancy-aware criterion (the kernel couples "
                  "the poses; the equivalence theorem of the noise-only criteria does not apply)")

#: The default discrepancy before any measurement (a stated assumption, not a fit): per-axis scale S, white level,
#: kernel amplitudes (share of S² in the whole-configuration and one-joint parts) and length scales (rad).
DEFAULT_DISCREPANCY = {"scale_m": 1e-4, "white_m": 1e-5, "product_share": 0.5, "length_scale_rad": 1.0,
                       "joint_length_scale_rad": 0.5}


@dataclass
class DiscrepancyPrior:
    """The discrepancy a design assumes: kernel, per-axis scale and white level.

    Attributes:
        kernel: the :class:`JointKernel` (normalised), or None for a white discrepancy (k ≡ 0).
        scale_m: per-axis scale S (3,) m, robot base frame.
        noise: white level w (normalised; the white σ per axis is s_a·sqrt(w), m).
        source: where it comes from (printed in the design output).
    """

    kernel: Any
    scale_m: np.ndarray
    noise: float
    source: str = ""

    def __post_init__(self) -> None:
        self.scale_m = np.broadcast_to(np.asarray(self.scale_m, float), (3,)).copy()
        if not (np.all(np.isfinite(self.scale_m)) and np.all(self.scale_m > 0)):
            raise InputError(f"discrepancy scale must be 3 positive numbers (m), got {self.scale_m}")
        if not (np.isfinite(self.noise) and self.noise > 0):
            raise InputError(f"discrepancy white level must be > 0, got {self.noise}")

    @classmethod
    def from_discrepancy(cls, d: Any, source: str = "") -> DiscrepancyPrior:
        """The prior (kernel, S, w) of a fitted :class:`~pin_kpi_oed.discrepancy.gp.Discrepancy` (its data not used:
        a new calibration re-fits the robot)."""
        kernel = d.kernel if getattr(d, "kind", "white") != "white" else None
        return cls(kernel, np.asarray(d.scale_m, float), float(max(d.noise, 1e-12)), source)

    def cov(self, Qa: np.ndarray, Qb: np.ndarray | None = None) -> np.ndarray:
        """k(Qa, Qb) (normalised; zeros for a white discrepancy)."""
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

    def prior_sigma_m(self) -> np.ndarray:
        """Prior σ of δ per axis (m): s_a sqrt(k(q, q))."""
        if self.kernel is None:
            return np.zeros(3)
        d = max(np.size(self.kernel.length_scale), np.size(self.kernel.joint_amplitude))
        kqq = float(self.kernel.diag(np.zeros((1, d)))[0])
        return self.scale_m * np.sqrt(kqq)

    def describe(self) -> str:
        """One line: source, σ of δ and of the white term per axis (µm), kernel hyper-parameters."""
        white = self.scale_m * np.sqrt(self.noise)
        words = (f"discrepancy ({self.source or 'given'}): delta sigma per axis "
                 f"{', '.join(f'{v * 1e6:.1f}' for v in self.prior_sigma_m())} um, white "
                 f"{', '.join(f'{v * 1e6:.1f}' for v in white)} um (base frame x, y, z)")
        if self.kernel is not None:
            kd = self.kernel.to_dict()
            words += (f"; kernel amplitude {kd['amplitude']:.3g}, length scales "
                      f"{', '.join(f'{v:.2g}' for v in kd['length_scale_rad'])} rad, joint amplitudes "
                      f"{', '.join(f'{v:.2g}' for v in kd['joint_amplitude'])}, joint length scales "
                      f"{', '.join(f'{v:.2g}' for v in kd['joint_length_scale_rad'])} rad")
        else:
            words += "; white only (no correlation between poses)"
        return words


def default_discrepancy(n_joints: int) -> DiscrepancyPrior:
    """The documented default before any measurement (:data:`DEFAULT_DISCREPANCY`).

    S = 0.1 mm per axis, white 10 µm per axis (w = (10 µm / 0.1 mm)² = 0.01), k(q, q) = 1 split half into the
    whole-configuration part (c² = 0.5, L_j = 1 rad) and half into one-joint parts (a_j² = 0.5/d, ℓ_j = 0.5 rad).
    A stated assumption of the order of the residuals after geometric calibration of industrial arms (the
    real UR10 data of this package leave 0.1-0.5 mm); pass ``--model`` with a fitted discrepancy for a real one.
    """
    from pin_kpi_oed.discrepancy.kernel import JointKernel

    D = DEFAULT_DISCREPANCY
    share = D["product_share"]
    k = JointKernel(np.sqrt(share), np.full(n_joints, D["length_scale_rad"]),
                    np.full(n_joints, np.sqrt((1 - share) / n_joints)), np.full(n_joints, D["joint_length_scale_rad"]))
    return DiscrepancyPrior(k, np.full(3, D["scale_m"]), (D["white_m"] / D["scale_m"]) ** 2,
                            "default: S = 0.1 mm, white 10 um per axis, length scales 1 rad (whole configuration) "
                            "and 0.5 rad (one joint); an assumption, not a fit")


# --------------------------------------------------------------------------- the covariance and its gradient
def _prep(J, E, Kqq, Kwq, scale, w, P):
    """A = G⁻¹, U, V_a, H_a (axis-major), C = M⁻¹ and s² (matrix products only: this runs at every IPOPT step)."""
    J = np.asarray(J, float)
    E = np.asarray(E, float)
    m, _, nb = J.shape
    G = Kqq + w * np.eye(m)
    try:
        L = np.linalg.cholesky(G)
    except np.linalg.LinAlgError:
        L = np.linalg.cholesky(G + 1e-10 * np.mean(np.diag(G)) * np.eye(m))
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


# --------------------------------------------------------------------------- the criterion of configurations
def base_frame_jacobian(model, p, Q, base, with_dq):
    """Reflector Jacobian in the robot base frame over the base parameters: J (m, 3, nb) and ∂J/∂q (m, 3, nb, n)."""
    R = model.tracker_pose(p).rotation
    if with_dq:
        _, J, dJ, _ = model.jacobian_dq(p, Q)
        J = np.einsum("ba,mbp->map", R, J[:, :3, base])
        dJ = np.einsum("ba,mbpk->mapk", R, dJ[:, :3][:, :, base])
        return J, dJ
    return model.base_jacobian(p, Q, base), None


def chain_q(g: dict, dJ: np.ndarray, disc: DiscrepancyPrior, Q: np.ndarray, Qa: np.ndarray, k: int) -> np.ndarray:
    """dφ/dQ of the moving poses Q = Qa[k:] from ∂φ/∂J and ∂φ/∂G (K_QQ through both its arguments), (m, n)."""
    grad = np.einsum("iac,iack->ik", g["J"][k:], dJ)
    Gs = g["G"] + g["G"].T
    return grad + np.einsum("ij,ijk->ik", Gs[k:], disc.grad_x(Q, Qa))


@dataclass
class DiscrepancyDesignCriterion:
    """``kpi_gp`` as a function of the measurement configurations Q (the :class:`DesignCriterion` interface).

    Attributes:
        model: the measurement model (3-D tracker; linearised at ``p``).
        base: indices of the identifiable parameters.
        discrepancy: the :class:`DiscrepancyPrior`.
        Q_work: working configurations (t, n) rad.
        Q_given: poses measured before (k, n) rad (their rows count; only Q moves), or None.
        prior_info: Σ₀⁻¹ (nb, nb) or None (default: the layout's prior, :func:`prior_of`).
        p: linearisation point (raw parameters); default nominal.
        Q_register: configurations where the set-up will be registered again before the calibration is used (another
            session), or None (used in the set-up it was measured in); see :meth:`set_registration`.

    Raises:
        InputError: a 6-D probe model (the discrepancy covers positions only).
    """

    model: Any
    base: np.ndarray
    discrepancy: DiscrepancyPrior
    Q_work: np.ndarray
    Q_given: np.ndarray | None = None
    prior_info: np.ndarray | None = None
    p: np.ndarray | None = None
    Q_register: np.ndarray | None = None
    name: str = "kpi_gp"
    is_ratio: bool = True
    crit: Criterion = field(default=None, repr=False)
    #: The :class:`~pin_kpi_oed.oed.reregistration.Reregistration` when the set-up is registered again, else None.
    reg: Any = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if getattr(self.model, "nh", 3) != 3:
            raise InputError("kpi_gp: the discrepancy covers reflector positions only; a 6-D probe model is not "
                             "supported")
        if self.p is None:
            self.p = np.zeros(self.model.n_params)
        self.crit = KpiDiscrepancy()
        self.Q_work = np.atleast_2d(np.asarray(self.Q_work, float))
        R = self.model.tracker_pose(self.p).rotation
        t = self.Q_work.shape[0]
        E = self.model.kpi_jacobian(self.p, self.Q_work).reshape(t, 3, -1)[:, :, self.base]
        self.E = np.einsum("ba,tbp->tap", R, E)
        if self.prior_info is None:
            ps = prior_of(self.model, self.base)
            self.prior_info = None if ps is None else np.diag(1.0 / np.asarray(ps, float) ** 2)
        d = self.discrepancy
        self.tr_kww = float(np.trace(d.cov(self.Q_work)))
        self.Kww = d.cov(self.Q_work)
        if self.Q_given is not None and len(self.Q_given):
            self.Q_given = np.atleast_2d(np.asarray(self.Q_given, float))
            self.J_given = base_frame_jacobian(self.model, self.p, self.Q_given, self.base, False)[0]
        else:
            self.Q_given, self.J_given = None, None
        if self.Q_register is not None:
            self.set_registration(self.Q_register)

    def set_registration(self, Q_register: np.ndarray) -> None:
        """Score the TCP error after the set-up is registered again on ``Q_register`` (another session): E becomes
        the re-registered KPI Jacobian Ẽ and the registration's own covariance is added to C_s
        (:mod:`pin_kpi_oed.oed.reregistration`). Set :attr:`E` before the first call; a later call (other
        configurations) starts again from that un-registered E.

        Raises:
            InputError: configurations that do not determine the set-up.
        """
        from pin_kpi_oed.oed.reregistration import reregistration

        Q_register = np.atleast_2d(np.asarray(Q_register, float))
        setup = self.model.layout.is_setup()[self.base]
        E = self.E if self.reg is None else self.reg.E_before
        d = self.discrepancy
        self.reg = reregistration(E, self.pool_jacobians(Q_register), setup, d.scale_m, d.noise, Q_register)
        self.E = self.reg.E
        self.Q_register = Q_register

    @property
    def tr_register(self) -> float:
        """tr C_reg (m²): the registration's own error at the working configurations (0 without re-registration)."""
        return 0.0 if self.reg is None else self.reg.trace_m2

    def _all(self, Q: np.ndarray, J: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        if J is None:  # no new poses: the measured ones alone
            return self.Q_given, self.J_given
        if self.Q_given is None:
            return Q, J
        return np.vstack([self.Q_given, Q]), np.concatenate([self.J_given, J])

    def covariance(self, Q: np.ndarray) -> np.ndarray:
        """C_s (3t, 3t) m² of the measured poses (``Q_given`` + Q), base frame."""
        Qa, Ja = self._all(np.atleast_2d(Q),
                           base_frame_jacobian(self.model, self.p, np.atleast_2d(Q), self.base, False)[0])
        d = self.discrepancy
        C = kpi_gp_covariance(Ja, self.E, d.cov(Qa), d.cov(self.Q_work, Qa), self.Kww, d.scale_m, d.noise,
                              self.prior_info)
        return C if self.reg is None else C + self.reg.cov_m2

    def reregistered_covariance(self, Q: np.ndarray) -> np.ndarray:
        """C_s (3t, 3t) m² of the measured poses (``Q_given`` + Q), base frame, after re-registration in the exact
        form: the kriging error at R in the registration
        (:func:`~pin_kpi_oed.oed.reregistration.reregistered_covariance`);
        :meth:`covariance` without re-registration."""
        from pin_kpi_oed.oed.reregistration import reregistered_covariance

        Q = np.atleast_2d(Q)
        if self.reg is None:
            return self.covariance(Q)
        Qa, Ja = self._all(Q, base_frame_jacobian(self.model, self.p, Q, self.base, False)[0] if len(Q) else None)
        d, WR = self.discrepancy, np.vstack([self.Q_work, self.Q_register])
        E2 = np.concatenate([self.reg.E_before, self.pool_jacobians(self.Q_register)])
        C_WR = kpi_gp_covariance(Ja, E2, d.cov(Qa), d.cov(WR, Qa), d.cov(WR), d.scale_m, d.noise, self.prior_info)
        return reregistered_covariance(self.reg, C_WR)

    def value(self, Q: np.ndarray) -> float:
        """tr C_s (m²)."""
        Q = np.atleast_2d(Q)
        if len(Q) == 0 and self.Q_given is None:
            raise IdentifiabilityError("no poses: the parameters are not identified")
        Qa, Ja = self._all(Q, base_frame_jacobian(self.model, self.p, Q, self.base, False)[0] if len(Q) else None)
        d = self.discrepancy
        return kpi_gp_value_and_grad(Ja, self.E, d.cov(Qa), d.cov(self.Q_work, Qa), self.tr_kww, d.scale_m,
                                     d.noise, self.prior_info, grad=False)[0] + self.tr_register

    def value_and_grad(self, Q: np.ndarray) -> tuple[float, np.ndarray]:
        """tr C_s (m²) and its exact gradient w.r.t. Q (m, n) (m² per rad)."""
        Q = np.atleast_2d(np.asarray(Q, float))
        J, dJ = base_frame_jacobian(self.model, self.p, Q, self.base, True)
        Qa, Ja = self._all(Q, J)
        k = 0 if self.Q_given is None else len(self.Q_given)
        d = self.discrepancy
        val, g = kpi_gp_value_and_grad(Ja, self.E, d.cov(Qa), d.cov(self.Q_work, Qa), self.tr_kww, d.scale_m,
                                       d.noise, self.prior_info)
        grad = chain_q(g, dJ, d, Q, Qa, k)
        grad += np.einsum("ti,itk->ik", g["Kwq"][:, k:], d.grad_x(Q, self.Q_work))
        return val + self.tr_register, grad

    def pool_jacobians(self, Q_pool: np.ndarray) -> np.ndarray:
        """Base-frame Jacobians of candidate poses (N, 3, nb)."""
        return base_frame_jacobian(self.model, self.p, np.atleast_2d(Q_pool), self.base, False)[0]

    def select(self, Q_pool: np.ndarray, m: int, J_pool: np.ndarray | None = None, **kw) -> GpPoolSelection:
        """m of the candidate poses by :func:`select_pool_gp` (on top of ``Q_given``)."""
        J_pool = self.pool_jacobians(Q_pool) if J_pool is None else J_pool
        sel = select_pool_gp(J_pool, np.atleast_2d(Q_pool), self.E, self.Q_work, self.discrepancy, m,
                             self.prior_info, Q_given=self.Q_given, J_given=self.J_given, **kw)
        if self.reg is not None:
            sel.value += self.tr_register
            sel.path = sel.path + self.tr_register
        return sel


# --------------------------------------------------------------------------- pool selection
@dataclass
class GpPoolSelection:
    """Result of :func:`select_pool_gp`.

    Attributes:
        indices: chosen candidates (m,), in order of addition (after the exchange: the swapped set).
        value: tr C_s of the chosen set recomputed from scratch (m²).
        path: tr C_s after each greedy addition (m², regularised until the set identifies the parameters).
        exchanges: swaps made by the exchange passes.
        time_s: wall time (s).
    """

    indices: np.ndarray
    value: float
    path: np.ndarray
    exchanges: int
    time_s: float


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
        from scipy.linalg import solve_triangular

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
                   time_budget_s: float | None = None) -> GpPoolSelection:
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
    return GpPoolSelection(indices=idx, value=float(val), path=np.array(path), exchanges=swaps,
                           time_s=time.perf_counter() - t0)


# --------------------------------------------------------------------------- how many poses
@dataclass
class PosesNeeded:
    """Predicted TCP σ at the working configurations (discrepancy included) against the number of poses.

    Attributes:
        n: numbers of new poses (on top of the measured ones, if any).
        sigma_designed_m: σ = sqrt(tr C_s / t) of the greedy kpi_gp design of each size from the pool (m;
            the sizes are nested: the first n poses of one greedy sequence), recomputed from scratch.
        sigma_random_m: mean σ of ``n_random`` seeded random subsets of the pool of each size (m).
        sigma_random_sd_m: their standard deviation (m).
        sigma_now_m: σ of the measured poses alone (m), or None without measured poses.
        order: the greedy sequence (pool indices).
        pool_size: candidates; seed: seed of the random subsets.
        target_sigma_m: the target (m) or None; n_for_target: fewest designed poses reaching it (None: not reached
            within ``n.max()``; 0: the measured poses already reach it); plateau_m: σ with the most designed poses tried
            (what the discrepancy allows
            with this pool and budget).
    """

    n: np.ndarray
    sigma_designed_m: np.ndarray
    sigma_random_m: np.ndarray
    sigma_random_sd_m: np.ndarray
    sigma_now_m: float | None
    order: np.ndarray
    pool_size: int
    seed: int
    target_sigma_m: float | None = None
    n_for_target: int | None = None
    plateau_m: float = float("nan")
    time_s: float = 0.0

    def to_dict(self) -> dict:
        """Plain JSON-able dict (SI units)."""
        return {"n": self.n.tolist(), "sigma_designed_m": self.sigma_designed_m.tolist(),
                "sigma_random_m": self.sigma_random_m.tolist(), "sigma_random_sd_m": self.sigma_random_sd_m.tolist(),
                "sigma_now_m": self.sigma_now_m, "pool_size": self.pool_size, "seed": self.seed,
                "target_sigma_m": self.target_sigma_m, "n_for_target": self.n_for_target,
                "plateau_m": self.plateau_m, "time_s": self.time_s,
                "note": "predicted TCP sigma at the working configurations with the discrepancy (universal kriging); "
                        "designed = greedy kpi_gp sequence from the pool "
                        "(nested; the IPOPT design of one size is usually better)"
                        ", random = mean of seeded random subsets"}

    def summary(self) -> str:
        """The answer in words (µm), with the honest plateau when the target is out of reach."""
        top = int(self.n.max())
        if self.target_sigma_m is None:
            return (f"poses needed (discrepancy included): {top} designed poses reach {self.plateau_m * 1e6:.1f} um "
                    f"at the working configurations (random: {self.sigma_random_m[-1] * 1e6:.1f} um)")
        tgt = self.target_sigma_m * 1e6
        if self.n_for_target == 0:
            return (f"--target-sigma {tgt:.3g} um (discrepancy included): the measured poses already reach it "
                    f"(predicted {self.sigma_now_m * 1e6:.1f} um); no more poses are needed")
        if self.n_for_target is not None:
            return (f"--target-sigma {tgt:.3g} um (discrepancy included): {self.n_for_target} designed pose(s) "
                    f"reach it (verified by recomputing C_s); random poses of this pool: "
                    + (f"{int(self.n[np.argmax(self.sigma_random_m <= self.target_sigma_m)])}"
                       if np.any(self.sigma_random_m <= self.target_sigma_m) else f"more than {top}"))
        half = int(np.argmin(np.abs(self.n - top / 2)))
        gain = 100.0 * (1.0 - self.plateau_m / self.sigma_designed_m[half])
        return (f"--target-sigma {tgt:.3g} um is below what the discrepancy allows within {top} poses: {top} designed "
                f"poses reach only {self.plateau_m * 1e6:.1f} um, {self.plateau_m * 1e6 - tgt:.1f} um "
                f"({self.plateau_m / self.target_sigma_m:.2f}x) above the target, "
                f"and going from {int(self.n[half])} to "
                f"{top} poses lowered sigma by only {gain:.0f} %; a better model (effects) or a smaller working "
                f"region helps more than poses")


def poses_needed(crit: DiscrepancyDesignCriterion, Q_pool: np.ndarray, n_max: int, n_points: int = 12,
                 target_sigma_m: float | None = None, n_random: int = 5, seed: int = 0) -> PosesNeeded:
    """The poses-needed curve: predicted σ at the working configurations (discrepancy included) vs number of poses,
    for the greedy kpi_gp sequence and for random subsets of a feasible pool; the fewest designed poses that reach
    ``target_sigma_m``.

    Args:
        crit: the discrepancy-aware criterion (with the measured poses, if any).
        Q_pool: feasible candidate poses (N, n) rad.
        n_max: most new poses (≤ N).
        n_points: sizes of the curve (geometric grid from the smallest identifying size to ``n_max``).
        target_sigma_m: target σ (m) or None.
        n_random: random subsets per size; seed: their seed.

    Raises:
        InputError: a non-positive target, fewer candidates than ``n_max``.
    """
    t0 = time.perf_counter()
    if target_sigma_m is not None and not (target_sigma_m > 0):
        raise InputError(f"--target-sigma: must be > 0 m, got {target_sigma_m}")
    N = len(Q_pool)
    n_max = min(int(n_max), N)
    t = crit.Q_work.shape[0]
    Jp = crit.pool_jacobians(Q_pool)
    sel = crit.select(Q_pool, n_max, J_pool=Jp, exchange_passes=0)
    order = sel.indices
    nb = crit.E.shape[2]
    given = crit.Q_given is not None
    n_min = 1 if given else max(1, int(np.ceil(nb / 3)))
    grid = np.unique(np.round(np.geomspace(n_min, n_max, n_points)).astype(int))

    def sigma(idx: np.ndarray) -> float:
        try:
            return float(np.sqrt(crit.value(Q_pool[idx]) / t))
        except IdentifiabilityError:
            return float("inf")
    des = np.array([sigma(order[:k]) for k in grid])
    rng = np.random.default_rng(seed)
    rs = np.array([[sigma(rng.choice(N, k, replace=False)) for _ in range(n_random)] for k in grid])
    rs = np.where(np.isfinite(rs), rs, np.nan)
    now = None
    if given:
        try:
            now = float(np.sqrt(crit.value(np.zeros((0, Q_pool.shape[1]))) / t))
        except IdentifiabilityError:
            now = float("inf")
    out = PosesNeeded(n=grid, sigma_designed_m=des, sigma_random_m=np.nanmean(rs, axis=1),
                      sigma_random_sd_m=np.nanstd(rs, axis=1), sigma_now_m=now, order=order, pool_size=N, seed=seed,
                      target_sigma_m=target_sigma_m, plateau_m=float(des[-1]))
    if target_sigma_m is not None and now is not None and now <= target_sigma_m:
        out.n_for_target = 0                                   # the measured poses already reach it
    elif target_sigma_m is not None:
        path = np.sqrt(np.maximum(sel.path, 0) / t)
        hit = np.flatnonzero(path <= target_sigma_m)
        if hit.size:
            k = int(hit[0]) + 1
            while k <= n_max and sigma(order[:k]) > target_sigma_m * (1 + 1e-9):  # verify from scratch
                k += 1
            out.n_for_target = k if k <= n_max else None
    out.time_s = time.perf_counter() - t0
    return out
