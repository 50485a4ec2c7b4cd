"""Sequential design: m more poses on top of poses already measured, and "how many more until σ ≤ X".

The information of the measured poses Q_g counts: every criterion is evaluated on the stacked
weighted Jacobian [F(Q_g); R₀; F(Q)] (eq. 24d), so C_p = (F_gᵀF_g + Σ₀⁻¹ + FᵀF)⁻¹ and C_s = E C_p Eᵀ
(eq. 19) include them; R₀ (R₀ᵀR₀ = Σ₀⁻¹) are the square-root rows of an optional prior from an earlier
calibration (:func:`~pin_kpi_oed.design.problem_options.prior_information`: a calibrated model file's parameter
covariance). A :class:`~pin_kpi_oed.design.optimize.DesignProblem` declared with ``Q_given`` (and ``given_prior``,
:class:`~pin_kpi_oed.design.problem_options.ProblemOptions`) takes them in every criterion
(:class:`~pin_kpi_oed.oed.objective.DesignCriterion` with ``F_given``), and IPOPT moves only the new poses Q; a
selection from a user pool takes F_gᵀF_g + Σ₀⁻¹ as the fixed part of its relaxation and certificate
(:mod:`pin_kpi_oed.design.user_pool`).

:func:`poses_until` answers "how many more poses until the predicted TCP σ = sqrt(tr C_s / t) at the
working configurations is ≤ X": a greedy sequential design over a feasible pool (each step adds the
candidate that lowers tr(C_s) most, rank-nh Woodbury updates for all candidates at once), stopped
at the first count that reaches X; the answer is then verified by recomputing C_s from scratch (the
KPI criterion on the stacked Jacobian of measured + chosen poses, no Woodbury updates).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from pin_kpi_oed.design.optimize import DesignProblem
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.results import Result

__all__ = ["PosesUntil", "poses_until"]


@dataclass(kw_only=True)
class PosesUntil(Result):
    """Answer of "how many more poses until the TCP σ ≤ target".

    Attributes:
        target_sigma_m: the target (m).
        n_more: poses to add (−1 when the pool cannot reach the target within ``max_add``).
        sigma_now_m: σ of the measured poses alone (m).
        sigma_path_m: σ after each greedy addition (m).
        sigma_verified_m: σ recomputed from scratch with the n_more chosen poses (m).
        Q_added: the chosen poses (n_more, n) rad.
    """

    target_sigma_m: float
    n_more: int
    sigma_now_m: float
    sigma_path_m: np.ndarray
    sigma_verified_m: float
    Q_added: np.ndarray

    def summary(self) -> str:
        """A readable line."""
        if self.n_more < 0:
            return (f"TCP sigma {self.sigma_now_m * 1e6:.3f} um now; {len(self.sigma_path_m)} more poses reach only "
                    f"{self.sigma_path_m[-1] * 1e6:.3f} um > target {self.target_sigma_m * 1e6:.3f} um")
        return (f"TCP sigma {self.sigma_now_m * 1e6:.3f} um now; {self.n_more} more pose(s) reach "
                f"{self.sigma_verified_m * 1e6:.3f} um <= target {self.target_sigma_m * 1e6:.3f} um "
                f"(verified by recomputing C_s with them)")


def poses_until(problem: DesignProblem, target_sigma_m: float, Q_pool: np.ndarray, max_add: int = 500,
                Fp: np.ndarray | None = None) -> PosesUntil:
    """Greedy sequential design over a feasible pool until the predicted TCP σ ≤ target (see module docstring).

    Args:
        problem: the design problem with measured poses (they must identify the parameters).
        target_sigma_m: target σ (m), > 0.
        Q_pool: feasible candidate poses (N, n) rad (random ones, or the user's pool).
        max_add: most poses to add.
        Fp: their weighted Jacobians over the identifiable parameters (N, nh, nb) if already computed.

    Returns:
        The :class:`PosesUntil` answer (``success``: target reached and verified).

    Raises:
        InputError: a non-positive target.
        IdentifiabilityError: the measured poses do not identify the parameters (a greedy step needs M⁻¹).
    """
    t0 = time.perf_counter()
    if not (target_sigma_m > 0):
        raise InputError(f"target_sigma_m: must be > 0 m, got {target_sigma_m}")
    problem.require_identified()
    t = problem.cell.q_work.shape[0]
    E = problem.E
    M = problem.fixed_information()
    if Fp is None:
        Fp = problem.model.weighted_jacobian(problem.p0, Q_pool)[:, :, problem.base]  # (N, nh, nb)
    Minv = np.linalg.inv(M)
    nh = Fp.shape[1]
    sig_now = float(np.sqrt(np.trace(E @ Minv @ E.T) / t))
    chosen: list[int] = []
    path: list[float] = []
    sig = sig_now
    avail = np.ones(Fp.shape[0], bool)
    while sig > target_sigma_m and len(chosen) < max_add and avail.any():
        A = np.einsum("iab,bc->iac", Fp, Minv)                       # F_i M⁻¹ (N, nh, nb)
        S = np.eye(nh) + np.einsum("iab,icb->iac", A, Fp)           # I + F_i M⁻¹ F_iᵀ
        B = np.einsum("kb,iab->ika", E, A)                           # E M⁻¹ F_iᵀ (N, nk, nh)
        gain = np.einsum("ika,iak->i", B, np.linalg.solve(S, np.swapaxes(B, 1, 2)))
        gain[~avail] = -np.inf
        i = int(np.argmax(gain))
        Minv = Minv - A[i].T @ np.linalg.solve(S[i], A[i])
        avail[i] = False
        chosen.append(i)
        sig = float(np.sqrt(max(np.trace(E @ Minv @ E.T), 0.0) / t))
        path.append(sig)
    Q_add = Q_pool[chosen]
    verified = problem.sigma_tcp(Q_add) if chosen else sig_now
    ok = verified <= target_sigma_m * (1 + 1e-9)
    n_more = len(chosen) if ok else -1
    return PosesUntil(target_sigma_m=float(target_sigma_m), n_more=n_more, sigma_now_m=sig_now,
                      sigma_path_m=np.array(path), sigma_verified_m=verified, Q_added=Q_add, success=bool(ok),
                      status="reached" if ok else "not reached", nit=len(chosen), time_s=time.perf_counter() - t0,
                      message="" if ok else f"the pool of {len(Q_pool)} feasible poses does not reach the target "
                                            f"within {max_add} more poses")
