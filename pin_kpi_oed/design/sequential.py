"""Sequential design: m more poses on top of poses already measured, and "how many more until σ ≤ X".

The information of the measured poses Q_g counts: every criterion is evaluated on the stacked
weighted Jacobian [F(Q_g); R₀; F(Q)] (eq. 24d), so C_p = (F_gᵀF_g + Σ₀⁻¹ + FᵀF)⁻¹ and C_s = E C_p Eᵀ
(eq. 19) include them; R₀ (R₀ᵀR₀ = Σ₀⁻¹) are the square-root rows of an optional prior from an earlier
calibration (:func:`prior_information`: a calibrated model file's parameter covariance). IPOPT moves
only the new poses Q (:class:`SequentialProblem`, a :class:`~pin_kpi_oed.design.optimize.DesignProblem`
whose criteria are :class:`GivenDesignCriterion`); a selection from a user pool takes F_gᵀF_g + Σ₀⁻¹
as the fixed part of its relaxation and certificate (:mod:`pin_kpi_oed.design.user_pool`).

:func:`poses_until` answers "how many more poses until the predicted TCP σ = sqrt(tr C_s / t) at the
working configurations is ≤ X": a greedy sequential design over a feasible pool (each step adds the
candidate that lowers tr(C_s) most, rank-nh Woodbury updates for all candidates at once), stopped
at the first count that reaches X; the answer is then verified by recomputing C_s from scratch (the
KPI criterion on the stacked Jacobian of measured + chosen poses, no Woodbury updates).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from pin_kpi_oed.cell.cell import Cell
from pin_kpi_oed.design.optimize import DesignProblem
from pin_kpi_oed.errors import IdentifiabilityError, InputError
from pin_kpi_oed.oed.covariance import prior_square_root
from pin_kpi_oed.oed.criteria import Criterion
from pin_kpi_oed.oed.objective import DesignCriterion, information_criterion
from pin_kpi_oed.results import Result


def prior_information(problem: DesignProblem, names: list[str], covariance: np.ndarray, source: str = "prior"
                      ) -> np.ndarray:
    """Prior information Σ₀⁻¹ over the problem's identifiable parameters from an earlier calibration.

    The covariance of the parameters (matched by name, e.g. ``joint_a2.tx``) is marginalised to the
    identifiable robot parameters it contains and inverted there (pseudo-inverse); set-up parameters
    (tracker, reflector) get no prior: a new measurement set-up is placed anew.

    Args:
        problem: the design problem (its layout and identifiable set).
        names: parameter names of the covariance.
        covariance: (k, k) in m², rad² (as the model file stores it).
        source: the file, for messages.

    Returns:
        (nb, nb) information (1/m², 1/rad²), zero where no prior.

    Raises:
        InputError: a covariance that does not match its names, or no identifiable robot parameter in it.
    """
    cov = np.asarray(covariance, float)
    if cov.ndim != 2 or cov.shape != (len(names), len(names)) or not np.all(np.isfinite(cov)):
        raise InputError(f"{source}: parameter covariance is {cov.shape} (finite values needed) for {len(names)} names")
    layout = problem.model.layout
    setup = set(layout.setup_groups)
    here = {layout.names[i]: k for k, i in enumerate(problem.base) if layout.names[i].split(".")[0] not in setup}
    pairs = [(here[n], j) for j, n in enumerate(names) if n in here]
    if not pairs:
        raise InputError(f"{source}: its covariance names none of the identifiable robot parameters "
                         f"({', '.join(list(here)[:3])}, ...)")
    ii, jj = np.array(pairs).T
    P = np.zeros((problem.base.size, problem.base.size))
    P[np.ix_(ii, ii)] = np.linalg.pinv(cov[np.ix_(jj, jj)], rcond=1e-12, hermitian=True)
    return 0.5 * (P + P.T)


@dataclass
class GivenDesignCriterion(DesignCriterion):
    """A design criterion with the information of already measured poses (rows ``F_given``) added.

    Attributes:
        F_given: weighted Jacobian rows of the measured poses over the base parameters, (k·nh, nb).
    """

    F_given: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))

    def fixed_rows(self) -> np.ndarray:
        """The measured poses' rows (their prior rows included): φ([F_given; F(Q)]), only Q moves."""
        return self.F_given


