r"""Parameter identification from measured data (paper eqs. 5–6), with effects, stations and validation.

Identification removes the systematic error TCP(p, q) − TCP(p_true, q) ≠ 0 (eq. 2) as far as the
model can represent it; :func:`validate` measures what remains on held-out data.

Problem
-------
Given m measurements (q_i, η_i) of a :class:`~pin_kpi_oed.data.measurements.MeasurementSet`, taken
from one or more *stations* (tracker placements; the data's ``station`` column), find the
identifiable parameters x = (P_B, θ) minimising the weighted least-squares cost (eqs. 5–6)

.. math::

    \min_x \; \tfrac12 \sum_i \rho\bigl(\lVert f_i(x) \rVert^2\bigr)
      + \tfrac12 \sum_{k \in B} (P_k / \sigma^{\mathrm{prior}}_k)^2,

with the weighted residual of measurement i of station s (position rows, then orientation rows
for a 6-D probe)

.. math::

    f_i^{\mathrm{pos}} = \Sigma_i^{-1}\bigl(h_s(p_s, q_i + \Delta q_i(θ)) + \Delta y_i(θ) - η_i\bigr)
    \quad [\text{m}/\text{m}],\qquad
    f_i^{\mathrm{rot}} = \log_3\bigl(R_{\mathrm{model},i}\, R_{\mathrm{meas},i}^\top\bigr) / σ_{\mathrm{rot}}

(the result reports the opposite sign, measured − model, i.e. ``log3(R_meas R_modelᵀ)``).
``ρ`` is the identity (plain least squares, Levenberg–Marquardt, MINPACK via
:func:`scipy.optimize.least_squares` ``method='lm'``) or a robust loss (``soft_l1``,
``huber``, ``cauchy``; trust-region reflective), which bounds the pull of outliers.

* P: the robot's joint-placement errors (shared by every station), every station's tracker pose,
  and the reflector offset (shared, or per station with ``reflector_per_station``); layout and
  identifiability in :mod:`pin_kpi_oed.identification.problem`. P_B are the identifiable ones
  (:func:`pin_kpi_oed.oed.identifiability.analyse`, convention: set-up parameters kept, robot
  parameters confounded with them held nominal); the others stay at their given value.
* θ: parameters of optional *effects* (``docs/ARCHITECTURE.md``, "Effect interface"):
  joint-angle errors Δq(θ, Q, aux) and additive tracker-frame offsets Δy(θ, Q, aux), composed
  by :func:`pin_kpi_oed.effects.library.predict_with_effects`.

Jacobian (analytic, exact at any x; :class:`~pin_kpi_oed.identification.problem.ResidualModel`):
with J_h = ∂h/∂p from :meth:`~pin_kpi_oed.model.tracker.TrackerModel.jacobian` (right
Jacobians of exp6 included), (v_k, ω_k) the world twist of joint k and p the reflector in the
base frame,

.. math::

    \frac{∂f^{\mathrm{pos}}}{∂P_B} = Σ^{-1} J_h^{\mathrm{pos}},\qquad
    \frac{∂f^{\mathrm{pos}}}{∂θ} = Σ^{-1}\bigl(R_T\,[v_k + ω_k × p]_k\, \tfrac{∂Δq}{∂θ}
        + \tfrac{∂Δy}{∂θ}\bigr),

    \frac{∂f^{\mathrm{rot}}}{∂(P_B, θ)} = σ_{\mathrm{rot}}^{-1}\, J_l^{-1}(φ)\,
        \bigl[J_h^{\mathrm{rot}},\; R_T [ω_k]_k \tfrac{∂Δq}{∂θ}\bigr],

where φ = log3(R_model R_measᵀ), J_l⁻¹ the inverse left Jacobian of SO(3) and
J_h^rot the spatial angular Jacobian of the model orientation. The p-dependence of an
effect's Δy (its ``model, p`` arguments) is neglected in the Jacobian (not in f).

Steps of :func:`identify`
-------------------------
1. **Inputs** (:func:`_check_inputs`): joint columns, units, duplicates, weights; every station
   has at least 3 rows (one row is refused by name).
2. **Start** (:func:`_start`): the tracker pose of every station is unknown in practice. It is
   guessed in closed form by point-set registration (Kabsch/Umeyama, no scale) of the nominal
   forward kinematics x_i (base frame) onto the station's measured points y_i (tracker frame)::

       H = Σ_i (x_i − x̄)(y_i − ȳ)ᵀ = U S Vᵀ,   R = V diag(1, 1, det(V Uᵀ)) Uᵀ,   t = ȳ − R x̄

   and, for a 6-D probe, the probe orientation by the chordal mean
   ``R_probe = proj_SO3(Σ_i (R_T R_tool,i)ᵀ R_meas,i)``. Every station is then measured
   through a working :class:`~pin_kpi_oed.model.tracker.TrackerModel` whose nominal tracker
   pose is its guess, so the tracker parameters stay small.
3. **Parameters** (:func:`_identifiable`): the structural analysis of one station lifted to all
   (:meth:`StationLayout.lift <pin_kpi_oed.identification.problem.StationLayout.lift>`); then the
   data checks on the stacked Jacobian: enough equations, every station's rows determine its own
   set-up and add information on the robot beyond it (:func:`_check_stations`), every unknown
   determined by the data of all stations together (:func:`_data_rank_check`).
4. **Solve** (:func:`_solve`), **outliers** (:func:`_settle_outliers`), **covariance**
   (:func:`_covariance`), **TCP uncertainty**, **result**.

``IdentificationResult.model`` and ``.p`` are the first station's working model and raw
parameter vector: ``result.model.predict(result.p, Q)`` reproduces its fit (without effects);
``result.calibrated_model()`` holds every station's set-up, the geometry and the effects
(:class:`~pin_kpi_oed.identification.model_file.CalibratedModel`, the model file).

Uncertainty
-----------
C = (FᵀF + P)⁻¹ over x with F = ∂f/∂x at the solution (inlier rows) and P the prior
(:func:`pin_kpi_oed.oed.covariance.param_covariance`); optionally scaled by the reduced χ²
when the weights are only relative (unknown σ). The predicted TCP uncertainty at working
configurations is ``C_s = E C_pp Eᵀ`` (eq. 25) with E = ds/dP_B (first station's tracker
frame), reported per configuration as ``sqrt(trace C_s,i)`` (m).

Outliers: measurement i is flagged when ``‖f_i‖ > sqrt(χ²_{nh}(1 − α)) · s`` with s the
robust (MAD) scale of the weighted residual components, 1.4826 · median |f|. With a robust
loss the sequence is: plain least squares (start), robust fit (f_scale = 3 s unless given),
flag, then plain least squares on the inliers, re-flag, until the flags settle (≤ 3 rounds);
the estimate, its covariance and χ² are those of the final inlier fit (a robust loss alone
still leaves a bias of order f_scale per outlier). With the plain loss, outliers are only
flagged.

Units: SI (m, rad) everywhere; summaries print mm, µm and mrad and say so.
"""

from __future__ import annotations

import copy
import dataclasses
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import pinocchio as pin
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation
from scipy.stats import chi2 as _chi2

