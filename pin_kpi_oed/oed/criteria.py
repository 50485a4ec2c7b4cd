"""Design criteria φ(q_meas) and their exact gradients w.r.t. the measurement configurations.

All criteria are written *to be minimised*. With F the weighted Jacobian over
the identifiable parameters (eq. 24d), M = FᵀF + P its information matrix,
C_p = M⁻¹, E the KPI sensitivity at the working configurations (eq. 24e) and
μ₁ ≥ … ≥ μ_r the singular values of F:

==========  =====================================  ==================================
name        φ                                      meaning
==========  =====================================  ==================================
``kpi``     tr(C_s) = tr(E C_p Eᵀ)  (m²)           A on C_s: the paper's KPI criterion (eq. 24a)
``param``   tr(C_p)                                A on C_p: the paper's state of the art
``D``       −log det M                             D-optimality (eq. 10, Daney)
``E``       λ_max(C_p) = 1/λ_min(M)                E-optimality
``cond``    μ₁/μ_r                                 condition number (eq. 9)
``O1``      −log((μ₁⋯μ_r)^{1/r}/√m)                Borm–Menq O1 (eq. 8), maximised
``O2``      −log(μ_r/μ₁)                           inverse condition number
``O3``      −log μ_r                               minimum singular value
``O4``      −log(μ_r²/μ₁)                          noise amplification index (Nahvi)
``O5``      log Σ 1/μ_i                            Sun–Hollerbach O5 = 1/Σ(1/μ_i)
==========  =====================================  ==================================

Gradients: dφ/dF is closed form (e.g. −2 F M⁻¹EᵀE M⁻¹ for tr C_s, and
dμ_i = u_iᵀ dF v_i for singular-value criteria), chained with dF/dq from
:meth:`TrackerModel.weighted_jacobian_dq`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pin_kpi_oed.oed.covariance import information
from pin_kpi_oed.errors import IdentifiabilityError, InputError
from pin_kpi_oed.model.tracker import TrackerModel

CRITERIA: dict[str, str] = {
    "kpi": "A on C_s: tr of the TCP covariance (m^2) - the paper's KPI criterion",
    "param": "A on C_p: tr of the parameter covariance - the paper's state of the art",
    "D": "D-optimality: -log det(F^T F)",
    "E": "E-optimality: largest eigenvalue of C_p",
    "cond": "condition number of F",
    "O1": "observability index O1 (Borm-Menq), as -log",
    "O2": "observability index O2 (inverse condition number), as -log",
    "O3": "observability index O3 (minimum singular value), as -log",
    "O4": "observability index O4 (noise amplification, Nahvi), as -log",
    "O5": "observability index O5 (Sun-Hollerbach), as -log",
}


def criterion_from_F(name: str, F: np.ndarray, E: np.ndarray | None = None,
                     prior_sigma: np.ndarray | None = None) -> tuple[float, np.ndarray]:
    """Value φ and gradient dφ/dF of a criterion.

    Args:
        name: one of :data:`CRITERIA`.
        F: weighted Jacobian over the identifiable parameters, (rows, nb).
        E: KPI sensitivity over the same parameters, (n_s, nb) (needed by ``kpi``).
        prior_sigma: optional prior standard deviations (MAP), (nb,).

    Returns:
        (φ, dφ/dF with the shape of F).

    Raises:
        InputError: unknown criterion name.
        IdentifiabilityError: singular information matrix.
    """
    if name not in CRITERIA:
        raise InputError(f"unknown criterion '{name}' (known: {', '.join(CRITERIA)})")
    if name in ("kpi", "param", "D", "E"):
        M = information(F, prior_sigma)
        try:
            L = np.linalg.cholesky(M)
        except np.linalg.LinAlgError:
            raise IdentifiabilityError("singular information matrix: the design does not identify the "
                                       "parameters; use more or more varied configurations") from None
        Linv = np.linalg.solve(L, np.eye(M.shape[0]))
        C = Linv.T @ Linv
        if name == "kpi":
            if E is None:
                raise InputError("the kpi criterion needs the working configurations (KPI sensitivity E)")
            CE = C @ E.T
            return float(np.sum(E * CE.T)), -2.0 * F @ (CE @ CE.T)
        if name == "param":
            return float(np.trace(C)), -2.0 * F @ (C @ C)
        if name == "D":
            return float(-2.0 * np.sum(np.log(np.diag(L)))), -2.0 * F @ C
        w, V = np.linalg.eigh(M)
        v = V[:, 0]
        return float(1.0 / w[0]), -(2.0 / w[0] ** 2) * np.outer(F @ v, v)
    U, mu, Vt = np.linalg.svd(F, full_matrices=False)
    if mu[-1] <= 1e-12 * mu[0]:
        raise IdentifiabilityError("rank-deficient Jacobian: the design does not identify the parameters")
    r = mu.size
    # dφ/dμ for each criterion
    dmu = np.zeros(r)
    if name == "cond":
        val = mu[0] / mu[-1]
        dmu[0], dmu[-1] = 1.0 / mu[-1], -mu[0] / mu[-1] ** 2
    elif name == "O1":
        m_meas = F.shape[0]
        val = -(np.sum(np.log(mu)) / r - 0.5 * np.log(m_meas))
        dmu[:] = -1.0 / (r * mu)
    elif name == "O2":
        val = -(np.log(mu[-1]) - np.log(mu[0]))
        dmu[0], dmu[-1] = 1.0 / mu[0], -1.0 / mu[-1]
    elif name == "O3":
        val = -np.log(mu[-1])
        dmu[-1] = -1.0 / mu[-1]
    elif name == "O4":
        val = -(2 * np.log(mu[-1]) - np.log(mu[0]))
        dmu[0], dmu[-1] = 1.0 / mu[0], -2.0 / mu[-1]
    else:  # O5
        s = np.sum(1.0 / mu)
        val = np.log(s)
        dmu[:] = -1.0 / (mu ** 2 * s)
    return float(val), (U * dmu) @ Vt


@dataclass
class DesignCriterion:
    """A criterion as a function of the measurement configurations.

    Attributes:
        model: the measurement model (evaluated at the nominal parameters ``p``).
        base: indices of the identifiable parameters.
        name: criterion name (see :data:`CRITERIA`).
        E: KPI sensitivity over the base parameters, (3t, nb), or None.
        p: linearisation point (raw parameters); default nominal.
    """

    model: TrackerModel
    base: np.ndarray
    name: str = "kpi"
    E: np.ndarray | None = None
    p: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.p is None:
            self.p = np.zeros(self.model.n_params)
        if self.name not in CRITERIA:
            raise InputError(f"unknown criterion '{self.name}' (known: {', '.join(CRITERIA)})")
        prior = self.model.layout.prior_sigma[self.base]
        self.prior = prior if np.isfinite(prior).any() else None

    def value(self, Q: np.ndarray) -> float:
        """φ(Q) for configurations Q, (m, n) rad."""
        F = self.model.weighted_jacobian(self.p, Q)[:, :, self.base].reshape(-1, self.base.size)
        return criterion_from_F(self.name, F, self.E, self.prior)[0]

    def value_and_grad(self, Q: np.ndarray) -> tuple[float, np.ndarray]:
        """φ(Q) and dφ/dQ, (m, n)."""
        F, dF = self.model.weighted_jacobian_dq(self.p, Q)
        Fb = F[:, :, self.base]
        m, nh, nb = Fb.shape
        val, G = criterion_from_F(self.name, Fb.reshape(-1, nb), self.E, self.prior)
        grad = np.einsum("mac,mack->mk", G.reshape(m, nh, nb), dF[:, :, self.base, :])
        return val, grad


def evaluate_all(model: TrackerModel, base: np.ndarray, Q: np.ndarray, E: np.ndarray | None) -> dict[str, float]:
    """Every criterion for one design (NaN where undefined, e.g. kpi without E)."""
    F = model.weighted_jacobian(np.zeros(model.n_params), Q)[:, :, base].reshape(-1, base.size)
    prior = model.layout.prior_sigma[base]
    prior = prior if np.isfinite(prior).any() else None
    out = {}
    for name in CRITERIA:
        if name == "kpi" and E is None:
            out[name] = float("nan")
            continue
        try:
            out[name] = criterion_from_F(name, F, E, prior)[0]
        except IdentifiabilityError:
            out[name] = float("inf")
    return out
