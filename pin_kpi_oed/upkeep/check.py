r"""Keep a calibration: the verdict of a quick check on a few measured poses.

On the check rows the set-up (tracker pose; the reflector held: a moved reflector is a tool change) is
re-registered with the robot held (:func:`~pin_kpi_oed.upkeep.transfer.register_setup`) and the residuals r
are whitened by the model's joint honest covariance Σ of the check rows
(:func:`~pin_kpi_oed.calibrated.prediction_sigma.predictive_covariance`: the honest σ of
:meth:`CalibratedModel.predict_with_sigma` on its diagonal, the discrepancy's posterior covariance and the
parameters' error shared between rows and axes off it; the registration's own σ factor is *not* applied: it would
hide the change under test): z = L⁻¹r (Σ = LLᵀ), the set-up's generalised least-squares step projected out. With the
marginal σ alone the rows' correlations (axes correlated by 0.3 on the real UR10) make T more spread than χ² and the
check raises false alarms well above its stated rate. T = ‖z‖² has 3m − 6 degrees of freedom; its law under no
change is the scaled χ² of :class:`~pin_kpi_oed.oed.check_power.CheckNull` — the standardised RMS f and the excess
kurtosis κ of the model's own K-fold held-out errors (the plain χ²(3m − 6) for a model without a K-fold check) — so
the check raises a false alarm with probability α (the stated level). Its power against the weakest change of RMS
size τ at the working configurations of each parameter group is that law's non-central tail
(:mod:`pin_kpi_oed.oed.check_power`).

The verdict, in this order:

* **holds** — T below the critical value and the registered set-up within its uncertainty of the model's
  station (Mahalanobis distance of the set-up change, χ²(6) at α); the TCP σ at the working configurations is stated;
* **set-up moved** — T below the critical value, the set-up changed beyond its uncertainty: re-registered, by how much
  (RMS displacement of the check points, mm);
* **robot changed** — T above; a group g explains the residuals: the group's detectable directions fitted with the
  set-up by least squares on the whitened rows, its remaining χ²(3m − 6 − r_g) below its critical value at α/5
  (among such groups the least remaining χ² + 2 r_g, Akaike's criterion); the change with its standard deviation,
  and the re-fitted model — when the check rows determine it; else the poses to add. The re-fit holds the model's
  set-up when the group's change alone explains the rows (its fit with the set-up held passes at α/5: the tracker did
  not move), else re-registers it on the check rows;
* **discrepancy level** — T above, no group explains it and none takes a significant share (χ²(r_g) at α over the
  groups, Bonferroni): the residuals are larger everywhere alike, σ × √(T/(3m − 6));
* **re-calibrate** — T above and no group explains it.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pinocchio as pin

from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.upkeep.check_poses import SETUP_FACTOR, poses_to_add, registration_sigma_m
from pin_kpi_oed.calibrated.model_file import CalibratedModel
from pin_kpi_oed.calibrated.tcp_sigma import tcp_sigma
from pin_kpi_oed.identification.problem import align_data
from pin_kpi_oed.upkeep.transfer import register_setup
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.oed.check_power import CheckGroup, CheckNull, CheckPower, check_groups
from pin_kpi_oed.results import Result

__all__ = ["CheckResult", "check_calibration", "check_criterion", "check_null", "check_powers", "CHECK_STATION"]

#: Station label of the set-up registered on the check rows.
CHECK_STATION = "check"
VERDICTS = ("holds", "setup_moved", "robot_changed", "discrepancy_level", "recalibrate")
#: The named group's goodness of fit is tested at α / FIT_SHARE.
FIT_SHARE = 5.0
#: Candidate configurations (within the joint limits) the poses to add are chosen from.
POOL_SIZE = 400


@dataclass(kw_only=True)
class CheckResult(Result):
    """The verdict of :func:`check_calibration` (SI units).

    Attributes:
        verdict: one of ``holds``, ``setup_moved``, ``robot_changed``, ``discrepancy_level``, ``recalibrate``.
        n_rows: check rows; dof: degrees of freedom 3m − 6 of the test; alpha: its level (false-alarm rate).
        chi2: T = Σ z²; threshold: χ²_{1−α}(dof); p_value: P(χ²(dof) > T).
        setup_shift_m: RMS displacement of the check points by the set-up change (m); setup_distance: its
            Mahalanobis distance (χ²(6) under no change).
        power: group name -> power of the test against the weakest change of size ``tolerance_m``.
        tolerance_m: RMS TCP change at the working configurations the power is stated for (m).
        tcp_sigma_m: TCP σ at the working configurations (norm, per configuration; m): the re-registered model's
            (:func:`~pin_kpi_oed.calibrated.tcp_sigma.tcp_sigma`) with the registration's share.
        tcp_held_m: its part from the joint-placement parameters held at nominal (per configuration, m): no check of
            a reflector sees a change of them (its power against them is zero).
        group: the named group (robot changed), or "".
        change: the group's fitted change in its columns (raw units: m, rad), std: its standard deviations.
        change_tcp_m: RMS TCP displacement of the change at the working configurations (m).
        determined: whether the check rows determine the named group's change.
        sigma_factor: √(T/dof) (the discrepancy's level against the model's).
        model: the re-registered (or re-fitted) model.
        refit_chi2: T of the re-fitted model on the check rows (NaN if none).
        groups: per group ``{name, chi2_remaining, dof, determined}``.
        registration_sigma_m: the σ the registration on the check rows alone leaves at the working configurations
            (RMS 3-D, m); honest_sigma_m: the model's honest σ there (RMS 3-D, m); setup_determined: the first at most
            :data:`~pin_kpi_oed.upkeep.check_poses.SETUP_FACTOR` × the second.
        setup_held: the re-fit kept the model's set-up (the group's change alone explains the rows, the tracker did
            not move): the change is then determined by the check rows with the calibration's set-up.
        poses_to_add: configurations (k, n) rad to measure next, with the check rows given
            (:func:`~pin_kpi_oed.upkeep.check_poses.poses_to_add`): when the rows do not determine the
            set-up at the working configurations or the named group; empty otherwise.
    """

    verdict: str
    n_rows: int
    dof: int
    alpha: float
    chi2: float
    threshold: float
    p_value: float
    setup_shift_m: float
    setup_distance: float
    power: dict = field(default_factory=dict)
    tolerance_m: float = 1e-4
    tcp_sigma_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    tcp_held_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    group: str = ""
    change: np.ndarray = field(default_factory=lambda: np.zeros(0))
    std: np.ndarray = field(default_factory=lambda: np.zeros(0))
    change_tcp_m: float = float("nan")
    determined: bool = False
    sigma_factor: float = 1.0
    model: CalibratedModel | None = field(default=None, repr=False)
    refit_chi2: float = float("nan")
    groups: list = field(default_factory=list)
    registration_sigma_m: float = float("nan")
    honest_sigma_m: float = float("nan")
    setup_determined: bool = True
    poses_to_add: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    setup_held: bool = False

    def summary(self) -> str:
        """One line (mm, mrad)."""
        stat = (f"chi2 {self.chi2:.1f} on {self.dof} dof (threshold {self.threshold:.1f} at alpha {self.alpha:g}, "
                f"p {self.p_value:.3g})")
        weakest = min(self.power, key=self.power.get) if self.power else ""
        pw = (f"; power against a {self.tolerance_m * 1e3:.3g} mm change: {min(self.power.values()):.2f} "
              f"(weakest: {weakest})") if self.power else ""
        pw += self.undetermined_text()
        if self.verdict in ("holds", "setup_moved"):
            tcp = (f", TCP sigma at the working configurations median {np.median(self.tcp_sigma_m) * 1e3:.3f} mm, max "
                   f"{np.max(self.tcp_sigma_m) * 1e3:.3f} mm" if self.tcp_sigma_m.size else "")
            if self.tcp_held_m.size and np.max(self.tcp_held_m) > 0:
                tcp += (f" (of which {np.median(self.tcp_held_m) * 1e3:.3f} mm from joint-placement parameters held "
                        "at their tolerance, which no check of this reflector sees)")
            head = "holds" if self.verdict == "holds" else (f"set-up moved by {self.setup_shift_m * 1e3:.3f} mm "
                                                             "(re-registered); the calibration holds")
            return f"check: {head}{tcp}; {stat}{pw}"
        if self.verdict == "robot_changed":
            what = _change_text(self) + ("; the set-up unchanged (held)" if self.setup_held else "")
            return f"check: the robot changed: {what}; {stat}{pw}"
        if self.verdict == "discrepancy_level":
            return (f"check: the discrepancy's level changed: residuals {self.sigma_factor:.2f}x the model's sigma "
                    f"everywhere alike (no group explains them); {stat}{pw}")
        return f"check: re-calibrate: no parameter group explains the residuals; {stat}{pw}"

    def undetermined_text(self) -> str:
        """What the check rows leave undetermined and the poses to add ("" when nothing)."""
        k = len(self.poses_to_add)
        add = f"measure the {k} poses of poses_to_add (--json) too" if k else "measure poses spread over the workspace"
        if not self.setup_determined:
            return (f"; the {self.n_rows} rows do not determine the set-up at the working configurations (the "
                    f"registration alone leaves {self.registration_sigma_m * 1e3:.3f} mm there, the honest sigma is "
                    f"{self.honest_sigma_m * 1e3:.3f} mm): {add}")
        if self.verdict == "robot_changed" and not self.determined:
            return f"; the rows do not determine the change of {self.group}: {add}"
        return ""

    def to_dict(self) -> dict:
        """Plain JSON-able dict (SI units)."""
        return {**self.result_dict(), "verdict": self.verdict, "n_rows": self.n_rows, "dof": self.dof,
                "alpha": self.alpha, "chi2": self.chi2, "threshold": self.threshold, "p_value": self.p_value,
                "setup_shift_m": self.setup_shift_m, "setup_distance": self.setup_distance, "power": self.power,
                "tolerance_m": self.tolerance_m, "tcp_sigma_m": np.asarray(self.tcp_sigma_m).tolist(),
                "tcp_held_m": np.asarray(self.tcp_held_m).tolist(),
                "group": self.group, "change": np.asarray(self.change).tolist(),
                "std": np.asarray(self.std).tolist(), "change_tcp_m": self.change_tcp_m,
                "determined": self.determined, "sigma_factor": self.sigma_factor, "refit_chi2": self.refit_chi2,
                "groups": self.groups, "registration_sigma_m": self.registration_sigma_m,
                "honest_sigma_m": self.honest_sigma_m, "setup_determined": self.setup_determined,
                "poses_to_add": np.asarray(self.poses_to_add).tolist(), "setup_held": self.setup_held}


def _change_text(r: CheckResult) -> str:
    if not r.determined:
        return f"{r.group} (not determined by the check rows)"
    if r.group.endswith(" offset"):
        k = int(np.argmax(np.abs(r.change)))
        return (f"{r.group} by {r.change[k] * 1e3:+.3f} ± {r.std[k] * 1e3:.3f} mrad "
                f"({r.change_tcp_m * 1e3:.3f} mm RMS at the TCP)")
    if r.group == "tool":
        return (f"tool by [{', '.join(f'{v * 1e3:+.3f}' for v in r.change)}] ± "
                f"[{', '.join(f'{v * 1e3:.3f}' for v in r.std)}] mm")
    names = ("tx", "ty", "tz", "rx", "ry", "rz")
    big = [k for k in range(r.change.size) if abs(r.change[k]) > 3 * r.std[k]] or [int(np.argmax(np.abs(r.change)))]
    parts = [f"{names[k]} {r.change[k] * 1e3:+.3f} ± {r.std[k] * 1e3:.3f} {'mm' if k < 3 else 'mrad'}" for k in big]
    return f"{r.group}: {', '.join(parts)} ({r.change_tcp_m * 1e3:.3f} mm RMS at the TCP)"


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


def _honest(model: CalibratedModel, Q: np.ndarray, data: MeasurementSet | None, label: str
            ) -> tuple[np.ndarray, np.ndarray]:
    """Predictions and honest σ (m, 3) of station ``label``, its σ factor left out."""
    st = dataclasses.replace(model.setups[label], sigma_scale=1.0)
    Y, sig, _ = model.with_setup(label, st).predict_with_sigma(Q, data, station=label)
    return Y, sig


def check_calibration(model: CalibratedModel, data: MeasurementSet, *, station: str | None = None,
                      alpha: float = 0.05, tolerance_m: float = 1e-4, q_work: np.ndarray | None = None,
                      seed: int = 0, propose: bool = True) -> CheckResult:
    """The verdict of a check on measured rows (module docstring).

    Args:
        model: the calibrated model; station: the model's station the check compares the set-up with.
        data: the check rows (joint columns, x, y, z in m).
        alpha: level of the test (its false-alarm rate), in (0, 0.5).
        tolerance_m: RMS TCP change at the working configurations the power is stated for (m).
        q_work: working configurations (t, n) rad; default the model's, else the check rows.
        seed: seed of the reference configurations of the groups (and of the poses to add).
        propose: design the poses to add when the rows do not determine the set-up at the working configurations or
            the named group (False: only say so; ``monitor`` asks once, not at every check).

    Returns:
        The :class:`CheckResult`.

    Raises:
        InputError: α out of range, a tolerance ≤ 0, too few rows (fewer than 3, or no degree of freedom left).
    """
    t0 = time.perf_counter()
    if not 0.0 < alpha < 0.5:
        raise InputError(f"check: alpha must be in (0, 0.5), got {alpha}")
    if not (np.isfinite(tolerance_m) and tolerance_m > 0):
        raise InputError(f"check: the tolerance must be > 0 m, got {tolerance_m}")
    old = model.station(station)
    Q = align_data(model.robot, data)
    m = len(data)
    if 3 * m - 6 < 3:
        raise InputError(f"{data.source or 'check data'}: {m} check rows are too few to register the set-up and test "
                         f"the rest (at least 3 rows; 10 recommended)")
    cm = _register(model, data)
    Y, Sigma = _joint_honest(cm, Q, data)
    sig = np.sqrt(np.diag(Sigma)).reshape(m, 3)
    dof = 3 * m - 6
    null = check_null(model)
    thr = null.threshold(dof, alpha)
    qw = np.atleast_2d(q_work if q_work is not None else (model.q_work if model.q_work is not None else Q))
    crit, wm, p = check_criterion(cm, qw, np.median(sig, axis=0), CHECK_STATION, seed=seed)
    z, F = _whiten(Sigma, data.position_m - Y, wm.jacobian(p, Q)[:, :3, :])
    z = _project_out(z, F[:, crit.setup])
    T = float(z @ z)
    E_w = wm.kpi_jacobian(p, qw)
    reach = _setup_reach(cm, crit, F, E_w, qw)
    shift, dist = _setup_change(model.setups[old].tracker_T_base, cm.setups[CHECK_STATION].tracker_T_base,
                                F[:, crit.setup], cm, Q, data)
    power = check_powers(crit, F, tolerance_m, alpha, null)
    out: dict[str, Any] = dict(n_rows=m, dof=dof, alpha=alpha, chi2=T, threshold=thr,
                               p_value=null.sf(T, dof), setup_shift_m=shift, setup_distance=dist,
                               power=power, tolerance_m=tolerance_m, registration_sigma_m=reach["reg"],
                               honest_sigma_m=reach["honest"], setup_determined=reach["determined"],
                               sigma_factor=float(np.sqrt(T / dof)), model=cm, success=True, status="checked")

    def add() -> np.ndarray:
        pool = np.random.default_rng(seed).uniform(model.robot.q_lower, model.robot.q_upper,
                                                   size=(POOL_SIZE, model.robot.nq))
        return poses_to_add(crit, wm, p, F, E_w[:, crit.setup], reach["honest"], pool, seed=seed)[0]

    if not reach["determined"] and propose:
        out["poses_to_add"] = add()
    if T <= thr:
        moved = dist > null.threshold(6, alpha)
        return CheckResult(verdict="setup_moved" if moved else "holds", tcp_sigma_m=reach["tcp"],
                           tcp_held_m=reach["held"],
                           message="the residuals are within the model's sigma", time_s=time.perf_counter() - t0,
                           **out)
    named = _name_group(crit, F, z, dof, alpha, null)
    out["groups"] = named["table"]
    if named["best"] is None:
        verdict = "recalibrate" if named["significant"] else "discrepancy_level"
        return CheckResult(verdict=verdict, message="no parameter group explains the residuals",
                           time_s=time.perf_counter() - t0, **out)
    if not named["best"][3] and "poses_to_add" not in out and propose:
        out["poses_to_add"] = add()
    return _changed(model, data, Q, named["best"], E_w, out, t0, held=_held_fit(model, data, Q, old, Sigma,
                                                                             named["best"], null, alpha))


def _held_fit(model: CalibratedModel, data: MeasurementSet, Q: np.ndarray, old: str, Sigma: np.ndarray, best: tuple,
              null: CheckNull, alpha: float) -> tuple | None:
    """The named group fitted with the set-up *held* at the model's station ``old`` (the tracker did not move): (its
    change, covariance of its basis coordinates, remaining χ²) when that simpler explanation passes its fit test at
    α / :data:`FIT_SHARE` on 3m − r_g degrees of freedom, else None. The held set-up was determined by the
    calibration's many rows, so the change is determined better than with the set-up re-fitted on the check rows."""
    g, _, _, det = best
    if not det:
        return None
    wm, p = model.station_model(old)
    z0, F0 = _whiten(Sigma, data.position_m - model.predict(Q, data, station=old), wm.jacobian(p, Q)[:, :3, :])
    A = F0[:, g.cols] @ g.basis
    x, *_ = np.linalg.lstsq(A, z0, rcond=None)
    rem = float(np.sum((z0 - A @ x) ** 2))
    if not rem <= null.threshold(len(z0) - A.shape[1], alpha / FIT_SHARE):
        return None
    return g.basis @ x, np.linalg.pinv(A.T @ A), rem


