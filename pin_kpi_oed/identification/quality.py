"""Fit-quality gate after identification: is the calibrated model plausible given the noise?

A least-squares fit always "converges"; whether its result may go to a robot is a separate
question. :func:`assess_fit` answers it from three tests, each against what the noise model
predicts:

1. **Reduced χ²** of the weighted residuals (eq. 5 weights) against its two-sided
   (1 - ``alpha``) interval ``χ²_{dof}(α/2, 1-α/2) / dof``: only when the noise level is known
   (sigma columns in the data or ``--sigma``); otherwise the covariance was scaled by χ² and
   the test is skipped (said so). χ² above ``chi2_poor``
   makes the fit **poor** (residuals four times the stated noise); above the interval only
   **suspect** (flagged, exit 0).
2. **Held-out error** after calibration against the nominal robot's (same fitted set-up): a
   calibration worse than no calibration is **poor**; held-out RMS above three times the
   training RMS is **suspect** (over-fit, or a session change).
   With a model discrepancy (a Gaussian process over the joint angles, :mod:`pin_kpi_oed.discrepancy`)
   whose K-fold held-out σ is honest, a χ² between the interval and ``chi2_poor`` is explained by it
   (the verdict says so); a poor χ² never is.
3. **Outliers** far beyond the noise with the plain (linear) loss: they bias every parameter;
   the robust loss (``--loss soft_l1``) is recommended (**poor** when they also spoil 1 or 2).
4. **Plausible geometry**: a fitted joint placement more than :data:`PLAUSIBLE_JOINT_TRANSLATION_M` or
   :data:`PLAUSIBLE_JOINT_ROTATION_RAD` from the nominal model is no real arm's (manufacturing errors are a few
   tenths of a mm and mrad). With few poses the least-squares fit can land on another local solution that fits
   them as well as the true one (on the real UR10, 12-20 poses of one session: joint rotations of 0.08-0.9 rad
   and TCP errors of 4-40 mm in another session, at a residual as small as the good fits'): **poor**.

5. **Determined effects**: an effect parameter whose σ exceeds ten times its plausible size is not determined.
6. **A regular covariance**: a geometric parameter whose σ exceeds 100 times its manufacturing tolerance (0.5 mm,
   1 mrad) or two parameters correlated beyond |r| = 0.999 are not determined by the data (a singular or
   ill-conditioned covariance): **poor**, the parameters named with the fix (hold them at nominal, a weak prior,
   or poses that determine them).

The verdict is one line naming the likely causes (reflector/TCP offset, units, outliers, wrong
robot or unmodelled effects) and what to try; :meth:`FitQuality.to_dict` puts it in the JSON.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from collections.abc import Callable
from typing import Any

import numpy as np
from scipy.special import gammaincinv  # the χ² quantiles below are scipy.stats.chi2.ppf's own formula

__all__ = ["FitQuality", "assess_fit", "robust_loss_reason"]

#: reduced chi2 above which the residuals are at least four times the stated noise: a poor fit (below it and
#: above the interval the fit is only "suspect": real arms have unmodelled effects a noise model omits)
CHI2_POOR = 16.0
#: an outlier whose weighted error exceeds this many robust standard deviations is "large"
OUTLIER_LARGE = 20.0
#: a fitted joint-placement translation (m) / rotation (rad) beyond these is no real arm's: ~40x the manufacturing
#: tolerances of :class:`~pin_kpi_oed.model.tolerances.Tolerances` (0.5 mm, 1 mrad)
PLAUSIBLE_JOINT_TRANSLATION_M = 0.02
PLAUSIBLE_JOINT_ROTATION_RAD = 0.05


@dataclass
class FitQuality:
    """Verdict of the fit-quality gate.

    Attributes:
        verdict: ``"good"``, ``"suspect"`` (flagged, accepted) or ``"poor"`` (refused unless accepted).
        chi2_reduced: reduced χ² of the fit (dimensionless).
        chi2_interval: (lo, hi) of its (1 - alpha) interval, or None when the noise level is unknown.
        dof: degrees of freedom of χ².
        noise_known: the weights came from sigma columns or a given sigma (absolute noise level).
        train_rms_m: RMS position error on the training inliers (m).
        heldout_rms_before_m, heldout_rms_after_m: held-out RMS of the nominal robot and of the
            calibration (m), or None without validation data.
        n_outliers: flagged measurements; large_outliers: those beyond ``OUTLIER_LARGE`` robust σ.
        causes: likely causes, most likely first; advice: what to try.
        reasons: the failed tests, one phrase each.
    """

    verdict: str
    chi2_reduced: float
    chi2_interval: tuple[float, float] | None
    dof: int
    noise_known: bool
    train_rms_m: float
    heldout_rms_before_m: float | None = None
    heldout_rms_after_m: float | None = None
    n_outliers: int = 0
    large_outliers: int = 0
    causes: list[str] = field(default_factory=list)
    advice: list[str] = field(default_factory=list)
    reasons: list[str] = field(default_factory=list)
    explained_by_discrepancy: str = ""

    @property
    def poor(self) -> bool:
        """True when the fit must not be used without ``--accept-poor-fit``."""
        return self.verdict == "poor"

    def line(self) -> str:
        """The one-line verdict (what failed, likely causes, what to try)."""
        if self.verdict == "good":
            chi = (f"reduced chi2 {self.chi2_reduced:.3g} within [{self.chi2_interval[0]:.3g}, "
                   f"{self.chi2_interval[1]:.3g}]" if self.chi2_interval else
                   "noise level unknown (no sigma columns, no parameter 'sigma_xyz_m'): chi2 not tested")
            if self.explained_by_discrepancy:
                chi = self.explained_by_discrepancy
            return f"fit quality: good ({chi})"
        out = f"fit quality: {self.verdict.upper()}: {'; '.join(self.reasons)}"
        if self.causes:
            out += f"; likely causes: {', '.join(self.causes)}"
        if self.advice:
            out += f"; try: {'; '.join(self.advice)}"
        return out

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (SI units)."""
        return {"verdict": self.verdict, "message": self.line(), "chi2_reduced": self.chi2_reduced,
                "chi2_interval": list(self.chi2_interval) if self.chi2_interval else None, "dof": self.dof,
                "noise_known": self.noise_known, "train_rms_m": self.train_rms_m,
                "heldout_rms_before_m": self.heldout_rms_before_m, "heldout_rms_after_m": self.heldout_rms_after_m,
                "n_outliers": self.n_outliers, "large_outliers": self.large_outliers, "causes": list(self.causes),
                "advice": list(self.advice), "reasons": list(self.reasons),
                "explained_by_discrepancy": self.explained_by_discrepancy}