from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.effects.library import predict_with_effects
from pin_kpi_oed.errors import IdentifiabilityError, InputError, SolverError
from pin_kpi_oed.identification.discrepancy_fit import discrepancy_options, result_discrepancy
from pin_kpi_oed.identification.model_file import CalibratedModel, Setup
from pin_kpi_oed.identification.problem import (ResidualModel, StationLayout, StationSet, align_data,
                                                effect_param_names, jl_inv, log3)
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.model.parameters import ParameterLayout
from pin_kpi_oed.oed.covariance import param_covariance
from pin_kpi_oed.oed.identifiability import Identifiability, analyse
from pin_kpi_oed.results import Result
from pin_kpi_oed.threads import limit_threads

__all__ = [
    "ROBUST_LOSSES",
    "IdentifyOptions",
    "IdentificationResult",
    "ResidualModel",
    "identify",
    "validate",
    "format_validation",
    "predict",
    "effect_param_names",
    "register_points",
    "align_data",
    "default_station_label",
]

#: Loss functions accepted by :func:`identify` (``linear`` = plain least squares).
ROBUST_LOSSES = ("linear", "soft_l1", "huber", "cauchy")

#: Number of seeded random configurations of the structural identifiability analysis.
N_EXCITATION = 60

#: Fewest rows of a station: a rigid registration of its tracker pose needs 3 points.
MIN_STATION_ROWS = 3

_jl_inv = jl_inv  # historical names, kept for the tests and callers
_log3 = log3


def _proj_so3(M: np.ndarray) -> np.ndarray:
    """Closest rotation to a 3×3 matrix (SVD projection)."""
    U, _, Vt = np.linalg.svd(M)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
    return U @ D @ Vt


def predict(model: TrackerModel, p: np.ndarray, Q: np.ndarray, effects: Sequence[Any] = (),
            thetas: Sequence[np.ndarray] = (), aux: MeasurementSet | None = None) -> np.ndarray:
    """Model response with effects: ``Y = h(p, Q + ΣΔq) + ΣΔy`` (tracker frame).

    A thin form of :func:`pin_kpi_oed.effects.library.predict_with_effects` (the one composition).

    Returns:
        (m, 3) positions (m), or (m, 6) with the orientation rotation vector (rad) for a 6-D model.
    """
    Q = np.atleast_2d(np.asarray(Q, float))
    return predict_with_effects(model, p, Q, aux, list(zip(effects, thetas)))


def default_station_label(data: MeasurementSet) -> str:
    """Label of a data set without a station column: its file name without extension (or ``station``)."""
    return Path(data.source).stem if data.source and Path(data.source).stem else "station"


# --------------------------------------------------------------------------- #
# Registration
# --------------------------------------------------------------------------- #
def register_points(X: np.ndarray, Y: np.ndarray, w: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    r"""Closed-form rigid registration (Kabsch/Umeyama, no scale): ``Y ≈ X Rᵀ + t``.

    Minimises Σ_i w_i |y_i − (R x_i + t)|² with the SVD of the weighted cross-covariance
    H = Σ w_i (x_i − x̄)(y_i − ȳ)ᵀ = U S Vᵀ: R = V diag(1, 1, det(V Uᵀ)) Uᵀ, t = ȳ − R x̄.

    Args:
        X: points in the source frame (robot base), (m, 3) m.
        Y: the same points in the target frame (tracker), (m, 3) m.
        w: optional non-negative weights, (m,).

    Returns:
        (R (3, 3), t (3,) m).

    Raises:
        InputError: fewer than 3 points, or points (nearly) collinear.
    """
    X = np.asarray(X, float)
    Y = np.asarray(Y, float)
    if X.shape[0] < 3:
        raise InputError(f"registration needs at least 3 points, got {X.shape[0]}")
    w = np.ones(len(X)) if w is None else np.asarray(w, float)
    w = w / w.sum()
    xm, ym = w @ X, w @ Y
    H = (X - xm).T @ ((Y - ym) * w[:, None])
    U, S, Vt = np.linalg.svd(H)
    if S[1] <= 1e-9 * max(S[0], 1e-300):
        raise InputError("the measured points are (nearly) collinear: the tracker pose cannot be registered; "
                         "use configurations spread over the workspace")
    d = np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0
    R = Vt.T @ np.diag([1.0, 1.0, d]) @ U.T
    return R, ym - R @ xm


# --------------------------------------------------------------------------- #
# Options
# --------------------------------------------------------------------------- #
@dataclass
class IdentifyOptions:
    """Knobs of :func:`identify` (SI units).

    Attributes:
        p0: raw parameters of the model to start from / hold fixed entries at (default zeros).
        loss: ``linear`` (Levenberg–Marquardt), ``soft_l1``, ``huber`` or ``cauchy`` (robust,
            followed by a plain refit on the inliers; see the module docstring).
        f_scale: robust-loss scale in weighted units; default 3 × the MAD scale of a first
            plain least-squares fit.
        weights: ``auto`` (the data's sigma columns if present, else the noise model),
            ``data`` or ``noise``.
        register: guess the tracker pose (and probe orientation) by point-set registration; skipped
            for the tracker (probe) when one of its parameters is fixed or has a prior, so that
            these refer to ``model.tracker_T_base`` (``model.probe_R``) (one station only).
        use_orientation: use the rx, ry, rz columns (6-D probe) when the data have them.
        setup_only: estimate the set-up parameters only (tracker, reflector, probe): the
            "nominal robot" baseline.
        scale_covariance: multiply the covariance by the reduced χ² (relative weights only).
        Q_work: working configurations of the TCP uncertainty (rad); default the data's.
        ident: a precomputed identifiability analysis of one station's working model (default:
            computed on ``N_EXCITATION`` seeded random configurations).
        outlier_alpha: false-alarm probability of the outlier flag.
        max_nfev: maximum number of residual evaluations (default 50 × unknowns).
        tol: ftol, xtol and gtol of the solver.
        max_median_error_m: fail if the median position error after the fit exceeds it
            (default 1 % of the robot's reach): the model cannot reach the data.
        raise_on_failure: raise :class:`SolverError` when the solver does not converge.
        seed: seed of the identifiability excitation.
        reflector_per_station: every station has its own reflector offset (and probe orientation).
        station: label of the data's one station when they have no ``station`` column
            (default: the file name without extension).
        effect_prior_rad: σ (rad) of a Gaussian prior θ_i ~ N(0, σ²) on every estimated effect
            parameter in rad (effects with ``unit == "rad"``): one row θ_i / σ in the cost and the
            covariance; it keeps a term the data barely determine (e.g. a harmonic fitted in one
            region of joint space) near zero instead of letting it extrapolate. None: no prior. An
            effect with its own ``prior_rad`` attribute (σ, rad) uses that instead.
        theta0: start values of the effects' θ (one array per effect; default zeros).
        held_effects: ``[(effect, θ), ...]`` applied with their parameters held (not estimated),
            e.g. the transferable effects of an earlier calibration; kept in the result and its model.
        discrepancy: model discrepancy δ(q) fitted to the residuals after the parametric fit
            (:mod:`pin_kpi_oed.discrepancy`): ``none`` (the paper's noise-only model, the default of
            this function), ``auto`` (the command line's default: a Gaussian process when the data are
            enough and it lowers the K-fold held-out error, else a white discrepancy at the residual
            level), ``on``, or :class:`~pin_kpi_oed.discrepancy.gp.DiscrepancyOptions`.
    """

    p0: np.ndarray | None = None
    loss: str = "linear"
    f_scale: float | None = None
    weights: str = "auto"
    register: bool = True
    use_orientation: bool = True
    setup_only: bool = False
    scale_covariance: bool = False
    Q_work: np.ndarray | None = None
    ident: Identifiability | None = None
    outlier_alpha: float = 1e-3
    max_nfev: int | None = None
    tol: float = 1e-10
    max_median_error_m: float | None = None
    raise_on_failure: bool = True
    seed: int = 0
    reflector_per_station: bool = False
    station: str | None = None
    effect_prior_rad: float | None = None
    theta0: Sequence[np.ndarray] | None = None
    held_effects: Sequence[tuple[Any, np.ndarray]] = ()
    discrepancy: Any = "none"

    def __post_init__(self) -> None:
        if self.effect_prior_rad is not None and not (np.isfinite(self.effect_prior_rad)
                                                      and self.effect_prior_rad > 0):
            raise InputError(f"effect_prior_rad must be a positive number of rad, got {self.effect_prior_rad}")
        if self.loss not in ROBUST_LOSSES:
            raise InputError(f"unknown loss '{self.loss}' (choose from {', '.join(ROBUST_LOSSES)})")
        if self.weights not in ("auto", "data", "noise"):
            raise InputError(f"weights must be auto, data or noise, got '{self.weights}'")
        if not 0.0 < float(self.outlier_alpha) < 1.0:
            raise InputError(f"outlier_alpha must be in (0, 1), got {self.outlier_alpha}")

    @classmethod
    def resolve(cls, options: "IdentifyOptions | None", overrides: dict) -> "IdentifyOptions":
        """``options`` (or the defaults) with the keyword ``overrides`` applied (:func:`resolve_options`)."""
        return resolve_options(cls, options, overrides, "identify")


def resolve_options(cls: type, options: Any, overrides: dict, what: str) -> Any:
    """An options dataclass ``options`` (or ``cls()``) with the keyword ``overrides`` applied.

    Raises:
        InputError: an unknown option name (the message lists the known ones).
    """
    known = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(overrides) - known)
    if unknown:
        raise InputError(f"{what}: unknown option(s) {', '.join(unknown)} (options: {', '.join(sorted(known))})")
    return dataclasses.replace(options or cls(), **overrides)


