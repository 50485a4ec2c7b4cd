r"""What a check needs of the calibrated model on its rows, taken once: the set-up re-registered, the rows whitened,
the parameter groups, the set-up's change and its reach at the working TCPs, and the statistics the verdict reads.

:func:`measure_rows` is the check's one pass over the calibrated model, in two questions to it: the set-up (tracker
pose; the reflector held) re-registered on the rows with the robot held
(:func:`~pin_kpi_oed.upkeep.transfer.register_setup`), then the registered model on the rows
(:func:`~pin_kpi_oed.calibrated.check_view.check_view`: the rows' configurations in the robot's joint order, the
residuals and the Jacobian whitened by the joint honest covariance of the rows, the registration's σ factor left
out, the check's groups, the KPI Jacobian at the working configurations W, the TCP σ there, the set-up's
displacement of the working TCPs). From these arrays it takes the set-up's change between the model's station and
the rows: its generalised least-squares step (the whitened residuals under the model's set-up projected on the
set-up's columns: χ²(6) under no change) and its displacement of the working TCPs with that displacement's σ; and
the statistics of :mod:`~pin_kpi_oed.upkeep.check_stats` the verdict reads: T's critical value and p-value, the
power against each group, the group that explains the residuals and its fit with the set-up held, the poses to add.
The verdict (:func:`~pin_kpi_oed.upkeep.check.check_calibration`) decides on these and asks the model once more
only to re-fit a change it names (:meth:`CheckRows.refit`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from pin_kpi_oed.calibrated.check_view import CheckView, check_criterion, check_null, check_view, cholesky, rows_chi2
from pin_kpi_oed.calibrated.model_file import CalibratedModel
from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.oed.check_power import CheckGroup, CheckNull, CheckPower
from pin_kpi_oed.upkeep.check_poses import SETUP_FACTOR, poses_to_add, registration_sigma_m
from pin_kpi_oed.upkeep.check_stats import check_group_name, check_powers, held_fit, sidak
from pin_kpi_oed.upkeep.transfer import register_setup

__all__ = ["CHECK_STATION", "CheckRows", "measure_rows", "apply_change", "check_criterion", "check_null", "registered",
           "POOL_SIZE"]

#: Station label of the set-up registered on the check rows.
CHECK_STATION = "check"
#: Candidate configurations (within the joint limits) the poses to add are chosen from.
POOL_SIZE = 400


@dataclass
class CheckRows:
    """The check rows seen through the calibrated model, and the statistics the verdict reads (SI units; module
    docstring).

    Attributes:
        Q: configurations (m, n) rad; m: rows; old: the model's station the set-up is compared with.
        model: the calibrated model checked; cm: the model with the set-up registered on the rows (station
            :data:`CHECK_STATION`, the default).
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
        alpha: the verdict's false-alarm rate; alpha_each: the level of each of its two tests (Šidák);
            tolerance_m: the RMS TCP change at W that matters (m).
        threshold: T's critical value at ``alpha_each``; p_value: P(T' > T) under no change.
        power: group name -> power of T against the group's weakest change of size ``tolerance_m``.
        named: :func:`~pin_kpi_oed.upkeep.check_stats.check_group_name` when T is above ``threshold``, else None.
        held: :func:`~pin_kpi_oed.upkeep.check_stats.held_fit` of the named group, or None.
        poses_to_add: configurations (k, n) rad to measure next (empty unless asked for and needed).
    """

    Q: np.ndarray
    m: int
    old: str
    model: CalibratedModel
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
    alpha: float = 0.05
    alpha_each: float = float("nan")
    tolerance_m: float = 1e-4
    threshold: float = float("nan")
    p_value: float = float("nan")
    power: dict = dataclasses.field(default_factory=dict)
    named: dict | None = None
    held: tuple | None = None
    poses_to_add: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 0)))

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

    def refit(self, data: MeasurementSet, g: CheckGroup, delta: np.ndarray, hold_setup: bool
              ) -> tuple[CalibratedModel, float]:
        """The checked model with a group's change applied (:func:`apply_change`) and T on the rows: with
        ``hold_setup`` under the model's own set-up (not linearised), whitened as the rows (:attr:`L`); else with the
        set-up re-registered on the rows (:func:`registered`), whitened by its own view.

        Args:
            data: the check rows (x, y, z in m); g: the group; delta: its change in its columns (raw units: m, rad).
            hold_setup: keep the model's set-up (the group's change alone explains the rows).

        Returns:
            (the model with the change applied — re-registered unless ``hold_setup`` —, its T on the rows).
        """
        applied = apply_change(self.model, data, g, delta)
        fitted = applied if hold_setup else registered(applied, data)
        station = self.old if hold_setup else CHECK_STATION
        return fitted, rows_chi2(fitted, data, self.Q, station, self.L if hold_setup else None)


def measure_rows(model: CalibratedModel, data: MeasurementSet, station: str | None, q_work: np.ndarray | None,
                 seed: int, *, alpha: float = 0.05, tolerance_m: float = 1e-4, propose: bool = False) -> CheckRows:
    """The check rows through the model, and the statistics the verdict reads (module docstring).

    Args:
        model: the calibrated model; station: its station the set-up is compared with (None: the default).
        data: the check rows (joint columns, x, y, z in m).
        q_work: working configurations (t, n) rad; default the model's, else the check rows.
        seed: seed of the groups' reference configurations (and of the poses to add).
        alpha: the verdict's false-alarm rate; tolerance_m: the RMS TCP change at the working configurations that
            matters (m).
        propose: design the poses to add when the rows do not determine the set-up at the working configurations or
            the named group.

    Returns:
        The :class:`CheckRows`.

    Raises:
        InputError: fewer than 3 rows, joint columns that are not the robot's, an unknown station.
    """
    m = len(data)
    if 3 * m - 6 < 3:
        raise InputError(f"{data.source or 'check data'}: {m} check rows are too few to register the set-up and test "
                         f"the rest (at least 3 rows; 10 recommended)")
    cm = registered(model, data)
    v = check_view(cm, data, None, CHECK_STATION, reference=(model, station), q_work=q_work, default_work=True,
                   seed=seed)
    rows = _from_view(model, cm, v)
    _statistics(rows, alpha, tolerance_m, propose, seed)
    return rows


def _from_view(model: CalibratedModel, cm: CalibratedModel, v: CheckView) -> CheckRows:
    """The rows' arrays from the registered model's view: the set-up's change and the registration's σ at W."""
    G = v.F[:, v.crit.setup]
    Ms = G.T @ G
    E_s = v.E_w[:, v.crit.setup]
    per = np.maximum(np.sum(np.diag(E_s @ np.linalg.pinv(Ms, hermitian=True) @ E_s.T).reshape(-1, 3), axis=1), 0.0)
    honest = float(np.sqrt(np.mean(v.tcp_sigma_m ** 2)))
    reg = registration_sigma_m(E_s, Ms)
    shift, shift_sd = _setup_shift(v.shift, len(v.qw), E_s, Ms)
    return CheckRows(Q=v.Q, m=len(v.Q), old=v.old, model=model, cm=cm, Sigma=v.Sigma, sig=v.sig, z=v.z, F=v.F,
                     z_old=v.z_old, crit=v.crit, wm=v.wm, p=v.p, E_w=v.E_w, qw=v.qw, null=v.null,
                     tcp_sigma_m=v.tcp_sigma_m, reg_share_m2=per, registration_sigma_m=reg, honest_sigma_m=honest,
                     setup_determined=bool(reg <= SETUP_FACTOR * honest), setup_distance=v.setup_distance,
                     setup_shift_m=shift, setup_shift_sigma_m=shift_sd, tcp_held_m=v.tcp_held_m)


def _statistics(rows: CheckRows, alpha: float, tolerance_m: float, propose: bool, seed: int) -> None:
    """The statistics of :mod:`~pin_kpi_oed.upkeep.check_stats` on the rows' arrays, set on ``rows``: T's critical
    value and p-value at the Šidák level, the powers, above the critical value the named group and its held fit,
    and the poses to add when asked for and the rows determine neither the set-up at W nor the named group."""
    a1 = sidak(alpha)
    null, T, dof = rows.null, rows.T, rows.dof
    rows.alpha, rows.alpha_each, rows.tolerance_m = alpha, a1, tolerance_m
    rows.threshold, rows.p_value = null.threshold(dof, a1), null.sf(T, dof)
    rows.power = check_powers(rows.crit, rows.F, tolerance_m, a1, null)
    if T > rows.threshold:
        rows.named = check_group_name(rows.crit, rows.F, rows.z, dof, alpha, null)
        best = rows.named["best"]
        rows.held = None if best is None else held_fit(rows.F, rows.z_old, best, null, alpha)
    undetermined = rows.named is not None and rows.named["best"] is not None and not rows.named["best"][3]
    if propose and (not rows.setup_determined or undetermined):
        rb = rows.model.robot
        pool = np.random.default_rng(seed).uniform(rb.q_lower, rb.q_upper, size=(POOL_SIZE, rb.nq))
        rows.poses_to_add = poses_to_add(rows.crit, rows.wm, rows.p, rows.F, rows.E_w[:, rows.crit.setup],
                                         rows.honest_sigma_m, pool, seed=seed)[0]


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


def apply_change(model: CalibratedModel, data: MeasurementSet, g: CheckGroup, delta: np.ndarray) -> CalibratedModel:
    """The model with a group's change applied (its stations' set-ups kept), the step in its history.

    Args:
        model: the calibrated model; data: the check rows (their source named in the history).
        g: the group; delta: its change in its columns (raw units: m, rad).

    Returns:
        The new model.
    """
    if g.kind == "tool":
        setups = {k: dataclasses.replace(s, reflector_m=s.reflector_m + delta,
                                         nests_m=None if s.nests_m is None else s.nests_m + delta)
                  for k, s in model.setups.items()}
        new = dataclasses.replace(model, setups=setups, tcp_m=model.tcp_m + delta)
    else:
        jp = model.joint_p.copy()
        jp[g.cols] += delta
        new = dataclasses.replace(model, joint_p=jp)
    new.history = list(model.history) + [{"step": "check", "data": data.source, "group": g.name,
                                          "change": delta.tolist()}]
    return new