def _rms(stats: dict | None) -> float | None:
    if not stats:
        return None
    v = stats.get("rms_m")
    return None if v is None else float(v)


def assess_fit(result: Any, validation: dict | None = None, *, nominal_reflector_m: Any = None,
               reflector_estimated: bool = False, alpha: float = 1e-3, chi2_poor: float = CHI2_POOR) -> FitQuality:
    """Judge an :class:`~pin_kpi_oed.identification.identify.IdentificationResult` against its noise model.

    Args:
        result: the identification result (``chi2_reduced``, ``covariance_scaled``, ``weighted_errors``,
            ``errors_m``, ``outliers``, ``loss``, ``names``, ``reflector_m``).
        validation: ``{"before": stats, "after": stats}`` of held-out errors (``rms_m`` in m), or None.
        nominal_reflector_m: the nominal reflector offset the identifiable set was chosen with (m).
        reflector_estimated: the nominal reflector was estimated from the data (not given by the user).
        alpha: two-sided false-alarm probability of the χ² interval.
        chi2_poor: reduced χ² above which the fit is poor.

    Returns:
        The :class:`FitQuality` verdict.
    """
    we = np.asarray(result.weighted_errors, float)
    m = we.size
    out_idx = np.asarray(result.outliers, int)
    keep = np.ones(m, bool)
    keep[out_idx] = False
    nh = 6 if getattr(result, "residuals_rad", None) is not None else 3
    dof = max(int(keep.sum()) * nh - len(result.names), 1)
    chi2_red = float(result.chi2_reduced)
    noise_known = not bool(result.covariance_scaled)
    err = np.asarray(result.errors_m, float)
    train_rms = float(np.sqrt(np.mean(err[keep] ** 2))) if keep.any() else float("nan")
    f = _Findings()
    large = _check_outliers(f, result, we, out_idx, nh, noise_known)
    interval = None
    explained = ""
    if noise_known:
        g = _Findings()
        interval = _check_chi2(g, chi2_red, dof, alpha, chi2_poor, nominal_reflector_m, reflector_estimated)
        explained = _explained_by_discrepancy(result, g, chi2_red, interval)
        if not explained:
            f.worse(g.verdict)
            f.reasons += g.reasons
            f.causes += g.causes
            f.advice += g.advice
    before, after = _check_heldout(f, validation, train_rms, large)
    _check_geometry(f, result)
    _check_effects(f, result)
    _check_covariance(f, result)
    causes = list(dict.fromkeys(f.causes))  # duplicates dropped, order kept
    advice = list(dict.fromkeys(f.advice))
    return FitQuality(verdict=f.verdict, chi2_reduced=chi2_red, chi2_interval=interval, dof=dof,
                      noise_known=noise_known, train_rms_m=train_rms, heldout_rms_before_m=before,
                      heldout_rms_after_m=after, n_outliers=int(out_idx.size), large_outliers=large,
                      causes=causes, advice=advice, reasons=f.reasons,
                      explained_by_discrepancy=explained if f.verdict == "good" else "")