# --------------------------------------------------------------------------- #
# Result
# --------------------------------------------------------------------------- #
def _unit(name: str) -> str:
    suffix = name.rsplit(".", 1)[-1]
    if name.split(".")[0].split("@")[0] in ("reflector",) or suffix in ("tx", "ty", "tz"):
        return "m"
    if suffix in ("rx", "ry", "rz"):
        return "rad"
    return ""


@dataclass
class IdentificationResult(Result):
    """Outcome of :func:`identify` (common fields ``success``, ``status``, ``message``, ``nit``,
    ``nfev``, ``time_s`` of :class:`~pin_kpi_oed.results.Result`).

    Attributes:
        names: names of the estimated parameters (identifiable raw parameters, then effect θ).
        values: their estimates (m, rad; θ in the effect's units). Raw parameters are the
            right-perturbation errors of ``parameters.py``; the tracker ones are relative to
            each station's registration guess, the reflector ones to the given nominal reflector.
        std: standard deviations (same units).
        covariance: covariance of the estimates, (k, k).
        correlation: correlation matrix, (k, k).
        p: full raw parameter vector of ``model`` (the first station; non-identifiable entries at
            their given value).
        theta: effect parameters, one array per effect.
        residuals_m: measured − model position per measurement, (m, 3) m (its station's tracker frame).
        residuals_rad: log3(R_meas R_modelᵀ) per measurement (m, 3) rad, or None (position only).
        errors_m: position error norm per measurement, (m,) m.
        weighted_errors: ‖f_i‖ per measurement (dimensionless).
        outliers: indices of flagged measurements.
        tcp_std_m: predicted TCP standard deviation sqrt(trace C_s) per working configuration, (t,) m.
        cost: final cost ½ Σ ρ(f²) (dimensionless).
        chi2_reduced: Σ f² / (rows − unknowns) over the measurements in use.
        tracker_T_base: fitted pose of the robot base in the (first station's) tracker frame, 4×4 (m).
        tracker_T_base_init: its registration guess (reference of the tracker parameters), 4×4 (m).
        reflector_m: fitted reflector offset in the tool frame (first station), (3,) m.
        probe_R: fitted probe orientation in the tool frame (6-D only), 3×3.
        model: the first station's working :class:`TrackerModel` (not serialised).
        effects: the effect objects (not serialised; names in ``to_dict``).
        identifiability: the analysis that chose the parameters (over every station's parameters).
        loss: loss function used; ``f_scale`` its scale (weighted units).
        covariance_scaled: covariance multiplied by ``chi2_reduced`` (relative weights only).
        sigma_source: where the weights came from (``data``, ``noise model``).
        solver_status: :func:`scipy.optimize.least_squares` status code.
        stations: station labels, in order; ``setups`` their fitted set-ups (label -> :class:`Setup`).
        station_models, station_p: per station, the working model and its raw parameter vector.
        station_rows: per station, the indices of its measurements.
        P: the global raw parameter vector; ``param_names`` its names.
        station_set: the working models and layout of every station (for
            :class:`~pin_kpi_oed.identification.problem.ResidualModel` on other rows: ``p_ref=P``).
        reflector_per_station: each station had its own reflector.
        source: where the data came from.
    """

    names: list[str]
    values: np.ndarray
    std: np.ndarray
    covariance: np.ndarray
    correlation: np.ndarray
    p: np.ndarray
    theta: list[np.ndarray]
    residuals_m: np.ndarray
    residuals_rad: np.ndarray | None
    errors_m: np.ndarray
    weighted_errors: np.ndarray
    outliers: np.ndarray
    tcp_std_m: np.ndarray
    cost: float
    chi2_reduced: float
    tracker_T_base: np.ndarray
    tracker_T_base_init: np.ndarray
    reflector_m: np.ndarray
    probe_R: np.ndarray | None
    model: TrackerModel = field(repr=False)
    effects: list = field(default_factory=list, repr=False)
    identifiability: Identifiability | None = field(default=None, repr=False)
    loss: str = "linear"
    f_scale: float = 1.0
    covariance_scaled: bool = False
    sigma_source: str = "noise model"
    solver_status: int = 0
    stations: list = field(default_factory=list)
    setups: dict = field(default_factory=dict)
    station_models: list = field(default_factory=list, repr=False)
    station_p: list = field(default_factory=list, repr=False)
    station_rows: list = field(default_factory=list, repr=False)
    P: np.ndarray | None = field(default=None, repr=False)
    param_names: list = field(default_factory=list, repr=False)
    station_set: StationSet | None = field(default=None, repr=False)
    reflector_per_station: bool = False
    source: str = ""
    held: list = field(default_factory=list, repr=False)
    discrepancy: Any = field(default=None, repr=False)

    @property
    def converged(self) -> bool:
        """Whether the solver stopped on a tolerance (= ``success``)."""
        return bool(self.success)

    @property
    def iterations(self) -> int:
        """Number of Jacobian evaluations (LM iterations) (= ``nit``)."""
        return int(self.nit)

    @property
    def n_measurements(self) -> int:
        """Number of measurements used in the fit."""
        return int(self.errors_m.size)

    @property
    def rms_m(self) -> float:
        """RMS of the position error norms over the inliers (m)."""
        keep = np.ones(self.errors_m.size, bool)
        keep[self.outliers] = False
        return float(np.sqrt(np.mean(self.errors_m[keep] ** 2))) if keep.any() else float("nan")

    def parameter(self, name: str) -> tuple[float, float]:
        """(value, std) of an estimated parameter by name.

        Raises:
            InputError: the parameter was not estimated.
        """
        if name not in self.names:
            raise InputError(f"parameter '{name}' was not estimated (estimated: {', '.join(self.names[:4])}, ...)")
        i = self.names.index(name)
        return float(self.values[i]), float(self.std[i])

    def _station_index(self, station: str | None) -> int:
        if station is None:
            return 0
        if station not in self.stations:
            raise InputError(f"unknown station '{station}' (stations: {', '.join(self.stations)})")
        return self.stations.index(station)

    def predict(self, Q: np.ndarray, aux: MeasurementSet | None = None, station: str | None = None) -> np.ndarray:
        """Predicted measurements at configurations ``Q`` (rad) in a station's tracker frame (default the
        first), (m, 3) m or (m, 6), with effects."""
        s = self._station_index(station)
        models = self.station_models or [self.model]
        ps = self.station_p or [self.p]
        eff, th = self.all_effects()
        return predict(models[s], ps[s], Q, eff, th, aux)

    def all_effects(self) -> tuple[list, list[np.ndarray]]:
        """(effects, θ) of the whole model: the held effects (``held_effects``), then the estimated ones."""
        return ([e for e, _ in self.held] + list(self.effects),
                [np.asarray(t, float) for _, t in self.held] + [np.asarray(t, float) for t in self.theta])

    def calibrated_model(self) -> CalibratedModel:
        """Everything the fit found as a :class:`CalibratedModel` (what ``--model-out`` writes)."""
        nj = 6 * self.model.robot.nq
        n_rows = {lab: int(r.size) for lab, r in zip(self.stations, self.station_rows)}
        fit = {"n_measurements": self.n_measurements, "rms_m": self.rms_m,
               "mean_m": float(np.mean(self.errors_m)), "max_m": float(np.max(self.errors_m)),
               "chi2_reduced": self.chi2_reduced, "covariance_scaled": self.covariance_scaled,
               "loss": self.loss, "outliers": int(self.outliers.size), "sigma_source": self.sigma_source,
               "success": bool(self.success), "status": self.status, "nit": int(self.nit), "nfev": int(self.nfev),
               "time_s": float(self.time_s), "rows_per_station": n_rows,
               "reflector_per_station": bool(self.reflector_per_station)}
        return CalibratedModel(
            robot=self.model.robot, joint_p=np.asarray(self.p[:nj], float).copy(), effects=self.all_effects()[0],
            thetas=[t.copy() for t in self.all_effects()[1]], setups=dict(self.setups),
            noise=self.model.noise, tcp_m=self.model.tcp_m, pose6d=bool(self.model.pose6d),
            parameters={"names": list(self.names), "values": self.values, "std": self.std,
                        "units": [_unit(n) for n in self.names], "covariance": self.covariance},
            fit=fit, default_station=self.stations[0] if len(self.stations) == 1 else None,
            history=[{"step": "identify", "data": self.source, "stations": list(self.stations),
                      "n_measurements": self.n_measurements, "rms_m": self.rms_m}],
            discrepancy=self.discrepancy)

    def to_dict(self) -> dict:
        """Plain JSON-able dict (SI units)."""
        L = self.model.layout
        return {
            **self.result_dict(),
            "robot": self.model.robot.name,
            "urdf": self.model.robot.urdf_path,
            "tool_frame": self.model.robot.tool_frame,
            "n_measurements": self.n_measurements,
            "pose6d": bool(self.model.pose6d),
            "loss": self.loss,
            "f_scale": self.f_scale,
            "sigma_source": self.sigma_source,
            "converged": bool(self.converged),
            "solver_status": int(self.solver_status),
            "cost": float(self.cost),
            "chi2_reduced": float(self.chi2_reduced),
            "iterations": int(self.nit),
            "rms_m": self.rms_m,
            "parameters": [{"name": n, "value": float(v), "std": float(s), "unit": _unit(n)}
                           for n, v, s in zip(self.names, self.values, self.std)],
            "covariance": self.covariance,
            "covariance_scaled": bool(self.covariance_scaled),
            "correlation": self.correlation,
            "p_raw": {n: float(v) for n, v in zip(L.names, self.p)},
            "effects": {e.name: {n: float(v) for n, v in zip(effect_param_names([e], self.model.robot), th)}
                        for e, th in zip(self.effects, self.theta)},
            "tracker_T_base": self.tracker_T_base,
            "tracker_T_base_init": self.tracker_T_base_init,
            "reflector_m": self.reflector_m,
            "probe_R": self.probe_R,
            "stations": {lab: st.to_dict() for lab, st in self.setups.items()},
            "reflector_per_station": bool(self.reflector_per_station),
            "joint_placements": [pin.SE3(M).homogeneous for M in self.model.joint_placements(self.p)],
            "residuals_m": self.residuals_m,
            "residuals_rad": self.residuals_rad,
            "errors_m": self.errors_m,
            "outliers": self.outliers,
            "discrepancy": None if self.discrepancy is None else {
                "kind": self.discrepancy.kind, "decision": self.discrepancy.decision, "cv": self.discrepancy.cv},
            "tcp_std_m": self.tcp_std_m,
            "identifiability": self.identifiability.to_dict() if self.identifiability is not None else None,
        }

    def summary(self) -> str:
        """Readable multi-line summary (display units: mm, µm, mrad)."""
        e = self.errors_m * 1e3
        st = "converged" if self.converged else "NOT converged"
        S = len(self.stations)
        where = f", {S} stations" if S > 1 else ""
        out = [f"identification of {self.model.robot.name} ({self.n_measurements} measurements{where}, "
               f"{'6-D' if self.model.pose6d else 'position'}, loss {self.loss}): {st} after "
               f"{self.nit} iterations ({self.nfev} evaluations, {self.time_s * 1e3:.1f} ms)",
               f"  position residuals: RMS {self.rms_m * 1e3:.4f} mm, mean {e.mean():.4f} mm, max {e.max():.4f} mm; "
               f"reduced chi2 {self.chi2_reduced:.3g} (weights: {self.sigma_source}"
               f"{', covariance scaled by it' if self.covariance_scaled else ''})"]
        if self.residuals_rad is not None:
            a = np.linalg.norm(self.residuals_rad, axis=1) * 1e3
            out.append(f"  orientation residuals: RMS {np.sqrt(np.mean(a ** 2)):.4f} mrad, max {a.max():.4f} mrad")
        if self.outliers.size:
            rows = ", ".join(str(i + 1) for i in self.outliers[:10])
            more = " ..." if self.outliers.size > 10 else ""
            out.append(f"  outliers flagged: {self.outliers.size} (rows {rows}{more})")
        for lab, rows in zip(self.stations, self.station_rows):
            su = self.setups[lab]
            T = su.tracker_T_base
            rpy = pin.rpy.matrixToRpy(T[:3, :3])
            pre = f"  station {lab} ({rows.size} rows, RMS {np.sqrt(np.mean(e[rows] ** 2)):.4f} mm): " if S > 1 \
                else "  "
            out.append(f"{pre}tracker_T_base: xyz {np.round(T[:3, 3], 6).tolist()} m, "
                       f"rpy {np.round(rpy, 6).tolist()} rad")
            if S == 1 or self.reflector_per_station or lab == self.stations[0]:
                out.append(f"  reflector in {self.model.robot.tool_frame}"
                           f"{f' (station {lab})' if self.reflector_per_station and S > 1 else ''}: "
                           f"{np.round(su.reflector_m * 1e3, 4).tolist()} mm")
        if self.discrepancy is not None:
            out.append(f"  {self.discrepancy.decision}")
        if self.tcp_std_m.size:
            out.append(f"  predicted TCP std at {self.tcp_std_m.size} working configurations: mean "
                       f"{self.tcp_std_m.mean() * 1e6:.2f} µm, max {self.tcp_std_m.max() * 1e6:.2f} µm")
        out.append(f"  {len(self.names)} estimated parameters (value ± std; mm or mrad):")
        for n, v, s in zip(self.names, self.values, self.std):
            u = _unit(n)
            f = 1e3 if u in ("m", "rad") else 1.0
            disp = {"m": "mm", "rad": "mrad"}.get(u, "")
            out.append(f"    {n:<28s} {v * f:+12.5f} ± {s * f:.5f} {disp}")
        C = self.correlation
        iu = np.triu_indices(len(self.names), 1)
        strong = [(abs(C[i, j]), i, j) for i, j in zip(*iu) if abs(C[i, j]) > 0.95]
        for c, i, j in sorted(strong, reverse=True)[:5]:
            out.append(f"  strongly correlated: {self.names[i]} / {self.names[j]} ({C[i, j]:+.3f})")
        return "\n".join(out)


