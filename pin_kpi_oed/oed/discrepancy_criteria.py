r"""The parameter criteria under model discrepancy: D, A, E and the singular-value indices on the GLS information.

With the discrepancy of :mod:`pin_kpi_oed.oed.discrepancy_kpi` the reflector errors of the measured poses Q are
correlated, per base-frame axis a: Σ_a = s_a² G with G = K_QQ + wI. The generalised-least-squares (MAP) estimate
of the parameters then has the covariance M⁻¹ with the information

.. math::  M = M_0 + \Sigma_0^{-1},\qquad M_0 = \sum_a s_a^{-2} J_a^T A J_a,\qquad A = G^{-1},

(J_a the parameter Jacobian rows of axis a in the robot base frame, Σ₀⁻¹ the layout's prior; the same M as in
``kpi_gp``). Every noise-only criterion of the parameters gets its discrepancy-aware form ``<name>_gp`` on it:

==============  ===================================================  =========================================
name            φ                                                    of
==============  ===================================================  =========================================
``D_gp``        −log det M = log det of the GLS covariance            M (prior included)
``param_gp``    tr M⁻¹ (A-optimality)                                M
``E_gp``        λ_max(M⁻¹) = 1/λ_min(M)                              M
``cond_gp``     μ₁/μ_r                                               μ_i = sqrt(λ_i(M₀)): the singular values
``O1_gp``…      the observability indices O1–O5 (as ``O1``…``O5``)   of the whitened Jacobian
==============  ===================================================  =========================================

The whitened Jacobian is the stack of s_a⁻¹ L⁻¹ J_a (G = LLᵀ): its Gram matrix is M₀, so its singular values are
sqrt(λ_i(M₀)); like the noise-only indices they ignore the prior (O1's √m counts the 3m whitened rows). With
k ≡ 0 every form is the noise-only criterion with the tracker noise σ_a² = w s_a² (tested; the noise-only F is in
the tracker frame, a rotation that keeps M for an isotropic σ).

Exact gradient. Each φ is a function of a symmetric matrix (M, or M₀ for the indices) with the derivative
Γ = ∂φ/∂M: −M⁻¹ (D), −M⁻² (A), −v vᵀ/λ_min² (E, v its eigenvector), Σ_i (∂φ/∂μ_i)/(2μ_i) v_i v_iᵀ (indices:
the registered criterion's own ∂φ/∂μ). With V_a = A J_a,

* ∂φ/∂J_a = 2 s_a⁻² V_a Γ, chained with ∂J/∂q (:meth:`MeasurementModel.jacobian_dq`);
* ∂φ/∂G = −Σ_a s_a⁻² V_a Γ V_aᵀ (dA = −A dG A), chained through both arguments of K_QQ
  (:meth:`JointKernel.grad_x`).

Exact like the noise-only gradients: E where λ_min is simple, the indices where the singular values they use are.

Pool selection (:func:`select_pool_gls`): the greedy + exchange of ``kpi_gp`` (:func:`select_pool_gp`, the same
rank-one kernel updates of every candidate's conditional Jacobian rows r_a and variance g = k_S(q, q) + w), with
the D or A value of every candidate after a rank-three information update M + Σ_a r_a r_aᵀ/(g s_a²):

    −log det M − log det(D_g + R M⁻¹ Rᵀ) + log det D_g,    tr M⁻¹ − tr(W R M⁻² Rᵀ),  W = (D_g + R M⁻¹ Rᵀ)⁻¹,

D_g = g diag(s_a²) (tr(K M⁻¹ Kᵀ) with the criterion's pool matrix K in general). A criterion with a pool matrix
(:meth:`~pin_kpi_oed.oed.criteria.Criterion.pool_form`: ``param``, K = I) selects with its A form, every other
criterion with the D form (the fallback of the noise-only pool selection); the returned value is the criterion
itself, recomputed from scratch.
No equivalence-theorem certificate exists for these criteria: M is not the information of a design measure (the
kernel couples the poses), so the output says so (:func:`no_certificate`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.linalg import solve_triangular

from pin_kpi_oed.errors import IdentifiabilityError, InputError
from pin_kpi_oed.oed.covariance import prior_of
from pin_kpi_oed.oed.criteria import Criterion, DiscrepancyForm, get_criterion
from pin_kpi_oed.oed.design_objective import DesignObjective
from pin_kpi_oed.oed.objective import information_criterion
from pin_kpi_oed.oed.selection_result import PoolSelection
from pin_kpi_oed.discrepancy.cholesky import jitter_cholesky
from pin_kpi_oed.discrepancy.prior import DiscrepancyPrior
from pin_kpi_oed.oed.discrepancy_kpi import base_frame_jacobian, chain_q
from pin_kpi_oed.oed.discrepancy_pool import NO_CERTIFICATE, GlsState, after_given, greedy_ridge
from pin_kpi_oed.oed.pool_search import greedy_exchange

__all__ = ["gls_information", "gls_value_and_grad", "GlsDesignCriterion",
           "select_pool_gls", "no_certificate"]


def no_certificate(name: str) -> str:
    """The design output's line for a discrepancy-aware criterion (the wording of ``kpi_gp``)."""
    return NO_CERTIFICATE.replace("kpi_gp", name, 1)


