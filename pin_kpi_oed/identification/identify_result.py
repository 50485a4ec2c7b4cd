"""The outcome of an identification: estimates, uncertainty, residuals, set-ups; summary and model file."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pinocchio as pin

from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.calibrated.model_file import CalibratedModel
from pin_kpi_oed.identification.problem import StationSet, effect_param_names, predict
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.oed.held import held_advice
from pin_kpi_oed.oed.identifiability import Identifiability
from pin_kpi_oed.validation.units import SIGMA_MAX_M, SIGMA_ROT_MAX_RAD
from pin_kpi_oed.results import Result

__all__ = ["IdentificationResult", "param_unit"]


def param_unit(name: str) -> str:
    """Unit of a raw parameter by its name: ``m`` (translations, reflector), ``rad`` (rotations) or ``""``."""
    suffix = name.rsplit(".", 1)[-1]
    if name.split(".")[0].split("@")[0] in ("reflector",) or suffix in ("tx", "ty", "tz"):
        return "m"
    if suffix in ("rx", "ry", "rz"):
        return "rad"
    return ""


@dataclass
class IdentificationResult(Result):
    """Outcome of :func:`~pin_kpi_oed.identification.identify.identify` (common fields ``success``, ``status``,
    ``message``, ``nit``,
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
        tcp_std_m: predicted TCP standard deviation sqrt(trace C_s) per working configuration, (t,) m, with the
            joint-placement parameters held at nominal under their tolerances (:mod:`pin_kpi_oed.oed.held`).
        tcp_std_at: where ``tcp_std_m`` is: ``working`` (the working configurations ``Q_work``) or ``training``
            (the training poses, when no working configurations were given).
        cost: final cost ½ Σ ρ(f²) (dimensionless).
        chi2_reduced: Σ f² / (rows − unknowns) over the measurements in use.
        tracker_T_base: fitted pose of the robot base in the (first station's) tracker frame, 4×4 (m).
        tracker_T_base_init: its registration guess (reference of the tracker parameters), 4×4 (m).
        reflector_m: fitted reflector offset in the tool frame (first station), (3,) m.
        probe_R: fitted probe orientation in the tool frame (6-D only), 3×3.
        model: the first station's working :class:`TrackerModel` (not serialised).
        effects: the effect objects (not serialised; names in ``to_dict``).
        identifiability: the analysis that chose the parameters (over every station's parameters).
        loss: loss function used; ``f_scale`` its scale (weighted units); ``loss_decision``: why ``loss="auto"``
            switched to the robust loss ("" when it did not).
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
        tool: the data's tool (:attr:`MeasurementSet.tool`: robot, tool frame, reflector, TCP, working
            configurations), carried into the model file; None: the data did not state it.
        tcp_held_m: the held parameters' share of ``tcp_std_m``, (t,) m.
        held_term: the held parameters and how the fit absorbed them (:class:`~pin_kpi_oed.oed.held.HeldTerm`),
            or None; ``tcp_held_contrib_m`` each one's RMS σ at the TCP over the working configurations (m).
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
    loss_decision: str = ""
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
    tool: Any = field(default=None, repr=False)
    coverage: Any = field(default=None, repr=False)
    fit_quality: Any = field(default=None, repr=False)
    tcp_held_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    held_term: Any = field(default=None, repr=False)
    tcp_held_contrib_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    tcp_std_at: str = "training"

    @property
    def converged(self) -> bool:
        """Whether the solver stopped on a tolerance (= ``success``)."""
        return bool(self.success)

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

    def residual_sigma_m(self) -> np.ndarray | None:
        r"""The fit's own residual level per axis (m): s_a = √(Σ_i r_{ia}² / (m − k/3)) over the m inlier rows,
        k the estimated parameters (robot, set-up and effects), i.e. the position residuals corrected for
        what the fit absorbed (3m − k degrees of freedom in all).

        What a new session of the same robot is compared with (``register``): a model written without the
        tracker's noise keeps its default noise, but its residual level says how well the robot fitted.

        Returns:
            (3,) m, or None when 3m ≤ k (no degrees of freedom left).
        """
        keep = np.ones(len(self.residuals_m), bool)
        keep[self.outliers] = False
        R = np.asarray(self.residuals_m, float)[keep, :3]
        dof = R.shape[0] - len(self.values) / 3.0  # values: robot, set-up and effect parameters
        if dof <= 0 or not np.all(np.isfinite(R)):
            return None
        return np.sqrt(np.sum(R ** 2, axis=0) / dof)

    def residual_sigma_rad(self) -> np.ndarray | None:
        r"""The fit's own orientation residual level per axis (rad, tracker frame) of a 6-D fit:
        s_a = √(Σ_i ω_{ia}² / (m − k/6)) over the m inlier rows (ω the orientation residuals, k the estimated
        parameters shared by the 6m rows): the white part of the orientation σ ``predict`` gives.

        Returns:
            (3,) rad, or None for a position-only fit or when 6m ≤ k.
        """
        if self.residuals_rad is None:
            return None
        keep = np.ones(len(self.residuals_rad), bool)
        keep[self.outliers] = False
        W = np.asarray(self.residuals_rad, float)[keep]
        dof = W.shape[0] - len(self.values) / 6.0
        if dof <= 0 or not np.all(np.isfinite(W)):
            return None
        return np.sqrt(np.sum(W ** 2, axis=0) / dof)

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

    def _tcp_m(self) -> np.ndarray:
        """The model's TCP (m, tool frame); at the origin, the data header's when it states one."""
        tcp = np.asarray(self.model.tcp_m, float)
        if not np.any(tcp != 0) and self.tool is not None and self.tool.tcp_m is not None:
            return self.tool.tcp_m.copy()
        return tcp.copy()

    def held_advice(self) -> str:
        """Which part of the TCP's σ no reflector measurement removes and what does (:func:`held_advice`), or ""."""
        if self.held_term is None or not self.tcp_std_m.size:
            return ""
        return held_advice(self.held_term.names, self.tcp_held_contrib_m, float(np.sqrt(np.mean(self.tcp_std_m ** 2))))

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
        level = self.residual_sigma_m()
        if level is not None and np.all(level > 0) and np.all(level <= SIGMA_MAX_M):  # else not a calibration
            fit["residual_sigma_m"] = level
        level_rad = self.residual_sigma_rad()
        if level_rad is not None and np.all(level_rad > 0) and np.all(level_rad <= SIGMA_ROT_MAX_RAD):
            fit["residual_sigma_rad"] = level_rad
        return CalibratedModel(
            robot=self.model.robot, joint_p=np.asarray(self.p[:nj], float).copy(), effects=self.all_effects()[0],
            thetas=[t.copy() for t in self.all_effects()[1]], setups=dict(self.setups),
            noise=self.model.noise, tcp_m=self._tcp_m(), pose6d=bool(self.model.pose6d),
            parameters={"names": list(self.names), "values": self.values, "std": self.std,
                        "units": [param_unit(n) for n in self.names], "covariance": self.covariance,
                        **({"held": self.held_term.to_dict()} if self.held_term is not None else {})},
            fit=fit, default_station=self.stations[0] if len(self.stations) == 1 else None,
            history=[{"step": "identify", "data": self.source, "stations": list(self.stations),
                      "n_measurements": self.n_measurements, "rms_m": self.rms_m}],
            discrepancy=self.discrepancy, q_work=None if self.tool is None else self.tool.q_work,
            tool_source=self._tool_source(), coverage=self.coverage)

    def _tool_source(self) -> str:
        """Where the model's TCP comes from: the data header's or the cell's tool, else a non-zero ``tcp_m`` the
        measurement model was built with; "" when nothing stated a TCP (``compensate`` then asks for one)."""
        if self.tool is not None and self.tool.tcp_m is not None:
            return self.tool.source or "the measurement model's tool"
        return "the measurement model's tcp_m" if np.any(np.asarray(self.model.tcp_m, float) != 0) else ""

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
            "loss": self.loss, "loss_decision": self.loss_decision,
            "f_scale": self.f_scale,
            "sigma_source": self.sigma_source,
            "converged": bool(self.converged),
            "solver_status": int(self.solver_status),
            "cost": float(self.cost),
            "chi2_reduced": float(self.chi2_reduced),
            "iterations": int(self.nit),
            "rms_m": self.rms_m,
            "parameters": [{"name": n, "value": float(v), "std": float(s), "unit": param_unit(n)}
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
            "tcp_held_m": self.tcp_held_m,
            "held": None if self.held_term is None else {
                "names": self.held_term.names, "sigma": self.held_term.sigma,
                "tcp_contribution_m": self.tcp_held_contrib_m, "advice": self.held_advice()},
            "tcp_std_at": self.tcp_std_at,
            "identifiability": self.identifiability.to_dict() if self.identifiability is not None else None,
        }

    def summary(self) -> str:
        """Readable multi-line summary (display units: mm, µm, mrad), the robot loader's notes included
        (:attr:`~pin_kpi_oed.model.robot.Robot.notes`)."""
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
        if self.loss_decision:
            out.append(f"  {self.loss_decision}")
        out += [f"  note: {n}" for n in self.model.robot.notes]  # what the loader made of the URDF
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
            t = self.tcp_std_m.size
            at = (f"{t} working configuration{'s' if t > 1 else ''}" if self.tcp_std_at == "working" else
                  f"the {t} training poses (no working configurations given)")
            out.append(f"  predicted TCP std at {at}: mean "
                       f"{self.tcp_std_m.mean() * 1e6:.2f} µm, max {self.tcp_std_m.max() * 1e6:.2f} µm"
                       + (f" (of which the parameters held at their tolerance: mean {self.tcp_held_m.mean() * 1e6:.2f}"
                          " µm)" if self.tcp_held_m.size and self.tcp_held_m.max() > 0 else ""))
            line = self.held_advice()
            if line:
                out.append(f"  {line}")
        out.append(f"  {len(self.names)} estimated parameters (value ± std; mm or mrad):")
        for n, v, s in zip(self.names, self.values, self.std):
            u = param_unit(n)
            f = 1e3 if u in ("m", "rad") else 1.0
            disp = {"m": "mm", "rad": "mrad"}.get(u, "")
            out.append(f"    {n:<28s} {v * f:+12.5f} ± {s * f:.5f} {disp}")
        C = self.correlation
        iu = np.triu_indices(len(self.names), 1)
        strong = [(abs(C[i, j]), i, j) for i, j in zip(*iu) if abs(C[i, j]) > 0.95]
        for _c, i, j in sorted(strong, reverse=True)[:5]:
            out.append(f"  strongly correlated: {self.names[i]} / {self.names[j]} ({C[i, j]:+.3f})")
        if self.fit_quality is not None:
            out.append(f"  {self.fit_quality.line()}")
        return "\n".join(out)