def _changed(model: CalibratedModel, data: MeasurementSet, Q: np.ndarray, best: tuple, E_w: np.ndarray,
             out: dict, t0: float, held: tuple | None = None) -> CheckResult:
    """The *robot changed* verdict of the named group: its change, the TCP displacement at the working
    configurations, and the re-fitted model when the rows determine the group (the set-up held when ``held``, the
    fit of :func:`_held_fit`, is given; else re-registered on the check rows)."""
    g, x, cov, det = best
    delta = g.basis @ x if held is None else held[0]
    cov = cov if held is None else held[1]
    std = np.sqrt(np.maximum(np.diag(g.basis @ cov @ g.basis.T), 0.0))
    E = E_w[:, g.cols]
    tcp_m = (float(np.linalg.norm(delta)) if g.kind == "tool"
             else float(np.sqrt(np.mean(np.sum((E @ delta).reshape(-1, 3) ** 2, axis=1)))))
    refit, T2 = (None, float("nan"))
    if held is not None:
        refit, T2 = _apply(model, data, g, delta), held[2]
        out = {**out, "setup_held": True}
    elif det:
        refit, T2 = _refit(model, data, Q, g, delta)
    if refit is not None:
        out = {**out, "model": refit}
    return CheckResult(verdict="robot_changed", group=g.name, change=delta, std=std, change_tcp_m=tcp_m,
                       determined=det, refit_chi2=T2, message=f"{g.name} changed",
                       time_s=time.perf_counter() - t0, **out)