class SequentialProblem(DesignProblem):
    """A design problem whose criteria and scores include the information of measured poses.

    Args:
        cell: the cell.
        Q_given: the measured configurations (k, n) rad.
        prior_info: prior information Σ₀⁻¹ over the identifiable parameters (nb, nb) (:func:`prior_information`),
            or None; its square-root rows are appended to the measured poses' rows.
        **kwargs: as :class:`DesignProblem`.

    Attributes:
        F_given: [F(Q_given); R₀] over the identifiable parameters.

    Raises:
        InputError: Q_given of the wrong width or outside the robot's joint limits, a prior of the wrong shape.
    """

    def __init__(self, cell: Cell, Q_given: np.ndarray, prior_info: np.ndarray | None = None, **kwargs):
        super().__init__(cell, **kwargs)
        Q_given = np.atleast_2d(np.asarray(Q_given, float))
        if Q_given.shape[1] != self.n:
            raise InputError(f"Q_given: expected {self.n} joint values per pose, got {Q_given.shape[1]}")
        self.Q_given = cell.robot.check_q(Q_given, "--given")
        F_given = self.model.weighted_jacobian(self.p0, self.Q_given)[:, :, self.base]
        self.F_measured = F_given.reshape(-1, self.base.size)
        self.prior_file: str | None = None  # the file the prior came from, for the design file
        self.set_prior(prior_info)

    def set_prior(self, prior_info: np.ndarray | None) -> None:
        """Set (or drop, None) the prior information Σ₀⁻¹ (nb, nb) of an earlier calibration.

        Raises:
            InputError: a prior of the wrong shape.
        """
        F = self.F_measured
        self.prior_info = None
        if prior_info is not None:
            if np.shape(prior_info) != (self.base.size, self.base.size):
                raise InputError(f"prior information must be {self.base.size}x{self.base.size}, "
                                 f"got {np.shape(prior_info)}")
            self.prior_info = np.asarray(prior_info, float)
            F = np.vstack([F, prior_square_root(self.prior_info)])
        self.F_given = F
        self.kpi_criterion = self.information_objective(information_criterion("kpi"))
        self._param = self.information_objective(information_criterion("param"))

    def fixed_information(self) -> np.ndarray | None:
        """The measured poses' information F_gᵀF_g (their prior rows included) plus the layout's prior, (nb, nb)."""
        M0 = self.F_given.T @ self.F_given
        P = super().fixed_information()
        return M0 if P is None else M0 + P

    def information_objective(self, crit: Criterion) -> GivenDesignCriterion:
        """A criterion of the information matrix with the measured poses' information."""
        return GivenDesignCriterion(self.model, self.base, crit, self.E, F_given=self.F_given)

    def identifies(self) -> bool:
        """Whether the measured poses alone identify the base parameters."""
        return bool(np.linalg.matrix_rank(self.F_given) == self.base.size) if self.F_given.size else False

    def require_identified(self, what: str = "--given") -> None:
        """Refuse a step that needs M⁻¹ of the measured poses alone (the "how many more" answer).

        Raises:
            IdentifiabilityError: the measured poses do not identify the parameters (names ``what`` and how
                many poses to design first).
        """
        if not self.identifies():
            raise IdentifiabilityError(f"{what}: the measured poses do not identify the parameters; design "
                                       f"at least {self.min_measurements()} more with --measurements first")

    def min_measurements(self) -> int:
        """Fewest new poses that can identify the base parameters together with the measured ones."""
        if self.identifies():
            return 1
        return max(1, int(np.ceil((self.base.size - np.linalg.matrix_rank(self.F_given)) / self.model.nh)))

    def sigma_tcp(self, Q_new: np.ndarray | None = None) -> float:
        """Predicted TCP σ = sqrt(tr C_s / t) (m) of the measured poses plus ``Q_new`` (eq. 19)."""
        t = self.cell.q_work.shape[0]
        if Q_new is None or len(Q_new) == 0:
            tr = self.kpi_criterion.crit.value(self.F_given, self.E, self.kpi_criterion.prior)
        else:
            tr = self.kpi_criterion.value(np.atleast_2d(Q_new))
        return float(np.sqrt(tr / t))


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


def poses_until(problem: SequentialProblem, target_sigma_m: float, Q_pool: np.ndarray, max_add: int = 500,
                Fp: np.ndarray | None = None) -> PosesUntil:
    """Greedy sequential design over a feasible pool until the predicted TCP σ ≤ target (see module docstring).

    Args:
        problem: the sequential problem (its measured poses must identify the parameters).
        target_sigma_m: target σ (m), > 0.
        Q_pool: feasible candidate poses (N, n) rad (random ones, or the user's ``--pool``).
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