# --------------------------------------------------------------------------- #
# Steps of the identification
# --------------------------------------------------------------------------- #
_IDENT_CACHE: dict[tuple, Identifiability] = {}


def _structural_identifiability(model: TrackerModel, seed: int) -> Identifiability:
    """:func:`analyse` on a seeded random excitation, cached per robot geometry and set-up."""
    rb = model.robot
    key = (rb.urdf_path, rb.tool_frame, tuple(rb.joint_names),
           np.array([rb.model.jointPlacements[j].homogeneous for j in rb.joint_ids]).round(12).tobytes(),
           model.reflector_m.round(12).tobytes(), bool(model.pose6d), model.layout.fixed.tobytes(),
           repr(model.noise.to_dict()), seed)
    hit = _IDENT_CACHE.get(key)
    if hit is None:
        Qx = rb.random_q(np.random.default_rng(seed), N_EXCITATION)
        hit = analyse(model, Q=Qx)
        if len(_IDENT_CACHE) > 64:
            _IDENT_CACHE.clear()
        _IDENT_CACHE[key] = hit
    return copy.deepcopy(hit)  # callers may keep or modify their copy


def _working_layout(model: TrackerModel, pose6d: bool, setup_only: bool) -> ParameterLayout:
    L0 = model.layout
    L = ParameterLayout(list(model.robot.joint_names), pose6d=pose6d)
    for i, n in enumerate(L.names):
        if n in L0.names:
            k = L0.names.index(n)
            L.fixed[i] = L0.fixed[k]
            L.prior_sigma[i] = L0.prior_sigma[k]
    if setup_only:
        L.fixed = L.fixed | ~L.is_setup()
    return L


