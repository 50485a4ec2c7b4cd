r"""Keep a calibration: the verdict of a quick check on a few measured rows, by the size of a change at the TCP.

On the check rows the set-up (tracker pose; the reflector held: a moved reflector is a tool change) is re-registered
with the robot held and the residuals are whitened by the model's joint honest covariance Σ of the rows
(:mod:`~pin_kpi_oed.upkeep.check_rows`: the honest σ of :meth:`CalibratedModel.predict_with_sigma` on its diagonal,
the discrepancy's posterior covariance and the parameters' error shared between rows and axes off it; the
registration's own σ factor is *not* applied: it would hide the change under test): z = L⁻¹r, the set-up's
generalised least-squares step projected out. T = ‖z‖² has 3m − 6 degrees of freedom; its law under no change is
the scaled χ² of :class:`~pin_kpi_oed.oed.check_power.CheckNull` (the standardised RMS and the excess kurtosis of the
model's own K-fold held-out errors; the plain χ² without a K-fold check).

Two tests decide whether anything changed: T against its critical value (the robot or the discrepancy), and the
set-up's displacement of the working TCPs against the tolerance τ (one-sided: the displacement less z₁₋ₐ' times its
σ above τ). Each runs at α' = 1 − (1 − α)^{1/2} (Šidák; the two are independent under no change: T lies in the
complement of the set-up's columns), so the whole verdict says anything but *holds* on an unchanged robot with
probability at most α — the one false-alarm rate ``--alpha`` states. A change *matters* only when it is shown to
exceed the user's tolerance τ at the working TCPs (RMS over the working configurations): its size less z₁₋ₐ times
its σ above τ (an equivalence-style decision with the change's own uncertainty); a significant change below it is
reported inside *holds*, with its size ± σ.

The verdict, in this order:

* **holds** — nothing shown to exceed τ; the TCP σ at the working configurations, and any significant change below
  the tolerance with its size ± σ at the TCP (a group's, the set-up's, or residuals beyond the model's σ);
* **set-up moved** — the set-up's displacement of the working TCPs shown above τ, no change of the robot shown
  above it: re-registered, by how much ± σ;
* **robot changed** — T above its critical value; a group g explains the residuals (its detectable directions
  fitted with the set-up, its remaining χ² below its critical value at α/5; among such groups the least remaining
  χ² + 2 r_g, Akaike's criterion), its change moves the TCP by more than τ (shown), and re-fitting it is expected to
  be within :data:`REFIT_MARGIN` of a full re-calibration: the expected TCP error of the re-fitted model (the
  original calibration's own error at the working TCPs — the TCP σ: its parameters' covariance and the
  discrepancy — plus the change's estimation error, plus the registration's share when the set-up is re-registered)
  against a re-calibration of the same design (the calibration's own TCP σ). The re-fit holds the model's set-up when
  the group's change alone explains the rows (its fit with the set-up held passes at α/5: the tracker did not move),
  else re-registers it on the check rows;
* **discrepancy level** — T above, no group explains it and none takes a significant share (χ²(r_g) at α over the
  groups, Bonferroni), the residuals beyond the model's σ shown to move the TCP by more than τ
  (σ_W × √(ρ − 1), ρ's lower bound T / T_crit(α)): the residuals are larger everywhere alike;
* **re-calibrate** — a change above τ that a re-calibration corrects better than a re-fit (by more than
  :data:`REFIT_MARGIN`, the verdict says by how much), or one no group explains, or one the check cannot size: its
  linear estimate moves the working TCPs by more than :data:`PLAUSIBLE_TCP_M`, or the model with the change applied
  (the re-fit, not linearised) fails the named group's fit test at α / :data:`FIT_SHARE` on the check rows — the
  change lies beyond what the check poses estimate linearly. Such a verdict states no size ("the check cannot size
  this change: re-calibrate").

:attr:`CheckResult.exit_code`: 0 holds, 1 the set-up moved or the robot changed (the re-registered or re-fitted
model is what ``--model-out`` writes), 3 re-calibrate or the discrepancy's level changed.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pin_kpi_oed.calibrated.model_file import CalibratedModel
from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.oed.check_power import CheckGroup
from pin_kpi_oed.results import Result
from pin_kpi_oed.upkeep.check_rows import CHECK_STATION, POOL_SIZE, CheckRows, check_criterion, check_null, measure_rows
from pin_kpi_oed.upkeep.check_stats import (FIT_SHARE, check_group_name, check_powers, shown_above, sidak,
                                            verdict_powers)

__all__ = ["CheckResult", "check_calibration", "check_criterion", "check_group_name", "check_null", "check_powers",
           "shown_above", "sidak", "verdict_powers", "CHECK_STATION", "EXIT_CODES", "FIT_SHARE", "POOL_SIZE",
           "REFIT_MARGIN"]

VERDICTS = ("holds", "setup_moved", "robot_changed", "discrepancy_level", "recalibrate")
#: The exit code of each verdict (the command line's): 0 holds, 1 changed (re-registered / re-fitted), 3 re-calibrate.
EXIT_CODES = {"holds": 0, "setup_moved": 1, "robot_changed": 1, "discrepancy_level": 3, "recalibrate": 3}
#: A re-fit is kept while its expected TCP error is at most (1 + REFIT_MARGIN) × a re-calibration's.
REFIT_MARGIN = 0.10
#: A change of a group moving the working TCPs by more than this (RMS, m) is not sized: no calibrated robot's joint
#: or tool drifts by centimetres unnoticed, and a change that large is a crash, a new tool or a wrong model file.
PLAUSIBLE_TCP_M = 5e-3


@dataclass(kw_only=True)
class CheckResult(Result):
    """The verdict of :func:`check_calibration` (SI units).

    Attributes:
        verdict: one of ``holds``, ``setup_moved``, ``robot_changed``, ``discrepancy_level``, ``recalibrate``.
        n_rows: check rows; dof: degrees of freedom 3m − 6 of T; alpha: the verdict's false-alarm rate;
            alpha_each: the level of each of its two tests (Šidák).
        chi2: T = Σ z²; threshold: its critical value at alpha_each; p_value: P(T' > T) under no change.
        setup_shift_m: RMS displacement of the working TCPs by the set-up's change (m); setup_shift_sigma_m: its σ;
            setup_distance: the set-up step's Mahalanobis distance (χ²(6) under no change).
        power: group name -> power of the test T against the weakest change of size ``tolerance_m``.
        tolerance_m: the RMS TCP change at the working configurations that matters (m).
        tcp_sigma_m: TCP σ at the working configurations (norm, per configuration; m), the registration's and the
            parameters held at nominal included (:func:`~pin_kpi_oed.calibrated.tcp_sigma.tcp_sigma`).
        tcp_held_m: its part from the joint-placement parameters held at nominal (per configuration, m): no check of
            a reflector sees a change of them (its power against them is zero).
        group: the group the residuals name (also below the tolerance), or "".
        change: the group's fitted change in its columns (raw units: m, rad), std: its standard deviations.
        change_tcp_m: RMS TCP displacement of the change at the working configurations (m); change_tcp_sigma_m: its σ.
        determined: whether the check rows determine the named group's change.
        sigma_factor: √(T/dof) (the discrepancy's level against the model's); excess_tcp_m: the residuals beyond the
            model's σ carried to the working TCPs, σ_W √(ρ − 1) (m; NaN unless no group explains them).
        model: the re-registered (or re-fitted) model; refit_chi2: T of the re-fitted model on the check rows.
        groups: per group ``{name, chi2_remaining, dof, determined, explains}``.
        registration_sigma_m, honest_sigma_m, setup_determined: the registration's σ at the working configurations,
            the model's honest σ there (RMS 3-D, m), and whether the first is at most twice the second.
        setup_held: the re-fit kept the model's set-up (the group's change alone explains the rows).
        refit_error_m, recalibrate_error_m: expected RMS TCP error at the working configurations of the re-fitted
            model and of a re-calibration of the same design (m; NaN unless a change above τ was named).
        note: what *holds* holds despite (a significant change below the tolerance), or why the check cannot size
            a change, or "".
        alike: the other parts (a joint, ``tool``) the check rows do not tell apart from the named group's (they fit
            the rows as well: :func:`check_group_name`); the verdict names "group or part ...".
        sized: False when a change shown above τ is beyond what the check can size (no size is stated; *re-calibrate*).
        poses_to_add: configurations (k, n) rad to measure next (:func:`~pin_kpi_oed.upkeep.check_poses.poses_to_add`).
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
    alpha_each: float = float("nan")
    setup_shift_sigma_m: float = float("nan")
    power: dict = field(default_factory=dict)
    tolerance_m: float = 1e-4
    tcp_sigma_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    tcp_held_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    group: str = ""
    change: np.ndarray = field(default_factory=lambda: np.zeros(0))
    std: np.ndarray = field(default_factory=lambda: np.zeros(0))
    change_tcp_m: float = float("nan")
    change_tcp_sigma_m: float = float("nan")
    determined: bool = False
    sigma_factor: float = 1.0
    excess_tcp_m: float = float("nan")
    model: CalibratedModel | None = field(default=None, repr=False)
    refit_chi2: float = float("nan")
    groups: list = field(default_factory=list)
    registration_sigma_m: float = float("nan")
    honest_sigma_m: float = float("nan")
    setup_determined: bool = True
    poses_to_add: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    setup_held: bool = False
    refit_error_m: float = float("nan")
    recalibrate_error_m: float = float("nan")
    note: str = ""
    sized: bool = True
    alike: list = field(default_factory=list)

    @property
    def exit_code(self) -> int:
        """0 holds, 1 the set-up moved or the robot changed (re-registered / re-fitted), 3 re-calibrate."""
        return EXIT_CODES[self.verdict]

    def summary(self) -> str:
        """One line (mm, mrad)."""
        stat = (f"chi2 {self.chi2:.1f} on {self.dof} dof (threshold {self.threshold:.1f}; false-alarm rate of the "
                f"verdict {self.alpha:g}, each of its two tests at {self.alpha_each:.3g}, p {self.p_value:.3g})")
        weakest = min(self.power, key=self.power.get) if self.power else ""
        pw = (f"; power against a {self.tolerance_m * 1e3:.3g} mm change: {min(self.power.values()):.2f} "
              f"(weakest: {weakest})") if self.power else ""
        pw += self.undetermined_text()
        tol = f"the tolerance of {self.tolerance_m * 1e3:.3g} mm"
        if self.verdict == "holds":
            tcp = (f", TCP sigma at the working configurations median {np.median(self.tcp_sigma_m) * 1e3:.3f} mm, max "
                   f"{np.max(self.tcp_sigma_m) * 1e3:.3f} mm" if self.tcp_sigma_m.size else "")
            if self.tcp_held_m.size and np.max(self.tcp_held_m) > 0:
                tcp += (f" (of which {np.median(self.tcp_held_m) * 1e3:.3f} mm from joint-placement parameters held "
                        "at their tolerance, which no check of this reflector sees)")
            note = f" ({self.note})" if self.note else ""
            return f"check: holds{note}{tcp}; {stat}{pw}"
        if self.verdict == "setup_moved":
            return (f"check: set-up moved by {_pm(self.setup_shift_m, self.setup_shift_sigma_m)} mm at the working "
                    f"TCPs, above {tol} (re-registered); the calibration holds; {stat}{pw}")
        if self.verdict == "robot_changed":
            what = _change_text(self) + ("; the set-up unchanged (held)" if self.setup_held else "")
            return f"check: the robot changed: {what}, above {tol}; {self.action_text()}; {stat}{pw}"
        if self.group and not self.sized:
            closest = " or ".join([self.group, *self.alike])
            return (f"check: re-calibrate: the check cannot size this change ({self.note}; linearly closest: "
                    f"{closest}); {stat}{pw}")
        if not self.sized:
            return (f"check: re-calibrate: the check cannot size this change (residuals {self.sigma_factor:.0f}x the "
                    f"model's sigma, beyond {PLAUSIBLE_TCP_M * 1e3:g} mm at the working TCPs; no parameter group "
                    f"explains them); {stat}{pw}")
        if self.group:
            return (f"check: re-calibrate: {_change_text(self)}, above {tol}; {self.action_text()}; {stat}{pw}")
        level = (f"residuals {self.sigma_factor:.2f}x the model's sigma, {self.excess_tcp_m * 1e3:.3f} mm beyond it at "
                 f"the working TCPs")
        if self.verdict == "discrepancy_level":
            return (f"check: the discrepancy's level changed: {level}, everywhere alike (no group explains them); "
                    f"re-calibrate; {stat}{pw}")
        return f"check: re-calibrate: no parameter group explains the residuals ({level}); {stat}{pw}"

    def action_text(self) -> str:
        """Which of re-fit and re-calibration is better on the expected TCP error, and by how much."""
        a, b = self.refit_error_m, self.recalibrate_error_m
        if not (np.isfinite(a) and np.isfinite(b)):
            return "the change is not determined by the rows: no re-fit"
        rel = (a / b - 1.0) * 100
        if self.verdict == "robot_changed":
            return (f"re-fitted (expected TCP error {a * 1e3:.3f} mm, a re-calibration of the same design "
                    f"{b * 1e3:.3f} mm: the re-fit within {max(rel, 0):.0f} %{self.held_left_out_text()})")
        return (f"a re-calibration is better by {rel:.0f} % (expected TCP error {b * 1e3:.3f} mm against the "
                f"re-fit's {a * 1e3:.3f} mm{self.held_left_out_text()})")

    def held_left_out_text(self) -> str:
        """The part of the TCP's σ no measurement determines, left out of both expected errors ("" when none).

        Returns:
            "; the X mm of the TCP's sigma that no measurement determines ... left out" with X the RMS over the
            working configurations of :attr:`tcp_held_m` (mm), or "" when it is zero or unknown.
        """
        held = np.asarray(self.tcp_held_m, dtype=float)
        if not held.size or not np.max(held) > 0:
            return ""
        rms = float(np.sqrt(np.mean(held ** 2)))
        return (f"; the {rms * 1e3:.3f} mm of the TCP's sigma that no measurement determines (joint-placement "
                "parameters held at their tolerance) is the same either way and left out")

    def undetermined_text(self) -> str:
        """What the check rows leave undetermined and the poses to add ("" when nothing)."""
        k = len(self.poses_to_add)
        add = f"measure the {k} poses of poses_to_add (--json) too" if k else "measure poses spread over the workspace"
        if not self.setup_determined:
            return (f"; the {self.n_rows} rows do not determine the set-up at the working configurations (the "
                    f"registration alone leaves {self.registration_sigma_m * 1e3:.3f} mm there, the honest sigma is "
                    f"{self.honest_sigma_m * 1e3:.3f} mm): {add}")
        if self.group and not self.determined:
            return f"; the rows do not determine the change of {self.group}: {add}"
        return ""

    def to_dict(self) -> dict:
        """Plain JSON-able dict (SI units)."""
        arrays = ("tcp_sigma_m", "tcp_held_m", "change", "std", "poses_to_add")
        skip = {"model", "success", "status", "message", "nit", "nfev", "time_s"}
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name not in skip}
        out.update({k: np.asarray(out[k]).tolist() for k in arrays})
        return {**self.result_dict(), **out, "exit_code": self.exit_code}