def _setup_reach(cm: CalibratedModel, crit: CheckPower, F: np.ndarray, E_w: np.ndarray, qw: np.ndarray) -> dict:
    """What the registration on the check rows leaves at the working configurations: its own σ there (RMS 3-D, m),
    the model's honest σ there, whether the first is at most :data:`SETUP_FACTOR` × the second, the TCP σ per
    working configuration (:func:`~pin_kpi_oed.calibrated.tcp_sigma.tcp_sigma`, the one σ at the TCP, its σ factor
    left out) with the registration's share, and the part of it from the joint-placement parameters held at nominal
    (m)."""
    s = crit.setup
    Ms = F[:, s].T @ F[:, s]
    sig_w = _honest(cm, qw, None, CHECK_STATION)[1]
    honest = float(np.sqrt(np.mean(np.sum(sig_w ** 2, axis=1))))
    reg = registration_sigma_m(E_w[:, s], Ms)
    C = E_w[:, s] @ np.linalg.pinv(Ms, hermitian=True) @ E_w[:, s].T
    per = np.sum(np.diag(C).reshape(-1, 3), axis=1)
    st = dataclasses.replace(cm.setups[CHECK_STATION], sigma_scale=1.0)
    at = tcp_sigma(cm.with_setup(CHECK_STATION, st), qw, station=CHECK_STATION)
    tcp = np.sqrt(at.sigma_m ** 2 + np.maximum(per, 0.0))
    return {"reg": reg, "honest": honest, "determined": bool(reg <= SETUP_FACTOR * honest), "tcp": tcp,
            "held": at.held_sigma_m}