def _check_duplicates(Q: np.ndarray, data: MeasurementSet) -> None:
    parts = [Q, data.position_m] + ([data.rotvec_rad] if data.rotvec_rad is not None else [])
    keys = np.ascontiguousarray(np.hstack(parts) + 0.0)
    _, first, inv, counts = np.unique(keys, axis=0, return_index=True, return_inverse=True, return_counts=True)
    if np.any(counts > 1):
        g = int(np.flatnonzero(counts > 1)[0])
        rows = np.flatnonzero(inv.ravel() == g) + 1
        raise InputError(f"{data.source or 'measurement set'}: duplicate measurements (same joint values and same "
                         f"measured values): rows {', '.join(map(str, rows[:5]))}; remove the copies")


def _check_units(robot: Any, Y: np.ndarray, reflector: np.ndarray, src: str) -> None:
    """Reject positions whose spread the robot cannot produce (mm instead of m)."""
    reach = robot.reach() + float(np.linalg.norm(reflector))
    spread = float(np.median(np.linalg.norm(Y - np.median(Y, axis=0), axis=1)))
    if spread > 3.0 * reach:
        raise InputError(f"{src}: the measured points lie a median {spread:.4g} from their median point, but the "
                         f"robot reaches only {reach:.3g} m: positions look like mm; convert x, y, z to m")


@dataclass
class _Inputs:
    """Checked inputs of one identification."""

    src: str
    Q: np.ndarray
    pose6d: bool
    sigma: np.ndarray | None
    sigma_source: str
    labels: list[str]
    rows: list[np.ndarray]


def _check_inputs(model: TrackerModel, data: MeasurementSet, opts: IdentifyOptions) -> _Inputs:
    """Step 1: joint columns, units, duplicates, weights, stations (at least 3 rows each)."""
    src = data.source or "measurement set"
    Q = align_data(model.robot, data)
    _check_duplicates(Q, data)
    if opts.weights == "data" and data.sigma_m is None:
        raise InputError(f"{src}: weights='data' but the file has no sigma columns")
    use_data_sigma = data.sigma_m is not None and opts.weights in ("auto", "data")
    groups = data.station_rows(opts.station if opts.station is not None else default_station_label(data))
    for lab, rows in groups.items():
        where = f"{src}: station '{lab}'" if data.station is not None else src
        if rows.size == 1:
            raise InputError(f"{where} has only one row (row {int(rows[0]) + 1}): a station needs at least "
                             f"{MIN_STATION_ROWS} rows to determine its tracker pose; add rows or remove the station")
        if rows.size < MIN_STATION_ROWS:
            raise InputError(f"{where} has {rows.size} rows: too few to determine its tracker pose (at least "
                             f"{MIN_STATION_ROWS}, better many more)")
        _check_units(model.robot, data.position_m[rows], model.reflector_m, where)
    return _Inputs(src, Q, bool(opts.use_orientation and data.rotvec_rad is not None),
                   np.asarray(data.sigma_m, float) if use_data_sigma else None,
                   "data" if use_data_sigma else "noise model", list(groups), list(groups.values()))