def _pm(value_m: float, sigma_m: float) -> str:
    return f"{value_m * 1e3:.3f} ± {sigma_m * 1e3:.3f}"


def _change_text(r: CheckResult) -> str:
    text = _group_text(r)
    if r.alike:
        text += (f", or a change of {' or '.join(r.alike)} (the check rows do not tell "
                 f"{'them' if len(r.alike) > 1 else 'the two'} apart: the size is the named group's)")
    return text


def _group_text(r: CheckResult) -> str:
    if not r.determined:
        return f"{r.group} (not determined by the check rows)"
    at = f"{_pm(r.change_tcp_m, r.change_tcp_sigma_m)} mm RMS at the TCP"
    if r.group.endswith(" offset"):
        k = int(np.argmax(np.abs(r.change)))
        return f"{r.group} by {r.change[k] * 1e3:+.3f} ± {r.std[k] * 1e3:.3f} mrad ({at})"
    if r.group == "tool":
        return (f"tool by [{', '.join(f'{v * 1e3:+.3f}' for v in r.change)}] ± "
                f"[{', '.join(f'{v * 1e3:.3f}' for v in r.std)}] mm ({at})")
    names = ("tx", "ty", "tz", "rx", "ry", "rz")
    big = [k for k in range(r.change.size) if abs(r.change[k]) > 3 * r.std[k]] or [int(np.argmax(np.abs(r.change)))]
    parts = [f"{names[k]} {r.change[k] * 1e3:+.3f} ± {r.std[k] * 1e3:.3f} {'mm' if k < 3 else 'mrad'}" for k in big]
    return f"{r.group}: {', '.join(parts)} ({at})"


