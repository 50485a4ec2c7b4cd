r"""What a check asks of a calibrated model on its rows, answered in one pass.

A check (``upkeep/check.py``) compares measured rows with a calibrated model whose set-up was registered on them.
Everything it needs of the model is asked here, once per question, so that the check works on arrays and on the
model only to apply a change:

* the rows' configurations in the robot's joint order (:func:`~pin_kpi_oed.model.measured_joints.align_data`), the
  reference station resolved, the working configurations defaulted (the reference model's, else the rows');
* the predictions Y of the rows at the registered station and their joint honest covariance Σ = LLᵀ
  (:func:`~pin_kpi_oed.calibrated.prediction_sigma.predictive_covariance`, the registration's σ factor left out: it
  would hide the change under test), the residuals and the station's Jacobian whitened by L;
* against a reference station (the model's own set-up): its whitened residuals and the displacement of the working
  TCPs between the two set-ups;
* at the working configurations W: the KPI Jacobian E_W, the TCP σ in two parts
  (:func:`~pin_kpi_oed.calibrated.tcp_sigma.tcp_sigma`: what the calibration determined, and the joint-placement
  parameters held at nominal), and the check criterion of the model's parameter groups
  (:func:`check_criterion`);
* the law of the check's statistic under no change (:func:`check_null`, the model's own K-fold held-out errors);
* a model with a change applied on the same rows (:func:`rows_chi2`: its T, the set-up re-registered or held).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg as sla

from pin_kpi_oed.calibrated.prediction_sigma import predictive_covariance
from pin_kpi_oed.calibrated.tcp_sigma import tcp_sigma
from pin_kpi_oed.model.measured_joints import align_data
from pin_kpi_oed.model.noise import NoiseModel
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.oed.check_power import CheckNull, CheckPower, check_groups

__all__ = ["CheckView", "check_view", "rows_chi2", "check_criterion", "check_null", "whiten", "project_out",
           "NULL_FACTOR_RANGE", "NULL_KURTOSIS_RANGE"]

#: Bounds of the fields of a model file's K-fold check the check's law of T depends on (checked on reading too).
NULL_FACTOR_RANGE = (0.5, 3.0)
NULL_KURTOSIS_RANGE = (0.0, 10.0)


@dataclass
class CheckView:
    """A calibrated model seen on check rows (SI units; module docstring).

    Attributes:
        Y: predictions of the rows at the registered station (m, 3) m; Sigma: their joint honest covariance
            (3m, 3m) m²; sig: its marginal σ (m, 3) m.
        z: whitened residuals under the registered set-up after the set-up's generalised least-squares step (the
            set-up's columns of F projected out; T = ‖z‖²) (3m,); F: whitened Jacobian of the rows (3m, np).
        wm, p: the registered station's measurement model (noise σ = the rows' median honest σ per axis when the
            working configurations were asked for) and its raw parameter vector.
        z_old: whitened residuals under the reference station's set-up (3m,), or None without a reference;
            setup_distance: ‖P_G z_old‖², the set-up's step in its own metric (χ²(6) under no change), NaN without.
        shift: displacement of the working TCPs from the reference set-up to the registered one (3t,) m, or None.
        E_w: KPI Jacobian at the working configurations (3t, np), or None without them.
        tcp_sigma_m, tcp_held_m: the TCP σ per working configuration (t,) m: the part the calibration determined
            and the part of the joint-placement parameters held at nominal (empty without working configurations).
        crit: the check criterion of the model's parameter groups, or None without working configurations.
        null: the law of the check's statistic under no change.
        Q: the rows' configurations in the robot's joint order (m, n) rad; old: the reference station, or None.
        qw: the working configurations (t, n) rad, or None.
    """

    Y: np.ndarray
    Sigma: np.ndarray
    sig: np.ndarray
    z: np.ndarray
    F: np.ndarray
    wm: TrackerModel
    p: np.ndarray
    null: CheckNull
    z_old: np.ndarray | None = None
    setup_distance: float = float("nan")
    shift: np.ndarray | None = None
    E_w: np.ndarray | None = None
    tcp_sigma_m: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))
    tcp_held_m: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))
    crit: CheckPower | None = None
    Q: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 0)))
    old: str | None = None
    qw: np.ndarray | None = None


def check_view(cm: Any, data: Any, Q: np.ndarray | None, station: str, *,
               reference: tuple[Any, str | None] | None = None, q_work: np.ndarray | None = None,
               default_work: bool = False, seed: int = 0) -> CheckView:
    """The calibrated model on check rows (module docstring).

    Args:
        cm: the :class:`~pin_kpi_oed.calibrated.model_file.CalibratedModel` with the set-up registered on the rows;
            station: that set-up's station.
        data: the check rows (:class:`~pin_kpi_oed.data.measurements.MeasurementSet`, x, y, z in m); Q: their
            configurations in the robot's joint order (m, n) rad, or None: aligned here
            (:func:`~pin_kpi_oed.model.measured_joints.align_data`).
        reference: (model, station) whose set-up the rows are compared with (the model before the registration;
            station None: its default), or None.
        q_work: working configurations (t, n) rad, or None (no TCP σ, KPI Jacobian or criterion unless
            ``default_work``).
        default_work: without ``q_work``, the reference model's working configurations, else the rows'.
        seed: seed of the criterion's reference configurations.

    Returns:
        The :class:`CheckView`.

    Raises:
        InputError: joint columns that are not the robot's (aligning the rows), an unknown reference station.
    """
    Q = align_data(cm.robot, data) if Q is None else Q
    if reference is not None:
        reference = (reference[0], reference[0].station(reference[1]))
    if q_work is None and default_work:
        own = None if reference is None else reference[0].q_work
        q_work = own if own is not None else Q
    st1 = cm.with_setup(station, dataclasses.replace(cm.setups[station], sigma_scale=1.0))
    Y, Sigma = predictive_covariance(st1, Q, data, station)
    sig = np.sqrt(np.diag(Sigma)).reshape(len(Q), 3)
    L = cholesky(Sigma)
    wm, p = cm.station_model(station)
    z, F = whiten(L, data.position_m - Y, wm.jacobian(p, Q)[:, :3, :])
    G = F[:, np.arange(wm.layout.tracker.start, wm.layout.tracker.stop)]
    more: dict[str, Any] = {}
    if reference is not None:
        model, old = reference
        more["z_old"] = z_old = whiten(L, data.position_m - model.predict(Q, data, station=old))
        step = z_old - project_out(z_old, G)
        more["setup_distance"] = float(step @ step)
    view = CheckView(Y=Y, Sigma=Sigma, sig=sig, z=project_out(z, G), F=F, wm=wm, p=p,
                     null=check_null(cm if reference is None else reference[0]), Q=Q,
                     old=None if reference is None else reference[1], **more)
    if q_work is not None:
        view.qw = qw = np.atleast_2d(q_work)
        view.E_w = wm.kpi_jacobian(p, qw)
        at = tcp_sigma(st1, qw, station=station)
        view.tcp_held_m = at.held_sigma_m
        view.tcp_sigma_m = np.sqrt(np.maximum(at.sigma_m ** 2 - at.held_sigma_m ** 2, 0.0))
        if reference is not None:
            a_m, a_p = reference[0].station_model(reference[1])
            view.shift = (wm.kpi(p, qw) - a_m.kpi(a_p, qw)).reshape(-1)
        wm.noise = NoiseModel(sigma_xyz_m=tuple(np.median(sig, axis=0).reshape(3)))
        view.crit = _group_criterion(wm, p, cm.robot, view.E_w, 300, seed)
    return view


def rows_chi2(cm: Any, data: Any, Q: np.ndarray, station: str, L: np.ndarray | None = None) -> float:
    """T = ‖z‖² of a model on the check rows: without ``L``, under the set-up registered at ``station``, whitened
    by the model's own joint honest covariance of the rows and the set-up's step projected out (:func:`check_view`);
    with ``L``, under the set-up held at ``station``, whitened by ``L`` (the factor of the rows' covariance a check
    computed before a change was applied), nothing projected out.

    Args:
        cm: the :class:`~pin_kpi_oed.calibrated.model_file.CalibratedModel`; station: its station the rows are
            predicted at.
        data: the check rows (x, y, z in m); Q: their configurations in the robot's joint order (m, n) rad.
        L: the whitening factor (3m, 3m) m, or None.

    Returns:
        T (dimensionless).
    """
    if L is None:
        z = check_view(cm, data, Q, station).z
    else:
        z = whiten(L, data.position_m - cm.predict(Q, data, station=station))
    return float(z @ z)


def check_criterion(model: Any, q_work: np.ndarray, sigma_m: np.ndarray, station: str | None = None,
                    n_ref: int = 300, seed: int = 0) -> tuple[CheckPower, TrackerModel, np.ndarray]:
    """The :class:`~pin_kpi_oed.oed.check_power.CheckPower` of a calibrated model.

    Args:
        model: the calibrated model; station: its station whose set-up the check re-registers.
        q_work: working configurations (t, n) rad.
        sigma_m: honest σ per axis (3,) m the poses are whitened with.
        n_ref: seeded random configurations within the joint limits that tell the groups' directions apart from
            the set-up; seed: their seed.

    Returns:
        (criterion, the station's measurement model with noise σ = ``sigma_m``, its raw parameter vector p).
    """
    wm, p = model.station_model(station)
    wm.noise = NoiseModel(sigma_xyz_m=tuple(np.asarray(sigma_m, float).reshape(3)))
    return _group_criterion(wm, p, model.robot, wm.kpi_jacobian(p, np.atleast_2d(q_work)), n_ref, seed), wm, p


def _group_criterion(wm: TrackerModel, p: np.ndarray, rb: Any, E: np.ndarray, n_ref: int, seed: int) -> CheckPower:
    """:func:`check_criterion` on a station's measurement model (its noise σ the whitening's) and the KPI Jacobian E
    at the working configurations."""
    L = wm.layout
    rng = np.random.default_rng(seed)
    Q_ref = rng.uniform(rb.q_lower, rb.q_upper, size=(n_ref, rb.nq))
    J_ref = wm.weighted_jacobian(p, Q_ref)[:, :3, :].reshape(-1, L.n)
    lin, ang = wm.joint_axes
    joint_cols = [np.arange(L.joint_slice(j).start, L.joint_slice(j).stop) for j in range(L.n_joints)]
    setup = np.arange(L.tracker.start, L.tracker.stop)
    tool = np.arange(L.reflector.start, L.reflector.stop)
    return CheckPower(setup, check_groups(J_ref, E, setup, joint_cols, list(rb.joint_names), np.hstack([lin, ang]),
                                          tool))


def check_null(model: Any) -> CheckNull:
    """The law of the check's statistic under no change (:class:`~pin_kpi_oed.oed.check_power.CheckNull`): the
    standardised RMS and excess kurtosis of the model's own K-fold held-out errors (a Gaussian-process discrepancy's
    ``cv``), else the plain χ². The model file's reader refuses values outside
    :data:`NULL_FACTOR_RANGE` / :data:`NULL_KURTOSIS_RANGE`; a model built in memory is held to them here."""
    d = model.discrepancy
    cv = d.cv if d is not None and d.kind != "white" else {}
    f, k = cv.get("z_rms"), cv.get("z_kurtosis")
    ok = [isinstance(v, (int, float)) and not isinstance(v, bool) and bool(np.isfinite(v)) for v in (f, k)]
    return CheckNull(factor=float(np.clip(f, *NULL_FACTOR_RANGE)) if ok[0] else 1.0,
                     kurtosis=float(np.clip(k, *NULL_KURTOSIS_RANGE)) if ok[1] else 0.0)


def cholesky(Sigma: np.ndarray) -> np.ndarray:
    """L with Σ (+ a relative jitter of 1e-12) = L Lᵀ."""
    return np.linalg.cholesky(Sigma + 1e-12 * np.mean(np.diag(Sigma)) * np.eye(len(Sigma)))


def whiten(L: np.ndarray, r: np.ndarray, J: np.ndarray | None = None) -> Any:
    """Residuals r (m, 3) — and a Jacobian J (m, 3, n) when given — whitened by the factor L of the rows' joint
    covariance: L⁻¹ r (and (L⁻¹ r, L⁻¹ J))."""
    z = sla.solve_triangular(L, np.asarray(r).reshape(-1), lower=True)
    if J is None:
        return z
    return z, sla.solve_triangular(L, J.reshape(len(L), -1), lower=True)


def project_out(z: np.ndarray, G: np.ndarray) -> np.ndarray:
    """z minus its least-squares fit by the columns G: the whitened residuals after the set-up's generalised
    least-squares re-registration (the registration itself fits without the rows' correlations)."""
    x, *_ = np.linalg.lstsq(G, z, rcond=None)
    return z - G @ x