def gls_information(J: np.ndarray, Kqq: np.ndarray, scale_m: np.ndarray, noise: float
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """M₀ = Σ_a s_a⁻² J_aᵀ G⁻¹ J_a (nb, nb), V_a = G⁻¹ J_a (3, m, nb) and s² (3,), G = K_QQ + wI.

    Args:
        J: base-frame parameter Jacobian of the measured poses (m, 3, nb); Kqq: k(Q, Q) (m, m) normalised.
        scale_m: S (3,) m; noise: w.
    """
    J = np.asarray(J, float)
    m = J.shape[0]
    G = Kqq + noise * np.eye(m)
    L = jitter_cholesky(G, what="K_QQ + wI")
    Ja = np.ascontiguousarray(np.swapaxes(J, 0, 1))                        # (3, m, nb)
    B = solve_triangular(L, np.concatenate(list(Ja), axis=1), lower=True, check_finite=False)   # L⁻¹ [J_x J_y J_z]
    V = solve_triangular(L.T, B, lower=False, check_finite=False)
    nb = J.shape[2]
    s2 = np.asarray(scale_m, float) ** 2
    Bs = B.reshape(m, 3, nb)
    M0 = np.einsum("a,mac,mad->cd", 1.0 / s2, Bs, Bs)
    return 0.5 * (M0 + M0.T), np.moveaxis(V.reshape(m, 3, nb), 1, 0), s2


def gls_value_and_grad(crit: Criterion | DiscrepancyForm, J: np.ndarray, Kqq: np.ndarray, scale_m: np.ndarray,
                       noise: float,
                       prior_info: np.ndarray | None = None, grad: bool = True) -> tuple[float, dict | None]:
    """φ of the GLS information and its gradient w.r.t. J (m, 3, nb) and G = K_QQ + wI (m, m) (module formulas).

    Returns:
        (φ, {"J": ∂φ/∂J, "G": ∂φ/∂G (entries treated as independent)} or None).
    """
    if isinstance(crit, DiscrepancyForm):
        crit = crit.base
    M0, V, s2 = gls_information(J, Kqq, scale_m, noise)
    phi, Gam = crit.value_and_grad_M(M0, None, prior_info, 3 * J.shape[0])
    if not grad:
        return phi, None
    VG = V @ Gam                                                           # (3, m, nb)
    gJ = np.stack([2.0 / s2[a] * VG[a] for a in range(3)], axis=1)
    gG = -sum(VG[a] @ V[a].T / s2[a] for a in range(3))
    return phi, {"J": gJ, "G": gG}


@dataclass
class GlsDesignCriterion(DesignObjective):
    """A criterion of the parameter information on the GLS information under the discrepancy (its ``<name>_gp``
    form), a :class:`~pin_kpi_oed.oed.objective.DesignObjective` of the measurement configurations Q.

    The attributes of :class:`~pin_kpi_oed.oed.discrepancy_kpi.DiscrepancyDesignCriterion` without the working
    configurations, plus ``criterion``: the noise-only criterion (name or instance, e.g. ``D``) or its registered
    ``_gp`` form.

    Raises:
        InputError: a 6-D probe model, or a criterion without a discrepancy-aware form.
    """

    model: Any
    base: np.ndarray
    discrepancy: DiscrepancyPrior
    criterion: Any = "D"
    Q_given: np.ndarray | None = None
    prior_info: np.ndarray | None = None
    p: np.ndarray | None = None
    crit: Any = field(default=None, repr=False)

    def __post_init__(self) -> None:
        c = get_criterion(self.criterion)
        self.form = c if isinstance(c, DiscrepancyForm) else DiscrepancyForm(information_criterion(c))
        self.crit = self.form  # name, unit, ratio: the <name>_gp form
        if getattr(self.model, "nh", 3) != 3:
            raise InputError(f"{self.name}: the discrepancy covers reflector positions only; a 6-D probe model is "
                             f"not supported")
        if self.p is None:
            self.p = np.zeros(self.model.n_params)
        if self.prior_info is None:
            ps = prior_of(self.model, self.base)
            self.prior_info = None if ps is None else np.diag(1.0 / np.asarray(ps, float) ** 2)
        if self.Q_given is not None and len(self.Q_given):
            self.Q_given = np.atleast_2d(np.asarray(self.Q_given, float))
            self.J_given = base_frame_jacobian(self.model, self.p, self.Q_given, self.base, False)[0]
        else:
            self.Q_given, self.J_given = None, None

    def _all(self, Q: np.ndarray, J: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        if J is None or len(Q) == 0:
            if self.Q_given is None:
                raise IdentifiabilityError("no poses: the parameters are not identified")
            return self.Q_given, self.J_given
        if self.Q_given is None:
            return Q, J
        return np.vstack([self.Q_given, Q]), np.concatenate([self.J_given, J])

    def value(self, Q: np.ndarray) -> float:
        """φ of the measured poses (``Q_given`` + Q)."""
        Q = np.atleast_2d(Q)
        Qa, Ja = self._all(Q, base_frame_jacobian(self.model, self.p, Q, self.base, False)[0] if len(Q) else None)
        d = self.discrepancy
        return gls_value_and_grad(self.form.base, Ja, d.covariance(Qa), d.scale_m, d.noise, self.prior_info,
                                  grad=False)[0]

    def value_and_grad(self, Q: np.ndarray) -> tuple[float, np.ndarray]:
        """φ and its exact gradient w.r.t. Q (m, n) (per rad): the Jacobian's and the kernel's parts."""
        Q = np.atleast_2d(np.asarray(Q, float))
        J, dJ = base_frame_jacobian(self.model, self.p, Q, self.base, True)
        Qa, Ja = self._all(Q, J)
        d = self.discrepancy
        val, g = gls_value_and_grad(self.form.base, Ja, d.covariance(Qa), d.scale_m, d.noise, self.prior_info)
        return val, chain_q(g, dJ, d, Q, Qa, len(Qa) - len(Q))

    def pool_jacobians(self, Q_pool: np.ndarray) -> np.ndarray:
        """Base-frame Jacobians of candidate poses (N, 3, nb)."""
        return base_frame_jacobian(self.model, self.p, np.atleast_2d(Q_pool), self.base, False)[0]

    def select(self, Q_pool: np.ndarray, m: int, seed: int = 0, J_pool: np.ndarray | None = None, **kw: Any
               ) -> PoolSelection:
        """m of the candidate poses by :func:`select_pool_gls` (on top of ``Q_given``; deterministic: ``seed``
        unused)."""
        J_pool = self.pool_jacobians(Q_pool) if J_pool is None else J_pool
        return select_pool_gls(self.form.base, J_pool, np.atleast_2d(Q_pool), self.discrepancy, m, self.prior_info,
                               Q_given=self.Q_given, J_given=self.J_given, **kw)


# --------------------------------------------------------------------------- pool selection
def select_pool_gls(crit: Criterion, J_pool: np.ndarray, Q_pool: np.ndarray, discrepancy: DiscrepancyPrior, m: int,
                    prior_info: np.ndarray | None = None, Q_given: np.ndarray | None = None,
                    J_given: np.ndarray | None = None, exchange_passes: int = 1,
                    time_budget_s: float | None = None) -> PoolSelection:
    """Choose m of N candidate poses for a discrepancy-aware parameter criterion (greedy + exchange).

    The one pool selector (:func:`~pin_kpi_oed.oed.pool_search.greedy_exchange`) on
    :class:`~pin_kpi_oed.oed.discrepancy_pool.GlsState`: the A form tr(K M⁻¹ Kᵀ) when the criterion has a pool
    matrix K (:meth:`~pin_kpi_oed.oed.criteria.Criterion.pool_form`; ``param``: K = I), else the D form (module
    formulas); ``path`` holds the form's values (regularised by the same tiny ridge until the set identifies the
    parameters), ``value`` the criterion ``crit`` of the chosen set recomputed from scratch.

    Args:
        crit: the noise-only criterion (e.g. ``get_criterion('D')``).
        J_pool: candidates' base-frame Jacobians (N, 3, nb); Q_pool: their configurations (N, n) rad.
        discrepancy: the :class:`DiscrepancyPrior`; m: poses to choose (≤ N); prior_info: Σ₀⁻¹ or None.
        Q_given, J_given: poses measured before and their Jacobians (always in the set), or None.
        exchange_passes: passes of the exchange (0: greedy only); time_budget_s: wall-time limit of the exchange.

    Raises:
        InputError: m larger than the pool.
        IdentifiabilityError: the chosen set does not identify the parameters.
    """
    t0 = time.perf_counter()
    Jall, Qall, k0 = after_given(J_pool, Q_pool, m, J_given, Q_given)
    nb = J_pool.shape[2]
    st = GlsState(Jall, Qall, np.zeros((0, 3, nb)), np.zeros((0, Q_pool.shape[1])), discrepancy, prior_info,
                  greedy_ridge(J_pool, discrepancy))
    st.K = crit.pool_form(None, nb) if not crit.needs_kpi else None
    found = greedy_exchange(st, m, k0, exchange_passes, deadline=None if time_budget_s is None
                            else t0 + time_budget_s)
    idx, path, swaps = found.indices, found.path, found.swaps
    sel = np.concatenate([np.arange(k0), k0 + idx])
    val = gls_value_and_grad(crit, Jall[sel], discrepancy.covariance(Qall[sel]), discrepancy.scale_m, discrepancy.noise,
                             prior_info, grad=False)[0]
    return PoolSelection(indices=idx, value=float(val), path=np.array(path), nit=swaps,
                         time_s=time.perf_counter() - t0, success=True, status="selected",
                         message=f"greedy + exchange ({swaps} swaps); no certificate")