def check_powers(crit: CheckPower, F: np.ndarray, tolerance_m: float, alpha: float, null: CheckNull | None = None
                 ) -> dict:
    """Group -> power of the check with whitened Jacobian F (3m, np) against the group's weakest change of size τ, under
    the law ``null`` of the statistic (default the plain χ²; :func:`check_null`)."""
    dof = F.shape[0] - crit.setup.size
    mu = crit.mu(F.T @ F)[0]
    law = null or CheckNull()
    return {g.name: law.power(tolerance_m ** 2 * u, dof, alpha) for g, u in zip(crit.groups, mu)}


def check_null(model: CalibratedModel) -> CheckNull:
    """The law of the check's statistic under no change (:class:`~pin_kpi_oed.oed.check_power.CheckNull`): the
    standardised RMS and excess kurtosis of the model's own K-fold held-out errors (a Gaussian-process discrepancy's
    ``cv``), else the plain χ²."""
    d = model.discrepancy
    cv = d.cv if d is not None and d.kind != "white" else {}
    f, k = cv.get("z_rms"), cv.get("z_kurtosis")
    ok = [v is not None and np.isfinite(v) for v in (f, k)]
    return CheckNull(factor=float(np.clip(f, 0.5, 3.0)) if ok[0] else 1.0,
                     kurtosis=float(np.clip(k, 0.0, 10.0)) if ok[1] else 0.0)