def _explained_by_discrepancy(result: Any, g: _Findings, chi2_red: float, interval: tuple[float, float]) -> str:
    """A χ² above its interval but below the poor threshold is the model discrepancy's when a Gaussian process
    over the joint angles was fitted to the residuals and its K-fold held-out σ is honest (standardised RMS within
    [0.67, 1.5]): every σ the model predicts then includes that error. A poor χ² (residuals far above the stated
    noise, e.g. a units mistake) is never explained away. Returns the sentence the verdict prints, or ""."""
    d = getattr(result, "discrepancy", None)
    cv = getattr(d, "cv", None) or {}
    if g.verdict != "suspect" or chi2_red <= interval[1] or d is None or getattr(d, "kind", "white") == "white":
        return ""
    z = cv.get("z_rms")
    if z is None or not (0.67 <= float(z) <= 1.5):
        return ""
    return (f"reduced chi2 {chi2_red:.3g} above the noise's interval [{interval[0]:.3g}, {interval[1]:.3g}]: the "
            f"residuals are the model discrepancy's (Gaussian process, {cv.get('folds', 5)}-fold held-out "
            f"standardised RMS {float(z):.2f}); every predicted sigma includes it")


def _check_geometry(f: _Findings, result: Any) -> None:
    """Check 4: every fitted joint placement within :data:`PLAUSIBLE_JOINT_TRANSLATION_M` /
    :data:`PLAUSIBLE_JOINT_ROTATION_RAD` of the nominal model, else poor (the worst one named)."""
    p, model = getattr(result, "p", None), getattr(result, "model", None)
    layout = getattr(model, "layout", None)
    if p is None or layout is None:
        return
    p = np.asarray(p, float)
    bad = []
    for j in range(layout.n_joints):
        sl = layout.joint_slice(j)
        for k in range(sl.start, sl.stop):
            lim = PLAUSIBLE_JOINT_TRANSLATION_M if k - sl.start < 3 else PLAUSIBLE_JOINT_ROTATION_RAD
            if abs(p[k]) > lim:
                bad.append((abs(p[k]) / lim, k, k - sl.start < 3))
    if not bad:
        return
    _, k, trans = max(bad)
    value = f"{p[k] * 1e3:.1f} mm" if trans else f"{p[k]:.3f} rad"
    f.worse("poor")
    f.reasons.append(f"{len(bad)} fitted joint placement(s) implausibly far from the nominal model ({layout.names[k]} "
                     f"{value}; real arms are within {PLAUSIBLE_JOINT_TRANSLATION_M * 1e3:g} mm and "
                     f"{PLAUSIBLE_JOINT_ROTATION_RAD:g} rad)")
    f.causes.append("poses that do not pin the geometry down (the fit found another solution that fits them)")
    f.advice.append("measure more or more varied poses (pin-kpi-oed design), or identify --geometry-prior 5e-3,1e-2 "
                    "(keeps every joint placement near the nominal model)")


