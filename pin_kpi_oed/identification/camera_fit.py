r"""Identification of a robot seen through a camera: weighted least squares on the reprojection error.

For images i at configurations q_i with the board's corner pixels η_i (m, 2N) px, the camera's
:class:`~pin_kpi_oed.model.camera.CameraModel` h(p, q) and the identifiable parameters p_B (the others held at
their reference value, the convention of :func:`~pin_kpi_oed.oed.identifiability.analyse`):

.. math::

    \min_{p_B} \sum_i \rho\bigl(\|(h(p, q_i) - η_i)/σ\|^2\bigr) + \sum_{k:\,σ_{0,k}<∞} (p_k/σ_{0,k})^2,

ρ the identity (``loss='linear'``) or a robust loss of SciPy's (``'huber'``, ``'soft_l1'``, ``'cauchy'``) with its
scale in σ units; corners not detected (NaN pixels) are left out row by row. The covariance of the identified
parameters is C_p = (FᵀF + P)⁻¹ at the stated σ (eq. 19), and the σ at the TCP adds the parameters held at
nominal (:func:`~pin_kpi_oed.oed.covariance.tcp_covariances`): C_s = E_B C_p E_Bᵀ + G Σ_N Gᵀ.

The package's :class:`~pin_kpi_oed.identification.problem.ResidualModel` is not used: it is built on laser-tracker
stations (3-D position rows of a measurement set, per-station tracker poses registered in closed form, 6-D
orientation rows), while an image is 2N pixel rows whose set-up (hand-eye transform, board pose) starts from the
nominal mounting.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.camera import CameraModel
from pin_kpi_oed.oed.covariance import param_covariance, tcp_covariances
from pin_kpi_oed.results import Result
from pin_kpi_oed.threads import limit_threads

__all__ = ["CameraFit", "fit_camera", "camera_tcp_covariance"]

LOSSES = ("linear", "huber", "soft_l1", "cauchy")


@dataclass(kw_only=True)
class CameraFit(Result):
    """The result of :func:`fit_camera` (a :class:`~pin_kpi_oed.results.Result`).

    Attributes:
        p: the raw parameter vector at the solution (the held ones at their reference), (np,) m, rad, px.
        base: the identified parameters' indices; names: their names.
        covariance: C_p of the identified parameters at the stated σ, (nb, nb).
        rms_px: RMS reprojection error of the rows used (px).
        chi2_reduced: Σ r² / (rows − nb) of the weighted residual (1 when the model and σ are right).
        n_images, n_rows: images and pixel rows used.
    """

    p: np.ndarray
    base: np.ndarray
    names: list[str]
    covariance: np.ndarray
    rms_px: float
    chi2_reduced: float
    n_images: int
    n_rows: int


def _check(model: CameraModel, Q: np.ndarray, uv: np.ndarray, loss: str) -> tuple[np.ndarray, np.ndarray]:
    Q = np.atleast_2d(np.asarray(Q, float))
    uv = np.atleast_2d(np.asarray(uv, float))
    if Q.shape[1] != model.robot.nq:
        raise InputError(f"camera fit: configurations need {model.robot.nq} joint values, got {Q.shape[1]}")
    if uv.shape != (Q.shape[0], model.nh):
        raise InputError(f"camera fit: pixels must be ({Q.shape[0]}, {model.nh}) (u, v of {model.board.n} corners "
                         f"per image), got {uv.shape}")
    if not np.all(np.isfinite(Q)):
        raise InputError("camera fit: a joint value is not finite")
    if loss not in LOSSES:
        raise InputError(f"camera fit: loss '{loss}' is not one of {', '.join(LOSSES)}")
    return Q, uv


@limit_threads
def fit_camera(model: CameraModel, Q: np.ndarray, uv: np.ndarray, base: np.ndarray, p_ref: np.ndarray | None = None,
               loss: str = "linear", f_scale: float = 3.0, max_nfev: int = 100) -> CameraFit:
    """Identify the robot, the hand-eye transform and the board pose (and the intrinsics, if the model estimates
    them) from corner pixels (module docstring).

    Args:
        model: the nominal camera model (its ``sigma_px`` weights the rows; its layout's prior σ add prior rows).
        Q: joint values of the images, (m, n) rad (m for prismatic joints).
        uv: detected corner pixels, (m, 2N) px; NaN for a corner not detected.
        base: indices of the identifiable parameters (``analyse(model).base``).
        p_ref: values of the raw parameters, the start of the identified ones and the value of the held ones;
            default the nominal model (zeros).
        loss: ``linear`` (least squares) or a robust loss (``huber``, ``soft_l1``, ``cauchy``).
        f_scale: the robust loss's scale, in σ units.
        max_nfev: the solver's evaluation budget.

    Returns:
        The :class:`CameraFit`.

    Raises:
        InputError: shapes, non-finite joints, an unknown loss, or fewer pixel rows than parameters.
        IdentifiabilityError: the images do not determine the parameters.
    """
    t0 = time.perf_counter()
    Q, uv = _check(model, Q, uv, loss)
    base = np.asarray(base, int)
    p = np.zeros(model.n_params) if p_ref is None else np.asarray(p_ref, float).copy()
    rows = np.isfinite(uv).ravel()
    if rows.sum() <= base.size:
        raise InputError(f"camera fit: {int(rows.sum())} pixel rows for {base.size} parameters")
    prior = model.layout.prior_sigma[base]
    has_prior = np.isfinite(prior)
    sig = model.sigma(p, Q).ravel()[rows]
    target = uv.ravel()[rows]

    def full(x: np.ndarray) -> np.ndarray:
        q = p.copy()
        q[base] = x
        return q

    def fun(x: np.ndarray) -> np.ndarray:
        r = (model.predict(full(x), Q).ravel()[rows] - target) / sig
        return np.concatenate([r, x[has_prior] / prior[has_prior]])

    def jac(x: np.ndarray) -> np.ndarray:
        F = model.jacobian(full(x), Q)[:, :, base].reshape(-1, base.size)[rows] / sig[:, None]
        return np.vstack([F, np.eye(base.size)[has_prior] / prior[has_prior][:, None]])

    sol = least_squares(fun, p[base], jac=jac, method="trf", loss=loss, f_scale=f_scale, x_scale="jac",
                        max_nfev=max_nfev)
    p_hat = full(sol.x)
    r = fun(sol.x)[:int(rows.sum())]
    F = jac(sol.x)[:int(rows.sum())]
    names = [model.layout.names[i] for i in base]
    C = param_covariance(F, np.where(has_prior, prior, np.inf) if has_prior.any() else None, names)
    dof = max(int(rows.sum()) - base.size, 1)
    return CameraFit(p=p_hat, base=base, names=names, covariance=C, rms_px=float(np.sqrt(np.mean((r * sig) ** 2))),
                     chi2_reduced=float(r @ r / dof), n_images=Q.shape[0], n_rows=int(rows.sum()),
                     success=bool(sol.success), status="converged" if sol.success else "max_iter", nfev=sol.nfev,
                     message=f"{sol.message}; RMS {np.sqrt(np.mean((r * sig) ** 2)):.3g} px",
                     time_s=time.perf_counter() - t0)


def camera_tcp_covariance(model: CameraModel, fit: CameraFit, Q: np.ndarray, Q_work: np.ndarray,
                          held: np.ndarray | None = None, sigma_held: np.ndarray | None = None
                          ) -> tuple[np.ndarray, np.ndarray]:
    """The covariance of the TCP (the model's KPI, in its device frame) at working configurations.

    C_s = E_B C_p E_Bᵀ, plus, with ``held``, the term of the parameters held at nominal G Σ_N Gᵀ
    (:func:`~pin_kpi_oed.oed.covariance.tcp_covariances`; their prior σ are their tolerances).

    Args:
        model: the camera model; fit: its :func:`fit_camera` result.
        Q: the fit's configurations (m, n); Q_work: the working configurations (t, n).
        held: raw indices of the parameters held at nominal whose uncertainty counts (e.g.
            :func:`~pin_kpi_oed.model.tolerances.held_columns`); sigma_held: their prior σ (m, rad).

    Returns:
        (C_s (t, 3, 3) m², held part (t, 3, 3) m², zeros without ``held``).

    Raises:
        InputError: ``held`` given without ``sigma_held`` of the same length.
    """
    E = model.kpi_jacobian(fit.p, Q_work)
    t = np.atleast_2d(Q_work).shape[0]
    if held is None or len(held) == 0:
        Cs = E[:, fit.base] @ fit.covariance @ E[:, fit.base].T
        return _blocks(Cs, t), np.zeros((t, 3, 3))
    held = np.asarray(held, int)
    if sigma_held is None or len(sigma_held) != held.size:
        raise InputError("camera TCP covariance: one prior sigma per held parameter (sigma_held)")
    F = model.weighted_jacobian(fit.p, Q).reshape(-1, model.n_params)
    prior = model.layout.prior_sigma[fit.base]
    _, Cs, Ch = tcp_covariances(F[:, fit.base], F[:, held], E[:, fit.base], E[:, held], sigma_held,
                                prior if np.isfinite(prior).any() else None, fit.names)
    return _blocks(Cs, t), _blocks(Ch, t)


def _blocks(C: np.ndarray, t: int) -> np.ndarray:
    """The (3, 3) diagonal blocks of a (3t, 3t) covariance, (t, 3, 3)."""
    return np.stack([C[3 * i:3 * i + 3, 3 * i:3 * i + 3] for i in range(t)])
