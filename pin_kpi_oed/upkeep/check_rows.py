r"""What a check needs of the calibrated model on its rows, taken once: the set-up re-registered, the rows whitened,
the parameter groups, the set-up's change and its reach at the working TCPs.

:func:`measure_rows` is the check's one pass over the calibrated model, in two questions to it: the set-up (tracker
pose; the reflector held) re-registered on the rows with the robot held
(:func:`~pin_kpi_oed.upkeep.transfer.register_setup`), then the registered model on the rows
(:func:`~pin_kpi_oed.calibrated.check_view.check_view`: the residuals and the Jacobian whitened by the joint honest
covariance of the rows, the registration's σ factor left out, the check's groups, the KPI Jacobian at the working
configurations W, the TCP σ there, the set-up's displacement of the working TCPs). From these arrays it takes the
set-up's change between the model's station and the rows: its generalised least-squares step (the whitened
residuals under the model's set-up projected on the set-up's columns: χ²(6) under no change) and its displacement of
the working TCPs with that displacement's σ. Every later step of the verdict works on these arrays and on the model
only to apply a change.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from pin_kpi_oed.calibrated.check_view import check_criterion, check_null, check_view, cholesky
from pin_kpi_oed.calibrated.model_file import CalibratedModel
from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.measured_joints import align_data
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.oed.check_power import CheckNull, CheckPower
from pin_kpi_oed.upkeep.check_poses import SETUP_FACTOR, registration_sigma_m
from pin_kpi_oed.upkeep.transfer import register_setup

__all__ = ["CHECK_STATION", "CheckRows", "measure_rows", "check_criterion", "check_null", "registered"]

#: Station label of the set-up registered on the check rows.
CHECK_STATION = "check"


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
            (3-D); tcp_held_m: the part of the parameters held at nominal (t,) m
            (:func:`~pin_kpi_oed.calibrated.check_view.check_view`).
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
        return cholesky(self.Sigma)


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
    qw = np.atleast_2d(q_work if q_work is not None else (model.q_work if model.q_work is not None else Q))
    v = check_view(cm, data, Q, CHECK_STATION, reference=(model, old), q_work=qw, seed=seed)
    G = v.F[:, v.crit.setup]
    Ms = G.T @ G
    E_s = v.E_w[:, v.crit.setup]
    per = np.maximum(np.sum(np.diag(E_s @ np.linalg.pinv(Ms, hermitian=True) @ E_s.T).reshape(-1, 3), axis=1), 0.0)
    honest = float(np.sqrt(np.mean(v.tcp_sigma_m ** 2)))
    reg = registration_sigma_m(E_s, Ms)
    shift, shift_sd = _setup_shift(v.shift, len(qw), E_s, Ms)
    return CheckRows(Q=Q, m=m, old=old, cm=cm, Sigma=v.Sigma, sig=v.sig, z=v.z, F=v.F,
                     z_old=v.z_old, crit=v.crit, wm=v.wm, p=v.p, E_w=v.E_w, qw=qw, null=v.null,
                     tcp_sigma_m=v.tcp_sigma_m, reg_share_m2=per, registration_sigma_m=reg, honest_sigma_m=honest,
                     setup_determined=bool(reg <= SETUP_FACTOR * honest), setup_distance=v.setup_distance,
                     setup_shift_m=shift, setup_shift_sigma_m=shift_sd, tcp_held_m=v.tcp_held_m)


def _setup_shift(s: np.ndarray, t: int, E_s: np.ndarray, Ms: np.ndarray) -> tuple[float, float]:
    """RMS displacement (m) of the t working TCPs (tracker frame) by the set-up's displacement s (3t,) m between the
    model's set-up and the one registered on the rows, and its σ along the displacement from the registration's
    covariance M_ss⁻¹ (m)."""
    size = float(np.linalg.norm(s))
    if size == 0.0:
        return 0.0, float(np.sqrt(np.trace(E_s @ np.linalg.pinv(Ms, hermitian=True) @ E_s.T) / (3 * t)))
    u = s / size
    var = float(u @ E_s @ np.linalg.pinv(Ms, hermitian=True) @ E_s.T @ u)
    return size / np.sqrt(t), float(np.sqrt(max(var, 0.0) / t))


def registered(model: CalibratedModel, data: MeasurementSet) -> CalibratedModel:
    """The set-up registered on the check rows (reflector held), fitted to the model's full prediction (geometry,
    effects and the discrepancy's mean, as :func:`~pin_kpi_oed.upkeep.transfer.register_setup` does)."""
    return register_setup(model, data, station=CHECK_STATION, hold_reflector=True).model