def _start(model: TrackerModel, data: MeasurementSet, inp: _Inputs, effects: Sequence[Any],
           opts: IdentifyOptions) -> tuple[StationSet, np.ndarray, list[np.ndarray]]:
    """Step 2: working models of every station, start values, registered tracker poses."""
    robot = model.robot
    L = _working_layout(model, inp.pose6d, opts.setup_only)
    layout = StationLayout.build(L, inp.labels, opts.reflector_per_station)
    S = layout.n_stations
    p_user = np.zeros(model.n_params) if opts.p0 is None else np.asarray(opts.p0, float).reshape(model.n_params)
    tracker_known = bool(L.fixed[L.tracker].any() or np.isfinite(L.prior_sigma[L.tracker]).any())
    probe_known = bool(L.fixed[L.probe].any() or np.isfinite(L.prior_sigma[L.probe]).any())
    if S > 1 and tracker_known:
        raise InputError(f"{inp.src}: {S} stations ({', '.join(inp.labels)}) but tracker parameters are fixed or have "
                         "a prior: with several stations every tracker pose is registered from its own rows")
    P = np.zeros(layout.n)
    for g, k in enumerate(layout.generic):
        n = L.names[k]
        if n in model.layout.names and not n.startswith(("tracker.", "reflector.")):
            P[g] = p_user[model.layout.index(n)]
    T0 = model.tracker_pose(p_user)
    reflector0 = model.reflector(p_user)
    models = [TrackerModel(robot, tracker_T_base=T0, reflector_m=reflector0, tcp_m=model.tcp_m, noise=model.noise,
                           pose6d=inp.pose6d, probe_R=np.asarray(model.probe_R, float), layout=L) for _ in range(S)]
    stations = StationSet(models, layout)
    if opts.register and not tracker_known:
        th0 = list(opts.theta0) if opts.theta0 is not None else [np.zeros(len(e.param_names(robot))) for e in effects]
        pairs = list(opts.held_effects) + list(zip(effects, th0))
        M_probe = []
        for s, rows in enumerate(inp.rows):
            wm = models[s]
            wm.tracker_T_base = pin.SE3.Identity()
            p_s = stations.station_p(P, s)
            aux = data if rows.size == len(data) else data.subset(rows)
            X = predict_with_effects(wm, p_s, inp.Q[rows], aux, pairs)[:, :3]  # base frame: tracker = identity
            w = None if inp.sigma is None else 1.0 / np.mean(inp.sigma[rows] ** 2, 1)
            R, t = register_points(X, data.position_m[rows], w)
            wm.tracker_T_base = pin.SE3(R, t)
            if inp.pose6d:
                kin = wm.kinematics(p_s, inp.Q[rows], wm.reflector(p_s))
                Rm = Rotation.from_rotvec(data.rotvec_rad[rows]).as_matrix()
                M_probe.append(np.einsum("mba,bc,mcd->ad", kin.R_tool, R.T, Rm))  # Σ (R_T R_tool)ᵀ R_meas
        if inp.pose6d and not probe_known:
            for s, wm in enumerate(models):
                wm.probe_R = _proj_so3(M_probe[s] if opts.reflector_per_station else sum(M_probe))
            P[layout.is_setup() & (layout.generic >= L.probe.start) & (layout.generic < L.probe.stop)] = 0.0
    return stations, P, [m.tracker_T_base.homogeneous.copy() for m in models]


def _identifiable(stations: StationSet, opts: IdentifyOptions) -> Identifiability:
    """Step 3a: the structural identifiable set of one station, lifted to every station."""
    ident = opts.ident if opts.ident is not None else _structural_identifiability(stations.models[0], opts.seed)
    return stations.layout.lift(ident)


def _rank(A: np.ndarray, tol: float = 1e-8) -> int:
    if A.size == 0:
        return 0
    s = np.linalg.svd(A, compute_uv=False)
    return int(np.sum(s > tol * max(s[0], 1e-300)))


def _check_stations(prob: ResidualModel, J: np.ndarray, src: str) -> None:
    """Step 3b (several stations): each station's rows determine its own set-up and add robot information.

    J is the weighted Jacobian (m, nh, nx) at the start; columns are scaled to unit norm over
    all rows. Station s's own columns are its tracker pose (and own reflector/probe); the
    others (robot, effects, shared reflector) are common to all stations.

    Raises:
        IdentifiabilityError: a station whose rows do not determine its set-up, or whose rows carry
            no information beyond its own set-up (no common robot information).
    """
    lay = prob.layout
    if lay.n_stations < 2:
        return
    norms = np.linalg.norm(J.reshape(-1, prob.nx), axis=0)
    Js = J / np.where(norms > 0, norms, 1.0)
    owner = np.full(prob.nx, -1)
    owner[:prob.nb] = lay.owner[prob.base]
    for s, (lab, rows) in enumerate(zip(lay.labels, prob.rows)):
        A = Js[rows].reshape(-1, prob.nx)
        own = A[:, owner == s]
        r_own = _rank(own)
        if r_own < own.shape[1]:
            raise IdentifiabilityError(
                f"{src}: station '{lab}': its {rows.size} rows do not determine its own set-up ({own.shape[1]} "
                f"parameters: tracker pose{', reflector' if lay.reflector_per_station else ''}); measure it at more "
                "configurations spread over the workspace")
        gain = _rank(A) - r_own
        if gain == 0:
            raise IdentifiabilityError(
                f"{src}: station '{lab}': its {rows.size} rows determine no more than its own set-up ({own.shape[1]} "
                f"parameters) and carry no information on the robot common to the stations; measure more rows "
                "there or leave the station out")


def _data_rank_check(F: np.ndarray, names: list[str], m: int, nh: int) -> None:
    """Step 3c: raise if the data (of all stations together) do not determine every unknown (pivoted QR)."""
    import scipy.linalg as sla

    norms = np.linalg.norm(F, axis=0)
    if np.any(norms == 0):
        k = int(np.flatnonzero(norms == 0)[0])
        raise IdentifiabilityError(f"the measurements do not move '{names[k]}': add configurations that do, "
                                   "or fix it as known")
    _, R, piv = sla.qr(F / norms, mode="economic", pivoting=True)
    d = np.abs(np.diag(R))
    bad = np.flatnonzero(d < 1e-8 * d[0])
    if bad.size:
        who = names[piv[bad[0]]]
        raise IdentifiabilityError(f"the {m} measurements do not determine '{who}' (and {bad.size - 1} more "
                                   f"direction(s)); the configurations are too similar: spread them over the "
                                   f"joint ranges, or fix the parameter as known")


def _effect_prior(effects: Sequence[Any], prior_rad: float | None, robot: Any) -> np.ndarray | None:
    """σ per effect parameter: an effect's own ``prior_rad`` attribute (a SubsetEffect: its base's), else
    ``effect_prior_rad`` on the rad-valued effects; inf (no prior) elsewhere."""
    sig, any_prior = [], prior_rad is not None
    for e in effects:
        own = getattr(e, "prior_rad", None)
        if own is None:
            own = getattr(getattr(e, "base", None), "prior_rad", None)
        if own is not None:
            any_prior = True
        s = own if own is not None else (prior_rad if getattr(e, "unit", "") == "rad" else None)
        sig.append(np.full(len(e.param_names(robot)), np.inf if s is None else float(s)))
    if not any_prior:
        return None
    return np.concatenate(sig) if sig else np.zeros(0)