#: a geometric parameter whose standard deviation exceeds this many times its manufacturing tolerance is not
#: determined by the data (the covariance is singular or ill-conditioned along it)
SIGMA_TOLERANCE_FACTOR = 100.0
#: two estimated parameters correlated beyond this are not told apart by the data
CORRELATION_SINGULAR = 0.999


def _tolerance_of(name: str) -> tuple[float, str] | None:
    """(manufacturing tolerance, unit) of a geometric parameter by its name (joint placements, tracker, reflector:
    the default :class:`~pin_kpi_oed.model.tolerances.Tolerances`, 0.5 mm and 1 mrad), None for an effect's."""
    from pin_kpi_oed.model.tolerances import Tolerances

    tol = Tolerances()
    suffix = name.rsplit(".", 1)[-1]
    if suffix in ("tx", "ty", "tz") or name.split(".")[0].split("@")[0] == "reflector":
        return tol.joint_translation_m, "m"
    if suffix in ("rx", "ry", "rz"):
        return tol.joint_rotation_rad, "rad"
    return None


def _check_covariance(f: _Findings, result: Any) -> None:
    """Check 6: a covariance that is singular or ill-conditioned: a geometric parameter whose σ exceeds
    :data:`SIGMA_TOLERANCE_FACTOR` times its tolerance, or two parameters correlated beyond
    :data:`CORRELATION_SINGULAR`, makes the fit poor (the parameters named): the data do not determine them, their
    values are arbitrary along that direction and every σ computed from the covariance is meaningless."""
    names = list(getattr(result, "names", []) or [])
    std = np.asarray(getattr(result, "std", []), float)
    if not names or std.size != len(names):
        return
    loose = []
    for k, n in enumerate(names):
        tu = _tolerance_of(n)
        if tu is not None and not (std[k] <= SIGMA_TOLERANCE_FACTOR * tu[0]):
            loose.append((std[k] / tu[0], n, std[k], tu))
    corr = np.asarray(getattr(result, "correlation", np.zeros((0, 0))), float)
    pairs = []
    if corr.shape == (len(names), len(names)):
        iu = np.triu_indices(len(names), 1)
        r = np.abs(corr[iu])
        pairs = sorted(((float(r[t]), iu[0][t], iu[1][t]) for t in np.flatnonzero(r > CORRELATION_SINGULAR)),
                       reverse=True)
    if not loose and not pairs:
        return
    what, named = [], []
    if loose:
        loose.sort(reverse=True)
        shown = ", ".join(f"{n} ± {s * 1e3:.4g} {'mm' if u == 'm' else 'mrad'}" for _, n, s, (_, u) in loose[:3])
        what.append(f"{len(loose)} parameter(s) with a sigma beyond {SIGMA_TOLERANCE_FACTOR:g}x their tolerance "
                    f"({shown}; tolerances 0.5 mm, 1 mrad)")
        named += [n for _, n, _, _ in loose[:3]]
    if pairs:
        rr, i, j = pairs[0]
        what.append(f"{len(pairs)} parameter pair(s) correlated beyond |r| {CORRELATION_SINGULAR:g} ({names[i]} / "
                    f"{names[j]}, r = {corr[i, j]:+.4f})")
        named += [names[i], names[j]]
    f.worse("poor")
    f.reasons.append("singular or ill-conditioned covariance: " + "; ".join(what))
    f.causes.append("parameters the poses do not determine (nearly parallel joint axes, e.g. a nominal model with "
                    "rounded angles, or too few / too similar poses): their values and every sigma are arbitrary")
    keep = [n for n in dict.fromkeys(named) if not n.startswith(("tracker", "reflector"))] or list(named)
    f.advice.append(f"hold {', '.join(keep[:2])} at the nominal value (identify --fix '{','.join(keep[:2])}') or near "
                    "it (identify --geometry-prior 5e-3,1e-2), or measure poses that determine them (pin-kpi-oed "
                    "design)")


