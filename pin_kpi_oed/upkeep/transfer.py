r"""Transfer of a calibration to another day: re-register the set-up, predict, score.

A calibration holds the robot (geometry + effects) and the set-up of the stations it was
measured from. On another day the tracker stands elsewhere (and the reflector may have been
re-mounted): :func:`register_setup` re-fits **only** the set-up — the tracker pose T (6) and,
unless held, the reflector offset r (3) (and a 6-D probe's orientation) — on a few rows of the
new session, with the robot held at its calibrated values:

.. math::

    \min_{T, r} \sum_i \bigl\lVert Σ_i^{-1}\bigl(T · \mathrm{oMtool}(δ, q_i + ΣΔq_i(θ)) · r
        + ΣΔy_i(θ) + R_T\,\bar d(q_i) − η_i\bigr)\bigr\rVert^2,

from a Kabsch/Umeyama registration of the calibrated forward kinematics onto the measured
points (:func:`pin_kpi_oed.identification.identify.register_points`), by Levenberg–Marquardt
with the analytic Jacobian (:class:`~pin_kpi_oed.identification.problem.ResidualModel` with
the effects *held*). \bar d(q) is the model's discrepancy mean (base frame, rotated by the tracker pose R_T; 0
without a discrepancy): the set-up is fitted to the same full prediction :meth:`CalibratedModel.predict` makes
with it (the Jacobian leaves out R_T's lever on \bar d, sub-millimetre against the arm's metres; the
minimum is checked by perturbing the tracker pose in the tests). :func:`validate_transfer` does what an
engineer does: register on some rows (a seeded random subset of the validation file, or another file)
and score the rest.

Set-up-specific effects (``setup_specific = True``, e.g. :class:`~pin_kpi_oed.effects.drift.Drift`)
describe one session, not the robot: they are not held (the new session's rows would have
none of their parameters); ``setup_effects`` are fitted *with* the set-up instead, and the
registered model carries them in place of the old ones.

A registration set that cannot determine the set-up is refused: fewer than 3 points, or a
set-up Jacobian without full column rank (e.g. all rows at one configuration, or collinear
points) — one line naming the file, the rows and the undetermined parameter.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import os
import time
from dataclasses import dataclass, field
from typing import Any
from collections.abc import Sequence

import numpy as np
import pinocchio as pin
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from pin_kpi_oed.data.atomic import atomic_write_text
from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.effects.library import predict_with_effects
from pin_kpi_oed.errors import InputError, SolverError
from pin_kpi_oed.identification.fit_inputs import MIN_STATION_ROWS, default_station_label
from pin_kpi_oed.identification.heldout import calibration_stats, error_stats
from pin_kpi_oed.identification.tracker_start import proj_so3, register_points
from pin_kpi_oed.calibrated.model_file import CalibratedModel, Setup
from pin_kpi_oed.calibrated.prediction_sigma import DEFAULT_TOOL_LENGTH_M, with_registered_station
from pin_kpi_oed.calibrated.shared_tables import discrepancy_at
from pin_kpi_oed.identification.problem import ResidualModel, StationSet, align_data
from pin_kpi_oed.model.nests import nest_column
from pin_kpi_oed.model.parameters import ParameterLayout
from pin_kpi_oed.results import Result

__all__ = ["RegistrationResult", "register_setup", "registration_split", "validate_transfer", "predict_table",
           "tcp_table", "write_predictions"]


@dataclass
class RegistrationResult(Result):
    """Outcome of :func:`register_setup` (common fields of :class:`~pin_kpi_oed.results.Result`).

    Attributes:
        model: the calibrated model with the registered set-up(s) added (the last one the default).
        stations: the registered station labels.
        setups: label -> the registered :class:`Setup`.
        rows: label -> indices (0-based) of the rows of the given data used.
        errors_m: position error norm of every given row after the registration (m).
        source: file the rows came from.
        setup_thetas: fitted parameters of the ``setup_effects`` of the registration (one array each).
        notes: one line per station whose rows did not determine the reflector (the calibration's was kept).
        quality: the registration gate of every station against the calibration's own level
            (:func:`~pin_kpi_oed.upkeep.registration_check.registration_gates`; what ``register`` refuses
            on): :attr:`poor` flags a registration whose model must not be used without a look at the cause.
    """

    model: CalibratedModel = field(repr=False, default=None)
    stations: list = field(default_factory=list)
    setups: dict = field(default_factory=dict)
    rows: dict = field(default_factory=dict)
    errors_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    source: str = ""
    setup_thetas: list = field(default_factory=list)
    quality: list = field(default_factory=list)
    notes: list = field(default_factory=list)

    @property
    def poor(self) -> bool:
        """A station's registration failed its gate (see :attr:`quality`: the line names the cause and the fix)."""
        return any(q.poor for q in self.quality)

    @property
    def rms_m(self) -> float:
        """RMS position error of the registration rows (m)."""
        return float(np.sqrt(np.mean(self.errors_m ** 2))) if self.errors_m.size else float("nan")

    def summary(self) -> str:
        """Readable lines (mm)."""
        out = [f"registered {len(self.stations)} set-up(s) on {self.errors_m.size} rows of {self.source or 'data'} "
               f"(robot held): RMS {self.rms_m * 1e3:.4f} mm, {self.nit} iterations, {self.time_s * 1e3:.0f} ms"]
        for lab in self.stations:
            st = self.setups[lab]
            T = st.tracker_T_base
            out.append(f"  station {lab} ({st.n_rows} rows, RMS {st.rms_m * 1e3:.4f} mm): tracker_T_base xyz "
                       f"{np.round(T[:3, 3], 6).tolist()} m, rpy {np.round(pin.rpy.matrixToRpy(T[:3, :3]), 6).tolist()}"
                       f" rad; reflector {np.round(st.reflector_m * 1e3, 4).tolist()} mm")
            out += [f"  {n}" for n in self.notes if f"station '{lab}'" in n]
            gate = next((q for q in self.quality if q.station == lab), None)
            if gate is not None:
                out.append(f"  {gate.line()}")
            if st.sigma_scale > 1.0:
                out.append(f"  station {lab}: predicted σ scaled by {st.sigma_scale:.2f}: "
                           f"its registration rows' errors "
                           f"are {st.sigma_scale:.2f}x the model's σ (another session than the calibration)")
        return "\n".join(out)

    def to_dict(self) -> dict:
        """Plain JSON-able dict (SI units)."""
        return {**self.result_dict(), "stations": list(self.stations), "source": self.source,
                "setups": {k: v.to_dict() for k, v in self.setups.items()},
                "rows": {k: (np.asarray(v) + 1).tolist() for k, v in self.rows.items()}, "rms_m": self.rms_m,
                "quality": [q.to_dict() for q in self.quality], "poor": self.poor, "notes": list(self.notes)}


def _groups(model: CalibratedModel, data: MeasurementSet, station: str | None) -> dict[str, np.ndarray]:
    if station is not None:
        return {str(station): np.arange(len(data))}
    return data.station_rows(default_station_label(data))


def transferable(model: CalibratedModel) -> list[tuple[Any, np.ndarray]]:
    """``[(effect, θ), ...]`` of the model's robot effects (the set-up-specific ones left out)."""
    return [(e, np.asarray(t, float)) for e, t in zip(model.effects, model.thetas)
            if not getattr(e, "setup_specific", False)]


class _DiscrepancyMean:
    """The discrepancy's mean δ(q) (base frame) as a held tool offset R_T δ(q) (tracker frame), so that the set-up
    is fitted to the model's full prediction, the one :meth:`CalibratedModel.predict` makes (no parameters)."""

    name = "discrepancy_mean"
    setup_specific = False

    def __init__(self, discrepancy: Any):
        self.discrepancy = discrepancy
        self._cache: tuple[bytes, np.ndarray] | None = None

    def _delta(self, Q: np.ndarray) -> np.ndarray:
        key = np.ascontiguousarray(Q).tobytes()
        if self._cache is None or self._cache[0] != key:
            self._cache = (key, np.asarray(discrepancy_at(self.discrepancy, Q, False)[0], float))
        return self._cache[1]

    def joint_offset(self, theta: np.ndarray, Q: np.ndarray, aux: Any = None) -> tuple[np.ndarray, np.ndarray]:
        Q = np.atleast_2d(np.asarray(Q, float))
        return np.zeros(Q.shape), np.zeros(Q.shape + (0,))

    def tool_offset(self, theta: np.ndarray, Q: np.ndarray, aux: Any = None, model: Any = None,
                    p: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        Q = np.atleast_2d(np.asarray(Q, float))
        R = np.eye(3) if model is None else model.tracker_pose(p).rotation
        return self._delta(Q) @ R.T, np.zeros((Q.shape[0], 3, 0))


#: the registration rows do not determine the reflector when its σ exceeds this many times their residual level
REFLECTOR_UNDETERMINED = 10.0


def _register_one(model: CalibratedModel, data: MeasurementSet, Q: np.ndarray, label: str, hold_reflector: bool,
                  weights: str, use_orientation: bool, tol: float, max_nfev: int | None,
                  setup_effects: Sequence[Any] = ()) -> tuple[Setup, Any]:
    """Kabsch start + Levenberg–Marquardt over one station's set-up with the robot held."""
    src = data.source or "registration data"
    m = len(data)
    if m < MIN_STATION_ROWS:
        raise InputError(f"{src}: station '{label}': {m} registration row(s) are too few to determine the set-up "
                         f"(tracker pose: at least {MIN_STATION_ROWS} points)")
    ref = model.setups.get(label)
    if ref is None:  # a new station starts from the default (or first) station's reflector
        default = model.default_station if model.default_station in model.setups else next(iter(model.setups))
        ref = model.setups[default]
    pose6d = bool(use_orientation and model.pose6d and data.rotvec_rad is not None and ref.probe_R is not None)
    L = ParameterLayout(list(model.robot.joint_names), pose6d=pose6d)
    pairs = transferable(model)
    cm = CalibratedModel(model.robot, model.joint_p, [e for e, _ in pairs], [t for _, t in pairs],
                         {label: Setup(np.eye(4), ref.reflector_m, ref.probe_R if pose6d else None,
                                       nests_m=ref.nests_m)},
                         model.noise, model.tcp_m, pose6d)
    wm, p = cm.station_model(label)
    if model.discrepancy is not None:  # the prediction the registered model makes: the discrepancy's mean on top
        pairs = pairs + [(_DiscrepancyMean(model.discrepancy), np.zeros(0))]
    X = predict_with_effects(wm.at_nests(nest_column(data, wm.n_nests)), p, Q, data, pairs)[:, :3]  # base frame
    use_sigma = data.sigma_m is not None and weights in ("auto", "data")
    sigma = np.asarray(data.sigma_m, float) if use_sigma else None
    R, t = register_points(X, data.position_m, None if sigma is None else 1.0 / np.mean(sigma ** 2, 1))
    wm.tracker_T_base = pin.SE3(R, t)
    if pose6d:
        kin = wm.kinematics(p, Q, wm.reflector(p))
        Rm = Rotation.from_rotvec(data.rotvec_rad).as_matrix()
        wm.probe_R = proj_so3(np.einsum("mba,bc,mcd->ad", kin.R_tool, R.T, Rm))
    base = np.r_[np.arange(L.tracker.start, L.tracker.stop),
                 [] if hold_reflector else np.arange(L.reflector.start, L.reflector.stop),
                 np.arange(L.probe.start, L.probe.stop)].astype(int)
    prob = ResidualModel(StationSet.single(wm, label), data, base, list(setup_effects), sigma=sigma, p_ref=p, Q=Q,
                         held=pairs)
    J0 = prob.jacobian_full(prob.x0()).reshape(-1, prob.nx)
    if J0.shape[0] < prob.nx:
        raise InputError(f"{src}: station '{label}': {m} registration rows give {J0.shape[0]} equations for the "
                         f"{prob.nx} set-up parameters; add rows")
    norms = np.linalg.norm(J0, axis=0)
    _, s, Vt = np.linalg.svd(J0 / np.where(norms > 0, norms, 1.0), full_matrices=False)
    if s[-1] < 1e-8 * s[0]:
        who = prob.names[int(np.argmax(np.abs(Vt[-1])))]
        raise InputError(f"{src}: station '{label}': the {m} registration rows do not determine the set-up "
                         f"('{who}' is free: rank {int(np.sum(s >= 1e-8 * s[0]))} of {prob.nx}); use rows spread "
                         "over the workspace" + ("" if hold_reflector else ", or hold the reflector"))
    try:
        sol = least_squares(prob.residual, prob.x0(), jac=prob.jacobian, method="lm", x_scale="jac", ftol=tol,
                            xtol=tol, gtol=tol, max_nfev=max_nfev or 50 * prob.nx)
    except (ValueError, np.linalg.LinAlgError) as exc:
        raise SolverError(f"{src}: registration failed: {str(exc).splitlines()[0]}") from None
    if not np.all(np.isfinite(sol.x)):
        raise SolverError(f"{src}: registration diverged; check the joint order and units (m, rad)")
    P, th_own = prob.unpack(sol.x)
    err = np.linalg.norm(prob.evaluate(sol.x)[0], axis=1)
    R_probe = wm.probe_R @ pin.exp3(P[L.probe]) if pose6d else None
    setup = Setup(wm.tracker_pose(P).homogeneous.copy(), wm.reflector(P), R_probe, m, "register", data.source,
                  float(np.sqrt(np.mean(err ** 2))), registered_q_rad=np.asarray(Q, float),
                  nests_m=None if ref.nests_m is None else ref.nests_m - ref.nests_m[0] + wm.reflector(P))
    noise_m = float(np.sqrt(np.mean(np.sum(1.0 / prob.W[:, :3] ** 2, axis=1))))  # the weights' 3-D σ
    note = "" if hold_reflector else _undetermined_reflector(sol, prob.names, setup, ref.reflector_m, label, src,
                                                             noise_m)
    return setup, (sol, err, th_own, note)


def _undetermined_reflector(sol: Any, names: Sequence[str], setup: Setup, reflector_cal_m: np.ndarray, label: str,
                            src: str, noise_m: float) -> str:
    """The one-line note when the registration rows do not determine the reflector, else "".

    The reflector's covariance from the registration's Jacobian, C = (JᵀJ)⁻¹ · max(1, χ²/dof) (its 3×3 block); the
    rows do not determine the reflector when σ along its worst direction, √λ_max(C_rr), exceeds
    :data:`REFLECTOR_UNDETERMINED` times the level they are fitted to (their residual RMS, at least the noise the
    weights state): rows that barely turn the flange axis leave the reflector's offset along it free against the
    tracker translation (the IPA UR10's Series D, 60 rows: σ 44 mm against a 0.93 mm RMS; rows that turn the flange:
    below half their RMS). The calibration's reflector, fitted on rows that turn the flange, is then the better
    value: :func:`register_setup` keeps it.
    """
    idx = [i for i, n in enumerate(names) if str(n).startswith("reflector.")]
    J = np.asarray(sol.jac, float)
    dof = J.shape[0] - J.shape[1]
    if len(idx) != 3 or dof <= 0 or setup.rms_m is None:
        return ""
    C = np.linalg.pinv(J.T @ J) * max(1.0, 2.0 * float(sol.cost) / dof)
    w, V = np.linalg.eigh(C[np.ix_(idx, idx)])
    sigma = float(np.sqrt(max(w[-1], 0.0)))
    level = max(float(setup.rms_m), float(noise_m))
    if not sigma > REFLECTOR_UNDETERMINED * level:
        return ""
    axis = V[:, -1] * np.sign(V[np.argmax(np.abs(V[:, -1])), -1])
    moved = float(np.linalg.norm(setup.reflector_m - np.asarray(reflector_cal_m, float)))
    return (f"registration of station '{label}' on {src}: the reflector is poorly determined by these "
            f"{setup.n_rows} rows (σ {sigma * 1e3:.1f} mm along {np.round(axis, 2).tolist()} of the tool frame, "
            f"over {REFLECTOR_UNDETERMINED:g}x their {level * 1e3:.3f} mm residual level: the flange axis barely "
            f"turns); fitted free it "
            f"moves {moved * 1e3:.1f} mm from the calibration's, so the calibration's reflector is kept — measure "
            f"rows turning the flange to register a new one")


def register_setup(model: CalibratedModel, data: MeasurementSet, *, station: str | None = None,
                   hold_reflector: bool = False, weights: str = "auto", use_orientation: bool = True,
                   tol: float = 1e-12, max_nfev: int | None = None, setup_effects: Sequence[Any] = (),
                   check: bool = True) -> RegistrationResult:
    """Re-fit only the set-up (tracker pose, reflector) of a station on ``data``, the robot held.

    Args:
        model: the calibrated model (geometry + effects are held).
        data: the registration rows (joint columns, x, y, z).
        station: label of the (new or re-fitted) station for all rows; default the data's
            ``station`` column (one set-up per label), else the file name without extension.
        hold_reflector: keep the reflector offset (fit the tracker pose only); rows that do not determine it keep
            the calibration's too (:func:`_undetermined_reflector`, said in :attr:`RegistrationResult.notes`).
        weights: ``auto`` (sigma columns if present, else the model's noise), ``data`` or ``noise``.
        use_orientation: use rx, ry, rz when both the model and the data have them.
        tol, max_nfev: solver tolerances, evaluation limit (default 50 × unknowns). setup_effects: the new
            session's set-up effects (``Drift.from_data(robot, data)``), fitted with the set-up (one station only).
        check: judge every station's registration against the calibration's own level (``quality``, ``poor``;
            a poor one with its tested cause, which registers the rows once more with the geometry alone).

    Returns:
        The :class:`RegistrationResult`; ``.model`` holds the new set-up(s), the last the default,
        and the robot effects plus ``setup_effects`` (with their fitted θ, also in ``setup_thetas``).

    Raises:
        InputError: missing joint columns, bad values, fewer than 3 rows, or rows that do not determine the
            set-up (rank-deficient), naming the file, station and parameter. SolverError: diverged.
    """
    t0 = time.perf_counter()
    if weights not in ("auto", "data", "noise"):
        raise InputError(f"weights must be auto, data or noise, got '{weights}'")
    if weights == "data" and data.sigma_m is None:
        raise InputError(f"{data.source or 'registration data'}: weights='data' but the file has no sigma columns")
    Q = align_data(model.robot, data)
    groups = _groups(model, data, station)
    setup_effects = list(setup_effects)
    if setup_effects and len(groups) > 1:
        raise InputError(f"{data.source or 'registration data'}: set-up effects are fitted for one station at a "
                         f"time; the data have {len(groups)} ({', '.join(groups)}); give station=")
    robot_pairs = transferable(model)
    new = model
    own_thetas: list[np.ndarray] = []
    setups: dict[str, Setup] = {}
    rows_used: dict[str, np.ndarray] = {}
    errors, notes = np.zeros(len(data)), []
    nit = nfev = 0
    ok = True
    for label, rows in groups.items():
        sub = data if rows.size == len(data) else data.subset(rows)
        args = (weights, use_orientation, tol, max_nfev, setup_effects)
        setup, (sol, err, own_thetas, note) = _register_one(model, sub, Q[rows], label, hold_reflector, *args)
        if note:  # the rows do not determine the reflector: the calibration's is kept
            setup, (sol, err, own_thetas, _) = _register_one(model, sub, Q[rows], label, True, *args)
            notes.append(note)
        errors[rows] = err
        nit += int(sol.njev or 0)
        nfev += int(sol.nfev)
        ok &= bool(sol.status > 0)
        new = with_registered_station(new, label, setup, sub, Q[rows], int(sol.x.size),
                                      {"step": "register", "data": data.source, "station": label,
                                       "n_rows": int(rows.size), "rms_m": setup.rms_m,
                                       "hold_reflector": bool(hold_reflector or note)})
        setups[label] = setup
        rows_used[label] = rows
    if setup_effects or len(robot_pairs) != len(model.effects):
        pairs = robot_pairs + list(zip(setup_effects, own_thetas))
        new = dataclasses.replace(new, effects=[e for e, _ in pairs], thetas=[t for _, t in pairs])
    res = RegistrationResult(success=ok, status="converged" if ok else "max_nfev",
                             message="set-up registered with the robot held", nit=nit, nfev=nfev,
                             time_s=time.perf_counter() - t0, model=new, stations=list(setups), setups=setups,
                             rows=rows_used, errors_m=errors, source=data.source,
                             setup_thetas=[np.asarray(t, float) for t in own_thetas], notes=notes)
    if check:
        from pin_kpi_oed.upkeep.registration_check import registration_gates

        res.quality = registration_gates(res, data, model, hold_reflector, register=register_setup)
        res.time_s = time.perf_counter() - t0
    return res


def registration_split(n: int, register_rows: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A seeded random choice of ``register_rows`` of ``n`` rows for registration; the rest are scored.

    Returns:
        (registration row indices, scored row indices), each sorted (0-based).

    Raises:
        InputError: fewer than 3 registration rows, or none left to score.
    """
    k = int(register_rows)
    if k < MIN_STATION_ROWS:
        raise InputError(f"register_rows {k}: at least {MIN_STATION_ROWS} rows are needed to determine the set-up")
    if k >= n:
        raise InputError(f"register_rows {k}: the validation data have only {n} rows, none would be left to score")
    perm = np.random.default_rng(seed).permutation(n)
    return np.sort(perm[:k]), np.sort(perm[k:])


def validate_transfer(model: CalibratedModel, data: MeasurementSet, *, register_rows: int | None = None,
                      register_data: MeasurementSet | None = None, seed: int = 0, hold_reflector: bool = False,
                      weights: str = "auto") -> dict:
    """Score a calibration on another session: register the set-up on some rows, score the rest.

    Args:
        model: the calibrated model.
        data: the other session's measurements.
        register_rows: register on this many seeded random rows of ``data``, score the others; or
        register_data: register on these rows (another file) and score all of ``data``.
        seed: seed of the random registration rows.
        hold_reflector: keep the reflector offset of the model.
        weights: as :func:`register_setup`.

    Returns:
        Statistics of the scored rows (:func:`error_stats`: ``n``, ``mean_m``, ``rms_m``, ``median_m``,
        ``p95_m``, ``max_m``, ``errors_m``), how honest the predicted σ is there
        (:func:`~pin_kpi_oed.identification.heldout.calibration_stats`: ``z_rms``, ``inside_95``,
        ``sigma_mean_m``, ``extrapolation_share``; ``sigma_scale`` of the registration; per scored row
        ``residuals_m`` and ``sigma_axes_m``, (m, 3)) plus ``registration``:
        ``source``, ``rows`` (1-based
        row numbers of the registration rows in their file), ``n``, ``rms_m``, ``seed``, the
        ``setup``; and ``scored_rows`` (1-based row numbers of ``data`` scored).

    Raises:
        InputError: neither or both of ``register_rows`` / ``register_data``, too few rows.
    """
    if (register_rows is None) == (register_data is None):
        raise InputError("transfer validation: give either register_rows (a number of rows) or register_data "
                         "(a file of rows), not both and not neither")
    label = "transfer"
    if register_data is not None:
        reg, held = register_data, data
        reg_idx, held_idx = np.arange(len(reg)), np.arange(len(data))
    else:
        reg_idx, held_idx = registration_split(len(data), register_rows, seed)
        reg, held = data.subset(reg_idx), data.subset(held_idx)
    rr = register_setup(model, reg, station=label, hold_reflector=hold_reflector, weights=weights)
    Q = align_data(model.robot, held)
    pred = rr.model.predict_with_sigma(Q, held, station=label)
    out = error_stats(np.linalg.norm(held.position_m - pred[0], axis=1))
    out.update(calibration_stats(rr.model, Q, held, prediction=pred))
    out["residuals_m"], out["sigma_axes_m"] = held.position_m - pred[0], pred[1]
    out["sigma_scale"] = rr.setups[label].sigma_scale
    out["registration"] = {"source": reg.source, "rows": (reg_idx + 1).tolist(), "n": int(len(reg)),
                           "rms_m": rr.rms_m, "seed": int(seed) if register_data is None else None,
                           "setup": rr.setups[label].to_dict(), "hold_reflector": bool(hold_reflector or rr.notes),
                           "notes": list(rr.notes)}
    out["scored_rows"] = (held_idx + 1).tolist()
    return out


def predict_table(model: CalibratedModel, data: MeasurementSet, station: str | None = None,
                  tool_length_m: float = DEFAULT_TOOL_LENGTH_M, at: str = "reflector",
                  tcp_m: np.ndarray | None = None) -> tuple[list[str], np.ndarray]:
    """Per row of ``data``: predicted reflector x, y, z (m, tracker frame), measured x, y, z and error if present.

    Args:
        model: the calibrated model.
        data: joint values (and measured positions, optional); its ``station`` column picks the
            set-up per row unless ``station`` is given.
        station: station label for every row (default: the data's column, else the model's default).
        at: ``reflector`` (what a tracker measures) or ``tcp``: the TCP ``tcp_m`` (tool frame, m; default the
            model's) with the σ of :meth:`CalibratedModel.predict_tcp` (:func:`tcp_table`).

    Returns:
        (column names, table (m, k)): ``x_pred, y_pred, z_pred``, ``sigma_x, sigma_y, sigma_z`` (m: the
        standard deviation of measured − predicted per axis, discrepancy posterior and white level included;
        :meth:`CalibratedModel.predict_with_sigma`), ``extrapolation`` (1 where a joint angle lies outside the
        training coverage) and, when the data have positions, ``x, y, z, error`` (m; error = |measured − predicted|).
        A 6-D model adds the probe orientation ``rx_pred, ry_pred, rz_pred`` (rotation vector, rad, tracker frame),
        ``sigma_rx, sigma_ry, sigma_rz`` (rad), ``sigma_at_length`` (m: the 3-D σ of the point ``tool_length_m``
        along the tool axis that the orientation error moves; :meth:`CalibratedModel.predict_orientation_with_sigma`)
        and, when the data have orientations, ``rot_error`` (rad, the angle of measured · predicted⁻¹).

    Raises:
        InputError: the data's joint names do not match the model's robot, an unknown station,
            values outside the joint limits.
    """
    names = list(model.robot.joint_names)
    if list(data.joint_names) != names and sorted(data.joint_names) != sorted(names):
        raise InputError(f"{data.source or 'data'}: joint columns {', '.join(data.joint_names)} do not match the "
                         f"model's robot {model.robot.name} ({', '.join(names)})")
    Q = align_data(model.robot, data, need_position=False)
    if at != "reflector":
        return tcp_table(model, Q, data, station, at, tcp_m)
    Y, sig, extra = model.predict_with_sigma(Q, data, station=station)
    cols = ["x_pred", "y_pred", "z_pred", "sigma_x", "sigma_y", "sigma_z", "extrapolation"]
    table = [Y, sig, extra.astype(float)[:, None]]
    if data.has_position:
        cols += ["x", "y", "z", "error"]
        table += [data.position_m, np.linalg.norm(data.position_m - Y, axis=1)[:, None]]
    if model.pose6d:
        W, sw, sl = model.predict_orientation_with_sigma(Q, data, station=station, length_m=tool_length_m)
        cols += ["rx_pred", "ry_pred", "rz_pred", "sigma_rx", "sigma_ry", "sigma_rz", "sigma_at_length"]
        table += [W, sw, sl[:, None]]
        if data.rotvec_rad is not None:
            err = (Rotation.from_rotvec(data.rotvec_rad) * Rotation.from_rotvec(W).inv()).magnitude()
            cols.append("rot_error")
            table.append(err[:, None])
    return cols, np.hstack(table)


def tcp_table(model: CalibratedModel, Q: np.ndarray, data: MeasurementSet, station: str | None, at: str = "tcp",
              tcp_m: np.ndarray | None = None) -> tuple[list[str], np.ndarray]:
    """:func:`predict_table` at the TCP: per row ``x_pred, y_pred, z_pred`` (the TCP, m, tracker frame),
    ``sigma_x, sigma_y, sigma_z`` (m, per axis), ``sigma_tcp`` (m, 3-D), ``sigma_held`` (m, 3-D: the part of the
    joint-placement parameters no reflector measurement determines) and ``extrapolation``: the one σ at the TCP
    (:func:`~pin_kpi_oed.calibrated.tcp_sigma.tcp_sigma`), per station of the rows. Measured positions are the
    reflector's and are not compared.

    Raises:
        InputError: ``at`` neither ``reflector`` nor ``tcp``; as :func:`predict_table`.
    """
    if at != "tcp":
        raise InputError(f"at={at!r}: must be 'reflector' or 'tcp'")
    labels = model.row_stations(len(Q), data, station)
    table = np.empty((len(Q), 9))
    for lab in dict.fromkeys(labels):
        rows = np.flatnonzero(labels == lab)
        ts = model.predict_tcp(Q[rows], tcp_m, lab, data if rows.size == len(Q) else data.subset(rows))
        sd = np.sqrt(np.maximum(np.einsum("maa->ma", ts.covariance_m2), 0.0))
        table[rows] = np.hstack([ts.position_m, sd, ts.sigma_m[:, None], ts.held_sigma_m[:, None],
                                 ts.extrapolation.astype(float)[:, None]])
    return ["x_pred", "y_pred", "z_pred", "sigma_x", "sigma_y", "sigma_z", "sigma_tcp", "sigma_held",
            "extrapolation"], table


def write_predictions(path: str | os.PathLike, data: MeasurementSet, cols: list[str], table: np.ndarray) -> None:
    """Write a prediction table as CSV atomically: the joint columns of ``data``, a ``station`` column if it
    has one, then ``cols`` (floats as ``repr``)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    head = list(data.joint_names) + (["station"] if data.station is not None else []) + list(cols)
    w.writerow(head)
    for i in range(len(data)):
        row = [repr(float(v)) for v in data.q[i]]
        if data.station is not None:
            row.append(str(data.station[i]))
        row += [repr(float(v)) for v in table[i]]
        w.writerow(row)
    atomic_write_text(path, buf.getvalue())