def _problem(stations: StationSet, data: MeasurementSet, inp: _Inputs, effects: Sequence[Any], P: np.ndarray,
             ident: Identifiability, opts: IdentifyOptions | None = None) -> ResidualModel:
    """Step 3: the residual model over the identifiable parameters, with every data check."""
    opts = opts or IdentifyOptions()
    prob = ResidualModel(stations, data, np.asarray(ident.base, int), effects, sigma=inp.sigma, p_ref=P, Q=inp.Q,
                         held=opts.held_effects, effect_prior_sigma=_effect_prior(effects, opts.effect_prior_rad, stations.robot),
                         theta0=opts.theta0)
    n_eq = prob.m * prob.nh
    if n_eq < prob.nx:
        raise IdentifiabilityError(
            f"{inp.src}: {prob.m} measurements give {n_eq} equations for {prob.nx} identifiable parameters "
            f"({prob.nb} geometric/set-up{f' + {prob.k} effect' if prob.k else ''}); measure at least "
            f"{int(np.ceil(prob.nx / prob.nh))} configurations (better 2–3× as many)")
    J0 = prob.jacobian_full(prob.x0())
    _check_stations(prob, J0, inp.src)
    Jr = J0.reshape(-1, prob.nx)
    eff_prior = prob.prior_idx[prob.prior_idx >= prob.nb]  # an effect prior determines its parameter
    if eff_prior.size:
        Pm = np.zeros((eff_prior.size, prob.nx))
        Pm[np.arange(eff_prior.size), eff_prior] = 1.0 / prob.prior_sigma[prob.prior_idx >= prob.nb]
        Jr = np.vstack([Jr, Pm])
    _data_rank_check(Jr, prob.names, prob.m, prob.nh)
    return prob


@dataclass
class _Solution:
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


def _solve(prob: ResidualModel, opts: IdentifyOptions) -> _Solution:
    """Step 4: Levenberg–Marquardt (or a plain fit then the robust loss), checked for divergence and reach."""
    nfev_max = opts.max_nfev if opts.max_nfev is not None else 50 * max(prob.nx, 1)
    x0 = prob.x0()
    lm_ok = prob.n_rows >= prob.nx
    fs, pre_iter, pre_fev = 1.0, 0, 0
    if opts.loss == "linear":
        sol = _least_squares(prob, x0, "linear", 1.0, "lm" if lm_ok else "trf", opts, nfev_max)
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
    return _Solution(sol.x, sol, fs, pre_iter + int(sol.njev or 0), pre_fev + int(sol.nfev))