#: an effect parameter whose standard deviation exceeds this many times its plausible size is not determined
UNDETERMINED_FACTOR = 10.0


def _check_effects(f: _Findings, result: Any) -> None:
    """Check 5: every estimated effect parameter determined by the data: its standard deviation below
    :data:`UNDETERMINED_FACTOR` times the effect's ``plausible_max``, else poor (the worst one named). A thermal
    expansion from a nearly constant temperature, for instance, is a link-length change the geometry absorbs."""
    names, std = list(getattr(result, "names", []) or []), np.asarray(getattr(result, "std", []), float)
    bad = []
    for eff in getattr(result, "effects", None) or []:
        lim = float(getattr(eff, "plausible_max", np.inf))
        if not np.isfinite(lim):
            continue
        for n in eff.param_names(result.model.robot):
            key = n if str(n).startswith(f"{eff.name}.") else f"{eff.name}.{n}"
            if key in names and std.size > names.index(key) and std[names.index(key)] > UNDETERMINED_FACTOR * lim:
                bad.append((std[names.index(key)] / lim, key, std[names.index(key)], lim, eff.unit))
    if not bad:
        return
    _, key, s, lim, unit = max(bad)
    f.worse("poor")
    f.reasons.append(f"{len(bad)} effect parameter(s) not determined by the data ({key} ± {s:.3g} {unit}, plausible "
                     f"size {lim:g} {unit})")
    f.causes.append("an effect the data do not excite (e.g. thermal expansion without a temperature change)")
    f.advice.append(f"leave {key.split('.')[0]} out of the effects (parameter 'effects'), or measure where it changes")


@dataclass
class _Findings:
    """The verdict so far ('good' < 'suspect' < 'poor') with its reasons, possible causes and advice."""

    verdict: str = "good"
    reasons: list[str] = field(default_factory=list)
    causes: list[str] = field(default_factory=list)
    advice: list[str] = field(default_factory=list)

    def worse(self, level: str) -> None:
        """Raise the verdict to ``level`` ('suspect' never lowers 'poor')."""
        if level == "poor" or self.verdict == "good":
            self.verdict = level


def _check_outliers(f: _Findings, result: Any, we: np.ndarray, out_idx: np.ndarray, nh: int,
                    noise_known: bool = True) -> int:
    """Check 3: outliers large against the noise (robust scale of all weighted errors); their number.

    With the noise level unknown, χ² cannot tell a fit pulled by its outliers from a good one: any flagged
    outlier fitted with the plain loss makes the fit suspect (never "good")."""
    large = _large_outliers(we, out_idx, nh)
    robust = str(result.loss) != "linear"
    if large and not robust:
        f.worse("suspect")
        f.reasons.append(f"{large} outlier(s) beyond {OUTLIER_LARGE:g} sigma fitted with the plain loss")
        f.causes.append("outliers (gross measurement errors)")
        f.advice.append("loss='soft_l1' (robust) or remove the flagged rows")
    elif out_idx.size and not robust and not noise_known:
        f.worse("suspect")
        f.reasons.append(f"{out_idx.size} flagged outlier(s) fitted with the plain loss and the noise level unknown "
                         "(chi2 not tested)")
        f.causes.append("outliers (gross measurement errors)")
        f.advice.append("loss='soft_l1' (robust), sigma columns or parameter 'sigma_xyz_m', or remove the flagged rows")
    return large


