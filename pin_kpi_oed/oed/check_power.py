r"""The check criterion: the power of a quick check to detect a change of the robot that matters at the TCP.

A calibration is checked on a few poses: the set-up s (tracker pose) is re-registered on them and the whitened
residuals z (per row and axis, divided by the model's honest σ) are tested, T = ‖z‖² against χ²(3m − k) (k set-up
parameters). A change Δθ_g of one parameter group g of the robot (a joint's offset, a joint's placement — a link —,
the tool) shifts the residuals by F_g Δθ_g minus what the registration absorbs; the test's non-centrality is

.. math::  λ_g(Δθ_g) = Δθ_g^T S_g Δθ_g,\qquad S_g = M_{gg} - M_{gs} M_{ss}^{-1} M_{sg},

the Schur complement of the information M₀ = FᵀF of the check poses on the group after the set-up. A change
*matters* by its RMS displacement of the TCP over the working configurations W, ‖E_g Δθ_g‖/√t (E_g the KPI
Jacobian's group columns; for the tool, the displacement itself). The weakest change of RMS size τ (the
tolerance, m) that the check must see has the non-centrality

.. math::  λ_g^{\min} = τ^2 μ_g,\qquad μ_g = λ_{\min}(C_g^T S_g C_g),\qquad
           C_g = U_g Λ_g^{-1/2}\ \text{from}\ A_g = E_g^T E_g / t = U_g Λ_g U_g^T,

restricted to the directions of the group that a rich set of poses tells apart from the set-up (a change that is
a set-up change — the first joint's placement, a rigid motion of the base — is a *set-up moved*, never a robot
change) and that move the TCP. The power of the test against it is P(χ'²(3m − k, τ²μ_g) > χ²_{1−α}(3m − k))
under the plain χ²; under the model's own held-out law the scaled form of :class:`CheckNull`.

The criterion maximises the smallest μ_g over the groups through a smooth maximum of 1/μ_g,

.. math::  φ(M_0) = \frac{1}{κ}\log \sum_g μ_g^{-κ},\qquad
           Γ = \frac{∂φ}{∂M_0} = -\sum_g \frac{μ_g^{-κ-1}}{\sum_h μ_h^{-κ}}\ \frac{∂μ_g}{∂M_0},

with ∂μ_g/∂M₀ from the eigenvector v of μ_g (w = C_g v, W = wwᵀ, K = M_{gs}M_{ss}^{-1}): the blocks
Γ_gg = W, Γ_gs = −WK, Γ_sg = −KᵀW, Γ_ss = KᵀWK (columns that belong to several groups add up). It is a
:class:`~pin_kpi_oed.oed.criteria.Criterion` of the information matrix over the raw parameters (set-up and every
group's columns); a design uses it through :class:`~pin_kpi_oed.oed.objective.DesignCriterion`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

from pin_kpi_oed.errors import IdentifiabilityError, InputError
from pin_kpi_oed.oed.criteria import Criterion

__all__ = ["CheckGroup", "CheckNull", "CheckPower", "check_groups", "test_threshold"]


@dataclass
class CheckGroup:
    """One parameter group of the robot a check tests.

    Attributes:
        name: readable name (``joint_a2 offset``, ``joint_a2 placement``, ``tool``).
        kind: ``offset``, ``placement`` or ``tool``.
        cols: raw parameter columns of the group.
        basis: (len(cols), r) orthonormal directions of the group the check can tell from the set-up.
        C: (len(cols), d) the TCP normalisation C_g (a change C_g u moves the TCP by ‖u‖ RMS), within ``basis``.
    """

    name: str
    kind: str
    cols: np.ndarray
    basis: np.ndarray
    C: np.ndarray


@dataclass(frozen=True)
class CheckNull:
    r"""The law of the check's statistic T when nothing changed, from the model's own held-out residuals.

    A Gaussian-process model's K-fold check states the RMS f of its standardised held-out errors and their excess
    kurtosis κ (real residuals have heavier tails than a Gaussian: on the UR10's Series C κ ≈ 0.5–1.2). The sum of
    ν whitened squares then has mean f²ν and variance 2f⁴ν(1 + κ/2), which the scaled χ² (Satterthwaite) matches:

    .. math::  T \sim f^2 c\, χ^2(ν / c),\qquad c = 1 + \max(κ, 0) / 2.

    f = 1, κ = 0 (a model without a K-fold check: white or noise-only) is the plain χ²(ν). A change of
    non-centrality λ (in the model's σ) gives T ≈ f²c χ'²(ν/c, λ / (f²c)).

    Attributes:
        factor: f, the held-out standardised RMS; kurtosis: κ.
    """

    factor: float = 1.0
    kurtosis: float = 0.0

    @property
    def scale(self) -> float:
        """f² c."""
        return self.factor ** 2 * self.spread

    @property
    def spread(self) -> float:
        """c = 1 + max(κ, 0)/2."""
        return 1.0 + max(float(self.kurtosis), 0.0) / 2.0

    def threshold(self, dof: float, alpha: float) -> float:
        """The critical value of T on ``dof`` degrees of freedom at level α (:meth:`thresholds` of one)."""
        return float(self.thresholds(np.array([float(dof)]), alpha)[0])

    def sf(self, T: float, dof: float) -> float:
        """P(T' > T) under no change (:meth:`sfs` of one)."""
        return float(self.sfs(np.array([float(T)]), np.array([float(dof)]))[0])

    def thresholds(self, dofs: np.ndarray, alpha: float) -> np.ndarray:
        """The critical value f²c·χ²_{1−α}(dof/c) of T on each number of degrees of freedom (NaN where a number is
        not positive).

        Args:
            dofs: (G,) degrees of freedom; alpha: the level.

        Returns:
            (G,) critical values of T (dimensionless).
        """
        return self.scale * np.asarray(stats.chi2.isf(alpha, np.asarray(dofs, float) / self.spread), float)

    def sfs(self, T: np.ndarray, dofs: np.ndarray) -> np.ndarray:
        """P(χ²(dof/c) > T/(f²c)) of each (T, dof) pair under no change (NaN where a dof is not positive).

        Args:
            T: (G,) statistics (dimensionless); dofs: (G,) their degrees of freedom.

        Returns:
            (G,) probabilities P(T' > T) under no change.
        """
        return np.asarray(stats.chi2.sf(np.asarray(T, float) / self.scale, np.asarray(dofs, float) / self.spread),
                          float)

    def power(self, noncentrality: float, dof: float, alpha: float) -> float:
        """The probability the test detects a change of non-centrality λ (in the model's σ)."""
        return float(self.powers(np.array([float(noncentrality)]), dof, alpha)[0])

    def powers(self, noncentralities: np.ndarray, dof: float, alpha: float) -> np.ndarray:
        """:meth:`power` of each non-centrality at once (one critical value, one χ'² survival over the array; each
        entry equals :meth:`power` of it bit for bit).

        Args:
            noncentralities: (G,) non-centralities λ (in the model's σ, dimensionless).
            dof: degrees of freedom of T; alpha: the test's level.

        Returns:
            (G,) detection probabilities.
        """
        nu = dof / self.spread
        lam = np.maximum(np.asarray(noncentralities, float) / self.scale, 1e-12)
        return np.asarray(stats.ncx2.sf(stats.chi2.isf(alpha, nu), nu, lam), float).reshape(lam.shape)


def test_threshold(dof: int, alpha: float) -> float:
    """χ²_{1−α}(dof): the test's critical value (a false alarm with probability α when σ is honest)."""
    return float(stats.chi2.isf(alpha, dof))


def check_groups(J_ref: np.ndarray, E: np.ndarray, setup: np.ndarray, joint_cols: list[np.ndarray],
                 joint_names: list[str], offset_dirs: np.ndarray, tool_cols: np.ndarray | None,
                 rtol: float = 1e-7, min_tcp: float = 1e-5) -> list[CheckGroup]:
    """The groups a check tests, from a rich reference set of poses.

    Args:
        J_ref: whitened Jacobian of a rich reference set of poses over the raw parameters, (rows, np).
        E: KPI Jacobian at the working configurations over the raw parameters, (3t, np) m per unit.
        setup: raw columns of the set-up the check re-registers.
        joint_cols: per joint, its 6 placement columns (tx, ty, tz, rx, ry, rz).
        joint_names: the joints' names.
        offset_dirs: per joint, the unit 6-vector of its offset (rotation about its axis) in its columns.
        tool_cols: the tool's (reflector's) 3 columns, or None.
        rtol: relative threshold of a direction told apart from the set-up / moving the TCP.
        min_tcp: a direction that moves the TCP by less than this per unit (m per m or per rad) does not matter
            (an offset of a joint whose axis passes through the TCP).

    Returns:
        The groups with at least one direction that is detectable and matters.
    """
    M = J_ref.T @ J_ref
    t = E.shape[0] // 3
    out = []
    cand = []
    for j, cols in enumerate(joint_cols):
        cand.append((f"{joint_names[j]} offset", "offset", cols, offset_dirs[j][:, None]))
        cand.append((f"{joint_names[j]} placement", "placement", cols, np.eye(len(cols))))
    if tool_cols is not None:
        cand.append(("tool", "tool", tool_cols, np.eye(len(tool_cols))))
    for name, kind, cols, D in cand:
        S = D.T @ schur(M, np.asarray(cols), setup) @ D
        lam, U = np.linalg.eigh(0.5 * (S + S.T))
        scale = np.trace(D.T @ M[np.ix_(cols, cols)] @ D)       # the group's information before the set-up
        keep = lam > rtol * max(scale, 1e-300)
        if not keep.any():
            continue
        B = D @ U[:, keep]                                  # detectable directions (orthonormal within D)
        A = np.eye(len(cols)) if kind == "tool" else E[:, cols].T @ E[:, cols] / t
        a, V = np.linalg.eigh(B.T @ A @ B)
        ok = a > max(rtol * a.max(), min_tcp ** 2)
        if not ok.any():
            continue
        out.append(CheckGroup(name, kind, np.asarray(cols), B, B @ (V[:, ok] / np.sqrt(a[ok]))))
    return out


def schur(M: np.ndarray, cols: np.ndarray, setup: np.ndarray) -> np.ndarray:
    """S = M_gg − M_gs M_ss⁻¹ M_sg (the group's information after the set-up is re-fitted)."""
    Mss = M[np.ix_(setup, setup)]
    Mgs = M[np.ix_(cols, setup)]
    try:
        K = np.linalg.solve(Mss, Mgs.T).T
    except np.linalg.LinAlgError:
        raise IdentifiabilityError("the check poses do not determine the set-up; use at least 3 poses spread "
                                   "over the workspace") from None
    return M[np.ix_(cols, cols)] - K @ Mgs.T


class CheckPower(Criterion):
    """The check criterion: a smooth maximum over the groups of 1/μ_g (module formulas), to be minimised.

    Args:
        setup: raw columns of the set-up the check re-registers.
        groups: the :class:`CheckGroup` s (:func:`check_groups`).
        kappa: sharpness of the smooth maximum (large: the weakest group alone).

    Raises:
        InputError: no group to check.
    """

    name, label, unit = "check", "power of a check to detect a change that matters at the TCP (1/smallest mu)", "log"
    is_ratio, needs_kpi = False, False

    def __init__(self, setup: np.ndarray, groups: list[CheckGroup], kappa: float = 8.0) -> None:
        if not groups:
            raise InputError("check criterion: no parameter group of the robot is detectable and moves the TCP")
        self.setup = np.asarray(setup, int)
        self.groups = list(groups)
        self.kappa = float(kappa)
        # index grids taken once (μ is evaluated thousands of times by a pool selection)
        cols = np.unique(np.concatenate([g.cols for g in self.groups]))
        self.ix_ss: tuple = np.ix_(self.setup, self.setup)
        self.ix_s_all: tuple = np.ix_(self.setup, cols)
        self.ix_groups: list[tuple[np.ndarray, tuple]] = [(np.searchsorted(cols, g.cols), np.ix_(g.cols, g.cols))
                                                          for g in self.groups]

    def mu(self, M0: np.ndarray) -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
        """μ_g per group (G,), the direction w_g = C_g v of each (v the eigenvector of μ_g; raw units) and the
        Cholesky factor of the set-up block M_ss.

        Raises:
            IdentifiabilityError: the poses do not determine the set-up.
        """
        Mss = M0[self.ix_ss]
        try:
            Lss = np.linalg.cholesky(Mss)
        except np.linalg.LinAlgError:
            raise IdentifiabilityError("the check poses do not determine the set-up; use at least 3 poses spread "
                                       "over the workspace") from None
        X_all = np.linalg.solve(Lss, M0[self.ix_s_all])      # L_ss⁻¹ M_sg of every group's columns at once
        mus, ws = [], []
        for g, (pos, gg) in zip(self.groups, self.ix_groups):
            X = X_all[:, pos]
            S = M0[gg] - X.T @ X
            H = g.C.T @ S @ g.C
            lam, V = np.linalg.eigh(0.5 * (H + H.T))
            mus.append(lam[0])
            ws.append(g.C @ V[:, 0])
        return np.array(mus), ws, Lss

    def _smooth_max(self, mu: np.ndarray) -> tuple[float, np.ndarray]:
        """φ = (1/κ) log Σ μ_g^{−κ} and dφ/dμ."""
        if np.any(mu <= 0):
            bad = self.groups[int(np.argmin(mu))].name
            raise IdentifiabilityError(f"the check poses cannot detect a change of {bad}")
        k = self.kappa
        lw = -k * np.log(mu)
        top = lw.max()
        s = np.exp(lw - top)
        return float((top + np.log(s.sum())) / k), -(s / s.sum()) / mu

    def value_M(self, M0: np.ndarray) -> float:
        """φ(M₀) alone (the pool selection's many evaluations)."""
        return self._smooth_max(self.mu(M0)[0])[0]

    def value_and_grad_M(self, M0: np.ndarray, E: np.ndarray | None = None, prior_info: np.ndarray | None = None,
                         rows: int = 0) -> tuple[float, np.ndarray]:
        mu, ws, Lss = self.mu(M0)
        phi, dmu = self._smooth_max(mu)
        Gam = np.zeros_like(M0)
        for g, w, d in zip(self.groups, ws, dmu):
            Mgs = M0[np.ix_(g.cols, self.setup)]
            K = np.linalg.solve(Lss.T, np.linalg.solve(Lss, Mgs.T)).T     # M_gs M_ss⁻¹
            W = d * np.outer(w, w)
            Gam[np.ix_(g.cols, g.cols)] += W
            WK = W @ K
            Gam[np.ix_(g.cols, self.setup)] -= WK
            Gam[np.ix_(self.setup, g.cols)] -= WK.T
            Gam[np.ix_(self.setup, self.setup)] += K.T @ W @ K
        return phi, Gam

    def noncentralities(self, M0: np.ndarray, tolerance_m: float) -> np.ndarray:
        """τ² μ_g per group: the test's non-centrality for the weakest change of RMS TCP size τ (m)."""
        return tolerance_m ** 2 * self.mu(M0)[0]