def check_calibration(model: CalibratedModel, data: MeasurementSet, *, station: str | None = None,
                      alpha: float = 0.05, tolerance_m: float = 1e-4, q_work: np.ndarray | None = None,
                      seed: int = 0, propose: bool = True) -> CheckResult:
    """The verdict of a check on measured rows (module docstring).

    Args:
        model: the calibrated model; station: the model's station the check compares the set-up with.
        data: the check rows (joint columns, x, y, z in m).
        alpha: the verdict's false-alarm rate (anything but *holds* on an unchanged robot), in (0, 0.5).
        tolerance_m: the RMS TCP change at the working configurations that matters (m).
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
    rows = measure_rows(model, data, station, q_work, seed, alpha=alpha, tolerance_m=tolerance_m, propose=propose)
    a1, T, dof = rows.alpha_each, rows.T, rows.dof
    out: dict[str, Any] = dict(n_rows=rows.m, dof=dof, alpha=alpha, alpha_each=a1, chi2=T, threshold=rows.threshold,
                               p_value=rows.p_value, setup_shift_m=rows.setup_shift_m,
                               setup_shift_sigma_m=rows.setup_shift_sigma_m, setup_distance=rows.setup_distance,
                               power=rows.power, tolerance_m=tolerance_m,
                               registration_sigma_m=rows.registration_sigma_m, honest_sigma_m=rows.honest_sigma_m,
                               setup_determined=rows.setup_determined, sigma_factor=float(np.sqrt(T / dof)),
                               tcp_sigma_m=np.sqrt(rows.tcp_sigma_m ** 2 + rows.reg_share_m2 + rows.tcp_held_m ** 2),
                               tcp_held_m=rows.tcp_held_m, model=rows.cm, poses_to_add=rows.poses_to_add,
                               success=True, status="checked")
    moved = shown_above(rows.setup_shift_m, rows.setup_shift_sigma_m, tolerance_m, a1)
    if rows.named is None:
        return _quiet(rows, out, moved, t0)
    named = rows.named
    out["groups"], out["alike"] = named["table"], named["alike"]
    if named["best"] is None:
        return _unexplained(rows, out, named["significant"], moved, t0)
    return _changed(data, rows, named["best"], out, t0, moved)


def _setup_note(rows: CheckRows, a1: float) -> str:
    """The set-up's significant displacement below the tolerance, or ""."""
    if rows.setup_distance > rows.null.threshold(6, a1):
        return (f"the set-up shifted by {_pm(rows.setup_shift_m, rows.setup_shift_sigma_m)} mm at the working TCPs, "
                "re-registered; below the tolerance")
    return ""