def _large_outliers(we: np.ndarray, out_idx: np.ndarray, nh: int) -> int:
    """Flagged outliers whose weighted error exceeds :data:`OUTLIER_LARGE` robust standard deviations."""
    scale = 1.4826 * float(np.median(we)) / np.sqrt(nh) if we.size else 0.0
    return int(np.sum(we[out_idx] > OUTLIER_LARGE * max(scale, 1e-300) * np.sqrt(nh))) if out_idx.size else 0


def robust_loss_reason(result: Any) -> str:
    """Why a plain (linear) fit should be refitted with the robust loss, or "" when it need not: outliers far
    beyond the noise (:data:`OUTLIER_LARGE`), or any flagged outlier with the noise level unknown (the covariance
    scaled by χ², which then cannot tell a fit pulled by its outliers from a good one) — check 3's two findings,
    the one decision of ``identify(loss="auto")`` (the default of the Python API and the command line)."""
    if str(result.loss) != "linear":
        return ""
    we, out_idx = np.asarray(result.weighted_errors, float), np.asarray(result.outliers, int)
    large = _large_outliers(we, out_idx, 6 if getattr(result, "residuals_rad", None) is not None else 3)
    if large:
        return f"{large} outlier(s) far beyond the noise"
    if out_idx.size and bool(result.covariance_scaled):
        return (f"{out_idx.size} outlier(s) flagged and the noise level unknown (no sigma columns, no parameter "
                f"'sigma_xyz_m')")
    return ""


def _check_chi2(f: _Findings, chi2_red: float, dof: int, alpha: float, chi2_poor: float, nominal_reflector_m: Any,
                reflector_estimated: bool) -> tuple[float, float]:
    """Check 1: reduced chi2 against its interval (absolute noise level known); the interval."""
    lo, hi = (float(v) / dof for v in 2.0 * gammaincinv(dof / 2, np.array([alpha / 2, 1 - alpha / 2])))
    if chi2_red > max(chi2_poor, hi):
        f.worse("poor")
        f.reasons.append(f"reduced chi2 {chi2_red:.3g} (residual RMS {np.sqrt(chi2_red):.2g}x the stated noise; "
                         f"expected within [{lo:.3g}, {hi:.3g}])")
    elif chi2_red > hi:
        f.worse("suspect")
        f.reasons.append(f"reduced chi2 {chi2_red:.3g} above its {100 * (1 - alpha):g}% interval "
                         f"[{lo:.3g}, {hi:.3g}]")
    elif chi2_red < lo:
        f.worse("suspect")
        f.reasons.append(f"reduced chi2 {chi2_red:.3g} below its interval [{lo:.3g}, {hi:.3g}]: the stated noise "
                         "is larger than the residuals")
        f.causes.append("sigma too large (units of sigma: m)")
    if chi2_red > hi:
        refl = None if nominal_reflector_m is None else np.asarray(nominal_reflector_m, float)
        if refl is not None and not reflector_estimated and float(np.linalg.norm(refl)) < 1e-9:
            f.causes.insert(0, "reflector/TCP offset (a nominal reflector at 0,0,0, parameter 'reflector_m', hides "
                               "parameters it makes identifiable)")
            f.advice.insert(0, "give the reflector offset (--reflector x,y,z in m) or leave --reflector out to "
                               "estimate it")
        else:
            f.causes.append("reflector/TCP offset")
        f.causes += ["sigma units (m) or an optimistic noise model", "wrong robot model or unmodelled effects"]
        f.advice += ["check parameter 'sigma_xyz_m' / sigma columns (m)", "run pin-kpi-oed diagnose"]
    return (lo, hi)


#: Below this share of validation rows inside the training's joint angles, a worse held-out error is extrapolation.
EXTRAPOLATION_COVERAGE = 0.5