def _joint_honest(cm: CalibratedModel, Q: np.ndarray, data: MeasurementSet) -> tuple[np.ndarray, np.ndarray]:
    """Predictions (m, 3) and the joint honest covariance (3m, 3m) of the check station's rows, its σ factor left
    out (:func:`~pin_kpi_oed.calibrated.prediction_sigma.predictive_covariance`)."""
    from pin_kpi_oed.calibrated.prediction_sigma import predictive_covariance

    st = dataclasses.replace(cm.setups[CHECK_STATION], sigma_scale=1.0)
    return predictive_covariance(cm.with_setup(CHECK_STATION, st), Q, data, CHECK_STATION)


def _whiten(Sigma: np.ndarray, r: np.ndarray, J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Residuals r (m, 3) and Jacobian J (m, 3, n) whitened by the joint covariance: L⁻¹ r, L⁻¹ J (Σ = L Lᵀ)."""
    import scipy.linalg as sla

    L = np.linalg.cholesky(Sigma + 1e-12 * np.mean(np.diag(Sigma)) * np.eye(len(Sigma)))
    z = sla.solve_triangular(L, r.reshape(-1), lower=True)
    F = sla.solve_triangular(L, J.reshape(len(Sigma), -1), lower=True)
    return z, F


def _project_out(z: np.ndarray, G: np.ndarray) -> np.ndarray:
    """z minus its least-squares fit by the columns G: the whitened residuals after the set-up's generalised
    least-squares re-registration (the registration itself fits without the rows' correlations)."""
    x, *_ = np.linalg.lstsq(G, z, rcond=None)
    return z - G @ x


def _register(model: CalibratedModel, data: MeasurementSet) -> CalibratedModel:
    """The set-up registered on the check rows (reflector held), fitted to the model's full prediction (geometry,
    effects and the discrepancy's mean, as :func:`~pin_kpi_oed.upkeep.transfer.register_setup` does)."""
    return register_setup(model, data, station=CHECK_STATION, hold_reflector=True).model


def _setup_change(T_old: np.ndarray, T_new: np.ndarray, G: np.ndarray, cm: CalibratedModel, Q: np.ndarray,
                  data: MeasurementSet) -> tuple[float, float]:
    """RMS displacement (m) of the check points between the old and the new set-up, and the Mahalanobis distance
    of the change under the registration's covariance (GᵀG)⁻¹ (G the whitened set-up columns)."""
    d = pin.log6(pin.SE3(T_old).inverse() * pin.SE3(T_new)).vector
    X = cm.predict(Q, data, station=CHECK_STATION)
    Rn, tn = T_new[:3, :3], T_new[:3, 3]
    base = (X - tn) @ Rn                                      # points in the robot base frame
    Xo = base @ T_old[:3, :3].T + T_old[:3, 3]
    shift = float(np.sqrt(np.mean(np.sum((X - Xo) ** 2, axis=1))))
    return shift, float(d @ (G.T @ G) @ d)


def _name_group(crit: CheckPower, F: np.ndarray, z: np.ndarray, dof: int, alpha: float, null: CheckNull) -> dict:
    """Each group fitted with the set-up; among the groups whose remaining χ² passes at α / :data:`FIT_SHARE` (the
    true group fails its own fit test at that rate, which caps the share named right at 1 − α / FIT_SHARE), the one
    of the least remaining χ² + 2 r_g (Akaike's criterion of the whitened rows: a larger group must explain more, a
    one-column group is not preferred when a three-column one fits far better)."""
    Gs = F[:, crit.setup]
    T = float(z @ z)
    table, passing, gains = [], [], []
    for g in crit.groups:
        A = np.hstack([Gs, F[:, g.cols] @ g.basis])
        x, *_ = np.linalg.lstsq(A, z, rcond=1e-6)
        sv = np.linalg.svd(A / np.maximum(np.linalg.norm(A, axis=0), 1e-300), compute_uv=False)
        det = bool(sv[-1] > 1e-6 * sv[0]) and A.shape[0] > A.shape[1]
        r = g.basis.shape[1] if det else max(int(np.sum(sv > 1e-6 * sv[0])) - Gs.shape[1], 0)
        rem = float(np.sum((z - A @ x) ** 2))
        # a group the rows do not determine may still explain them: named, with the poses that determine it
        ok = r > 0 and rem <= null.threshold(dof - r, alpha / FIT_SHARE)
        table.append({"name": g.name, "chi2_remaining": rem, "dof": dof - r, "determined": det, "explains": ok})
        gains.append(null.sf(T - rem, r))
        if ok:
            k = g.basis.shape[1]
            cov = np.linalg.pinv(A.T @ A, rcond=1e-12)[-k:, -k:]
            passing.append((r, rem, g, x[-k:], cov, det))
    best = min(passing, key=lambda c: c[1] + 2 * c[0])[2:] if passing else None
    significant = bool(min(gains) < alpha / len(crit.groups)) if gains else False
    return {"best": best, "table": table, "significant": significant}


def _refit(model: CalibratedModel, data: MeasurementSet, Q: np.ndarray, g: CheckGroup, delta: np.ndarray
           ) -> tuple[CalibratedModel, float]:
    """The model with the group's change applied and the set-up re-registered on the check rows; its χ²."""
    reg = _register(_apply(model, data, g, delta), data)
    Y, Sigma = _joint_honest(reg, Q, data)
    wm, p = reg.station_model(CHECK_STATION)
    z, F = _whiten(Sigma, data.position_m - Y, wm.jacobian(p, Q)[:, :3, :])
    L = wm.layout
    z = _project_out(z, F[:, L.tracker.start:L.tracker.stop])
    return reg, float(z @ z)


def _apply(model: CalibratedModel, data: MeasurementSet, g: CheckGroup, delta: np.ndarray) -> CalibratedModel:
    """The model with the group's change applied (its stations' set-ups kept)."""
    if g.kind == "tool":
        setups = {k: dataclasses.replace(s, reflector_m=s.reflector_m + delta) for k, s in model.setups.items()}
        new = dataclasses.replace(model, setups=setups, tcp_m=model.tcp_m + delta)
    else:
        jp = model.joint_p.copy()
        jp[g.cols] += delta
        new = dataclasses.replace(model, joint_p=jp)
    new.history = list(model.history) + [{"step": "check", "data": data.source, "group": g.name,
                                          "change": delta.tolist()}]
    return new
