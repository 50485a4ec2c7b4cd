"""Parameter covariance C_p and KPI covariance C_s (paper eqs. 19, 24c, 25).

With F₁ = Σ⁻¹ dh/dp the weighted Jacobian over the identifiable parameters
(stacked over the m measurements) and an optional Gaussian prior
P = diag(1/σ_prior²) (MAP estimate), the information matrix is

    M = F₁ᵀ F₁ + P,        C_p = M⁻¹.

The KPI s = TCP(p, q_work) (eq. 12) has sensitivity E = ds/dp (F₂ = [E, −I] in
eq. 24e, with v = (p, s)), and its covariance by linear error propagation is

    C_s = E C_p Eᵀ                                   (explicit form, Appendix)

or, from the constrained least-squares problem (13), the KKT form of eq. (19)::

    C_v = [I 0] [[F₁ᵀF₁, F₂ᵀ], [F₂, 0]]⁻¹ [I 0]ᵀ,    C_s = lower-right block of C_v.

Both are implemented; the tests check they agree. The constrained least-squares problem
(eq. 13a–13b) with F₁, F₂ of eq. 14 needs the regularity conditions (CQ) rank F₂ = n₂ and (PD)
rank [F₁; F₂] = n_v (eq. 15): (CQ) holds by construction (F₂ = [E, −I]), (PD) is what
:mod:`pin_kpi_oed.oed.identifiability` secures by choosing identifiable parameters. The Lemma
(eqs. 17–18) gives Δv = [I 0] K⁻¹ [F₁ᵀ Σ⁻¹; 0] Δη, whose covariance is eq. 19.

**Parameters held at nominal** (:func:`held_absorption`, :func:`held_covariance`, :func:`tcp_covariances`). The
raw parameters split into p = (p_B identified, p_N held at their nominal value: the ones no measurement of the
reflector determines, e.g. the last joint's offset along its axis, aliased with the reflector offset). A real
robot's p_N is not zero: it has the manufacturing tolerance prior p_N ~ N(0, Σ_N). The weighted least-squares
estimate absorbs it,

    p̂_B − p_B = A p_N + M⁻¹ F_Bᵀ ε,        A = M⁻¹ F_Bᵀ F_N,   M = F_BᵀF_B + P,

and the TCP's error s(p̂) − s(p) = E_B (p̂_B − p_B) − E_N p_N has the covariance

    C_s = E_B C_p E_Bᵀ + G Σ_N Gᵀ,        G = E_B A − E_N

(p_N and the noise independent). A depends on the measurement design only (F), E_B and E_N on the working
configurations and the TCP. At the reflector a structurally unidentifiable direction gives G = 0 (its effect is
absorbed exactly: F_N = F_B A₀ at every configuration); at a TCP away from it G ≠ 0 in general: the held term is
what no measurement of the reflector removes. For such a structural dependency A = A₀ for every design that
identifies p_B without a prior on them, so the held term does not depend on the design (its gradient with
respect to the measurement configurations is zero).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.linalg as sla

from pin_kpi_oed.errors import IdentifiabilityError

if TYPE_CHECKING:
    from pin_kpi_oed.model.tracker import TrackerModel

__all__ = ["information", "prior_of", "param_covariance", "check_pivots", "check_covariance", "singular_error",
           "weakest_direction", "MIN_SCALED_PIVOT", "covariances", "kpi_covariance", "design_covariances",
           "kpi_covariance_kkt", "prior_square_root", "held_absorption", "held_covariance", "tcp_covariances"]


def information(F: np.ndarray, prior_sigma: np.ndarray | None = None) -> np.ndarray:
    """Information matrix M = FᵀF + diag(1/σ_prior²).

    Args:
        F: weighted Jacobian, (rows, nb) or (m, nh, nb).
        prior_sigma: prior standard deviation per column (m or rad); inf = no prior.
    """
    F2 = F.reshape(-1, F.shape[-1])
    M = F2.T @ F2
    if prior_sigma is not None:
        M = M + np.diag(1.0 / np.asarray(prior_sigma, float) ** 2)
    return M


def prior_of(model: TrackerModel, base: np.ndarray) -> np.ndarray | None:
    """Prior standard deviations of the identifiable parameters from the model's layout.

    Args:
        model: the measurement model (its ``layout.prior_sigma``, m or rad, ``inf`` = no prior).
        base: indices of the identifiable parameters.

    Returns:
        (nb,) prior σ (m or rad), or None when no identifiable parameter has a prior.
    """
    prior = model.layout.prior_sigma[base]
    return prior if np.isfinite(prior).any() else None


#: the smallest pivot of a Cholesky factor of the information scaled to a unit diagonal (each parameter's information
#: relative to its own: the squared share of a parameter's effect the others leave it) from which a covariance is
#: computed; below it C_p has lost its digits (condition beyond 1e12) and would show negative eigenvalues
MIN_SCALED_PIVOT = 1e-12


def weakest_direction(M: np.ndarray, names: list[str] | None = None, where: str = "every measured pose") -> str:
    """The information's weakest direction in words: the parameters that move the measurements alike.

    The information is scaled to a unit diagonal (each parameter measured by its own effect: units and scales
    cancel); the eigenvector of its smallest eigenvalue names the parameters whose combination changes no
    measurement, with their weights.

    Args:
        M: information matrix (n, n), 1/(parameter unit)².
        names: parameter names (default ``column k``).
        where: what the rows are, for the sentence (e.g. ``every pose of the pool``).

    Returns:
        e.g. "'joint3.ty' and 'joint2.tz' move the measurements alike in every pose of the pool (the combination
        +0.71 joint3.ty -0.70 joint2.tz, each scaled to its own effect, changes them by 3e-06 of one parameter's
        effect)".
    """
    M = 0.5 * (np.asarray(M, float) + np.asarray(M, float).T)
    d = np.sqrt(np.clip(np.diag(M), 0.0, None))
    names = names or [f"column {k}" for k in range(M.shape[0])]
    if np.any(~np.isfinite(M)):
        return f"the information of {where} is not finite"
    if np.any(d <= 0.0):
        k = int(np.flatnonzero(d <= 0.0)[0])
        return f"'{names[k]}' moves no measurement in {where}"
    w, V = np.linalg.eigh(M / np.outer(d, d))
    v = V[:, 0] / np.abs(V[:, 0]).max()
    top = [k for k in np.argsort(-np.abs(v)) if abs(v[k]) >= 0.2][:4]
    combo = " ".join(f"{v[k]:+.2f} {names[k]}" for k in top)
    share = np.sqrt(max(float(w[0]), 0.0))
    size = f"{share:.1g} of one parameter's effect" if share >= 1e-8 else "less than 1e-8 of one parameter's effect"
    if len(top) == 1:
        return f"'{names[top[0]]}' barely moves the measurements in {where} (by {size})"
    who = " and ".join(f"'{names[k]}'" for k in top[:2]) + (f" (and {len(top) - 2} more)" if len(top) > 2 else "")
    return (f"{who} move the measurements alike in {where} (the combination {combo}, each scaled to its own effect, "
            f"changes them by {size})")


def check_pivots(M: np.ndarray, factor_diag: np.ndarray, names: list[str] | None = None,
                 where: str = "every measured pose") -> None:
    """Refuse an information matrix whose Cholesky factor has a scaled pivot below :data:`MIN_SCALED_PIVOT`.

    A Cholesky factor L of M (M = L Lᵀ) gives the factor of the information scaled to a unit diagonal for free:
    D⁻¹L with D = diag(M)^½, so (L_ii / d_i)² is the share of parameter i's information that the parameters before
    it leave (0 … 1; units and scales cancel).

    Args:
        M: information matrix (n, n).
        factor_diag: the diagonal of a Cholesky factor of M.
        names: parameter names, for the message.
        where: what the rows are, for the message.

    Raises:
        IdentifiabilityError: naming the parameters that move the measurements alike (:func:`weakest_direction`)
            and what to change.
    """
    d = np.diag(M)
    piv = np.asarray(factor_diag, float) ** 2 / np.where(d > 0, d, np.inf)
    if not np.all(np.isfinite(piv)) or piv.size and float(piv.min()) < MIN_SCALED_PIVOT:
        raise singular_error(M, names, where)


def singular_error(M: np.ndarray, names: list[str] | None = None, where: str = "every measured pose"
                   ) -> IdentifiabilityError:
    """The one refusal of a singular information matrix: which parameters move the measurements alike, what to do."""
    return IdentifiabilityError(f"singular information matrix: {weakest_direction(M, names, where)}; add measurement "
                                "configurations that tell them apart (spread over the joint ranges), or fix one of "
                                "them as known")


def check_covariance(C: np.ndarray, what: str = "the covariance", rtol: float = 1e-9) -> None:
    """Refuse a covariance that is no covariance: a non-finite entry or an eigenvalue below −``rtol`` × the largest
    (a number printed from it would be meaningless: a negative variance, an infinite condition).

    Args:
        C: covariance (n, n) in any unit.
        what: its name, for the message.
        rtol: the relative round-off a positive semi-definite covariance may show.

    Raises:
        IdentifiabilityError: naming the covariance and its smallest eigenvalue, and what to change.
    """
    C = np.asarray(C, float)
    if C.size == 0:
        return
    if not np.all(np.isfinite(C)):
        raise IdentifiabilityError(f"{what} is not finite: the measurements do not determine the parameters; add "
                                   "measurement configurations spread over the joint ranges")
    w = np.linalg.eigvalsh(0.5 * (C + C.T))
    if w[0] < -rtol * max(float(np.abs(w).max()), 1e-300):
        raise IdentifiabilityError(f"{what} has a negative eigenvalue ({w[0]:.3g} against the largest {w[-1]:.3g}): "
                                   "its information matrix is numerically singular; add measurement configurations "
                                   "spread over the joint ranges, or fix the parameters they do not determine")


def param_covariance(F: np.ndarray, prior_sigma: np.ndarray | None = None, names: list[str] | None = None
                     ) -> np.ndarray:
    """C_p = (FᵀF + P)⁻¹ (eq. 19 upper-left block), refused when the scaled information is singular.

    Raises:
        IdentifiabilityError: the information matrix is singular (parameters not identifiable
            from these measurements), naming the parameters that move the measurements alike
            (:func:`check_pivots`).
    """
    M = information(F, prior_sigma)
    try:
        c, low = sla.cho_factor(M)
    except (np.linalg.LinAlgError, ValueError):
        raise singular_error(M, names) from None
    check_pivots(M, np.diag(c), names)
    return sla.cho_solve((c, low), np.eye(M.shape[0]))


def covariances(F: np.ndarray, E: np.ndarray, prior_sigma: np.ndarray | None = None,
                names: list[str] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """C_p = (FᵀF + P)⁻¹ and C_s = E C_p Eᵀ, the KPI covariance by the explicit formula (eq. 19, m²).

    The one place where C_s is assembled from a design's Jacobian.

    Args:
        F: weighted Jacobian over the identifiable parameters, (rows, nb) or (m, nh, nb).
        E: KPI sensitivity ds/dp over the same parameters, (n_s, nb).
        prior_sigma: prior standard deviations (m or rad), (nb,), or None.
        names: parameter names for the error message.

    Returns:
        (C_p (nb, nb), C_s (n_s, n_s) m²).

    Raises:
        IdentifiabilityError: as :func:`param_covariance`.
    """
    C_p = param_covariance(F, prior_sigma, names)
    return C_p, E @ C_p @ E.T


def kpi_covariance(F: np.ndarray, E: np.ndarray, prior_sigma: np.ndarray | None = None) -> np.ndarray:
    """C_s = E C_p Eᵀ, the KPI covariance by the explicit formula (eq. 19, m²); see :func:`covariances`."""
    return covariances(F, E, prior_sigma)[1]


def design_covariances(model: TrackerModel, base: np.ndarray, Q_meas: np.ndarray, E: np.ndarray,
                       p: np.ndarray | None = None, names: list[str] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """C_p and C_s of measurement configurations, F and the prior taken from the model (eqs. 19, 24c–24d).

    Args:
        model: the measurement model (weighted Jacobian, ``layout.prior_sigma``).
        base: indices of the identifiable parameters.
        Q_meas: measurement configurations, (m, n) rad.
        E: KPI sensitivity over the base parameters, (n_s, nb).
        p: linearisation point (raw parameters), default nominal.
        names: base parameter names for the error message.

    Returns:
        (C_p, C_s (n_s, n_s) m²), with the model's prior (MAP) where it has one.

    Raises:
        IdentifiabilityError: the measurements do not identify the parameters.
    """
    p = np.zeros(model.n_params) if p is None else p
    F = model.weighted_jacobian(p, Q_meas)[:, :, base].reshape(-1, base.size)
    return covariances(F, E, prior_of(model, base), names)


def kpi_covariance_kkt(F: np.ndarray, E: np.ndarray, prior_sigma: np.ndarray | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
    """C_p and C_s from the KKT system of the constrained least-squares problem (eq. 19).

    Variables v = (p, s), F₁ = [F, 0], F₂ = [E, −I] (the constraint s = TCP(p, q_work)).

    Returns:
        (C_p, C_s).
    """
    F2d = F.reshape(-1, F.shape[-1])
    nb, ns = F2d.shape[1], E.shape[0]
    nv = nb + ns
    F1 = np.hstack([F2d, np.zeros((F2d.shape[0], ns))])
    F2 = np.hstack([E, -np.eye(ns)])
    H = F1.T @ F1
    if prior_sigma is not None:
        H[:nb, :nb] += np.diag(1.0 / np.asarray(prior_sigma, float) ** 2)
    K = np.block([[H, F2.T], [F2, np.zeros((ns, ns))]])
    rhs = np.vstack([np.eye(nv), np.zeros((ns, nv))])
    C_v = np.linalg.solve(K, rhs)[:nv]
    return C_v[:nb, :nb], C_v[nb:, nb:]


def prior_square_root(P: np.ndarray, rtol: float = 1e-12) -> np.ndarray:
    """Square-root rows R of a prior information matrix P = Σ₀⁻¹ (positive semi-definite): RᵀR = P.

    Appending R to a weighted Jacobian F gives [F; R]ᵀ[F; R] = FᵀF + Σ₀⁻¹, the MAP information of
    eq. 19 with a full (not only diagonal) prior covariance; directions without prior information
    (eigenvalues below ``rtol`` of the largest) get no row.

    Args:
        P: prior information, (n, n), symmetric positive semi-definite (1/m² or 1/rad²).
        rtol: relative eigenvalue threshold.

    Returns:
        (r, n) rows, r ≤ n.
    """
    P = 0.5 * (np.asarray(P, float) + np.asarray(P, float).T)
    w, V = np.linalg.eigh(P)
    keep = w > rtol * max(float(w.max(initial=0.0)), 0.0)
    return (V[:, keep] * np.sqrt(w[keep])).T


def held_absorption(F_B: np.ndarray, F_N: np.ndarray, prior_sigma: np.ndarray | None = None) -> np.ndarray:
    """A = M⁻¹ F_Bᵀ F_N: how the estimate of the identified parameters absorbs the held ones (module docstring).

    Args:
        F_B: weighted Jacobian over the identified parameters, (rows, nb) or (m, nh, nb).
        F_N: weighted Jacobian over the held parameters on the same rows, (rows, k) or (m, nh, k).
        prior_sigma: prior standard deviations of the identified parameters (MAP), (nb,), or None.

    Returns:
        (nb, k): p̂_B moves by A p_N (identified-parameter unit per held-parameter unit).

    Raises:
        IdentifiabilityError: F_B does not identify the parameters.
    """
    FB = F_B.reshape(-1, F_B.shape[-1])
    FN = F_N.reshape(-1, F_N.shape[-1])
    return param_covariance(FB, prior_sigma) @ (FB.T @ FN)


def held_covariance(E_B: np.ndarray, E_N: np.ndarray, A: np.ndarray, sigma_N: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """(G, G Σ_N Gᵀ): the KPI's error per unit held parameter G = E_B A − E_N and its covariance under the held
    parameters' prior Σ_N = diag(σ_N²) (module docstring).

    Args:
        E_B: KPI sensitivity over the identified parameters, (n_s, nb) (m per parameter unit).
        E_N: KPI sensitivity over the held parameters, (n_s, k).
        A: :func:`held_absorption`, (nb, k).
        sigma_N: the held parameters' prior standard deviations (m or rad), (k,).

    Returns:
        (G (n_s, k) m per parameter unit, covariance (n_s, n_s) m²).
    """
    G = E_B @ A - E_N
    Gs = G * np.asarray(sigma_N, float)
    return G, Gs @ Gs.T


def tcp_covariances(F_B: np.ndarray, F_N: np.ndarray, E_B: np.ndarray, E_N: np.ndarray, sigma_N: np.ndarray,
                    prior_sigma: np.ndarray | None = None, names: list[str] | None = None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """C_p, the KPI covariance C_s = E_B C_p E_Bᵀ + G Σ_N Gᵀ and its held part G Σ_N Gᵀ (module docstring, m²).

    Args:
        F_B, F_N: weighted Jacobians over the identified and the held parameters, same rows.
        E_B, E_N: KPI sensitivities over the same parameters, (n_s, nb), (n_s, k).
        sigma_N: the held parameters' prior standard deviations, (k,).
        prior_sigma: prior σ of the identified parameters, or None; names: their names for the error message.

    Returns:
        (C_p (nb, nb), C_s (n_s, n_s) m², held part (n_s, n_s) m²).

    Raises:
        IdentifiabilityError: F_B does not identify the parameters.
    """
    FB = F_B.reshape(-1, F_B.shape[-1])
    C_p = param_covariance(FB, prior_sigma, names)
    A = C_p @ (FB.T @ F_N.reshape(-1, F_N.shape[-1]))
    _, C_h = held_covariance(E_B, E_N, A, sigma_N)
    return C_p, E_B @ C_p @ E_B.T + C_h, C_h