def _explain_worse_heldout(f: _Findings, validation: dict) -> None:
    """Causes of a held-out error worse than the nominal robot's: extrapolation when the validation rows lie
    outside the training's joint angles (``validation["coverage"]``), else a wrong model or units."""
    cov = validation.get("coverage") or {}
    rows = cov.get("rows_covered")
    if rows is not None and rows < EXTRAPOLATION_COVERAGE:
        low = sorted(cov.get("per_joint", {}).items(), key=lambda kv: kv[1])[:2]
        where = ", ".join(f"{n} {100 * c:.0f}%" for n, c in low)
        f.causes.append(f"extrapolation: only {100 * rows:.0f}% of the validation rows lie within the training's "
                        f"joint angles (least covered: {where})")
        f.advice.append("measure training poses over the validation's joint ranges (pin-kpi-oed diagnose names "
                        "the poses to add), or validate inside the training's ranges")
        return
    f.causes += ["wrong robot or joint order/zero", "units (m, rad)"]


def _check_heldout(f: _Findings, validation: dict | None, train_rms: float,
                   large: int) -> tuple[float | None, float | None]:
    """Check 2: held-out error against the nominal robot's and the training error; (before, after) RMS (m)."""
    before, after = (_rms(validation.get("before")), _rms(validation.get("after"))) if validation else (None, None)
    if before is not None and after is not None:
        if after > before:
            f.worse("poor")
            f.reasons.append(f"held-out RMS {after * 1e3:.4g} mm after calibration is worse than the nominal "
                             f"robot's {before * 1e3:.4g} mm")
            if not large:
                _explain_worse_heldout(f, validation)
        elif np.isfinite(train_rms) and after > 3.0 * train_rms and after > 1e-6:
            f.worse("suspect")
            f.reasons.append(f"held-out RMS {after * 1e3:.4g} mm is more than 3x the training RMS "
                             f"{train_rms * 1e3:.4g} mm")
            f.causes.append("over-fit or another session (re-register with register_rows)")
    return before, after


