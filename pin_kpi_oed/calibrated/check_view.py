r"""What a check asks of a calibrated model on its rows, answered in one pass.

A check (``upkeep/check.py``) compares measured rows with a calibrated model whose set-up was registered on them.
Everything it needs of the model is asked here, once per question, so that the check works on arrays and on the
model only to apply a change:

* the predictions Y of the rows at the registered station and their joint honest covariance Σ = LLᵀ
  (:func:`~pin_kpi_oed.calibrated.prediction_sigma.predictive_covariance`, the registration's σ factor left out: it
  would hide the change under test), the residuals and the station's Jacobian whitened by L;
* against a reference station (the model's own set-up): its whitened residuals and the displacement of the working
  TCPs between the two set-ups;
* at the working configurations W: the KPI Jacobian E_W, the TCP σ in two parts
  (:func:`~pin_kpi_oed.calibrated.tcp_sigma.tcp_sigma`: what the calibration determined, and the joint-placement
  parameters held at nominal), and the check criterion of the model's parameter groups
  (:func:`check_criterion`);
* the law of the check's statistic under no change (:func:`check_null`, the model's own K-fold held-out errors).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg as sla

from pin_kpi_oed.calibrated.prediction_sigma import predictive_covariance
from pin_kpi_oed.calibrated.tcp_sigma import tcp_sigma
from pin_kpi_oed.model.noise import NoiseModel
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.oed.check_power import CheckNull, CheckPower, check_groups

__all__ = ["CheckView", "check_view", "check_criterion", "check_null", "whiten", "NULL_FACTOR_RANGE",
           "NULL_KURTOSIS_RANGE"]

#: Bounds of the fields of a model file's K-fold check the check's law of T depends on (checked on reading too).
NULL_FACTOR_RANGE = (0.5, 3.0)
NULL_KURTOSIS_RANGE = (0.0, 10.0)


@dataclass
class CheckView:
    """A calibrated model seen on check rows (SI units; module docstring).

    Attributes:
        Y: predictions of the rows at the registered station (m, 3) m; Sigma: their joint honest covariance
            (3m, 3m) m²; sig: its marginal σ (m, 3) m.
        z: whitened residuals under the registered set-up (3m,); F: whitened Jacobian of the rows (3m, np).
        wm, p: the registered station's measurement model (noise σ = the rows' median honest σ per axis when the
            working configurations were asked for) and its raw parameter vector.
        z_old: whitened residuals under the reference station's set-up (3m,), or None without a reference.
        shift: displacement of the working TCPs from the reference set-up to the registered one (3t,) m, or None.
        E_w: KPI Jacobian at the working configurations (3t, np), or None without them.
        tcp_sigma_m, tcp_held_m: the TCP σ per working configuration (t,) m: the part the calibration determined
            and the part of the joint-placement parameters held at nominal (empty without working configurations).
        crit: the check criterion of the model's parameter groups, or None without working configurations.
        null: the law of the check's statistic under no change.
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
    shift: np.ndarray | None = None
    E_w: np.ndarray | None = None
    tcp_sigma_m: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))
    tcp_held_m: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))
    crit: CheckPower | None = None


def check_view(cm: Any, data: Any, Q: np.ndarray, station: str, *, reference: tuple[Any, str] | None = None,
               q_work: np.ndarray | None = None, seed: int = 0) -> CheckView:
    """The calibrated model on check rows (module docstring).

    Args:
        cm: the :class:`~pin_kpi_oed.calibrated.model_file.CalibratedModel` with the set-up registered on the rows;
            station: that set-up's station.
        data: the check rows (:class:`~pin_kpi_oed.data.measurements.MeasurementSet`, x, y, z in m); Q: their
            configurations in the robot's joint order (m, n) rad.
        reference: (model, station) whose set-up the rows are compared with (the model before the registration), or
            None.
        q_work: working configurations (t, n) rad, or None (no TCP σ, KPI Jacobian or criterion).
        seed: seed of the criterion's reference configurations.

    Returns:
        The :class:`CheckView`.
    """
    st1 = cm.with_setup(station, dataclasses.replace(cm.setups[station], sigma_scale=1.0))
    Y, Sigma = predictive_covariance(st1, Q, data, station)
    sig = np.sqrt(np.diag(Sigma)).reshape(len(Q), 3)
    L = cholesky(Sigma)
    at_w: dict[str, Any] = {}
    if q_work is None:
        wm, p = cm.station_model(station)
    else:
        qw = np.atleast_2d(q_work)
        at_w["crit"], wm, p, at_w["E_w"] = _criterion(cm, qw, np.median(sig, axis=0), station, 300, seed)
        at = tcp_sigma(st1, qw, station=station)
        at_w["tcp_held_m"] = at.held_sigma_m
        at_w["tcp_sigma_m"] = np.sqrt(np.maximum(at.sigma_m ** 2 - at.held_sigma_m ** 2, 0.0))
    z, F = whiten(L, data.position_m - Y, wm.jacobian(p, Q)[:, :3, :])
    if reference is not None:
        model, old = reference
        at_w["z_old"] = whiten(L, data.position_m - model.predict(Q, data, station=old))
        if q_work is not None:
            a_m, a_p = model.station_model(old)
            at_w["shift"] = (wm.kpi(p, qw) - a_m.kpi(a_p, qw)).reshape(-1)
    null = check_null(cm if reference is None else reference[0])
    return CheckView(Y=Y, Sigma=Sigma, sig=sig, z=z, F=F, wm=wm, p=p, null=null, **at_w)


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
    crit, wm, p, _ = _criterion(model, np.atleast_2d(q_work), sigma_m, station, n_ref, seed)
    return crit, wm, p


def _criterion(model: Any, qw: np.ndarray, sigma_m: np.ndarray, station: str | None, n_ref: int, seed: int
               ) -> tuple[CheckPower, TrackerModel, np.ndarray, np.ndarray]:
    """:func:`check_criterion` and the KPI Jacobian E at ``qw`` it was built on."""
    wm, p = model.station_model(station)
    wm.noise = NoiseModel(sigma_xyz_m=tuple(np.asarray(sigma_m, float).reshape(3)))
    L = wm.layout
    rb = model.robot
    rng = np.random.default_rng(seed)
    Q_ref = rng.uniform(rb.q_lower, rb.q_upper, size=(n_ref, rb.nq))
    J_ref = wm.weighted_jacobian(p, Q_ref)[:, :3, :].reshape(-1, L.n)
    E = wm.kpi_jacobian(p, qw)
    lin, ang = wm.joint_axes
    joint_cols = [np.arange(L.joint_slice(j).start, L.joint_slice(j).stop) for j in range(L.n_joints)]
    setup = np.arange(L.tracker.start, L.tracker.stop)
    tool = np.arange(L.reflector.start, L.reflector.stop)
    groups = check_groups(J_ref, E, setup, joint_cols, list(rb.joint_names), np.hstack([lin, ang]), tool)
    return CheckPower(setup, groups), wm, p, E


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