def _flag(prob: ResidualModel, x: np.ndarray, alpha: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    fw = prob.weighted_rows(x)
    we = np.linalg.norm(fw, axis=1)
    s_rob = 1.4826 * float(np.median(np.abs(fw)))
    thr = float(np.sqrt(_chi2.ppf(1.0 - alpha, prob.nh))) * max(s_rob, 1e-300)
    return fw, we, np.flatnonzero(we > thr)


def _settle_outliers(prob: ResidualModel, solution: _Solution, opts: IdentifyOptions, src: str
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Step 5: flag outliers; with a robust loss refit plain least squares on the inliers until the flags settle.

    Returns:
        (weighted rows (m, nh), weighted error norms (m,), outlier indices); ``solution`` and
        ``prob.mask`` are updated.
    """
    fw, we, outliers = _flag(prob, solution.x, opts.outlier_alpha)
    if opts.loss == "linear":
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
        fw, we, new_out = _flag(prob, solution.x, opts.outlier_alpha)
        if np.array_equal(new_out, outliers):
            break
        outliers = new_out
    prob.mask = np.ones(prob.m, bool)
    prob.mask[outliers] = False
    return fw, we, outliers


def _covariance(prob: ResidualModel, x: np.ndarray, fw: np.ndarray, opts: IdentifyOptions
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Step 6: C = (FᵀF + P)⁻¹ (optionally × reduced χ²), standard deviations, correlations, reduced χ²."""
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
    return C, std, np.where(np.isfinite(corr), corr, 0.0), chi2_red


def _tcp_std(prob: ResidualModel, P: np.ndarray, C: np.ndarray, Qw: np.ndarray) -> np.ndarray:
    """Step 7: sqrt(trace C_s) per working configuration (eq. 25), first station's tracker frame (m)."""
    st = prob.stations
    model, p0 = st.models[0], st.station_p(P, 0)
    E0 = model.kpi_jacobian(p0, Qw)  # (3t, n_station)
    cols = prob._xcol[0]
    E = np.zeros((E0.shape[0], prob.nb))
    use = cols >= 0
    E[:, cols[use]] = E0[:, use]
    var = np.einsum("ij,jk,ik->i", E, C[:prob.nb, :prob.nb], E).reshape(-1, 3).sum(axis=1)
    return np.sqrt(np.clip(var, 0.0, None))


def _setups(prob: ResidualModel, P: np.ndarray, errors: np.ndarray, inp: _Inputs, data: MeasurementSet
            ) -> dict[str, Setup]:
    st = prob.stations
    out = {}
    for s, (lab, rows) in enumerate(zip(st.labels, prob.rows)):
        model, p = st.models[s], st.station_p(P, s)
        R_probe = model.probe_R @ pin.exp3(p[model.layout.probe]) if model.pose6d else None
        out[lab] = Setup(model.tracker_pose(p).homogeneous.copy(), model.reflector(p), R_probe, int(rows.size),
                         "identify", data.source, float(np.sqrt(np.mean(errors[rows] ** 2))))
    return out


@limit_threads
def identify(model: TrackerModel, data: MeasurementSet, options: IdentifyOptions | None = None, *,
             effects: Sequence[Any] = (), **overrides: Any) -> IdentificationResult:
    r"""Identify the robot's geometric parameters (and effect parameters θ) from measurements.

    Weighted nonlinear least squares (eqs. 5–6) over the identifiable parameters, by
    Levenberg–Marquardt with the analytic Jacobian (or trust-region reflective with a robust
    loss), from the nominal model and a closed-form registration of every station's tracker pose
    (steps: see the module docstring).

    Args:
        model: measurement model: robot, nominal reflector in the tool frame, noise (weights),
            TCP point, layout (``fixed`` parameters held at their value, ``prior_sigma``). Its
            ``tracker_T_base`` is only used when ``register`` is False or the tracker is fixed.
        data: the measurements (joint columns named as the robot's joints; SI units); a
            ``station`` column makes each station's rows share one tracker pose.
        options: :class:`IdentifyOptions` (default: the defaults).
        effects: objects of the Effect interface (``docs/ARCHITECTURE.md``); their θ are
            identified jointly (start at 0).
        **overrides: fields of :class:`IdentifyOptions` given by name (``loss="soft_l1"``,
            ``setup_only=True``, ...); they replace those of ``options``.

    Returns:
        The :class:`IdentificationResult`.

    Raises:
        InputError: missing joint columns, NaN, degrees or mm instead of rad or m, duplicate
            rows, an unknown loss or option, a station with fewer than 3 rows.
        IdentifiabilityError: fewer equations than unknowns, a station whose rows determine
            nothing beyond its own set-up, or configurations that do not determine a parameter.
        SolverError: no convergence, or the fitted model does not reach the data.
    """
    t_start = time.perf_counter()
    opts = IdentifyOptions.resolve(options, overrides)
    inp = _check_inputs(model, data, opts)
    stations, P0, T_init = _start(model, data, inp, effects, opts)
    ident = _identifiable(stations, opts)
    prob = _problem(stations, data, inp, effects, P0, ident, opts)
    solution = _solve(prob, opts)
    fw, we, outliers = _settle_outliers(prob, solution, opts, inp.src)
    x = solution.x
    rpos, rrot = prob.evaluate(x)
    errors = np.linalg.norm(rpos, axis=1)
    C, std, corr, chi2_red = _covariance(prob, x, fw, opts)
    P_hat, th_hat = prob.unpack(x)
    Qw = inp.Q if opts.Q_work is None else model.robot.check_q(opts.Q_work, "Q_work")
    tcp_std = _tcp_std(prob, P_hat, C, Qw)
    setups = _setups(prob, P_hat, errors, inp, data)
    first = setups[stations.labels[0]]
    sol = solution.sol
    converged = bool(sol.status > 0)
    result = IdentificationResult(
        success=converged, status="converged" if converged else "max_nfev", message=str(sol.message),
        nit=solution.nit, nfev=solution.nfev, solver_status=int(sol.status),
        names=prob.names, values=x.copy(), std=std, covariance=C, correlation=corr,
        p=stations.station_p(P_hat, 0), theta=th_hat, residuals_m=-rpos, residuals_rad=None if rrot is None else -rrot,
        errors_m=errors, weighted_errors=we, outliers=outliers, tcp_std_m=tcp_std, cost=float(sol.cost),
        chi2_reduced=chi2_red, tracker_T_base=first.tracker_T_base.copy(), tracker_T_base_init=T_init[0],
        reflector_m=first.reflector_m.copy(), probe_R=first.probe_R, model=stations.models[0],
        effects=list(effects), identifiability=ident, loss=opts.loss, f_scale=solution.f_scale,
        covariance_scaled=bool(opts.scale_covariance), sigma_source=inp.sigma_source,
        stations=list(stations.labels), setups=setups, station_models=list(stations.models),
        station_p=[stations.station_p(P_hat, s) for s in range(len(stations.labels))],
        station_rows=list(prob.rows), P=P_hat, param_names=list(stations.layout.names), station_set=stations,
        reflector_per_station=bool(opts.reflector_per_station), source=data.source,
        held=[(e, np.asarray(t, float)) for e, t in opts.held_effects], time_s=time.perf_counter() - t_start)
    result.discrepancy = result_discrepancy(result, data, discrepancy_options(opts.discrepancy, opts.seed), inp.Q)
    result.time_s = time.perf_counter() - t_start
    return result


# --------------------------------------------------------------------------- #
# Validation
# --------------------------------------------------------------------------- #
def error_stats(err: np.ndarray) -> dict:
    """n, mean, RMS, median, p95 and max of position error norms (m), plus the norms themselves."""
    err = np.asarray(err, float)
    if err.size == 0:
        return {"n": 0, "mean_m": None, "rms_m": None, "median_m": None, "p95_m": None, "max_m": None,
                "errors_m": err}
    return {"n": int(err.size), "mean_m": float(err.mean()), "rms_m": float(np.sqrt(np.mean(err ** 2))),
            "median_m": float(np.median(err)), "p95_m": float(np.percentile(err, 95)), "max_m": float(err.max()),
            "errors_m": err}


def validate(result: IdentificationResult | CalibratedModel, data: MeasurementSet) -> dict:
    """Position errors of the identified model on held-out measurements (nothing is re-fitted).

    The tracker pose, reflector offset, geometry and effect parameters all come from
    ``result``; rows of a station the result knows use that station's set-up (a data set
    without a station column: the result's only or default station); the effects see
    ``data`` as their auxiliary data (temperature, ...).

    Args:
        result: an identification result, or a calibrated model (e.g. re-registered on another day).
        data: held-out measurements (same robot joints, SI units).

    Returns:
        ``{"n", "mean_m", "rms_m", "median_m", "p95_m", "max_m", "errors_m"}`` (m), plus
        ``"rot_rms_rad"``, ``"rot_max_rad"`` when both the result and the data are 6-D.

    Raises:
        InputError: missing joint columns, NaN, degrees or out-of-limit joint values, a station
            the result does not know, or several stations and no station column.
    """
    cm = result if isinstance(result, CalibratedModel) else result.calibrated_model()
    Q = align_data(cm.robot, data)
    want_rot = bool(cm.pose6d and data.rotvec_rad is not None)
    Y = cm.predict(Q, data, orientation=want_rot)
    out = error_stats(np.linalg.norm(data.position_m - Y[:, :3], axis=1))
    out.update(calibration_stats(cm, Q, data))
    if want_rot:
        Rp = Rotation.from_rotvec(Y[:, 3:]).as_matrix()
        Rm = Rotation.from_rotvec(data.rotvec_rad).as_matrix()
        a = np.linalg.norm(log3(Rm @ np.swapaxes(Rp, 1, 2)), axis=1)
        out["rot_rms_rad"] = float(np.sqrt(np.mean(a ** 2)))
        out["rot_max_rad"] = float(a.max())
    return out


def calibration_stats(cm: CalibratedModel, Q: np.ndarray, data: MeasurementSet) -> dict:
    """How honest the model's σ is on measured rows: standardised errors z = (measured − predicted)/σ per axis.

    Returns:
        ``z_rms`` (RMS of z over rows and axes; 1 when σ is right), ``inside_95`` (share of rows whose
        Σ z² ≤ χ²₃(0.95) = 7.815: their 95 % ellipsoid holds the measurement), ``sigma_mean_m`` (mean
        predicted 3-D σ = sqrt(Σ σ²), m), ``extrapolation_share`` (rows outside the training coverage).
    """
    Yp, sig, extra = cm.predict_with_sigma(Q, data)
    z2 = ((data.position_m - Yp) / sig) ** 2
    return {"z_rms": float(np.sqrt(z2.mean())), "inside_95": float(np.mean(z2.sum(axis=1) <= 7.8147)),
            "sigma_mean_m": float(np.sqrt((sig ** 2).sum(axis=1)).mean()),
            "extrapolation_share": float(np.mean(extra))}


def format_validation(stats: dict, title: str = "held-out") -> str:
    """One line of validation statistics in mm (``stats`` from :func:`validate`)."""
    s = (f"{title}: n={stats['n']}, mean {stats['mean_m'] * 1e3:.4f} mm, RMS {stats['rms_m'] * 1e3:.4f} mm, "
         f"p95 {stats['p95_m'] * 1e3:.4f} mm, max {stats['max_m'] * 1e3:.4f} mm")
    if "rot_rms_rad" in stats:
        s += f", orientation RMS {stats['rot_rms_rad'] * 1e3:.4f} mrad"
    if "z_rms" in stats:
        s += (f"; predicted σ (3-D) mean {stats['sigma_mean_m'] * 1e3:.4f} mm, standardised error RMS "
              f"{stats['z_rms']:.2f} (1 = honest), {stats['inside_95'] * 100:.0f} % inside the 95 % ellipsoid"
              + (f", {stats['extrapolation_share'] * 100:.0f} % of rows outside the training coverage"
                 if stats.get("extrapolation_share") else ""))
    return s
