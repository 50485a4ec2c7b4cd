r"""Model discrepancy δ(q): a Gaussian process over the joint angles, beside the parametric robot model.

The measurement model becomes (Kennedy & O'Hagan 2001)

.. math::  y = h(p, q) + R_s\,\delta(q) + \varepsilon, \qquad
           \delta \sim \mathcal{GP}(0, S\,k(q, q')\,S), \quad \varepsilon \sim \mathcal N(0, w S^2),

with h the parametric model (geometry, effects, set-up of station s), R_s the rotation of
station s's tracker frame relative to the robot base (δ is a property of the robot, expressed in
its base frame, so it survives a moved tracker), k the :class:`~pin_kpi_oed.discrepancy.kernel.JointKernel`
and S = diag(s_x, s_y, s_z) the per-axis scale (m) of the residuals. The white term w S² holds
what repeats from pose to pose only: tracker noise and the robot's repeatability.

Separation of p and δ (confounding, Plumlee 2017): the parametric part is fitted first, exactly
as without a discrepancy, and δ is fitted to its residuals. The residuals of a least-squares fit
are orthogonal to the span of the parameter Jacobian, so δ only learns what no parameter of the
model can express, and the identified parameters are the same with or without the discrepancy
(tested). The parameter covariance is then the generalised-least-squares one under
Σ = K + w S² (:func:`gls_covariance`), larger than the noise-only one because correlated
residuals carry less information.

Hyper-parameters (k's amplitudes and length scales, w) by maximum marginal likelihood
(:mod:`~pin_kpi_oed.discrepancy.marginal`: scikit-learn's regressor's objective, evaluated on the pairs of rows;
L-BFGS-B from each deterministic start, at most ``max_iter`` iterations: more change the hyper-parameters but not the
held-out error; the starts raced on it) on a seeded subset of at most ``n_fit`` rows; the K-fold check of each start
comes from one inverse of Σ = K + wI (block inversion, no refit per fold); the posterior uses every row: exactly up to
``max_exact`` rows, above that the projected-process (DTC) approximation on ``n_inducing``
seeded inducing configurations (Titsias 2009; Rasmussen & Williams §8.3), built in chunks so a
100,000-row file needs O(n · m) time and O(m²) memory.

Posterior at configurations W (normalised units, one kernel for the three axes):

* exact:  μ = K_WQ (K_QQ + wI)⁻¹ ỹ,   v = k_WW − K_WQ (K_QQ + wI)⁻¹ K_QW;
* DTC:    A = K_ZZ + w⁻¹ K_ZQ K_QZ,  μ = w⁻¹ K_WZ A⁻¹ K_ZQ ỹ,  v = k_WW − K_WZ (K_ZZ⁻¹ − A⁻¹) K_ZW;

then δ(W) = S μ + mean, var δ = S² v, and the variance of a new measurement adds w S².
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any
from collections.abc import Sequence

import numpy as np
from scipy import linalg as sla

from pin_kpi_oed.discrepancy.arrays import decode_array, encode_array
from pin_kpi_oed.discrepancy.sandwich import row_sandwich
from pin_kpi_oed.discrepancy.base import DiscrepancyModel
from pin_kpi_oed.discrepancy.coverage import JointCoverage, joint_space_box
from pin_kpi_oed.discrepancy.kernel import JointKernel
from pin_kpi_oed.errors import InputError

__all__ = ["DiscrepancyOptions", "Discrepancy", "white_level", "grouped_folds", "NEAR_DUPLICATE_RAD", "sigma_plan"]

#: Width of the joint-angle bins of the coverage in model files written before the joint-space measure (rad).
_LEGACY_BIN_RAD = 0.05
_NBINS = int(np.ceil(2 * np.pi / _LEGACY_BIN_RAD))
JITTER = 1e-8
#: Configurations closer than this (wrapped joint-space distance, rad) are one pose measured again: they share a
#: fold of the K-fold check and count once towards the rows a Gaussian process needs.
NEAR_DUPLICATE_RAD = 0.05


@dataclass
class DiscrepancyOptions:
    """How the discrepancy is fitted.

    Attributes:
        mode: ``auto`` (fitted when there are at least ``min_rows`` measurements and the K-fold
            held-out error drops by at least ``min_gain``; otherwise a white discrepancy: the residual
            level as an independent error per row), ``on`` (always the GP), ``none`` (the paper's
            noise-only model).
        n_fit: rows for the marginal-likelihood fit of the hyper-parameters (seeded subset).
        max_exact: largest number of rows for the exact posterior; above it, DTC with ``n_inducing``.
        n_inducing: inducing configurations of the sparse posterior.
        folds: K of the K-fold held-out check.
        min_rows: fewest measurements for a GP.
        min_gain: smallest relative drop of the K-fold held-out mean error that keeps the GP.
        max_iter: iterations of the marginal-likelihood optimiser (L-BFGS-B) per start.
        restarts: extra random starts of the marginal-likelihood optimiser (scikit-learn's, drawn over the
            bounds).
        starts: the additive part's amplitude at each deterministic start; the marginal likelihood of
            this kernel has local optima (the product or the one-joint part explaining the residuals), so
            each start is fitted and the one with the smaller K-fold held-out error kept (a start far behind the
            others on the likelihood is stopped and not checked: :class:`~pin_kpi_oed.discrepancy.marginal.StartRace`).
        seed: seed of every random choice (subsets, folds, restarts).
    """

    mode: str = "auto"
    n_fit: int = 400
    max_exact: int = 3000
    n_inducing: int = 600
    folds: int = 5
    min_rows: int = 60
    min_gain: float = 0.01
    max_iter: int = 60
    restarts: int = 0
    starts: tuple = (0.1, 0.01)
    seed: int = 0

    def __post_init__(self) -> None:
        if self.mode not in ("auto", "on", "none"):
            raise InputError(f"discrepancy mode must be auto, on or none, got '{self.mode}'")
        for name in ("n_fit", "max_exact", "n_inducing", "folds", "min_rows", "max_iter"):
            if int(getattr(self, name)) < (2 if name == "folds" else 1):
                raise InputError(f"discrepancy option {name} must be a positive integer, got {getattr(self, name)}")


def grouped_folds(Q: np.ndarray, folds: int, seed: int, periodic: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """K folds that keep near-duplicate configurations together: (fold of each row (n,), number of pose groups).

    Rows within :data:`NEAR_DUPLICATE_RAD` of each other (joint-space distance of
    :func:`~pin_kpi_oed.discrepancy.coverage.joint_space_box`: wrapped for ``periodic`` joints, None: every joint;
    chained) form one group (a pose measured again, or jittered around the same pose); groups are dealt in a seeded
    random order to the fold with the fewest rows so far. A held-out row then never has its own repeat in the
    training folds, which would make the K-fold gain of a model that can fit the repeat (a Gaussian process, a
    selected effect term) look larger than on new poses. With fewer groups than ``folds``, each group is its own fold.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    W, box = joint_space_box(Q, periodic)
    n = len(W)
    pairs = cKDTree(W, boxsize=box).query_pairs(NEAR_DUPLICATE_RAD, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    n_groups, group = connected_components(graph, directed=False)
    k = min(int(folds), int(n_groups))
    sizes = np.bincount(group, minlength=n_groups)
    fold_of_group = np.empty(n_groups, int)
    load = np.zeros(k, int)
    for g in np.random.default_rng(seed).permutation(n_groups):
        f = int(np.argmin(load))
        fold_of_group[g] = f
        load[f] += sizes[g]
    return fold_of_group[group], int(n_groups)


def white_level(R: np.ndarray, n_params: int = 0, floor_m: np.ndarray | None = None) -> tuple[np.ndarray, int, float]:
    r"""Per-axis white level (m) of residuals R (n, 3) of a fit of ``n_params`` parameters, honest for a new pose.

    * **Degrees of freedom** (the 3m − p correction): a least-squares fit of p parameters to 3n residual components
      leaves E[Σ r²] = σ² (3n − p), so s_a² = Σ_i r_ia² · 3 / (3n − p) per axis (the residuals of the fitted rows
      are smaller than the error at a new pose).
    * **Small-sample uncertainty**: s² is itself uncertain (χ² with k = 3n − p degrees of freedom); the 3-D error
      of a new pose standardised by s follows 3·F(3, k), not χ²₃, so the level is widened by
      f = sqrt(3 F₀.₉₅(3, k) / χ²₃(0.95)) (1.35 at k = 6, 1.02 at k = 75): its 95 % ellipsoid holds 95 %.
    * **Floor**: never below the data's stated noise ``floor_m`` (per axis, m).

    Returns:
        (level per axis (3,) m, k, f).
    """
    from scipy.special import fdtri, gammaincinv  # scipy.stats' f.ppf and chi2.ppf, without importing it

    R = np.asarray(R, float).reshape(-1, 3)
    k = max(3 * len(R) - int(n_params), 1)
    s = np.sqrt(np.sum(R ** 2, axis=0) * 3.0 / k)
    widen = float(np.sqrt(3.0 * fdtri(3, k, 0.95) / (2.0 * gammaincinv(1.5, 0.95))))
    s = s * widen
    if floor_m is not None:
        s = np.maximum(s, np.asarray(floor_m, float))
    return np.maximum(s, 1e-12), int(k), widen


def sigma_plan(n_poses: int, n_params: int, options: DiscrepancyOptions | None = None) -> str:
    """One line: what the discrepancy fit of ``identify --discrepancy auto`` will need and how the honest σ will be
    obtained from ``n_poses`` distinct poses and a fit of ``n_params`` parameters (what ``design`` prints)."""
    opts = options or DiscrepancyOptions()
    k = 3 * int(n_poses) - int(n_params)
    if k <= 0:
        return (f"sigma at {n_poses} poses: {3 * n_poses} equations for {n_params} parameters leave no residual to "
                f"learn the error beyond the noise from; measure more than {int(np.ceil(n_params / 3))} poses")
    _, _, widen = white_level(np.zeros((int(n_poses), 3)), n_params)
    white = (f"a white level from the residuals, corrected for the {n_params} fitted parameters (3m - p = {k}) and "
             f"widened x{widen:.2f} for its small-sample uncertainty, with joint-angle errors beside it when they "
             "predict left-out poses better, plus the parameter covariance at every pose")
    if n_poses < opts.min_rows:
        return (f"sigma at {n_poses} poses: fewer than the {opts.min_rows} distinct poses a Gaussian process needs: "
                f"identify will give {white} (measure {opts.min_rows} or more for a Gaussian process)")
    return (f"sigma at {n_poses} poses: identify fits a Gaussian process over the joint angles and keeps it when its "
            f"{opts.folds}-fold held-out error (repeated poses in one fold) is at least {opts.min_gain * 100:.0f} % "
            f"lower; otherwise {white}")


def _legacy_bins(cov: Any, names: list, where: str) -> np.ndarray:
    """The per-joint bins of a model file written before the joint-space coverage (checked)."""
    if (not isinstance(cov, list) or len(cov) != len(names)
            or any(not isinstance(r, str) or len(r) != _NBINS or set(r) - {"0", "1"} for r in cov)):
        raise ValueError(f"{where}.coverage: must be {len(names)} strings of {_NBINS} '0'/'1'")
    return np.array([[c == "1" for c in r] for r in cov])


@dataclass
class Discrepancy(DiscrepancyModel):
    """A fitted discrepancy in the robot base frame (see the module docstring): the prior of
    :class:`~pin_kpi_oed.discrepancy.base.DiscrepancyModel` (``covariance``, ``prior_sigma_m``, ...) and the posterior.

    Attributes:
        kind: ``exact``, ``inducing`` (DTC) or ``white`` (no correlation: the residual level per row).
        joint_names: the robot's joints, in the order of the columns of Q.
        scale_m: S, per-axis scale (3,) m; mean_m: the residuals' mean (3,) m.
        noise: w, the white level in normalised units (variance ratio).
        kernel: the :class:`JointKernel` (None for ``white``).
        Z: training (exact) or inducing (DTC) configurations (m, d) rad.
        y: normalised training residuals (exact only), (m, 3).
        alpha: posterior weights (m, 3) (DTC: stored; exact: computed).
        Minv: DTC's K_ZZ⁻¹ − A⁻¹ (m, m).
        coverage: the training configurations' :class:`~pin_kpi_oed.discrepancy.coverage.JointCoverage`.
        n_rows: training rows; cv: the K-fold held-out check (plain numbers); decision: one line.
        param_names, param_cov, Bn: the parametric part's uncertainty under the discrepancy (universal
            kriging, :meth:`set_parametric` / :meth:`parametric_covariance`): the names of the robot
            parameters it covers, C = (Σ_a s_a⁻² F_aᵀ (K + wI)⁻¹ F_a)⁻¹ over them and the training set-ups
            (P, P), and (K + wI)⁻¹ F_a per axis (n, 3, P) (exact only; the white kind needs none);
            param_cov_ls: the least-squares covariance (Σ_a F_aᵀ F_a / (k₀ + w) s_a²)⁻¹ of a Gaussian process's
            parameters, as if its residuals were independent at their prior level (inside the coverage);
            param_stations: the training stations whose set-up columns follow the robot's (9 each: tracker pose,
            reflector), in order.
        joint_term: the joint-angle part of a white discrepancy fitted below what a Gaussian process needs
            (:class:`~pin_kpi_oed.discrepancy.joint_angle.JointAngleTerm`; ``param_cov`` is then its parameters'
            covariance), or None.
    """

    kind: str
    joint_names: list
    scale_m: np.ndarray
    mean_m: np.ndarray
    noise: float
    kernel: JointKernel | None = None
    Z: np.ndarray | None = None
    y: np.ndarray | None = None
    alpha: np.ndarray | None = None
    Minv: np.ndarray | None = None
    coverage: JointCoverage | None = None
    n_rows: int = 0
    cv: dict = field(default_factory=dict)
    decision: str = ""
    time_s: float = 0.0
    param_names: list = field(default_factory=list)
    param_cov: np.ndarray | None = None
    Bn: np.ndarray | None = None
    param_cov_ls: np.ndarray | None = None
    param_stations: list = field(default_factory=list)
    joint_term: Any = None
    _chol: Any = field(default=None, repr=False)

    # ------------------------------------------------------------------ posterior
    def _factor(self) -> Any:
        if self._chol is None and self.kind == "exact":
            K = self.kernel(self.Z) + (self.noise + JITTER) * np.eye(len(self.Z))
            self._chol = sla.cho_factor(K, lower=True, check_finite=False)
            self.alpha = sla.cho_solve(self._chol, self.y, check_finite=False)
        return self._chol

    def set_factor(self, L: np.ndarray) -> None:
        """Use L, the lower Cholesky factor of K(Z, Z) + (w + jitter) I (the K-fold check's), as the exact posterior's
        factor instead of forming it again."""
        self._chol = (L, True)
        self.alpha = sla.cho_solve(self._chol, self.y, check_finite=False)

    def predict_normalised(self, Q: np.ndarray, return_var: bool = True, chunk: int = 4000
                           ) -> tuple[np.ndarray, np.ndarray | None]:
        """Posterior mean (m, 3) and variance (m,) of δ in normalised units (variance without the white term)."""
        Q = np.atleast_2d(np.asarray(Q, float))
        m = Q.shape[0]
        if self.kind == "white":
            return np.zeros((m, 3)), (np.zeros(m) if return_var else None)
        self._factor()
        mu = np.empty((m, 3))
        var = np.empty(m) if return_var else None
        for a in range(0, m, chunk):
            W = Q[a:a + chunk]
            Kwz = self.kernel(W, self.Z)
            mu[a:a + chunk] = Kwz @ self.alpha
            if return_var:
                if self.kind == "exact":
                    V = sla.solve_triangular(self._chol[0], Kwz.T, lower=True, check_finite=False)
                    red = np.einsum("ij,ij->j", V, V)
                else:
                    red = np.einsum("ij,ij->i", Kwz @ self.Minv, Kwz)
                var[a:a + chunk] = np.maximum(self.kernel.diag(W) - red, 0.0)
        return mu, var

    def posterior_covariance(self, Q: np.ndarray) -> np.ndarray:
        """Posterior covariance of δ between the configurations Q, (m, m) in normalised units (multiply by s_a² for
        axis a; the white term not included): k(Q, Q) − k(Q, Z) (K + wI)⁻¹ k(Z, Q) (DTC: k(Q, Z) M⁻¹ k(Z, Q)). Its
        diagonal is :meth:`predict_normalised`'s variance; zeros for a white discrepancy."""
        Q = np.atleast_2d(np.asarray(Q, float))
        if self.kind == "white":
            return np.zeros((len(Q), len(Q)))
        self._factor()
        Kqz = self.kernel(Q, self.Z)
        if self.kind == "exact":
            V = sla.solve_triangular(self._chol[0], Kqz.T, lower=True, check_finite=False)
            red = V.T @ V
        else:
            red = Kqz @ self.Minv @ Kqz.T
        return self.kernel(Q) - red

    def predict(self, Q: np.ndarray, return_var: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """δ at configurations Q in the base frame: mean (m, 3) m and its variance per axis (m, 3) m².

        The variance is that of δ (posterior); :attr:`noise_var_m2` is added for a new measurement.
        """
        mu, v = self.predict_normalised(Q, return_var)
        mean = mu * self.scale_m + self.mean_m if self.kind != "white" else np.zeros_like(mu)
        var = None
        if return_var:
            var = v[:, None] * self.scale_m ** 2
        return mean, var

    def set_parametric(self, F: np.ndarray, names: list, stations: Sequence[str] = ()) -> None:
        """Store the generalised-least-squares covariance of the parameters under Σ = S²(K + wI).

        Args:
            F: Jacobian of the training rows' predictions (base frame) w.r.t. the parameters, (n, 3, P)
                (robot parameters first, named by ``names``; then the training stations' set-up parameters).
            names: the robot parameters' names (the first ``len(names)`` columns of F).
            stations: the training stations of the set-up columns, in order.
        """
        n, _, P = F.shape
        if self.kind == "exact":
            self._factor()
            Bn = np.stack([sla.cho_solve(self._chol, F[:, a, :], check_finite=False) for a in range(3)], axis=1)
            info = sum(F[:, a, :].T @ Bn[:, a, :] / self.scale_m[a] ** 2 for a in range(3))
            self.Bn = Bn
        elif self.kind == "white" and self.joint_term is not None:
            if self.joint_term.Fplus.shape != (P, 3 * n):
                raise ValueError(f"discrepancy: the joint-angle term was fitted on another Jacobian "
                                 f"{self.joint_term.Fplus.shape} than ({P}, {3 * n})")
            info = None
            self.param_cov = self.joint_term.param_cov
        elif self.kind == "white":
            info = sum(F[:, a, :].T @ F[:, a, :] / self.noise_var_m2[a] for a in range(3))
        else:
            info = None
        if info is not None:
            self.param_cov = np.linalg.pinv(0.5 * (info + info.T), rcond=1e-12, hermitian=True)
        if self.kind != "white":
            ls = sum(F[:, a, :].T @ F[:, a, :] / self.prior_sigma_m[a] ** 2 for a in range(3))
            self.param_cov_ls = np.linalg.pinv(0.5 * (ls + ls.T), rcond=1e-12, hermitian=True)
        self.param_names = list(names)
        self.param_stations = [str(x) for x in stations]

    def parametric_covariance(self, Q: np.ndarray, E: np.ndarray, inside: bool = False) -> np.ndarray:
        """(m, 3, 3) base-frame covariance (m²) of the prediction error the parametric part adds at Q.

        Outside the coverage, universal kriging: (E − K_WQ Σ⁻¹ F) C (E − K_WQ Σ⁻¹ F)ᵀ with E the Jacobian of the
        predictions at Q w.r.t. the robot parameters (base frame, (m, 3, R)), followed by a training station's
        set-up columns when the rows are that station's (zero for a re-registered one); far from the training
        rows it is E C Eᵀ. Inside the coverage
        (``inside``), E C_ls Eᵀ with the least-squares covariance :attr:`param_cov_ls`: the fitted kernel's
        universal-kriging term overcounts there (on the UR10's Series C halves, 1,387 rows, the standardised RMS
        falls to 0.49 with it), while leaving the parameters' error out makes a design of 70 poses 1.2-1.4x
        overconfident; the least-squares term is that error at its size p / 3n of the residual level.
        """
        m = len(Q)
        C = self.param_cov_ls if inside and self.param_cov_ls is not None else self.param_cov
        if C is None:
            C = self.param_cov_ls
        if C is None:
            return np.zeros((m, 3, 3))
        P = C.shape[0]
        D = np.zeros((m, 3, P))
        D[:, :, :E.shape[2]] = E
        if self.Bn is not None and C is self.param_cov:
            Kwq = self.kernel(np.atleast_2d(Q), self.Z)
            for a in range(3):
                D[:, a, :] -= Kwq @ self.Bn[:, a, :]
        return row_sandwich(D, C)

    def parametric_factor(self, Q: np.ndarray, E: np.ndarray, inside: np.ndarray) -> np.ndarray:
        """A factor A (m, 3, P) of the parametric part's covariance *between* rows: cov(row i axis a, row j axis b) =
        Σ_p A[i, a, p] A[j, b, p]; its diagonal blocks are :meth:`parametric_covariance` (``inside``: per row, (m,)
        bool, the least-squares term inside the coverage, universal kriging outside; the two terms have separate
        columns: a row inside and a row outside the coverage are uncorrelated in this part)."""
        m = len(Q)
        out = np.zeros((m, 3, 0))
        for mask, ins in ((~inside, False), (inside, True)):
            C = self.param_cov_ls if ins and self.param_cov_ls is not None else self.param_cov
            if C is None:
                C = self.param_cov_ls
            if C is None or not mask.any():
                continue
            w, U = np.linalg.eigh(0.5 * (C + C.T))
            Lc = U * np.sqrt(np.maximum(w, 0.0))
            D = np.zeros((int(mask.sum()), 3, C.shape[0]))
            D[:, :, :E.shape[2]] = E[mask]
            if self.Bn is not None and C is self.param_cov:
                Kwq = self.kernel(np.atleast_2d(Q[mask]), self.Z)
                for a in range(3):
                    D[:, a, :] -= Kwq @ self.Bn[:, a, :]
            A = np.zeros((m, 3, out.shape[2] + C.shape[0]))
            A[:, :, :out.shape[2]] = out
            A[mask, :, out.shape[2]:] = D @ Lc
            out = A
        return out

    @property
    def n_joints(self) -> int:
        """The robot's joints (the columns of Q)."""
        return len(self.joint_names)

    def extrapolation(self, Q: np.ndarray) -> np.ndarray:
        """(m,) bool: configurations outside the training's joint-space coverage
        (:class:`~pin_kpi_oed.discrepancy.coverage.JointCoverage`: the combination of the angles counts)."""
        if self.coverage is None:
            return np.zeros(len(np.atleast_2d(Q)), bool)
        return self.coverage.extrapolation(Q)

    # ------------------------------------------------------------------ plain data
    def to_dict(self) -> dict:
        """The model file's ``discrepancy`` block (SI units; arrays base64 float64)."""
        d: dict[str, Any] = {"format": "pin_kpi_oed.discrepancy/1", "kind": self.kind, "frame": "robot_base",
             "joint_names": list(self.joint_names), "scale_m": [float(v) for v in self.scale_m],
             "mean_m": [float(v) for v in self.mean_m], "noise": float(self.noise), "n_rows": int(self.n_rows),
             "cv": self.cv, "decision": self.decision}
        if self.coverage is not None:
            d["coverage"] = self.coverage.to_dict()
        if self.param_cov is not None or self.param_cov_ls is not None:
            d["parametric"] = {"param_names": list(self.param_names), "stations": list(self.param_stations)}
            if self.param_cov is not None:
                d["parametric"]["covariance"] = encode_array(self.param_cov)
            if self.param_cov_ls is not None:
                d["parametric"]["covariance_ls"] = encode_array(self.param_cov_ls)
            if self.Bn is not None:
                d["parametric"]["Bn"] = encode_array(self.Bn)
        if self.joint_term is not None:
            d["joint_angle"] = self.joint_term.to_dict()
        if self.kind != "white":
            d["kernel"] = self.kernel.to_dict()
            d["Z_rad"] = encode_array(self.Z)
            if self.kind == "exact":
                d["y"] = encode_array(self.y)
            else:
                d["alpha"] = encode_array(self.alpha)
                d["Minv"] = encode_array(self.Minv)
        return d

    @classmethod
    def from_dict(cls, d: Any, joint_names: Sequence[str], where: str = "discrepancy",
                  joint_units: Sequence[str] | None = None) -> Discrepancy:
        """Rebuild from :meth:`to_dict` output, every field checked against the robot's joints (and their units
        ``rad`` / ``m``, when given, against the kernel's linear joints: :meth:`JointKernel.check_units`).

        Raises:
            InputError: a damaged block (the field named, with ``where``).
        """
        try:
            out = cls._from_dict(d, list(joint_names), where)
            if joint_units is not None and out.kernel is not None:
                out.kernel.check_units(list(joint_units), list(joint_names), f"{where}.kernel")
            return out
        except ValueError as exc:
            raise InputError(f"{exc}") from None

    @classmethod
    def _from_dict(cls, d: Any, names: list, where: str) -> Discrepancy:
        if not isinstance(d, dict):
            raise ValueError(f"{where}: must be an object (write it with identify or diagnose)")
        if d.get("format") != "pin_kpi_oed.discrepancy/1":
            raise ValueError(f"{where}.format: {d.get('format')!r} is not 'pin_kpi_oed.discrepancy/1'")
        kind = d.get("kind")
        if kind not in ("exact", "inducing", "white"):
            raise ValueError(f"{where}.kind: {kind!r} is not exact, inducing or white")
        if list(d.get("joint_names") or []) != names:
            raise ValueError(f"{where}.joint_names: {d.get('joint_names')!r} do not match the robot's joints "
                             f"{', '.join(names)}")

        def vec3(key: str, positive: bool) -> np.ndarray:
            try:
                v = np.asarray(d.get(key), dtype=float)
            except (TypeError, ValueError):
                raise ValueError(f"{where}.{key}: must be 3 numbers (m), got {d.get(key)!r}") from None
            if v.shape != (3,) or not np.all(np.isfinite(v)) or (positive and np.any(v <= 0)):
                raise ValueError(f"{where}.{key}: must be 3 finite{' positive' if positive else ''} numbers (m), "
                                 f"got {d.get(key)!r}")
            return v
        scale, mean = vec3("scale_m", True), vec3("mean_m", False)
        noise = d.get("noise")
        if isinstance(noise, bool) or not isinstance(noise, (int, float)) or not np.isfinite(noise) or noise < 0:
            raise ValueError(f"{where}.noise: must be a non-negative number, got {noise!r}")
        cov = d.get("coverage")
        coverage = None
        if isinstance(cov, dict):
            coverage = JointCoverage.from_dict(cov, len(names), f"{where}.coverage")
        elif cov is not None:
            _legacy_bins(cov, names, where)  # checked; the joint-space measure is rebuilt from Z_rad below
        out = cls(kind, names, scale, mean, float(noise), coverage=coverage, n_rows=_file_int(d, "n_rows", where),
                  cv=_file_cv(d.get("cv"), where), decision=str(d.get("decision") or ""))
        par = d.get("parametric")
        if par is not None:
            if not isinstance(par, dict) or not isinstance(par.get("param_names"), list):
                raise ValueError(f"{where}.parametric: must hold 'param_names' and 'covariance'")
            out.param_names = _file_param_names(par["param_names"], names, where)
            if kind == "white" and par.get("Bn") is not None:
                raise ValueError(f"{where}.parametric.Bn: a white discrepancy ('kind') has no Gaussian process to "
                                 "hold it; the block was written for kind exact (was 'kind' edited?)")
            out.param_stations = [str(x) for x in (par.get("stations") or [])]
            for key, attr in (("covariance", "param_cov"), ("covariance_ls", "param_cov_ls")):
                if par.get(key) is None and (key == "covariance_ls" or par.get("covariance_ls") is not None):
                    continue
                C = decode_array(par.get(key), f"{where}.parametric.{key}", (None, None))
                if C.shape[0] != C.shape[1] or len(out.param_names) > C.shape[0]:
                    raise ValueError(f"{where}.parametric.{key}: must be square with at least one row per name")
                setattr(out, attr, C)
            P = (out.param_cov if out.param_cov is not None else out.param_cov_ls).shape[0]
            if par.get("Bn") is not None:
                out.Bn = decode_array(par["Bn"], f"{where}.parametric.Bn", (None, 3, P))
        if d.get("joint_angle") is not None:
            from pin_kpi_oed.discrepancy.joint_angle import JointAngleTerm
            if kind != "white":
                raise ValueError(f"{where}.joint_angle: only a white discrepancy ('kind') holds one")
            out.joint_term = JointAngleTerm.from_dict(d["joint_angle"], len(names), out.param_cov,
                                                      f"{where}.joint_angle")
        if kind == "white":
            _check_file_sigma(out, where)
            return out
        out.kernel = JointKernel.from_dict(d.get("kernel"), len(names), f"{where}.kernel")
        _check_file_sigma(out, where)
        out.Z = decode_array(d.get("Z_rad"), f"{where}.Z_rad", (None, len(names)))
        m = out.Z.shape[0]
        if out.Bn is not None and out.Bn.shape[0] != m:
            raise ValueError(f"{where}.parametric.Bn: {out.Bn.shape[0]} rows for {m} training configurations")
        if out.coverage is None and cov is not None:
            out.coverage = JointCoverage.from_training(out.Z)
        if kind == "exact":
            out.y = decode_array(d.get("y"), f"{where}.y", (m, 3))
        else:
            out.alpha = decode_array(d.get("alpha"), f"{where}.alpha", (m, 3))
            out.Minv = decode_array(d.get("Minv"), f"{where}.Minv", (m, m))
        return out


#: the largest per-axis sigma of a discrepancy a model file may hold (m): a robot's residual after its geometric
#: calibration is a fraction of a millimetre; 5 mm means a value written in mm (``scale_m``) or an edited kernel
FILE_SIGMA_MAX_M = 5e-3
#: the largest white level of a model file (normalised units; the fit keeps it at most 10)
FILE_NOISE_MAX = 1e3
_PARAM_KINDS = ("tx", "ty", "tz", "rx", "ry", "rz")


def kfold_rows(n: int, opts: DiscrepancyOptions) -> np.ndarray:
    """The rows of the K-fold check: all up to ``max_exact`` (exact folds); beyond, a seeded subset of ``max_exact``
    (folds of inducing posteriors over every row cost minutes on 50,000 rows and tell no more about the gain)."""
    if n <= opts.max_exact:
        return np.arange(n)
    return np.sort(np.random.default_rng(opts.seed + 7).choice(n, opts.max_exact, replace=False))


def _file_int(d: dict, key: str, where: str) -> int:
    v = d.get(key) or 0
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or v < 0 or v != int(v):
        raise ValueError(f"{where}.{key}: must be a whole number >= 0, got {v!r}")
    return int(v)


#: the range of each number of a model file's K-fold check that a verdict depends on (the check's law of T: the
#: standardised RMS and the excess kurtosis of the held-out errors; the factors the σ was widened by): a value outside
#: it is an edited or damaged file, refused naming the field
CV_RANGES = {"z_rms": (0.25, 4.0), "z_kurtosis": (-2.0, 50.0), "dof_factor": (1.0, 10.0),
             "small_sample_factor": (1.0, 10.0), "inside_95": (0.0, 1.0), "mean_with_m": (0.0, FILE_SIGMA_MAX_M),
             "mean_without_m": (0.0, 1.0), "rms_with_m": (0.0, FILE_SIGMA_MAX_M), "rms_without_m": (0.0, 1.0)}


def _file_cv(cv: Any, where: str) -> dict:
    if cv is None:
        return {}
    if not isinstance(cv, dict):
        raise ValueError(f"{where}.cv: must be an object (the K-fold check's numbers), got {cv!r:.60}")
    for key, (lo, hi) in CV_RANGES.items():
        v = cv.get(key)
        if v is None:
            continue
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or not lo <= v <= hi:
            raise ValueError(f"{where}.cv.{key}: must be a number in [{lo:g}, {hi:g}], got {v!r:.40} (was the file "
                             "edited? the check's verdict depends on it)")
    return dict(cv)


def _file_param_names(names: list, joints: list, where: str) -> list:
    known = {f"{j}.{k}" for j in joints for k in _PARAM_KINDS}
    for x in names:
        if str(x) not in known:
            raise ValueError(f"{where}.parametric.param_names: {x!r} is not a joint-placement parameter of this robot "
                             f"(JOINT.tx .. JOINT.rz of {', '.join(joints)})")
    return [str(x) for x in names]


def _check_file_sigma(disc: Discrepancy, where: str) -> None:
    if disc.noise > FILE_NOISE_MAX:
        raise ValueError(f"{where}.noise: {disc.noise:g} is more than {FILE_NOISE_MAX:g} (normalised units; the fit "
                         "keeps it at most 10); was the file edited?")
    sig = disc.prior_sigma_m
    if not np.all(np.isfinite(sig)) or np.any(sig > FILE_SIGMA_MAX_M):
        raise ValueError(f"{where}.scale_m: the discrepancy's sigma per axis {', '.join(f'{s:.3g}' for s in sig)} m is "
                         f"more than {FILE_SIGMA_MAX_M * 1e3:g} mm: scale_m is in m (and noise, kernel amplitudes "
                         "normalised); was it written in mm?")