def _quiet(rows: CheckRows, out: dict, moved: bool, t0: float) -> CheckResult:
    """T below its critical value: *set-up moved* when its displacement is shown above τ, else *holds*."""
    if moved:
        return CheckResult(verdict="setup_moved", message="the set-up moved; the residuals are within the model's "
                           "sigma", time_s=time.perf_counter() - t0, **out)
    return CheckResult(verdict="holds", note=_setup_note(rows, out["alpha_each"]),
                       message="the residuals are within the model's sigma", time_s=time.perf_counter() - t0, **out)


def _unexplained(rows: CheckRows, out: dict, significant: bool, moved: bool, t0: float) -> CheckResult:
    """T above, no group explains it: the residuals beyond the model's σ carried to the working TCPs, σ_W √(ρ − 1);
    *discrepancy level* / *re-calibrate* when its lower bound (ρ ≥ T / T_crit(α)) exceeds τ, else *holds* (or *set-up
    moved*) with the excess stated."""
    null, T, dof, alpha = rows.null, rows.T, rows.dof, out["alpha"]
    rho = T / (null.scale * dof)
    excess = rows.honest_sigma_m * np.sqrt(max(rho - 1.0, 0.0))
    low = rows.honest_sigma_m * np.sqrt(max(T / null.threshold(dof, alpha) - 1.0, 0.0))
    out = {**out, "excess_tcp_m": float(excess)}
    if low > out["tolerance_m"]:
        verdict = "recalibrate" if significant else "discrepancy_level"
        if excess > PLAUSIBLE_TCP_M:        # a level that large is no discrepancy's: a change the check cannot size
            verdict, out = "recalibrate", {**out, "excess_tcp_m": float("nan"), "sized": False}
        return CheckResult(verdict=verdict, message="no parameter group explains the residuals",
                           time_s=time.perf_counter() - t0, **out)
    note = (f"residuals {np.sqrt(rho):.2f}x the model's sigma that no group explains, {excess * 1e3:.3f} mm beyond "
            f"it at the working TCPs (at least {low * 1e3:.3f} mm), not shown above the tolerance")
    if moved:
        return CheckResult(verdict="setup_moved", note=note, message="the set-up moved",
                           time_s=time.perf_counter() - t0, **out)
    return CheckResult(verdict="holds", note=note, message="below the tolerance", time_s=time.perf_counter() - t0,
                       **out)