@dataclass
class RegistrationQuality:
    """Verdict of the registration gate (``register``): one station's set-up fitted with the robot held.

    Attributes:
        station: the station label; n_rows: its rows; n_unknowns: set-up parameters fitted.
        chi2_reduced: Σ|e_i|²/σ_i² / (3 m − unknowns) with σ from the sigma columns or the model's noise.
        rms_m: RMS position error (m); mirrored_rms_m: RMS of the best mirrored (improper) frame (m).
        verdict: ``good`` or ``poor``; reasons: the failed tests, one phrase each.
    """

    station: str
    n_rows: int
    n_unknowns: int
    chi2_reduced: float
    rms_m: float
    mirrored_rms_m: float
    verdict: str = "good"
    reasons: list[str] = field(default_factory=list)

    @property
    def poor(self) -> bool:
        """True when the registered set-up must not be written without ``--accept-poor-fit``."""
        return self.verdict == "poor"

    def line(self) -> str:
        """The one-line verdict."""
        head = f"registration of station '{self.station}' ({self.n_rows} rows, RMS {self.rms_m * 1e3:.4g} mm)"
        if not self.poor:
            return f"{head}: good (reduced chi2 {self.chi2_reduced:.3g})"
        return f"{head}: POOR: {'; '.join(self.reasons)}"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (SI units)."""
        return {"station": self.station, "n_rows": self.n_rows, "n_unknowns": self.n_unknowns,
                "chi2_reduced": self.chi2_reduced, "rms_m": self.rms_m, "mirrored_rms_m": self.mirrored_rms_m,
                "verdict": self.verdict, "message": self.line(), "reasons": list(self.reasons)}


def _rigid_rms(X: np.ndarray, Y: np.ndarray, proper: bool) -> float:
    """RMS of the best rigid fit Y ≈ R X + t (proper: det R = +1; else the best mirrored one, det R = -1)."""
    xm, ym = X.mean(0), Y.mean(0)
    U, _, Vt = np.linalg.svd((X - xm).T @ (Y - ym))
    d = np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0
    R = Vt.T @ np.diag([1.0, 1.0, d if proper else -d]) @ U.T
    if not proper and np.linalg.det(R) > 0:
        R = Vt.T @ np.diag([1.0, 1.0, -1.0]) @ U.T
    return float(np.sqrt(np.mean(np.sum((Y - ym - (X - xm) @ R.T) ** 2, axis=1))))


#: a registration whose reduced χ² is below this fits ~30× better than its stated noise: the noise is in wrong units
CHI2_TOO_SMALL = 1e-3


def assess_registration(station: str, X: np.ndarray, Y: np.ndarray, errors_m: np.ndarray, sigma_m: np.ndarray,
                        n_unknowns: int, chi2_poor: float = CHI2_POOR,
                        explain: Callable[[float], str] | None = None) -> RegistrationQuality:
    """Judge a registered set-up: enough rows, residuals near the noise, a proper (not mirrored) frame.

    Args:
        station: the station label.
        X: the positions the held robot predicts for the rows (any rigid frame), (m, 3) m.
        Y: the measured positions (tracker frame), (m, 3) m.
        errors_m: position errors after the registration, (m,) m.
        sigma_m: per-axis noise σ of each row (sigma columns, else the model's noise), (m, 3) or (3,) m.
        n_unknowns: set-up parameters fitted (6 for the tracker pose, 9 with the reflector).
        chi2_poor: reduced χ² above which the registration is poor (residuals 4× the noise).
        explain: called with the reduced χ² when the residuals are too large and the frame is not mirrored: the
            tested cause and its fix (:func:`~pin_kpi_oed.upkeep.registration_check.poor_registration_cause`);
            without it the likely causes are listed.

    Returns:
        The :class:`RegistrationQuality`; poor when the rows give fewer than twice as many equations as
        unknowns (a fit that passes through every point proves nothing), when the residuals are far above
        the noise or far below it (reduced χ² under :data:`CHI2_TOO_SMALL`: the noise stated in mm), or when the
        frame fits only mirrored (axes swapped or negated in the export).
    """
    m = int(len(errors_m))
    sig2 = np.mean(np.broadcast_to(np.asarray(sigma_m, float) ** 2, (m, 3)), axis=1)
    dof = 3 * m - int(n_unknowns)
    chi2_red = float(np.sum(np.asarray(errors_m, float) ** 2 / sig2) / max(dof, 1))
    rms = float(np.sqrt(np.mean(np.asarray(errors_m, float) ** 2))) if m else float("nan")
    mirrored = _rigid_rms(np.asarray(X, float), np.asarray(Y, float), proper=False) if m >= 4 else float("inf")
    q = RegistrationQuality(station, m, int(n_unknowns), chi2_red, rms, mirrored)
    need = -(-2 * int(n_unknowns) // 3)
    if m < need:
        q.reasons.append(f"{m} rows give {3 * m} equations for {n_unknowns} set-up unknowns: at least {need} rows are "
                         "needed to check the fit (it passes through fewer exactly)")
    if dof > 0 and chi2_red > chi2_poor:
        q.reasons.append(f"residual RMS {rms * 1e3:.4g} mm is {np.sqrt(chi2_red):.2g}x the expected level "
                         f"(sigma {np.sqrt(np.mean(sig2)) * 1e3:.3g} mm per axis)")
        if mirrored < 0.25 * rms:
            q.reasons.append(f"the points fit only a mirrored frame (RMS {mirrored * 1e3:.4g} mm): x/y swapped or an "
                             "axis negated in the export")
        elif explain is not None:
            q.reasons.append(explain(chi2_red))
        else:
            q.reasons.append("likely: another robot's or another session's data, the joint order, or units (m, rad)")
    if dof > 0 and chi2_red < CHI2_TOO_SMALL:
        q.reasons.append(f"residual RMS {rms * 1e3:.4g} mm is {np.sqrt(chi2_red):.2g}x the stated noise (sigma "
                         f"{np.sqrt(np.mean(sig2)) * 1e3:.3g} mm per axis): the sigma columns or the model's noise are "
                         "far too large (in mm, not m?); give sigma in m")
    if q.reasons:
        q.verdict = "poor"
    return q
