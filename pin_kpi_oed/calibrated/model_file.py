r"""Calibrated model files: everything a calibration found, to predict with it on another day.

``pin-kpi-oed identify --model-out model.json`` writes, and :func:`load_model_file` reads, a
versioned JSON file (``"format": "pin_kpi_oed.model/1"``, written atomically) that holds

==================== ======================================================================
key                  content (SI units: m, rad)
==================== ======================================================================
``format``           ``"pin_kpi_oed.model/1"`` (another format or version is refused)
``robot``            ``spec`` (robot name or URDF path for :func:`load_robot`), ``name``,
                     ``urdf_path``, ``tool_frame``, ``joint_names``, and the nominal joint
                     placements (4×4) the calibration started from (checked on loading)
``geometry``         ``joint_placement_errors``: the right perturbation δ_j of every joint
                     placement, name -> value (``joint_a2.tx`` m, ``joint_a2.rx`` rad);
                     ``joint_placements``: the calibrated placements M_j·exp6(δ_j), 4×4;
                     ``parameters``: the estimated parameters (names, values, std, units,
                     covariance), as the fit reported them
``effects``          per effect: ``name``, ``kind`` (library class), ``options`` (constructor
                     keyword arguments), ``param_names``, ``theta`` (its unit: ``unit``)
``stations``         per station label: ``tracker_T_base`` (pose of the robot base in the
                     tracker frame, 4×4), ``reflector_m`` (tool frame), ``probe_R`` (6-D),
                     ``n_rows``, ``fitted_by`` (``identify`` or ``register``), ``source``,
                     ``rms_m``, ``nests_m`` (the tool's reflector nests as fitted, tool frame)
``default_station``  the station used when none is named (the last registered one)
``noise``            the noise model (:meth:`NoiseModel.to_dict`)
``tcp_m``, ``pose6d`` KPI point in the tool frame; whether the model predicts orientations
``tool_source``      where ``tcp_m`` and the tool frame come from (a cell file or a measurement
                     file's tool header); absent: not stated, ``compensate`` then takes the
                     station's reflector as its default TCP
``q_work``           optional: the cell's working configurations (rad / m per joint), the branch
                     ``compensate`` keeps for targets without a joint hint
``fit``              fit statistics (measurements, RMS, reduced χ², iterations, ...) and
                     ``residual_sigma_m``: the fit's own residual level per axis (m, corrected
                     for the fitted parameters), what ``register`` compares a new session with;
                     a 6-D fit's ``residual_sigma_rad``: the orientation residual level per axis
                     (rad), the white part of the orientation σ ``predict`` gives
``discrepancy``      optional: the model discrepancy δ(q) of the robot (base frame; kernel,
                     hyper-parameters, training or inducing configurations; see
                     :mod:`pin_kpi_oed.discrepancy.gp`), kept by ``register``
``history``          what produced the file, step by step (identify, register)
==================== ======================================================================

Prediction (:meth:`CalibratedModel.predict`): for station s with set-up (T_s, r_s) (r_s the row's nest) and the
robot's δ and effects (θ), the reflector in the tracker frame is ``y = T_s · oMtool(δ, q + ΣΔq(θ)) · r_s + ΣΔy(θ)``
(:func:`pin_kpi_oed.effects.library.predict_with_effects`), the same model the fit used: a model file loaded back
predicts what the fit predicted (to ~1e-15 m, tested).

With a discrepancy, :meth:`CalibratedModel.predict` adds ``R_s · δ̄(q)`` (its posterior mean in the station's
tracker frame); :meth:`CalibratedModel.predict_with_sigma` gives the σ of measured − predicted per axis (posterior
variance, white level, rows outside the training coverage flagged); :meth:`CalibratedModel.predict_tcp` the TCP's
position and σ (:mod:`pin_kpi_oed.calibrated.tcp_sigma`: with the parameters held at nominal).

Effects are stored as their library class and constructor options: a library effect (:mod:`pin_kpi_oed.effects`,
``joint_angle_table``, a subset of one) from its attributes; any other one if it has ``options() -> dict``
(JSON-able keyword arguments of its constructor) and its class is registered under its ``name``. The calibrated
URDF (``--urdf-out``) carries the geometry only.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from pin_kpi_oed.data.atomic import atomic_write_json, to_jsonable
from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.discrepancy.coverage import JointCoverage
from pin_kpi_oed.discrepancy.gp import Discrepancy
from pin_kpi_oed.effects.library import predict_with_effects
from pin_kpi_oed.effects.spec import effect_from_spec, effect_spec
from pin_kpi_oed.errors import InputError, PinKpiOedError
from pin_kpi_oed.model.nests import check_nests, nest_column
from pin_kpi_oed.model.noise import NoiseModel
from pin_kpi_oed.calibrated.shared_tables import StationTracker, discrepancy_at
from pin_kpi_oed.model.parameters import ParameterLayout
from pin_kpi_oed.model.robot import Robot, load_robot, portable_spec
from pin_kpi_oed.model.serialize import se3_from_matrix
from pin_kpi_oed.validation.schema import validate_model_dict
from pin_kpi_oed.validation.units import check_sigma_m, check_sigma_rad

__all__ = ["MODEL_FORMAT", "Setup", "CalibratedModel", "load_model_file", "effect_spec", "effect_from_spec"]

#: Format tag of the model files this version writes and reads.
MODEL_FORMAT = "pin_kpi_oed.model/1"
_FORMAT_NAME = MODEL_FORMAT.split("/")[0]


# --------------------------------------------------------------------------- the model
#: most registration configurations a station keeps (:attr:`Setup.registered_q_rad`)
REGISTERED_Q_MAX = 2000


@dataclass
class Setup:
    """The measurement set-up of one station (SI units).

    Attributes:
        tracker_T_base: pose of the robot base in the tracker frame, 4×4 (m).
        reflector_m: reflector offset in the tool frame, (3,) m.
        nests_m: the reflector nests as fitted, (k, 3) m, nest 0 = ``reflector_m`` (a row's ``nest`` picks one).
        probe_R: probe orientation in the tool frame (6-D only), 3×3; None otherwise.
        n_rows: measurements the set-up was fitted on.
        fitted_by: ``identify`` (fitted with the robot) or ``register`` (robot held).
        source: file(s) the rows came from.
        rms_m: RMS position error of those rows after the fit (m), or None.
        sigma_scale: factor (≥ 1) on every predicted σ at this station: a registration sets it from its
            own rows' standardised errors (:func:`~pin_kpi_oed.upkeep.transfer.register_setup`), so
            a session that is worse than the calibrated one says so; 1 for a fitted station.
        registered_q_rad: the configurations a registration fitted the set-up on, (k, n) rad (at most
            :data:`REGISTERED_Q_MAX`, a seeded subset beyond): the predicted σ at this station counts the robot's
            error that the set-up fitted on them could not absorb
            (:func:`~pin_kpi_oed.calibrated.prediction_sigma.predictive_sigma`); None for a fitted station and
            for model files written before it was recorded.
    """

    tracker_T_base: np.ndarray
    reflector_m: np.ndarray
    probe_R: np.ndarray | None = None
    n_rows: int = 0
    fitted_by: str = "identify"
    source: str = ""
    rms_m: float | None = None
    sigma_scale: float = 1.0
    registered_q_rad: np.ndarray | None = None
    nests_m: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.sigma_scale = float(self.sigma_scale)
        if self.registered_q_rad is not None:
            Q = np.asarray(self.registered_q_rad, float)
            if len(Q) > REGISTERED_Q_MAX:
                Q = Q[np.sort(np.random.default_rng(0).choice(len(Q), REGISTERED_Q_MAX, replace=False))]
            self.registered_q_rad = Q
        if not np.isfinite(self.sigma_scale) or self.sigma_scale < 1.0:
            raise InputError(f"station set-up: sigma_scale must be a finite number >= 1, got {self.sigma_scale!r}")
        self.tracker_T_base = se3_from_matrix(self.tracker_T_base, "tracker_T_base").homogeneous.copy()
        self.reflector_m = np.asarray(self.reflector_m, float).reshape(3)
        if self.probe_R is not None:
            self.probe_R = se3_from_matrix(np.block([[np.asarray(self.probe_R, float), np.zeros((3, 1))],
                                                     [np.zeros((1, 3)), np.ones((1, 1))]]), "probe_R").rotation

    def to_dict(self) -> dict:
        """Plain numbers for JSON."""
        return to_jsonable({"tracker_T_base": self.tracker_T_base, "reflector_m": self.reflector_m,
                            "probe_R": self.probe_R, "n_rows": int(self.n_rows), "fitted_by": self.fitted_by,
                            "source": self.source, "rms_m": self.rms_m, "sigma_scale": self.sigma_scale,
                            **{k: v for k, v in (("registered_q_rad", self.registered_q_rad),
                                                 ("nests_m", self.nests_m)) if v is not None}})

    @classmethod
    def from_dict(cls, d: dict, where: str) -> Setup:
        """Inverse of :meth:`to_dict`.

        Raises:
            InputError: a missing or malformed field, named.
        """
        if not isinstance(d, dict) or "tracker_T_base" not in d or "reflector_m" not in d:
            raise InputError(f"{where}: needs 'tracker_T_base' (4x4) and 'reflector_m' (3 numbers)")
        refl = np.asarray(d["reflector_m"], float)
        if refl.shape != (3,) or not np.all(np.isfinite(refl)):
            raise InputError(f"{where}: 'reflector_m' must be 3 finite numbers (m), got {d['reflector_m']!r}")
        T = se3_from_matrix(d["tracker_T_base"], f"{where}: tracker_T_base").homogeneous
        R = d.get("probe_R")
        if R is not None:
            R = np.asarray(R, float)
            if R.shape != (3, 3) or not np.all(np.isfinite(R)):
                raise InputError(f"{where}: 'probe_R' must be a 3x3 rotation matrix")
        scale = d.get("sigma_scale", 1.0)
        if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not np.isfinite(scale) or scale < 1.0:
            raise InputError(f"{where}: 'sigma_scale' must be a finite number >= 1, got {scale!r}")
        Qr = d.get("registered_q_rad")
        if Qr is not None:
            try:
                Qr = np.asarray(Qr, float)
            except (TypeError, ValueError):
                Qr = np.zeros((0, 0, 0))
            if Qr.ndim != 2 or len(Qr) == 0 or not np.all(np.isfinite(Qr)):
                raise InputError(f"{where}: 'registered_q_rad' must be rows of finite joint values (rad), one per "
                                 "registration row")
        nests = None if d.get("nests_m") is None else check_nests(refl, d["nests_m"], f"{where}: nests_m")
        return cls(T, refl, R, int(d.get("n_rows", 0)), str(d.get("fitted_by", "identify")),
                   str(d.get("source", "")), d.get("rms_m"), float(scale), Qr, nests)


@dataclass
class CalibratedModel:
    """A calibrated robot with the set-up of every station: predicts tracker readings.

    Attributes:
        robot: the arm (URDF, tool frame).
        joint_p: joint-placement errors δ, (6 n,) in :class:`ParameterLayout` order (m, rad).
        effects: effect objects (Effect interface); thetas: their parameters.
        setups: station label -> :class:`Setup`.
        noise: the noise model of the fit.
        tcp_m: KPI point in the tool frame (m).
        pose6d: predicts probe orientations too.
        parameters: the estimated parameters of the fit: ``names``, ``values``, ``std``, ``covariance``.
        fit: fit statistics (plain numbers).
        default_station: station used when none is named (None: the only one, if there is one).
        history: provenance, one dict per step (``identify``, ``register``).
        discrepancy: the robot's model discrepancy δ(q) (base frame), or None (noise-only model).
        q_work: the cell's working configurations, (k, n) rad / m, or None.
        tool_source: where ``tcp_m`` and the tool frame come from (cell or measurement header); "" = not stated.
        coverage: the training configurations' joint-space coverage
            (:class:`~pin_kpi_oed.discrepancy.coverage.JointCoverage`; the discrepancy's when it has one).
    """

    robot: Robot
    joint_p: np.ndarray
    effects: list = field(default_factory=list)
    thetas: list = field(default_factory=list)
    setups: dict = field(default_factory=dict)
    noise: NoiseModel = field(default_factory=NoiseModel)
    tcp_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    pose6d: bool = False
    parameters: dict = field(default_factory=dict)
    fit: dict = field(default_factory=dict)
    default_station: str | None = None
    history: list = field(default_factory=list)
    discrepancy: Discrepancy | None = None
    q_work: np.ndarray | None = None
    tool_source: str = ""
    coverage: JointCoverage | None = None

    def __post_init__(self) -> None:
        self.joint_p = np.asarray(self.joint_p, float).reshape(-1)
        if self.joint_p.size != 6 * self.robot.nq:
            raise InputError(f"joint_p must have {6 * self.robot.nq} entries (6 per joint), got {self.joint_p.size}")
        self.thetas = [np.asarray(t, float).reshape(-1) for t in self.thetas]
        if len(self.thetas) != len(self.effects):
            raise InputError(f"{len(self.effects)} effects but {len(self.thetas)} parameter vectors")
        self.tcp_m = np.asarray(self.tcp_m, float).reshape(3)
        if self.q_work is not None:
            self.q_work = self.robot.check_q(self.q_work, "q_work (working configurations)")

    @property
    def default_tcp_m(self) -> np.ndarray:
        """The TCP in the tool frame (m) a command uses by default: ``tcp_m`` when a cell or a measurement
        header stated it, else the default station's reflector (the point the calibration measured)."""
        if self.tool_source:
            return self.tcp_m.copy()
        return self.setups[self.station(None)].reflector_m.copy()

    # ------------------------------------------------------------------ stations
    @property
    def stations(self) -> list[str]:
        """Station labels."""
        return list(self.setups)

    def station(self, label: str | None = None) -> str:
        """Resolve a station label (None: the default station, or the only one).

        Raises:
            InputError: unknown label, or no label given and no default among several stations.
        """
        if label is not None:
            if str(label) not in self.setups:
                raise InputError(f"unknown station '{label}' (stations of the model: {', '.join(self.setups)})")
            return str(label)
        if self.default_station is not None and self.default_station in self.setups:
            return self.default_station
        if len(self.setups) == 1:
            return next(iter(self.setups))
        raise InputError(f"the model has {len(self.setups)} stations ({', '.join(self.setups)}) and no default: "
                         "name one (parameter 'station'), give the data a 'station' column, or register the set-up "
                         "first")

    def station_model(self, label: str | None = None) -> tuple[StationTracker, np.ndarray]:
        """The measurement model of a station and its raw parameter vector (set-up errors zero).

        Returns:
            (model, p): ``model.predict(p, Q)`` is the geometric prediction (without effects).
        """
        st = self.setups[self.station(label)]
        L = ParameterLayout(list(self.robot.joint_names), pose6d=self.pose6d and st.probe_R is not None)
        model = StationTracker(self.robot, tracker_T_base=pin.SE3(st.tracker_T_base), reflector_m=st.reflector_m,
                             tcp_m=self.tcp_m, noise=self.noise, pose6d=L.pose6d,
                             probe_R=np.eye(3) if st.probe_R is None else st.probe_R, layout=L, nests_m=st.nests_m)
        p = np.concatenate([self.joint_p, np.zeros(L.n - self.joint_p.size)])
        return model, p

    def predict(self, Q: np.ndarray, aux: MeasurementSet | None = None, station: str | None = None,
                orientation: bool = False) -> np.ndarray:
        """Predicted reflector positions in the tracker frame of the station(s), (m, 3) m.

        Args:
            Q: configurations in the robot's joint order, (m, n) rad.
            aux: the measurement rows (temperature, payload, time for the effects; its
                ``station`` column picks each row's station when ``station`` is None).
            station: station label for every row (default: ``aux``'s station column, else the
                default station).
            orientation: also return the probe orientation (rotation vector, rad): (m, 6).

        Raises:
            InputError: unknown station, wrong shape, joint values outside the limits.
        """
        Q = self.robot.check_q(np.atleast_2d(np.asarray(Q, float)), "predict: Q")
        delta = discrepancy_at(self.discrepancy, Q, False)[0] if self.discrepancy is not None else None
        return self.predict_rows(Q, aux, station, orientation, delta)

    def predict_rows(self, Q: np.ndarray, aux: MeasurementSet | None, station: str | None, orientation: bool,
                 delta: np.ndarray | None) -> np.ndarray:
        """:meth:`predict` of checked configurations with the discrepancy's mean ``delta`` (base frame, m) given."""
        m = Q.shape[0]
        if aux is not None and len(aux) != m:
            raise InputError(f"predict: {len(aux)} rows of auxiliary data for {m} configurations")
        if station is None and aux is not None and aux.station is not None:
            labels = [self.station(lab) for lab in dict.fromkeys(aux.station.tolist())]
            groups = [(lab, np.flatnonzero(aux.station == lab)) for lab in labels]
        else:
            groups = [(self.station(station), np.arange(m))]
        pairs = list(zip(self.effects, self.thetas))
        out = np.full((m, 6 if orientation else 3), np.nan)
        for lab, rows in groups:
            model, p = self.station_model(lab)
            sub = aux if (aux is None or rows.size == m) else aux.subset(rows)
            model = model.at_nests(nest_column(sub, model.n_nests)) if sub is not None and model.n_nests > 1 else model
            Y = predict_with_effects(model, p, Q[rows], sub, pairs)
            if orientation and Y.shape[1] < 6:
                raise InputError(f"station '{lab}' has no probe orientation: the model predicts positions only")
            out[rows] = Y[:, :out.shape[1]]
            if delta is not None:
                out[rows, :3] += delta[rows] @ self.setups[lab].tracker_T_base[:3, :3].T
        return out

    def predict_with_sigma(self, Q: np.ndarray, aux: MeasurementSet | None = None, station: str | None = None
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Predicted reflector positions with the standard deviation of measured − predicted.

        σ² per axis (tracker frame of the row's station) = diag(R_s V R_sᵀ), V the discrepancy's posterior variance
        and white level (tracker noise, repeatability), plus the parametric part's error (noise-only and white
        models at every row; a Gaussian process outside the training coverage, where its posterior does not hold
        it: docs/results.md), every σ of a station times its :attr:`Setup.sigma_scale`
        (:mod:`~pin_kpi_oed.calibrated.prediction_sigma`). At the TCP instead: :meth:`predict_tcp`.

        Args: Q, aux, station: as :meth:`predict`.
        Returns: (Y (m, 3) m, sigma (m, 3) m, extrapolation (m,) bool: outside the training's joint-space coverage).
        Raises: InputError: as :meth:`predict`.
        """
        from pin_kpi_oed.calibrated.prediction_sigma import predictive_sigma
        Q = self.robot.check_q(np.atleast_2d(np.asarray(Q, float)), "predict: Q")
        return predictive_sigma(self, Q, aux, station, self.row_stations(len(Q), aux, station))

    def predict_tcp(self, Q: np.ndarray, tcp_m: np.ndarray | None = None, station: str | None = None,
                    aux: MeasurementSet | None = None, frame: str = "cell", tolerances: Any = None) -> Any:
        """The TCP's position and the covariance of its error at configurations Q (rad): the one σ at the TCP,
        :func:`~pin_kpi_oed.calibrated.tcp_sigma.tcp_sigma` (the discrepancy, the parameters through the TCP's
        Jacobian and the joint-placement parameters held at nominal under their tolerance ``tolerances``).

        Args: Q, station, aux as :meth:`predict`; tcp_m: the point in the tool frame (m), default :attr:`tcp_m`;
        frame: ``cell`` (the station's tracker frame) or ``base`` (the robot base frame).
        Returns: a :class:`~pin_kpi_oed.calibrated.tcp_sigma.TcpSigma` (``position_m``, ``sigma_m``, ...).
        Raises: InputError as :meth:`predict`, or an unknown frame.
        """
        from pin_kpi_oed.calibrated.tcp_sigma import tcp_sigma
        return tcp_sigma(self, Q, tcp_m, station=station, aux=aux, frame=frame, tolerances=tolerances)

    def predict_orientation_with_sigma(self, Q: np.ndarray, aux: MeasurementSet | None = None,
                                       station: str | None = None, length_m: float = 0.0
                                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A 6-D model's predicted probe orientation with the σ of measured − predicted
        (:func:`~pin_kpi_oed.calibrated.prediction_sigma.orientation_sigma`; Q, aux, station as :meth:`predict`).

        Returns:
            (rotation vectors (m, 3) rad, σ per axis (m, 3) rad, both in the station's tracker frame; the 3-D σ (m,)
            m of the point ``length_m`` (m) along the tool axis that the orientation error moves).

        Raises:
            InputError: a position-only model or station, a negative length, as :meth:`predict`.
        """
        from pin_kpi_oed.calibrated.prediction_sigma import orientation_sigma
        Q = self.robot.check_q(np.atleast_2d(np.asarray(Q, float)), "predict: Q")
        return orientation_sigma(self, Q, aux, station, self.row_stations(len(Q), aux, station), length_m)

    @property
    def residual_sigma_m(self) -> np.ndarray | None:
        """The calibration's own residual level per axis (m; ``fit.residual_sigma_m``), or None if the file has none.

        A new session of the same robot is expected to fit about this well after its set-up is re-registered,
        whatever noise the model file states (a model written without the tracker's noise keeps its default).
        """
        level = self.fit.get("residual_sigma_m") if isinstance(self.fit, dict) else None
        return None if level is None else np.asarray(level, float).reshape(3)

    def row_stations(self, m: int, aux: MeasurementSet | None = None, station: str | None = None) -> np.ndarray:
        """The station label of each of ``m`` rows, as :meth:`predict` picks it: ``station`` for every row, else
        ``aux``'s station column, else the default station (object array of labels).

        Raises:
            InputError: an unknown station.
        """
        if station is None and aux is not None and aux.station is not None:
            return np.array([self.station(lab) for lab in aux.station.tolist()], dtype=object)
        return np.array([self.station(station)] * m, dtype=object)

    def noise_only(self) -> CalibratedModel:
        """A copy without the discrepancy and with every station's σ factor 1: the paper's noise-only model
        (its σ counts the tracker noise only), for contrast with the honest σ."""
        new = copy.copy(self)
        new.discrepancy = None
        new.setups = {lab: dataclasses.replace(st, sigma_scale=1.0) for lab, st in self.setups.items()}
        return new

    def with_setup(self, label: str, setup: Setup, default: bool = True, step: dict | None = None
                   ) -> CalibratedModel:
        """A copy with station ``label`` set to ``setup`` (added or replaced)."""
        new = copy.copy(self)
        new.setups = dict(self.setups)
        new.setups[str(label)] = setup
        new.default_station = str(label) if default else self.default_station
        new.history = list(self.history) + ([step] if step else [])
        return new

    # ------------------------------------------------------------------ files
    def to_dict(self) -> dict:
        """The model file content (plain numbers, SI units; see the module docstring).

        Raises:
            InputError: an effect that cannot be stored.
        """
        rb = self.robot
        L = ParameterLayout(list(rb.joint_names))
        nominal = [rb.model.jointPlacements[j] for j in rb.joint_ids]
        calibrated = [M * pin.exp6(self.joint_p[L.joint_slice(k)]) for k, M in enumerate(nominal)]
        return to_jsonable({
            "format": MODEL_FORMAT,
            "robot": {"spec": portable_spec(rb), "name": rb.name, "urdf_path": str(rb.urdf_path),
                      "tool_frame": rb.tool_frame, "joint_names": list(rb.joint_names),
                      "nominal_joint_placements": [M.homogeneous for M in nominal],
                      **({"kinematics": rb.kinematics.layout()} if rb.kinematics is not None else {})},
            "tcp_m": self.tcp_m,
            **({"tool_source": self.tool_source} if self.tool_source else {}),
            **({"q_work": self.q_work} if self.q_work is not None else {}),
            "pose6d": bool(self.pose6d),
            "geometry": {"joint_placement_errors": {n: float(v) for n, v in zip(L.names, self.joint_p)},
                         "joint_placements": [M.homogeneous for M in calibrated],
                         "parameters": self.parameters},
            "effects": [{**effect_spec(e), "theta": th, "unit": getattr(e, "unit", "")}
                        for e, th in zip(self.effects, self.thetas)],
            "stations": {lab: st.to_dict() for lab, st in self.setups.items()},
            "default_station": self.default_station,
            "noise": self.noise.to_dict(),
            "fit": self.fit,
            "history": self.history,
            **({"discrepancy": self.discrepancy.to_dict()} if self.discrepancy is not None else {}),
            **({"coverage": self.coverage.to_dict()} if self.coverage is not None else {}),
        })

    def save(self, path: str | os.PathLike) -> None:
        """Write the model file atomically (everything is serialised before anything is written)."""
        atomic_write_json(path, self.to_dict())

    @classmethod
    def from_dict(cls, d: Any, where: str = "model file") -> CalibratedModel:
        """Build the model from a model file's content.

        Raises:
            InputError: another format or version, a missing or malformed field (named),
                a robot whose URDF no longer matches the calibrated one.
        """
        _check_format(d, where)
        validate_model_dict(d, where)
        rob = d.get("robot")
        if not isinstance(rob, dict) or not (rob.get("spec") or rob.get("urdf_path")):
            raise InputError(f"{where}: field 'robot' must hold 'spec' (robot name or URDF path) and 'tool_frame'")
        robot = _load_model_robot(rob, where)
        geo = d.get("geometry") or {}
        errs = geo.get("joint_placement_errors")
        L = ParameterLayout(list(robot.joint_names))
        if not isinstance(errs, dict):
            raise InputError(f"{where}: field 'geometry.joint_placement_errors' is missing")
        missing = [n for n in L.names[:6 * robot.nq] if n not in errs]
        if missing:
            raise InputError(f"{where}: geometry.joint_placement_errors lacks {', '.join(missing[:3])}")
        joint_p = np.array([float(errs[n]) for n in L.names[:6 * robot.nq]])
        if not np.all(np.isfinite(joint_p)):
            raise InputError(f"{where}: geometry.joint_placement_errors has non-finite values")
        effects, thetas = [], []
        for i, spec in enumerate(d.get("effects") or []):
            eff = effect_from_spec(spec, robot, f"{where}: effects[{i}]")
            th = np.asarray(spec.get("theta", []), float).reshape(-1)
            if th.size != len(eff.param_names()) or not np.all(np.isfinite(th)):
                raise InputError(f"{where}: effects[{i}] ('{spec.get('name')}'): 'theta' must be "
                                 f"{len(eff.param_names())} finite numbers")
            effects.append(eff)
            thetas.append(th)
        st = d.get("stations")
        if not isinstance(st, dict) or not st:
            raise InputError(f"{where}: field 'stations' must name at least one station set-up")
        setups = {str(k): Setup.from_dict(v, f"{where}: stations.{k}") for k, v in st.items()}
        for k, v in setups.items():
            if v.registered_q_rad is not None and v.registered_q_rad.shape[1] != robot.nq:
                raise InputError(f"{where}: stations.{k}.registered_q_rad: {v.registered_q_rad.shape[1]} joint "
                                 f"values per row, the robot has {robot.nq}")
        default = d.get("default_station")
        if default is not None and str(default) not in setups:
            raise InputError(f"{where}: default_station '{default}' is not among the stations "
                             f"({', '.join(setups)})")
        try:
            noise = NoiseModel.from_dict(d.get("noise") or {})
        except (TypeError, ValueError) as exc:
            raise InputError(f"{where}: field 'noise': {exc}") from None
        tcp = np.asarray(d.get("tcp_m", [0.0, 0.0, 0.0]), float)
        if tcp.shape != (3,):
            raise InputError(f"{where}: field 'tcp_m' must be 3 numbers (m)")
        fit = _checked_fit(d.get("fit"), where)
        disc = None
        if d.get("discrepancy") is not None:
            disc = Discrepancy.from_dict(d["discrepancy"], robot.joint_names, f"{where}: discrepancy",
                                         robot.joint_units)
        q_work = d.get("q_work")
        if q_work is not None:
            try:
                q_work = np.asarray(q_work, float).reshape(-1, robot.nq)
            except (TypeError, ValueError):
                raise InputError(f"{where}: field 'q_work' must be a list of {robot.nq} joint values each "
                                 f"({', '.join(robot.joint_names)})") from None
        coverage = None
        if d.get("coverage") is not None:
            try:
                coverage = JointCoverage.from_dict(d["coverage"], robot.nq, f"{where}: coverage",
                                                   robot.periodic_joints)
            except ValueError as exc:
                raise InputError(str(exc)) from None
        return cls(robot, joint_p, effects, thetas, setups, noise, tcp, bool(d.get("pose6d", False)),
                   dict(geo.get("parameters") or {}), fit,
                   None if default is None else str(default), list(d.get("history") or []), disc,
                   q_work=q_work, tool_source=str(d.get("tool_source") or ""), coverage=coverage)


def _check_format(d: Any, where: str) -> None:
    fmt = d.get("format") if isinstance(d, dict) else None
    if fmt == MODEL_FORMAT:
        return
    if isinstance(fmt, str) and fmt.startswith(_FORMAT_NAME + "/"):
        raise InputError(f"{where}: model file format '{fmt}' is not supported by this version of pin_kpi_oed "
                         f"(it reads '{MODEL_FORMAT}')")
    raise InputError(f"{where}: not a pin_kpi_oed model file (field 'format' is {fmt!r}, expected '{MODEL_FORMAT}'; "
                     "write one with identify)")


def _load_model_robot(rob: dict, where: str) -> Robot:
    spec = str(rob.get("spec") or rob.get("urdf_path"))
    try:
        robot = load_robot(spec, rob.get("tool_frame"), kinematics=rob.get("kinematics"))
    except PinKpiOedError as exc:
        raise InputError(f"{where}: robot '{spec}': {exc}") from None
    names = rob.get("joint_names")
    if names is not None and list(names) != list(robot.joint_names):
        raise InputError(f"{where}: the robot '{spec}' has joints {', '.join(robot.joint_names)}, the model file "
                         f"{', '.join(map(str, names))}")
    nominal = rob.get("nominal_joint_placements")
    if nominal is not None:
        A = np.asarray(nominal, float)
        B = np.array([robot.model.jointPlacements[j].homogeneous for j in robot.joint_ids])
        if A.shape != B.shape or np.abs(A - B).max() > 1e-9:
            k = int(np.argmax(np.abs(A - B).reshape(len(B), -1).max(axis=1))) if A.shape == B.shape else 0
            raise InputError(f"{where}: the URDF of robot '{spec}' differs from the one calibrated (joint "
                             f"{robot.joint_names[k]}'s nominal placement changed): load the model with that URDF")
    return robot


def _checked_fit(fit: Any, where: str) -> dict:
    """A model file's ``fit`` block with its residual levels checked: ``residual_sigma_m`` (3 sigmas in m) and a 6-D
    fit's ``residual_sigma_rad`` (3 sigmas in rad)."""
    fit = dict(fit or {})
    for key, check, unit in (("residual_sigma_m", check_sigma_m, "m"), ("residual_sigma_rad", check_sigma_rad, "rad")):
        if fit.get(key) is not None:
            fit[key] = check(fit[key], f"{where}: field fit.{key}")
            if fit[key].size != 3:
                raise InputError(f"{where}: field fit.{key} must be 3 numbers ({unit} per axis)")
    return fit


def load_model_file(path: str | os.PathLike) -> CalibratedModel:
    """Read a calibrated model file (``identify --model-out``, ``register --model-out``).

    Args: path: the JSON file.  Returns: the :class:`CalibratedModel`.

    Raises:
        InputError: missing or unreadable file, not JSON, another format or version, a
            missing or malformed field (named with the file).
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(f"model file '{p}' does not exist")
    try:
        d = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{p}: cannot read the model file ({exc})") from None
    except json.JSONDecodeError as exc:
        raise InputError(f"{p}: not a JSON file (line {exc.lineno}: {exc.msg})") from None
    return CalibratedModel.from_dict(d, str(p))