def _tcp_change(rows: CheckRows, g: CheckGroup, delta: np.ndarray, cov_delta: np.ndarray) -> tuple[float, float, float]:
    """(RMS TCP displacement of the change at the working configurations, its σ along it, the RMS σ of the change's
    estimation error at the TCP), m; the σ scaled by the model's held-out standardised RMS."""
    t = len(rows.qw)
    if g.kind == "tool":
        e, C = np.tile(delta, t), np.kron(np.ones((t, t)), cov_delta)    # one displacement at every TCP
    else:
        E = rows.E_w[:, g.cols]
        e, C = E @ delta, E @ cov_delta @ E.T
    C = C * rows.null.factor ** 2
    size = float(np.linalg.norm(e))
    u = e / size if size > 0 else np.zeros_like(e)
    along, total = float(u @ C @ u), float(np.trace(C))
    return size / np.sqrt(t), float(np.sqrt(max(along, 0.0) / t)), float(np.sqrt(max(total, 0.0) / t))


def _changed(data: MeasurementSet, rows: CheckRows, best: tuple, out: dict, t0: float, moved: bool) -> CheckResult:
    """A group explains the residuals: its change ± σ at the TCP — fitted with the model's set-up held when that
    explains the rows (:attr:`CheckRows.held`) —; above τ (shown) the re-fitted model and the choice between it and a
    re-calibration on the expected TCP error; below, *holds* (or *set-up moved*) saying so."""
    g, x, cov, det = best
    held = rows.held
    delta = g.basis @ x if held is None else held[0]
    cov = cov if held is None else held[1]
    cov_delta = g.basis @ cov @ g.basis.T
    std = np.sqrt(np.maximum(np.diag(cov_delta), 0.0)) * rows.null.factor
    size, sd, est = _tcp_change(rows, g, delta, cov_delta) if det else (float("nan"),) * 3
    out = {**out, "group": g.name, "change": delta, "std": std, "change_tcp_m": size, "change_tcp_sigma_m": sd,
           "determined": det}
    implausible = bool(det and size > PLAUSIBLE_TCP_M)
    if not shown_above(size, sd, out["tolerance_m"], out["alpha"]):
        what = (f"a change of {g.name} the rows do not determine" if not det else
                f"a change of {g.name} the check cannot size, not shown above the tolerance" if implausible else
                f"a change of {g.name} of {_pm(size, sd)} mm at the TCP, not shown above the tolerance")
        verdict = "setup_moved" if moved else "holds"
        return CheckResult(verdict=verdict, note=what, message=f"{g.name}: below the tolerance",
                           time_s=time.perf_counter() - t0, **out)
    if implausible:
        return _unsized(out, f"its linear estimate moves the working TCPs by more than {PLAUSIBLE_TCP_M * 1e3:g} mm",
                        t0)
    refit, T2 = rows.refit(data, g, delta, hold_setup=held is not None)
    dof2 = (3 * rows.m if held is not None else rows.dof) - g.basis.shape[1]
    out["setup_held"] = held is not None
    if not T2 <= rows.null.threshold(dof2, out["alpha"] / FIT_SHARE):
        return _unsized({**out, "refit_chi2": T2}, f"the model with the change applied leaves chi2 {T2:.1f} on "
                        f"{dof2} dof: the change lies beyond what the check poses estimate linearly", t0)
    cal2 = float(np.mean(rows.tcp_sigma_m ** 2))
    reg2 = 0.0 if held is not None else float(np.mean(rows.reg_share_m2))
    refit_err, recal_err = float(np.sqrt(cal2 + est ** 2 + reg2)), float(np.sqrt(cal2))
    out = {**out, "refit_error_m": refit_err, "recalibrate_error_m": recal_err, "model": refit, "refit_chi2": T2}
    verdict = "robot_changed" if refit_err <= (1.0 + REFIT_MARGIN) * recal_err else "recalibrate"
    return CheckResult(verdict=verdict, message=f"{g.name} changed", time_s=time.perf_counter() - t0, **out)


def _unsized(out: dict, why: str, t0: float) -> CheckResult:
    """A change shown above τ that the check cannot size (module docstring): *re-calibrate*, no size stated, the
    model re-registered only."""
    out = {**out, "change_tcp_m": float("nan"), "change_tcp_sigma_m": float("nan"), "sized": False, "note": why}
    return CheckResult(verdict="recalibrate", message=f"{out['group']}: the check cannot size this change",
                       time_s=time.perf_counter() - t0, **out)
