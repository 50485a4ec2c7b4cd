"""Steps 4–7 of :func:`~pin_kpi_oed.identification.identify.identify`: solve, outliers, covariance, the held
parameters' term of the TCP σ."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import least_squares
from scipy.special import gammainccinv  # the χ² quantile below is scipy.stats.chi2.isf's own formula: no scipy.stats

from pin_kpi_oed.errors import IdentifiabilityError, SolverError
from pin_kpi_oed.identification.identify_options import IdentifyOptions
from pin_kpi_oed.identification.problem import ResidualModel
from pin_kpi_oed.model.tolerances import Tolerances, held_columns
from pin_kpi_oed.oed.covariance import param_covariance
from pin_kpi_oed.oed.held import HeldTerm

__all__ = ["Solution", "solve", "settle_outliers", "fit_covariance", "held_term"]


@dataclass
class Solution:
    x: np.ndarray
    sol: Any
    f_scale: float
    nit: int
    nfev: int


def _least_squares(prob: ResidualModel, x_init: np.ndarray, loss: str, f_scale: float, method: str,
                   opts: IdentifyOptions, nfev_max: int) -> Any:
    try:
        return least_squares(prob.residual, x_init, jac=prob.jacobian, method=method, loss=loss, f_scale=f_scale,
                             x_scale="jac", ftol=opts.tol, xtol=opts.tol, gtol=opts.tol, max_nfev=nfev_max)
    except (ValueError, np.linalg.LinAlgError) as exc:
        raise SolverError(f"identification failed: {str(exc).splitlines()[0]}") from None


def solve(prob: ResidualModel, opts: IdentifyOptions, plain: tuple[np.ndarray, Any] | None = None) -> Solution:
    """Step 4: Levenberg–Marquardt (or a plain fit then the robust loss), checked for divergence and reach.

    Args:
        prob: the residual model; opts: the options (``loss``, tolerances, ``max_nfev``).
        plain: (start, least-squares result) of the plain fit of this same problem (a fit with ``loss='linear'``
            and otherwise the same options: its :attr:`Solution.sol`): the robust loss starts from it instead of
            computing it again; used only when its start is this problem's start.

    Returns:
        The :class:`Solution`.

    Raises:
        SolverError: divergence, no convergence (``raise_on_failure``), or the fit does not reach the data.
    """
    nfev_max = opts.max_nfev if opts.max_nfev is not None else 50 * max(prob.nx, 1)
    x0 = prob.x0()
    lm_ok = prob.n_rows >= prob.nx
    fs, pre_iter, pre_fev = 1.0, 0, 0
    if opts.loss == "linear":
        sol = _least_squares(prob, x0, "linear", 1.0, "lm" if lm_ok else "trf", opts, nfev_max)
    else:
        if plain is not None and np.array_equal(plain[0], x0):
            first = plain[1]  # the same call on the same problem: the same result
        else:
            first = _least_squares(prob, x0, "linear", 1.0, "lm" if lm_ok else "trf", opts, nfev_max)
        if opts.f_scale is None:
            f_lin = prob.weighted_rows(first.x).ravel()
            fs = 3.0 * 1.4826 * float(np.median(np.abs(f_lin))) or 1.0
        else:
            fs = float(opts.f_scale)
        sol = _least_squares(prob, first.x, opts.loss, fs, "trf", opts, nfev_max)
        pre_iter, pre_fev = int(first.njev or 0), int(first.nfev)
    if not np.all(np.isfinite(sol.x)):
        raise SolverError("identification diverged (non-finite parameters); check the robot, joint order and units")
    if sol.status <= 0 and opts.raise_on_failure:
        raise SolverError(f"identification did not converge in {sol.nfev} evaluations (cost {sol.cost:.4g}): "
                          "check the joint order, units (m, rad) and the reflector offset, or raise max_nfev")
    rpos, _ = prob.evaluate(sol.x)
    errors = np.linalg.norm(rpos, axis=1)
    robot = prob.stations.robot
    limit = 0.01 * robot.reach() if opts.max_median_error_m is None else float(opts.max_median_error_m)
    if float(np.median(errors)) > limit:
        raise SolverError(f"the fitted model does not reach the data: median position error "
                          f"{np.median(errors) * 1e3:.4g} mm after {sol.njev or 0} iterations (limit {limit * 1e3:.3g} "
                          f"mm); check the robot model, tool frame, joint order/zero and units (m, rad)")
    return Solution(sol.x, sol, fs, pre_iter + int(sol.njev or 0), pre_fev + int(sol.nfev))


def _flag(prob: ResidualModel, x: np.ndarray, alpha: float, family_wise: bool = True
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(weighted rows, their norms, flagged rows): a row is flagged when its norm exceeds sqrt(χ²_nh(1 − α'))
    times the robust (MAD) scale of the weighted components. ``family_wise``: α' = α/m, m the number of rows, so
    that an outlier-free fit flags any row with probability about α whatever m (the test that decides whether
    outliers are there at all); otherwise α' = α per row (which rows to leave out once the robust loss is in use:
    heavy-tailed real data lose their tail rows, not only the few beyond the family-wise bound)."""
    fw = prob.weighted_rows(x)
    we = np.linalg.norm(fw, axis=1)
    s_rob = 1.4826 * float(np.median(np.abs(fw)))
    level = alpha / max(fw.shape[0], 1) if family_wise else alpha
    thr = float(np.sqrt(2.0 * gammainccinv(prob.nh / 2, level))) * max(s_rob, 1e-300)
    return fw, we, np.flatnonzero(we > thr)


