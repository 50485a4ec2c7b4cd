r"""What a check needs of the calibrated model on its rows, taken once: the set-up re-registered, the rows whitened,
the parameter groups, the set-up's change and its reach at the working TCPs.

:func:`measure_rows` is the check's one pass over the calibrated model: the set-up (tracker pose; the reflector
held) re-registered on the rows with the robot held (:func:`~pin_kpi_oed.upkeep.transfer.register_setup`), the
residuals and the Jacobian whitened by the joint honest covariance of the rows (Σ = LLᵀ,
:func:`~pin_kpi_oed.calibrated.prediction_sigma.predictive_covariance`, the registration's σ factor left out), the
check's groups (:func:`check_criterion`), the KPI Jacobian at the working configurations W, the TCP σ there
(:func:`tcp_sigma_m`, the one place the check takes it from), and the set-up's change between the model's station
and the rows: its generalised least-squares step (the whitened residuals under the model's set-up projected on the
set-up's columns: χ²(6) under no change) and its displacement of the working TCPs with that displacement's σ. Every
later step of the verdict works on these arrays and on the model only to apply a change.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from pin_kpi_oed.calibrated.model_file import CalibratedModel
from pin_kpi_oed.calibrated.tcp_sigma import tcp_sigma
from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.identification.problem import align_data
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.oed.check_power import CheckNull, CheckPower, check_groups
from pin_kpi_oed.upkeep.check_poses import SETUP_FACTOR, registration_sigma_m
from pin_kpi_oed.upkeep.transfer import register_setup

__all__ = ["CHECK_STATION", "CheckRows", "measure_rows", "check_criterion", "check_null", "tcp_sigma_m",
           "tcp_sigma_parts", "whiten", "project_out", "registered"]

#: Station label of the set-up registered on the check rows.
CHECK_STATION = "check"
#: Bounds of the fields of a model file's K-fold check the check's law of T depends on (checked on reading too).
NULL_FACTOR_RANGE = (0.5, 3.0)
NULL_KURTOSIS_RANGE = (0.0, 10.0)


@dataclass
class CheckRows:
    """The check rows seen through the calibrated model (SI units; module docstring).

    Attributes:
        Q: configurations (m, n) rad; m: rows; old: the model's station the set-up is compared with.
        cm: the model with the set-up registered on the rows (station :data:`CHECK_STATION`, the default).
        Sigma: joint honest covariance of the rows (3m, 3m) m²; sig: its marginal σ (m, 3) m.
        z: whitened residuals after the set-up's GLS step (3m,); F: whitened Jacobian (3m, np).
        z_old: whitened residuals under the model's own set-up (3m,).
        crit: the check criterion (set-up columns, groups); wm, p: the check station's measurement model and its raw
            parameters; E_w: KPI Jacobian at W (3t, np); qw: W (t, n) rad.
        null: the law of T under no change.
        tcp_sigma_m: TCP σ per working configuration, the model's honest σ at the TCP, the determined part (t,) m
            (3-D); tcp_held_m: the part of the parameters held at nominal (t,) m (:func:`tcp_sigma_parts`).
        reg_share_m2: the registration's variance share per working configuration (t,) m².
        registration_sigma_m, honest_sigma_m, setup_determined: as :class:`~pin_kpi_oed.upkeep.check.CheckResult`.
        setup_distance: ‖P_G z_old‖², the set-up's GLS step in its own metric (χ²(6) under no change).
        setup_shift_m: RMS displacement of the working TCPs by the set-up's change (m); setup_shift_sigma_m: its σ
            along the displacement (m).
    """

    Q: np.ndarray
    m: int
    old: str
    cm: CalibratedModel
    Sigma: np.ndarray
    sig: np.ndarray
    z: np.ndarray
    F: np.ndarray
    z_old: np.ndarray
    crit: CheckPower
    wm: TrackerModel
    p: np.ndarray
    E_w: np.ndarray
    qw: np.ndarray
    null: CheckNull
    tcp_sigma_m: np.ndarray
    reg_share_m2: np.ndarray
    registration_sigma_m: float
    honest_sigma_m: float
    setup_determined: bool
    setup_distance: float
    setup_shift_m: float
    setup_shift_sigma_m: float
    tcp_held_m: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))

    @property
    def dof(self) -> int:
        """Degrees of freedom 3m − 6 of T."""
        return 3 * self.m - 6

    @property
    def T(self) -> float:
        """T = ‖z‖²."""
        return float(self.z @ self.z)

    @property
    def L(self) -> np.ndarray:
        """The Cholesky factor of :attr:`Sigma` (the rows' whitening)."""
        return _cholesky(self.Sigma)


def measure_rows(model: CalibratedModel, data: MeasurementSet, station: str | None, q_work: np.ndarray | None,
                 seed: int) -> CheckRows:
    """The check rows through the model (module docstring).

    Args:
        model: the calibrated model; station: its station the set-up is compared with (None: the default).
        data: the check rows (joint columns, x, y, z in m).
        q_work: working configurations (t, n) rad; default the model's, else the check rows.
        seed: seed of the groups' reference configurations.

    Raises:
        InputError: fewer than 3 rows, joint columns that are not the robot's.
    """
    old = model.station(station)
    Q = align_data(model.robot, data)
    m = len(data)
    if 3 * m - 6 < 3:
        raise InputError(f"{data.source or 'check data'}: {m} check rows are too few to register the set-up and test "
                         f"the rest (at least 3 rows; 10 recommended)")
    cm = registered(model, data)
    Y, Sigma = _joint_honest(cm, Q, data)
    sig = np.sqrt(np.diag(Sigma)).reshape(m, 3)
    qw = np.atleast_2d(q_work if q_work is not None else (model.q_work if model.q_work is not None else Q))
    crit, wm, p = check_criterion(cm, qw, np.median(sig, axis=0), CHECK_STATION, seed=seed)
    L = _cholesky(Sigma)
    z, F = whiten(L, data.position_m - Y, wm.jacobian(p, Q)[:, :3, :])
    G = F[:, crit.setup]
    z_old = whiten(L, data.position_m - model.predict(Q, data, station=old))
    E_w = wm.kpi_jacobian(p, qw)
    w_sig, w_held = tcp_sigma_parts(cm, qw)
    Ms = G.T @ G
    E_s = E_w[:, crit.setup]
    per = np.maximum(np.sum(np.diag(E_s @ np.linalg.pinv(Ms, hermitian=True) @ E_s.T).reshape(-1, 3), axis=1), 0.0)
    honest = float(np.sqrt(np.mean(w_sig ** 2)))
    reg = registration_sigma_m(E_s, Ms)
    shift, shift_sd = _setup_shift(model, old, cm, qw, E_s, Ms)
    step = z_old - project_out(z_old, G)
    return CheckRows(Q=Q, m=m, old=old, cm=cm, Sigma=Sigma, sig=sig, z=project_out(z, G), F=F, z_old=z_old,
                     crit=crit, wm=wm, p=p, E_w=E_w, qw=qw, null=check_null(model), tcp_sigma_m=w_sig,
                     reg_share_m2=per, registration_sigma_m=reg, honest_sigma_m=honest,
                     setup_determined=bool(reg <= SETUP_FACTOR * honest), setup_distance=float(step @ step),
                     setup_shift_m=shift, setup_shift_sigma_m=shift_sd, tcp_held_m=w_held)


def tcp_sigma_parts(cm: CalibratedModel, qw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The TCP σ of the check, per working configuration (t,) m (3-D), at the check's station with its registration
    σ factor left out (:func:`~pin_kpi_oed.calibrated.tcp_sigma.tcp_sigma`, the one σ at the TCP), in two parts:
    what the calibration determined (the part a re-fit and a re-calibration differ in, which the verdict weighs) and
    the joint-placement parameters held at nominal under their tolerance (no check of a reflector sees them)."""
    st = dataclasses.replace(cm.setups[CHECK_STATION], sigma_scale=1.0)
    at = tcp_sigma(cm.with_setup(CHECK_STATION, st), qw, station=CHECK_STATION)
    held = at.held_sigma_m
    return np.sqrt(np.maximum(at.sigma_m ** 2 - held ** 2, 0.0)), held


def tcp_sigma_m(cm: CalibratedModel, qw: np.ndarray) -> np.ndarray:
    """The determined part of :func:`tcp_sigma_parts` (t,) m: the TCP σ the verdict weighs a re-fit against a
    re-calibration with."""
    return tcp_sigma_parts(cm, qw)[0]


def _setup_shift(model: CalibratedModel, old: str, cm: CalibratedModel, qw: np.ndarray, E_s: np.ndarray,
                 Ms: np.ndarray) -> tuple[float, float]:
    """RMS displacement (m) of the working TCPs (tracker frame) between the model's set-up and the one registered on
    the rows, and its σ along the displacement from the registration's covariance M_ss⁻¹ (m)."""
    a_m, a_p = model.station_model(old)
    b_m, b_p = cm.station_model(CHECK_STATION)
    s = (b_m.kpi(b_p, qw) - a_m.kpi(a_p, qw)).reshape(-1)
    t = len(qw)
    size = float(np.linalg.norm(s))
    if size == 0.0:
        return 0.0, float(np.sqrt(np.trace(E_s @ np.linalg.pinv(Ms, hermitian=True) @ E_s.T) / (3 * t)))
    u = s / size
    var = float(u @ E_s @ np.linalg.pinv(Ms, hermitian=True) @ E_s.T @ u)
    return size / np.sqrt(t), float(np.sqrt(max(var, 0.0) / t))


def check_criterion(model: CalibratedModel, q_work: np.ndarray, sigma_m: np.ndarray, station: str | None = None,
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
    from pin_kpi_oed.model.noise import NoiseModel

    wm, p = model.station_model(station)
    wm.noise = NoiseModel(sigma_xyz_m=tuple(np.asarray(sigma_m, float).reshape(3)))
    L = wm.layout
    rb = model.robot
    rng = np.random.default_rng(seed)
    Q_ref = rng.uniform(rb.q_lower, rb.q_upper, size=(n_ref, rb.nq))
    J_ref = wm.weighted_jacobian(p, Q_ref)[:, :3, :].reshape(-1, L.n)
    E = wm.kpi_jacobian(p, np.atleast_2d(q_work))
    lin, ang = wm.joint_axes
    joint_cols = [np.arange(L.joint_slice(j).start, L.joint_slice(j).stop) for j in range(L.n_joints)]
    setup = np.arange(L.tracker.start, L.tracker.stop)
    tool = np.arange(L.reflector.start, L.reflector.stop)
    groups = check_groups(J_ref, E, setup, joint_cols, list(rb.joint_names), np.hstack([lin, ang]), tool)
    return CheckPower(setup, groups), wm, p


def check_null(model: CalibratedModel) -> CheckNull:
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


def _joint_honest(cm: CalibratedModel, Q: np.ndarray, data: MeasurementSet) -> tuple[np.ndarray, np.ndarray]:
    """Predictions (m, 3) and the joint honest covariance (3m, 3m) of the check station's rows, its σ factor left
    out (:func:`~pin_kpi_oed.calibrated.prediction_sigma.predictive_covariance`)."""
    from pin_kpi_oed.calibrated.prediction_sigma import predictive_covariance

    st = dataclasses.replace(cm.setups[CHECK_STATION], sigma_scale=1.0)
    return predictive_covariance(cm.with_setup(CHECK_STATION, st), Q, data, CHECK_STATION)


def _cholesky(Sigma: np.ndarray) -> np.ndarray:
    """L with Σ (+ a relative jitter of 1e-12) = L Lᵀ."""
    return np.linalg.cholesky(Sigma + 1e-12 * np.mean(np.diag(Sigma)) * np.eye(len(Sigma)))


def whiten(L: np.ndarray, r: np.ndarray, J: np.ndarray | None = None):
    """Residuals r (m, 3) — and a Jacobian J (m, 3, n) when given — whitened by the factor L of the rows' joint
    covariance: L⁻¹ r (and (L⁻¹ r, L⁻¹ J))."""
    import scipy.linalg as sla

    z = sla.solve_triangular(L, np.asarray(r).reshape(-1), lower=True)
    if J is None:
        return z
    return z, sla.solve_triangular(L, J.reshape(len(L), -1), lower=True)


def project_out(z: np.ndarray, G: np.ndarray) -> np.ndarray:
    """z minus its least-squares fit by the columns G: the whitened residuals after the set-up's generalised
    least-squares re-registration (the registration itself fits without the rows' correlations)."""
    x, *_ = np.linalg.lstsq(G, z, rcond=None)
    return z - G @ x


def registered(model: CalibratedModel, data: MeasurementSet) -> CalibratedModel:
    """The set-up registered on the check rows (reflector held), fitted to the model's full prediction (geometry,
    effects and the discrepancy's mean, as :func:`~pin_kpi_oed.upkeep.transfer.register_setup` does)."""
    return register_setup(model, data, station=CHECK_STATION, hold_reflector=True).model


def joint_honest_factor(cm: CalibratedModel, Q: np.ndarray, data: MeasurementSet) -> tuple[np.ndarray, np.ndarray]:
    """Predictions (m, 3) of the check station and the Cholesky factor of the rows' joint honest covariance."""
    Y, Sigma = _joint_honest(cm, Q, data)
    return Y, _cholesky(Sigma)