def settle_outliers(prob: ResidualModel, solution: Solution, opts: IdentifyOptions, src: str
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Step 5: flag outliers; with a robust loss refit plain least squares on the inliers until the flags settle.

    Returns:
        (weighted rows (m, nh), weighted error norms (m,), outlier indices); ``solution`` and
        ``prob.mask`` are updated.
    """
    robust = opts.loss != "linear"
    fw, we, outliers = _flag(prob, solution.x, opts.outlier_alpha, family_wise=not robust)
    if not robust:
        return fw, we, outliers
    nfev_max = opts.max_nfev if opts.max_nfev is not None else 50 * max(prob.nx, 1)
    for _ in range(3):
        prob.mask = np.ones(prob.m, bool)
        prob.mask[outliers] = False
        if prob.n_rows < prob.nx:
            raise IdentifiabilityError(f"{src}: too few inliers ({int(prob.mask.sum())}) for {prob.nx} parameters")
        sol2 = _least_squares(prob, solution.x, "linear", 1.0, "lm", opts, nfev_max)
        if sol2.status <= 0 and opts.raise_on_failure:
            raise SolverError(f"the refit on the inliers did not converge in {sol2.nfev} evaluations")
        solution.x = sol2.x
        solution.nit += int(sol2.njev or 0)
        solution.nfev += int(sol2.nfev)
        fw, we, new_out = _flag(prob, solution.x, opts.outlier_alpha, family_wise=False)
        if np.array_equal(new_out, outliers):
            break
        outliers = new_out
    prob.mask = np.ones(prob.m, bool)
    prob.mask[outliers] = False
    return fw, we, outliers


def fit_covariance(prob: ResidualModel, x: np.ndarray, fw: np.ndarray, opts: IdentifyOptions
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, np.ndarray]:
    """Step 6: C = (FᵀF + P)⁻¹ (optionally × reduced χ²), standard deviations, correlations, reduced χ², and F, the
    weighted Jacobian on the rows in use (rows, nx), which :func:`held_term` reads again."""
    F = prob.jacobian_full(x)[prob.mask].reshape(-1, prob.nx)
    chi2 = float(np.sum(fw[prob.mask] ** 2))
    dof = max(F.shape[0] + prob.prior_idx.size - prob.nx, 1)
    chi2_red = chi2 / dof
    prior = np.full(prob.nx, np.inf)
    prior[prob.prior_idx] = prob.prior_sigma
    C = param_covariance(F, prior, prob.names)
    if opts.scale_covariance:
        C = C * chi2_red
    std = np.sqrt(np.clip(np.diag(C), 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = C / np.outer(std, std)
    return C, std, np.where(np.isfinite(corr), corr, 0.0), chi2_red, F


def held_term(prob: ResidualModel, x: np.ndarray, F: np.ndarray, C_unscaled: np.ndarray,
              tolerances: Tolerances | None = None) -> HeldTerm | None:
    """Step 7: the joint-placement parameters the fit held at nominal, under their tolerances, and how this fit
    absorbed them (A = C_unscaled F_Bᵀ F_N on its rows in use, :mod:`pin_kpi_oed.oed.held`): what the calibrated
    model's σ at the TCP adds for them (:func:`~pin_kpi_oed.calibrated.tcp_sigma.tcp_sigma`, which ``identify``
    states at the working configurations).

    Args:
        prob: the residual model; x: the fitted unknowns; F: its weighted Jacobian on the rows in use at ``x``,
            (rows, nx), as :func:`fit_covariance` returns it; C_unscaled: (FᵀF + P)⁻¹ before any χ² scaling;
        tolerances: the held parameters' prior (default :class:`~pin_kpi_oed.model.tolerances.Tolerances`).

    Returns:
        The :class:`HeldTerm`, or None when the fit holds no joint-placement parameter.
    """
    model = prob.stations.models[0]
    held = held_columns(model, [prob.layout.names[i] for i in prob.base])
    if not held.size:
        return None
    FN = prob.held_jacobian(x, held)[prob.mask].reshape(-1, held.size)
    return HeldTerm([model.layout.names[i] for i in held], (tolerances or Tolerances()).sigma_vector(model)[held],
                    list(prob.names), C_unscaled @ (F.T @ FN))
