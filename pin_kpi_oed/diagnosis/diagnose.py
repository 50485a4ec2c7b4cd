r"""Sim-to-real gap diagnosis: is what remains noise, where is it, which effect causes it, how far it shrinks.

Everything is judged on **held-out** measurements (a validation file, or K-fold
cross-validation of one file), never on the data a model was fitted to.

Steps of :func:`diagnose`
-------------------------
(a) **Geometric calibration** on the training part (:func:`pin_kpi_oed.identification.identify.identify`,
    position rows, weights from the data's sigma columns or the noise model). In K-fold
    mode every model is identified once on all the data; each fold's fit is then one
    Gauss-Newton step from that solution on the fold's training rows (exact to second order
    in the small fold-to-fold differences; ``exact_kfold=True`` re-identifies per fold), and
    the held-out residuals of the folds are pooled.

(b) **Gap test.** With r_i the held-out residual (measured − predicted) of measurement i,
    σ_i its noise and v_i = diag(F_i C Fᵢᵀ) the (weighted) prediction variance from the
    parameter covariance C of the fit, under "the model is right and σ is the noise"::

        T = Σ_i Σ_axes r_ia² / (σ_ia² (1 + v_ia))  ~  χ²(3 n_heldout)

    A gap is detected when P(χ² ≥ T) < α (default α = 0.01). The noise floor is the
    RMS error a perfect model would show, sqrt(mean_i Σ_axes σ_ia²) (3-D, m).

(c) **Where.** The held-out residuals are summarised against candidate regressors: the
    TCP position in the robot base frame (x, y, z, distance from the base axis), the
    tracker range, every joint angle, the gravity torque of the loaded joints, the
    temperature, the time and the measurement order (row number; the order is the time
    when there is no time column). For each regressor the residual components (in units
    of σ) are averaged in quantile bins; the share of their variance explained by the
    bin means (correlation ratio η², pooled over x, y, z) and a one-way ANOVA F-test
    give its strength; the strongest significant ones are named. The residuals are also
    summarised per workspace octant (around the median TCP position).

(d) **Which.** Every candidate effect of :mod:`pin_kpi_oed.effects.library` is identified jointly
    with the geometry on the training part and scored on the held-out part; then forward
    selection adds, step by step, the effect that reduces the held-out error most, as
    long as it is *significant*: all of

    * F-test on training (nested models, weighted RSS χ², k added parameters, N rows,
      P parameters): F = ((χ²₀ − χ²₁)/k) / (χ²₁/(N − P)), p_F < α / (number of candidates);
    * information criterion on training: ΔBIC = N ln(χ²₁/χ²₀) + k ln N < 0;
    * held-out improvement: the per-measurement reduction d_i = Σ_axes (r₀² − r₁²)/σ² has a
      positive mean (one-sided t-test, p < α), and the held-out RMS decreases.

    So noise is not "explained": an effect with nothing to fit fails the F-test and BIC,
    and one that only fits training noise fails the held-out test. The likelihood-ratio
    p-value (known σ, Δχ² ~ χ²(k)) is reported too. Parameters the data cannot determine
    (e.g. backlash of a joint whose torque never changes sign, which is a constant joint
    offset the geometry already holds) are dropped and named; an effect that needs a
    column the data lack (``thermal_expansion`` needs ``temperature``), or has more
    parameters than the training rows can support, is skipped with a note.

(e) **How far.** Held-out mean / RMS / max error (3-D norms, m) with geometry only and with
    the selected effects, and the share of the gap closed::

        gap_closed = (rms_before − rms_after) / (rms_before − noise_floor)

The dominant effect is the first one selected (the largest significant held-out
reduction), or ``none`` when no gap is detected or no effect is significant.

Bad input: validation rows whose residuals are far beyond any effect (more than 20× the
training RMS and the noise floor: another robot or tracker placement) are named; when
they are the majority the report says the validation data do not match and names no
effect; otherwise they are left out of the effect analysis. What the data cannot
reveal (a tracker range-scale error, :data:`pin_kpi_oed.effects.library.UNOBSERVABLE_NOTES`) is
stated in every report.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np
from scipy import stats as _st

from pin_kpi_oed.data.atomic import to_jsonable
from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.effects.library import (EFFECT_NAMES, UNOBSERVABLE_NOTES, Effect, SubsetEffect, candidate_effects,
                                         gravity_torque, loaded_joints)
from pin_kpi_oed.errors import InputError, PinKpiOedError
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.results import Result
from pin_kpi_oed.threads import limit_threads

__all__ = ["DiagnosisReport", "DiagnoseOptions", "EffectResult", "diagnose", "MISMATCH_FACTOR", "heldout_stats"]

#: Held-out residuals beyond this factor × max(training RMS, noise floor) are "far beyond any effect".
MISMATCH_FACTOR = 20.0
#: Minimum residual degrees of freedom per effect parameter (too-few-rows guard).
MIN_DOF_PER_PARAM = 2
#: An effect parameter is kept when the part of its (unit) column orthogonal to the model's exceeds this.
PRUNE_TOL = 1e-3


def _f(x: Any) -> Any:
    """JSON-safe float (NaN/inf -> None)."""
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def heldout_stats(R: np.ndarray) -> dict:
    """Mean / RMS / max / median of the 3-D error norms of residuals R (n, 3), m."""
    e = np.linalg.norm(np.asarray(R, float), axis=1)
    if e.size == 0:
        return {"n": 0, "mean_m": None, "rms_m": None, "max_m": None, "median_m": None}
    return {"n": int(e.size), "mean_m": float(e.mean()), "rms_m": float(np.sqrt(np.mean(e ** 2))),
            "max_m": float(e.max()), "median_m": float(np.median(e))}


# --------------------------------------------------------------------------- results
@dataclass
class EffectResult:
    """One candidate effect added (alone, or at a forward-selection step) to a reference model.

    Attributes:
        name: effect name.
        status: ``ok`` or ``skipped``.
        note: why it was skipped, or which parameters were dropped.
        n_params: number of identified parameters (after dropping undeterminable ones).
        heldout_rms_before_m / heldout_rms_after_m: held-out RMS error without / with it (m).
        heldout_mean_after_m / heldout_max_after_m: held-out mean / max error with it (m).
        gap_closed_fraction: (rms_before − rms_after) / (rms_before − noise floor).
        f_stat, f_pvalue: F-test on training; lr_pvalue: likelihood-ratio (known σ) p-value.
        delta_bic: BIC(with) − BIC(without) on training (< 0 favours the effect).
        heldout_pvalue: one-sided t-test of the per-measurement held-out improvement.
        significant: all tests passed (see module docstring).
        theta: identified parameters (name -> value, in the effect's unit).
    """

    name: str
    status: str = "ok"
    note: str = ""
    n_params: int = 0
    heldout_rms_before_m: float = float("nan")
    heldout_rms_after_m: float = float("nan")
    heldout_mean_after_m: float = float("nan")
    heldout_max_after_m: float = float("nan")
    gap_closed_fraction: float = float("nan")
    f_stat: float = float("nan")
    f_pvalue: float = float("nan")
    lr_pvalue: float = float("nan")
    delta_bic: float = float("nan")
    heldout_pvalue: float = float("nan")
    significant: bool = False
    theta: dict = field(default_factory=dict)

    @property
    def reduction_m(self) -> float:
        """Held-out RMS reduction (m); −inf when skipped."""
        if self.status != "ok" or not np.isfinite(self.heldout_rms_after_m):
            return -np.inf
        return self.heldout_rms_before_m - self.heldout_rms_after_m

    def to_dict(self) -> dict:
        """Plain JSON-able dict (SI units)."""
        return {"name": self.name, "status": self.status, "note": self.note, "n_params": self.n_params,
                "heldout_rms_before_m": _f(self.heldout_rms_before_m),
                "heldout_rms_after_m": _f(self.heldout_rms_after_m),
                "heldout_mean_after_m": _f(self.heldout_mean_after_m),
                "heldout_max_after_m": _f(self.heldout_max_after_m),
                "gap_closed_fraction": _f(self.gap_closed_fraction), "f_stat": _f(self.f_stat),
                "f_pvalue": _f(self.f_pvalue), "lr_pvalue": _f(self.lr_pvalue), "delta_bic": _f(self.delta_bic),
                "heldout_pvalue": _f(self.heldout_pvalue), "significant": bool(self.significant),
                "theta": {k: _f(v) for k, v in self.theta.items()}}


@dataclass
class DiagnosisReport(Result):
    """Outcome of :func:`diagnose` (SI units; ``summary()`` prints mm / µm); common fields of
    :class:`~pin_kpi_oed.results.Result`: ``success`` (the report was produced), ``status``
    (``gap``, ``no_gap`` or ``mismatch``), ``message`` (the verdict), ``nit`` (forward-selection
    steps), ``nfev`` (identifications run), ``time_s``.

    Attributes:
        robot, tool_frame: the arm.
        mode: ``split`` (train / validate), ``transfer`` (validation from another session, set-up
            re-registered on some of its rows) or ``kfold``; k_folds its K.
        n_train, n_heldout: measurements used for fitting / scoring.
        noise_floor_m: RMS 3-D error of a perfect model, sqrt(mean Σ σ²) (m).
        expected_rms_m: the same plus the parameter-estimation uncertainty (m).
        gap_detected: the χ² gap test rejects "noise only" at level ``alpha``.
        gap_test: statistic, dof, p-value, RMS / noise floor.
        dominant_effect: effect name or ``none``.
        selected_effects: effects kept by forward selection, in order.
        heldout_before / heldout_after: held-out mean / RMS / max (m), geometry only / with the selection.
        gap_closed_fraction: share of the gap closed by the selection.
        remaining_gap: the gap test after the selection.
        effects: every candidate alone, ranked by held-out reduction (skipped ones last).
        selection: forward-selection steps (every candidate scored at every step).
        where: regressor associations, strongest ones, workspace regions.
        validation_mismatch: the held-out data look like another robot / tracker placement.
        mismatch: details (factor, rows far beyond any effect).
        notes: plain-words notes (skipped effects, dropped parameters, ...).
        unobservable: what the data cannot reveal.
        figures: PNG files written (by :func:`pin_kpi_oed.viz.diagnosis_plots.diagnosis_figures`).
        geometry: training fit of the geometric model (RMS, χ²_red, parameters, tracker).
        registration: transfer mode: the registration rows (1-based row numbers of their file),
            their file, number and seed, and the scored rows.
        transfer: with validation data (:func:`pin_kpi_oed.diagnosis.transfer_gap.transfer_section`):
            per-joint ranges of train and validation (rad, wrapped as the coverage), coverage per
            joint and overall, held-out RMS inside / outside the coverage, before / after the
            set-up registration (m), the predicted TCP σ at the validation configurations vs the
            observed error, the classification of the gap (``extrapolation``, ``set-up change``,
            ``unmodelled effect``) with the numbers behind it, and for extrapolation the poses to add.
        term_selection: the sparse selection of transferable terms (``transmission_error``,
            ``link_bending`` candidates): chosen terms in plain words, held-out RMS path (m).
        plot_data: what the figures need (not in ``to_dict``): ``residuals_m`` (held-out geometric
            residuals, n × 3, m), ``regressors`` (name -> (values, unit)).
    """

    robot: str
    tool_frame: str
    mode: str
    k_folds: int
    n_train: int
    n_heldout: int
    alpha: float
    weights: str
    noise_floor_m: float
    expected_rms_m: float
    gap_detected: bool
    gap_test: dict
    dominant_effect: str
    selected_effects: list
    heldout_before: dict
    heldout_after: dict
    gap_closed_fraction: float
    remaining_gap: dict
    effects: list
    selection: list
    where: dict
    validation_mismatch: bool = False
    mismatch: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    unobservable: list = field(default_factory=lambda: list(UNOBSERVABLE_NOTES))
    figures: list = field(default_factory=list)
    geometry: dict = field(default_factory=dict)
    registration: dict = field(default_factory=dict)
    term_selection: dict = field(default_factory=dict)
    transfer: dict = field(default_factory=dict)
    plot_data: dict = field(default_factory=dict, repr=False)

    def effect(self, name: str) -> EffectResult:
        """The single-effect result of ``name``."""
        for e in self.effects:
            if e.name == name:
                return e
        raise InputError(f"effect '{name}' was not a candidate (candidates: {', '.join(e.name for e in self.effects)})")

    def to_dict(self) -> dict:
        """Plain JSON-able dict (SI units)."""
        return {
            **self.result_dict(),
            "robot": self.robot, "tool_frame": self.tool_frame, "mode": self.mode, "k_folds": self.k_folds,
            "n_train": self.n_train, "n_heldout": self.n_heldout, "alpha": self.alpha, "weights": self.weights,
            "noise_floor_m": _f(self.noise_floor_m), "expected_rms_m": _f(self.expected_rms_m),
            "gap_detected": bool(self.gap_detected), "gap_test": to_jsonable(self.gap_test),
            "dominant_effect": self.dominant_effect, "selected_effects": list(self.selected_effects),
            "heldout_before": to_jsonable(self.heldout_before), "heldout_after": to_jsonable(self.heldout_after),
            "gap_closed_fraction": _f(self.gap_closed_fraction), "remaining_gap": to_jsonable(self.remaining_gap),
            "effects": [e.to_dict() for e in self.effects],
            "selection": [to_jsonable(s) for s in self.selection],
            "where": to_jsonable(self.where), "validation_mismatch": bool(self.validation_mismatch),
            "mismatch": to_jsonable(self.mismatch), "notes": list(self.notes), "unobservable": list(self.unobservable),
            "figures": [str(f) for f in self.figures], "geometry": to_jsonable(self.geometry),
            "registration": to_jsonable(self.registration),
            "term_selection": to_jsonable(self.term_selection),
            "transfer": to_jsonable(self.transfer),
        }

    def summary(self) -> str:
        """Readable multi-line summary (mm / µm)."""
        um = 1e6
        b, a = self.heldout_before, self.heldout_after
        g = self.gap_test
        out = [f"sim-to-real gap diagnosis of {self.robot} ({self.mode}"
               f"{f', K={self.k_folds}' if self.mode == 'kfold' else ''}: {self.n_train} training, "
               f"{self.n_heldout} held-out measurements; weights: {self.weights})"]
        if self.registration:
            r = self.registration
            seed = f" (seed {r['seed']})" if r.get("seed") is not None else ""
            out.append(f"  transfer: the set-up (tracker pose, reflector) is re-registered, robot held, on {r['n']} "
                       f"rows of {r['source']}{seed}; only the other {self.n_heldout} rows are scored")
        out.append(f"  noise floor {self.noise_floor_m * um:.1f} µm RMS (3-D); held-out geometry only: mean "
                   f"{_um(b.get('mean_m'))}, RMS {_um(b.get('rms_m'))}, max {_um(b.get('max_m'))} µm")
        out.append(f"  gap test: chi2 = {g.get('chi2', float('nan')):.4g} on {g.get('dof')} dof, p = "
                   f"{g.get('p_value', float('nan')):.3g}, RMS/floor = {g.get('ratio_rms_to_floor', float('nan')):.3g}"
                   f" -> {'GAP DETECTED' if self.gap_detected else 'consistent with noise'}")
        if self.validation_mismatch:
            out.append(f"  VALIDATION MISMATCH: {self.mismatch.get('message', '')}")
        elif self.mismatch.get("rows"):
            out.append(f"  {self.mismatch.get('message', '')}")
        st = self.where.get("strongest", [])
        if st:
            out.append("  where: residuals vary most with " + "; ".join(
                f"{s['name']} (eta2 {s['eta2']:.3f}, p {s['p_value']:.2g})" for s in st))
        reg = self.where.get("regions", [])
        if reg:
            worst = max(reg, key=lambda r: r["rms_m"] or 0)
            out.append(f"  worst workspace region: {worst['region']} (RMS {_um(worst['rms_m'])} µm, n={worst['n']})")
        tf = self.transfer
        if tf:
            out.append(f"  transfer gap: {tf['classification'].upper()}: {tf['reason']}")
            if tf.get("poses_to_add", {}).get("text"):
                out.append(f"    to fix it: {tf['poses_to_add']['text']}")
            out.append(f"    {'joint':<22}{'train range rad':>20}{'validation range rad':>24}{'covered':>9}"
                       "   (angles wrapped to [-pi, pi) as the coverage; smallest arc, may end beyond pi)")
            for j in tf["joints"]:
                out.append(f"    {j['joint']:<22}{j['train_min']:>9.3f} .. {j['train_max']:<7.3f}"
                           f"{j['validate_min']:>11.3f} .. {j['validate_max']:<9.3f}{_pct(j['coverage']):>9}")
        ts = self.term_selection
        if ts:
            out.append(f"  term selection ({', '.join(ts['candidates'])}; orders 1..{ts['max_order']}, "
                       f"{ts['folds']}-fold held-out RMS {_um(ts['cv_rms_m'][0])} -> {_um(ts['cv_rms_m'][-1])} µm): "
                       f"{len(ts['terms'])} term(s) chosen" + (":" if ts["terms"] else ""))
            for t in ts["terms"]:
                out.append(f"    {t['text']}")
        out.append("  effects alone (ranked by held-out RMS reduction):")
        out.append(f"    {'effect':<19}{'k':>4}{'RMS after µm':>14}{'closed':>8}{'p_F':>10}{'dBIC':>10}"
                   f"{'p_heldout':>11}  significant")
        for e in self.effects:
            if e.status != "ok":
                out.append(f"    {e.name:<19}{'-':>4}  skipped: {e.note}")
                continue
            out.append(f"    {e.name:<19}{e.n_params:>4}{e.heldout_rms_after_m * um:>14.2f}"
                       f"{_pct(e.gap_closed_fraction):>8}{e.f_pvalue:>10.2g}{e.delta_bic:>10.1f}"
                       f"{e.heldout_pvalue:>11.2g}  {'yes' if e.significant else 'no'}")
        sel = ", ".join(self.selected_effects) or "none"
        out.append(f"  forward selection: {sel}; dominant effect: {self.dominant_effect}")
        out.append(f"  held-out with the selection: mean {_um(a.get('mean_m'))}, RMS {_um(a.get('rms_m'))}, max "
                   f"{_um(a.get('max_m'))} µm; gap closed {_pct(self.gap_closed_fraction)}; remaining gap "
                   f"{'yes' if self.remaining_gap.get('gap_detected') else 'no'} "
                   f"(p = {self.remaining_gap.get('p_value', float('nan')):.3g})")
        for n in self.notes:
            out.append(f"  note: {n}")
        for n in self.unobservable:
            out.append(f"  not observable: {n}")
        if self.figures:
            out.append(f"  figures: {', '.join(str(f) for f in self.figures)}")
        return "\n".join(out)

    def __str__(self) -> str:
        return self.summary()


def _um(x: Any) -> str:
    return "nan" if x is None or not np.isfinite(x) else f"{x * 1e6:.1f}"


def _pct(x: Any) -> str:
    return "-" if x is None or not np.isfinite(x) else f"{100 * x:.0f}%"


# --------------------------------------------------------------------------- fitting
@dataclass
class _Fit:
    """One identification and what the diagnosis needs of it."""

    result: Any  # IdentificationResult
    chi2: float
    n_rows: int
    nx: int


@dataclass
class _Scored:
    """A model (set of effects) fitted on the training side and scored on the held-out side."""

    effects: list
    full: _Fit  # training-side statistics (train fit; all-data fit in K-fold)
    R: np.ndarray  # held-out residuals, measured − predicted (n, 3) m
    S: np.ndarray  # held-out σ (n, 3) m
    V: np.ndarray  # held-out weighted prediction variance (n, 3)

    @property
    def w2(self) -> np.ndarray:
        """Per-measurement weighted squared held-out residual Σ_axes (r/σ)²."""
        return np.sum((self.R / self.S) ** 2, axis=1)


@dataclass
class _Plan:
    """How the data are split: folds (train, held-out) and the held-out rows' numbers in their file."""

    mode: str
    k: int
    folds: list  # [(train, test)]
    orders: list  # per fold: row indices of the held-out rows in ``heldout_source``
    fold_rows: list | None  # K-fold: per fold (train rows, test rows) of the training file
    heldout_source: MeasurementSet
    registration: MeasurementSet | None = None
    registration_info: dict = field(default_factory=dict)


class _Engine:
    """Fits and scores models on a fixed set of folds (with a set-up registration in transfer mode)."""

    def __init__(self, model: TrackerModel, plan: _Plan, full_train: MeasurementSet, heldout_idx: list,
                 weights: str, identify_options: dict, exact_kfold: bool = False):
        self.model = model
        self.plan = plan
        self.folds = plan.folds
        self.full_train = full_train
        self.heldout_idx = heldout_idx  # per fold: rows of the test set kept for scoring
        self.weights = weights
        self.opts = dict(identify_options)
        self.split = plan.fold_rows is None
        self.fold_rows = plan.fold_rows
        self.exact_kfold = exact_kfold
        self.unconverged: set[str] = set()
        self.n_fits = 0

    def sigma(self, data: MeasurementSet) -> np.ndarray:
        use_data = data.sigma_m is not None and self.weights in ("auto", "data")
        return np.asarray(data.sigma_m, float) if use_data else self.model.noise.sigma(data.position_m)

    def fit(self, data: MeasurementSet, effects: Sequence[Effect]) -> _Fit:
        from pin_kpi_oed.identification.identify import identify

        opts = {"raise_on_failure": False, **self.opts}
        res = identify(self.model, data, effects=list(effects), weights=self.weights, use_orientation=False, **opts)
        self.n_fits += 1
        if not res.converged:
            self.unconverged.add(", ".join(e.name for e in effects) or "geometry")
        chi2 = float(np.sum(res.weighted_errors ** 2))
        return _Fit(res, chi2, 3 * len(data), len(res.names))

    def heldout(self, fit: _Fit, test: MeasurementSet) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Held-out residuals (measured − predicted), σ and weighted prediction variance of ``fit`` on ``test``.

        In transfer mode the fit's set-up is first re-registered on the registration rows
        (robot and effects held); the variance then counts the robot and effect parameters only.
        """
        from pin_kpi_oed.identification.problem import ResidualModel

        res = fit.result
        S = self.sigma(test)
        if self.plan.registration is not None:
            rm, x, keep = self._registered(res, test, S)
        else:
            rm, x, keep = ResidualModel(res.station_set, test, res.identifiability.base, res.effects, sigma=S,
                                        p_ref=res.P), res.values, np.arange(res.values.size)
        R = -rm.evaluate(x)[0]
        F = rm.jacobian_full(x)[:, :3, :]  # weighted
        C = res.covariance[np.ix_(keep, keep)]
        V = np.einsum("mai,ij,maj->ma", F, C, F)
        return R, S, np.clip(V, 0.0, None)

    def _registered(self, res: Any, test: MeasurementSet, S: np.ndarray) -> tuple[Any, np.ndarray, np.ndarray]:
        """Residual model of ``test`` at the set-up re-registered on the registration rows (robot held)."""
        from pin_kpi_oed.identification.problem import ResidualModel
        from pin_kpi_oed.identification.transfer import register_setup

        rr = register_setup(res.calibrated_model(), self.plan.registration, station="transfer", weights=self.weights)
        wm, p = rr.model.station_model("transfer")
        nb = len(res.identifiability.base)
        setup = set(res.model.layout.setup_groups)
        robot = [i for i, n in enumerate(res.names[:nb]) if n.split(".")[0].split("@")[0] not in setup]
        base = np.array([wm.layout.index(res.names[i]) for i in robot], int)
        rm = ResidualModel(wm, test, base, res.effects, sigma=S, p_ref=p)
        x = np.concatenate([p[base]] + [np.asarray(t, float) for t in res.theta])
        keep = np.r_[np.asarray(robot, int), np.arange(nb, res.values.size)]
        return rm, x, keep

    def _fold_linear(self, full: _Fit) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """K-fold held-out residuals by one Gauss-Newton step from the all-data fit per fold.

        The fold's fit differs from the all-data fit by O(noise); one Gauss-Newton step on the
        fold's training rows from the all-data solution x̂ reaches it to second order:
        δ_f = −(J_Tᵀ J_T)⁺ J_Tᵀ f_T, held-out residual f_test + J_test δ_f (weighted).
        """
        from pin_kpi_oed.identification.problem import ResidualModel

        res = full.result
        data = self.full_train
        S = self.sigma(data)
        rm = ResidualModel(res.station_set, data, res.identifiability.base, res.effects, sigma=S, p_ref=res.P)
        J = rm.jacobian_full(res.values)[:, :3, :]
        fw = rm.weighted_rows(res.values)[:, :3]  # (model − measured) / σ
        out = []
        for tr, te in self.fold_rows:
            A = J[tr].reshape(-1, J.shape[2])
            n = np.linalg.norm(A, axis=0)
            n = np.where(n > 0, n, 1.0)
            U, s, Vt = np.linalg.svd(A / n, full_matrices=False)
            ok = s > 1e-10 * s[0]
            Ainv = (Vt[ok].T / s[ok]) @ U[:, ok].T  # scaled pseudo-inverse
            delta = -(Ainv @ fw[tr].ravel()) / n
            Jt = J[te]
            f_new = fw[te] + Jt @ delta
            Cs = (Vt[ok].T / s[ok] ** 2) @ Vt[ok]
            Jts = Jt / n
            V = np.einsum("mai,ij,maj->ma", Jts, Cs, Jts)
            out.append((-f_new * S[te], S[te], V))
        return out

    def score(self, effects: Sequence[Effect], full: _Fit | None = None) -> _Scored:
        full = full or self.fit(self.full_train, effects)
        if self.split:
            parts = [self.heldout(full, self.folds[0][1])]
        elif not self.exact_kfold:
            parts = self._fold_linear(full)
        else:
            parts = [self.heldout(self.fit(train, effects), test) for train, test in self.folds]
        Rs, Ss, Vs = [], [], []
        for (R, S, V), keep in zip(parts, self.heldout_idx):
            Rs.append(R[keep])
            Ss.append(S[keep])
            Vs.append(V[keep])
        return _Scored(list(effects), full, np.vstack(Rs), np.vstack(Ss), np.vstack(Vs))


def _gap_test(sc: _Scored, alpha: float) -> dict:
    n = sc.R.shape[0]
    if n == 0:
        return {"chi2": float("nan"), "dof": 0, "p_value": float("nan"), "gap_detected": False}
    T = float(np.sum(sc.R ** 2 / (sc.S ** 2 * (1.0 + sc.V))))
    dof = 3 * n
    p = float(_st.chi2.sf(T, dof))
    floor = float(np.sqrt(np.mean(np.sum(sc.S ** 2, axis=1))))
    rms = float(np.sqrt(np.mean(np.sum(sc.R ** 2, axis=1))))
    return {"chi2": T, "dof": dof, "chi2_per_dof": T / dof, "p_value": p, "gap_detected": bool(p < alpha),
            "rms_m": rms, "noise_floor_m": floor, "ratio_rms_to_floor": rms / floor if floor > 0 else float("nan")}


def _compare(ref: _Scored, new: _Scored, name: str, n_tests: int, alpha: float, floor: float) -> EffectResult:
    """Nested-model tests of ``new`` (= ref + one effect) against ``ref``."""
    N = ref.full.n_rows
    k = new.full.nx - ref.full.nx
    c0, c1 = ref.full.chi2, new.full.chi2
    dchi = c0 - c1
    df2 = max(N - new.full.nx, 1)
    if k <= 0:
        F = p_F = p_LR = float("nan")
    else:
        F = (dchi / k) / (c1 / df2) if c1 > 0 else float("inf")
        p_F = float(_st.f.sf(F, k, df2)) if dchi > 0 else 1.0
        p_LR = float(_st.chi2.sf(dchi, k)) if dchi > 0 else 1.0
    dbic = N * math.log(max(c1, 1e-300) / max(c0, 1e-300)) + k * math.log(N)
    d = ref.w2 - new.w2
    n = d.size
    if n > 1 and np.std(d, ddof=1) > 0:
        t = float(np.mean(d) / (np.std(d, ddof=1) / math.sqrt(n)))
        p_ho = float(_st.t.sf(t, n - 1))
    else:
        p_ho = float("nan")
    rb = float(np.sqrt(np.mean(np.sum(ref.R ** 2, axis=1))))
    e1 = np.linalg.norm(new.R, axis=1)
    ra = float(np.sqrt(np.mean(e1 ** 2)))
    closed = (rb - ra) / (rb - floor) if rb - floor > 1e-3 * floor else float("nan")
    sig = bool(k > 0 and p_F < alpha / max(n_tests, 1) and dbic < 0 and np.isfinite(p_ho) and p_ho < alpha
               and ra < rb)
    res = new.full.result
    theta = {n_: float(v) for n_, v in zip(res.names, res.values) if n_.startswith(name + ".")}
    return EffectResult(name=name, n_params=int(k), heldout_rms_before_m=rb, heldout_rms_after_m=ra,
                        heldout_mean_after_m=float(e1.mean()), heldout_max_after_m=float(e1.max()),
                        gap_closed_fraction=closed, f_stat=float(F), f_pvalue=p_F, lr_pvalue=p_LR, delta_bic=dbic,
                        heldout_pvalue=p_ho, significant=sig, theta=theta)


def _prune(engine: _Engine, ref: _Fit, effect: Effect, ref_effects: list) -> tuple[Effect | None, str]:
    """Drop the parameters of ``effect`` the training data cannot determine next to the reference model."""
    from pin_kpi_oed.identification.problem import ResidualModel

    res = ref.result
    data = engine.full_train
    S = engine.sigma(data)
    effs = list(ref_effects) + [effect]
    x = np.concatenate([res.values, np.zeros(effect.n_params)])
    try:
        rm = ResidualModel(res.station_set, data, res.identifiability.base, effs, sigma=S, p_ref=res.P)
        J = rm.jacobian_full(x)[:, :3, :].reshape(-1, x.size)
    except PinKpiOedError as exc:
        return None, f"{effect.name}: skipped ({exc})"
    nref = res.values.size
    A, E = J[:, :nref], J[:, nref:]
    na = np.linalg.norm(A, axis=0)
    U, s, _ = np.linalg.svd(A / np.where(na > 0, na, 1.0), full_matrices=False)
    U = U[:, s > 1e-9 * s[0]]
    En = np.linalg.norm(E, axis=0)
    keep: list[int] = []
    weak: list[int] = []
    basis = U
    for i in range(E.shape[1]):
        if En[i] <= 0:
            continue
        v = E[:, i] / En[i]
        v = v - basis @ (basis.T @ v)
        v = v - basis @ (basis.T @ v)
        nv = float(np.linalg.norm(v))
        # std of θ_i given the model and the parameters kept so far (weighted units: σ = 1)
        std = 1.0 / (nv * En[i]) if nv > 0 else np.inf
        if nv > PRUNE_TOL and std < effect.plausible_max:
            keep.append(i)
            basis = np.hstack([basis, (v / nv)[:, None]])
        elif nv > PRUNE_TOL:
            weak.append(i)
    names = effect.param_names()
    if not keep:
        why = ("the data determine none of its parameters better than their plausible size "
               f"({effect.plausible_max:g} {effect.unit})") if weak else \
            "every parameter is confounded with the geometric parameters"
        return None, f"{effect.name}: skipped, {why}"
    if len(keep) == len(names):
        return effect, ""
    dropped = [names[i] for i in range(len(names)) if i not in keep]
    return SubsetEffect(effect, keep), (
        f"{effect.name}: {len(dropped)} parameter(s) not determined by the data (confounded with the model, or "
        f"standard deviation above {effect.plausible_max:g} {effect.unit}) and held at 0: "
        f"{', '.join(dropped[:6])}{' ...' if len(dropped) > 6 else ''}")


# --------------------------------------------------------------------------- where
def _regressors(model: TrackerModel, p: np.ndarray, data: MeasurementSet, order: np.ndarray) -> dict:
    """Candidate regressors per held-out measurement: name -> (values, unit)."""
    rb = model.robot
    Q = np.asarray(data.q, float)[:, [data.joint_names.index(j) for j in rb.joint_names]]
    kin = model.kinematics(p, Q, model.reflector(p))
    P = kin.p
    out: dict[str, tuple[np.ndarray, str]] = {
        "tcp_x_base": (P[:, 0], "m"), "tcp_y_base": (P[:, 1], "m"), "tcp_z_base": (P[:, 2], "m"),
        "tcp_reach": (np.hypot(P[:, 0], P[:, 1]), "m"),
        "tracker_range": (np.linalg.norm(data.position_m, axis=1), "m"),
    }
    for j, n in enumerate(rb.joint_names):
        out[f"q_{n}"] = (Q[:, j], "rad")
    tau = gravity_torque(rb, Q, data.payload_kg)
    for j in np.flatnonzero(loaded_joints(rb)):
        out[f"gravity_torque_{rb.joint_names[j]}"] = (tau[:, j], "N*m")
    if data.temperature_c is not None and np.ptp(data.temperature_c) > 0:
        out["temperature"] = (np.asarray(data.temperature_c, float), "degC")
    if data.time_s is not None and np.ptp(data.time_s) > 0:
        out["time"] = (np.asarray(data.time_s, float), "s")
    out["order"] = (np.asarray(order, float), "row")
    if data.payload_kg is not None and np.ptp(data.payload_kg) > 0:
        out["payload"] = (np.asarray(data.payload_kg, float), "kg")
    return out


def _association(x: np.ndarray, Z: np.ndarray, R: np.ndarray) -> dict:
    """η² (pooled over axes) of standardised residuals Z (n, 3) on quantile bins of x, ANOVA p, bin table."""
    n = x.size
    uniq = np.unique(x)
    nb = int(np.clip(n // 30, 3, 10))
    if uniq.size <= nb:
        labels = np.searchsorted(uniq, x)
        edges = uniq
    else:
        edges = np.quantile(x, np.linspace(0, 1, nb + 1))
        labels = np.clip(np.searchsorted(edges[1:-1], x, side="right"), 0, nb - 1)
    B = int(labels.max()) + 1 if n else 0
    gm = Z.mean(axis=0)
    ss_tot = float(np.sum((Z - gm) ** 2))
    ss_b = 0.0
    bins = []
    used = 0
    for b in range(B):
        sel = labels == b
        c = int(sel.sum())
        if c == 0:
            continue
        used += 1
        mb = Z[sel].mean(axis=0)
        ss_b += c * float(np.sum((mb - gm) ** 2))
        e = np.linalg.norm(R[sel], axis=1)
        bins.append({"lo": float(x[sel].min()), "hi": float(x[sel].max()), "n": c,
                     "rms_m": float(np.sqrt(np.mean(e ** 2))), "mean_residual_m": R[sel].mean(axis=0).tolist()})
    eta2 = ss_b / ss_tot if ss_tot > 0 else 0.0
    df1, df2 = 3 * (used - 1), 3 * (n - used)
    if df1 > 0 and df2 > 0 and ss_tot - ss_b > 0:
        F = (ss_b / df1) / ((ss_tot - ss_b) / df2)
        p = float(_st.f.sf(F, df1, df2))
    else:
        p = 1.0
    return {"eta2": float(eta2), "p_value": p, "bins": bins}


def _where(model: TrackerModel, p: np.ndarray, data: MeasurementSet, order: np.ndarray, R: np.ndarray,
           S: np.ndarray, alpha: float) -> tuple[dict, dict]:
    regs = _regressors(model, p, data, order)
    Z = R / S
    items = []
    for name, (x, unit) in regs.items():
        a = _association(x, Z, R)
        items.append({"name": name, "unit": unit, **a})
    items.sort(key=lambda d: -d["eta2"])
    strongest = [{"name": d["name"], "eta2": d["eta2"], "p_value": d["p_value"]} for d in items
                 if d["p_value"] < alpha][:3]
    P = model.kinematics(p, np.asarray(data.q, float)[:, [data.joint_names.index(j) for j in model.robot.joint_names]],
                         model.reflector(p)).p
    med = np.median(P, axis=0)
    regions = []
    e = np.linalg.norm(R, axis=1)
    code = (P > med).astype(int)
    for cx in (0, 1):
        for cy in (0, 1):
            for cz in (0, 1):
                sel = (code[:, 0] == cx) & (code[:, 1] == cy) & (code[:, 2] == cz)
                if not sel.any():
                    continue
                regions.append({"region": f"x{'+-'[1 - cx]} y{'+-'[1 - cy]} z{'+-'[1 - cz]}", "n": int(sel.sum()),
                                "mean_m": float(e[sel].mean()), "rms_m": float(np.sqrt(np.mean(e[sel] ** 2))),
                                "max_m": float(e[sel].max())})
    where = {"regressors": items, "strongest": strongest, "regions": regions,
             "regions_about": "octants around the median TCP position in the robot base frame (x+ = above median)"}
    return where, regs


# --------------------------------------------------------------------------- steps of the diagnosis
@dataclass
class DiagnoseOptions:
    """Knobs of :func:`diagnose` (SI units).

    Attributes:
        kfold: K-fold cross-validation on the training data alone (K ≥ 2), instead of a validation set.
        effects: candidate effect names or objects (default: all of :data:`EFFECT_NAMES`).
        weights: ``auto`` (sigma columns if present, else the noise model), ``data`` or ``noise``.
        alpha: significance level of the gap test and of the effect tests.
        seed: seed of the K-fold split and of the random registration rows.
        max_selected: at most this many effects in forward selection (default: all).
        t_ref_c: reference temperature of ``thermal_expansion`` (°C; default the training mean).
        identify_options: extra keyword arguments (fields of
            :class:`~pin_kpi_oed.identification.identify.IdentifyOptions`) of every identification.
        exact_kfold: re-identify every model on every fold (K+1 fits per model); by default the
            folds' fits are one Gauss-Newton step from the all-data fit (exact to second order,
            K times faster).
        register_rows: transfer mode: the validation data come from another session; re-register
            the set-up on this many seeded random rows of them and score only the others.
        register_data: transfer mode: re-register the set-up on these rows and score every
            validation row.
        harmonics: highest Fourier order (cycles per revolution) of the ``transmission_error``
            candidate; its terms (and those of ``link_bending``) are chosen by sparse forward
            selection on K-fold held-out error (:func:`pin_kpi_oed.diagnosis.selection.select_terms`)
            before they are scored like any other candidate.
        show_progress: False: no progress bars; None: bars on a terminal (steps of the diagnosis,
            the term selection).
        transfer_prior_rad: σ (rad) of a Gaussian prior on the parameters of the selected terms
            (``--term-prior``), in their refit and in every identification that scores them; it
            limits how far a term fitted in one region of joint space extrapolates (None: none).
    """

    kfold: int | None = None
    effects: Sequence[str | Effect] | None = None
    weights: str = "auto"
    alpha: float = 0.01
    seed: int = 0
    max_selected: int | None = None
    t_ref_c: float | None = None
    identify_options: dict | None = None
    exact_kfold: bool = False
    register_rows: int | None = None
    register_data: MeasurementSet | None = None
    harmonics: int = 40
    transfer_prior_rad: float | None = None
    show_progress: bool | None = None

    @classmethod
    def resolve(cls, options: "DiagnoseOptions | None", overrides: dict) -> "DiagnoseOptions":
        """``options`` (or the defaults) with the keyword ``overrides`` applied.

        Raises:
            InputError: an unknown option name.
        """
        from pin_kpi_oed.identification.identify import resolve_options

        return resolve_options(cls, options, overrides, "diagnose")


def _check_joints(model: TrackerModel, data: MeasurementSet, what: str) -> None:
    missing = [j for j in model.robot.joint_names if j not in data.joint_names]
    if missing:
        raise InputError(f"{data.source or what}: missing joint column(s) {', '.join(missing)} for robot "
                         f"{model.robot.name} (columns: {', '.join(data.joint_names)})")


def _check_options(model: TrackerModel, train: MeasurementSet, validate: MeasurementSet | None,
                   opts: DiagnoseOptions) -> None:
    """Step 0: one validation mode, a valid alpha and weights, the joint columns."""
    if (validate is None) == (opts.kfold is None):
        raise InputError("diagnose: give either validation data (--validate) or a number of folds (--kfold), "
                         "not both and not neither")
    if (opts.register_rows is not None or opts.register_data is not None) and validate is None:
        raise InputError("diagnose: --register-rows/--register-data re-register the set-up on rows of another "
                         "session: they need validation data (--validate)")
    if opts.register_rows is not None and opts.register_data is not None:
        raise InputError("diagnose: give --register-rows or --register-data, not both")
    if not 0 < opts.alpha < 1:
        raise InputError(f"diagnose: alpha must be in (0, 1), got {opts.alpha}")
    if opts.weights not in ("auto", "data", "noise"):
        raise InputError(f"diagnose: weights must be auto, data or noise, got '{opts.weights}'")
    _check_joints(model, train, "training data")
    for d, what in ((validate, "validation data"), (opts.register_data, "registration data")):
        if d is not None:
            _check_joints(model, d, what)


#: Candidates whose terms are chosen from the data by sparse selection (:func:`_select_transfer_terms`).
SELECTED_TERM_EFFECTS: tuple[str, ...] = ("transmission_error", "link_bending")


def _select_transfer_terms(geo_fit: Any, train: MeasurementSet, names: Sequence[str], opts: DiagnoseOptions,
                           notes: list[str]) -> tuple[list[Effect], dict]:
    """Step 3b: sparse forward selection of transmission-error orders / link-bending angles on the training data.

    Returns:
        (the selected effects, restricted to the chosen terms, to be scored like any candidate;
        the report's ``term_selection`` dict with the terms in plain words).
    """
    from pin_kpi_oed.effects.coupled import LinkBending
    from pin_kpi_oed.effects.periodic import TransmissionError
    from pin_kpi_oed.diagnosis.selection import select_terms

    if isinstance(opts.harmonics, bool) or not isinstance(opts.harmonics, (int, np.integer)) or opts.harmonics < 1:
        raise InputError(f"diagnose: --harmonics must be an integer >= 1, got {opts.harmonics!r}")
    robot = geo_fit.result.model.robot
    cands: list[Effect] = []
    if "transmission_error" in names:
        cands.append(TransmissionError(robot, max_order=int(opts.harmonics)))
    if "link_bending" in names:
        cands.append(LinkBending(robot))
    sel = select_terms(geo_fit.result, train, candidates=cands, seed=opts.seed, prior_rad=opts.transfer_prior_rad,
                       refit=True, show_progress=opts.show_progress)
    info = {"candidates": list(names), "max_order": int(opts.harmonics), "folds": sel.folds,
            "cv_rms_m": [float(v) for v in sel.cv_rms_m], "stop": sel.stop, "n_candidate_groups": sel.n_candidates,
            "left_out": list(sel.left_out), "terms": [dict(t) for t in sel.terms]}
    if opts.transfer_prior_rad is not None:
        if not (np.isfinite(opts.transfer_prior_rad) and opts.transfer_prior_rad > 0):
            raise InputError(f"diagnose: --term-prior must be a positive number of rad, got {opts.transfer_prior_rad}")
        for e in sel.effects:
            e.prior_rad = float(opts.transfer_prior_rad)  # identify's per-effect prior (effect_prior_rad)
        info["prior_rad"] = float(opts.transfer_prior_rad)
    if not sel.terms:
        notes.append(f"term selection ({', '.join(names)}): no term lowers the {sel.folds}-fold held-out error")
    return list(sel.effects), info


def _candidates(robot: Any, train: MeasurementSet, opts: DiagnoseOptions) -> list[Effect]:
    """Step 1: the candidate effects (names are built for this robot; ``thermal_expansion`` at T_ref).

    The names of :data:`SELECTED_TERM_EFFECTS` are left out here: their terms are chosen later.
    """
    t_ref_c = opts.t_ref_c
    if t_ref_c is None:
        t_ref_c = float(np.mean(train.temperature_c)) if train.temperature_c is not None else 20.0
    cands: list[Effect] = []
    for e in (opts.effects if opts.effects is not None else EFFECT_NAMES):
        if isinstance(e, str) and e in SELECTED_TERM_EFFECTS:
            continue
        cands += candidate_effects(robot, [e], t_ref_c=t_ref_c) if isinstance(e, str) else [e]
    return cands


def _plan(train: MeasurementSet, validate: MeasurementSet | None, opts: DiagnoseOptions) -> _Plan:
    """Step 2: the folds: train / validate, train / validate with a set-up registration, or K-fold."""
    if validate is not None and opts.register_rows is None and opts.register_data is None:
        return _Plan("split", 1, [(train, validate)], [np.arange(len(validate))], None, validate)
    if validate is not None:
        from pin_kpi_oed.identification.transfer import registration_split

        if opts.register_data is not None:
            reg, reg_rows, scored = opts.register_data, np.arange(len(opts.register_data)), np.arange(len(validate))
        else:
            reg_rows, scored = registration_split(len(validate), opts.register_rows, opts.seed)
            reg = validate.subset(reg_rows)
        info = {"source": reg.source, "n": int(len(reg)), "rows": (reg_rows + 1).tolist(),
                "seed": int(opts.seed) if opts.register_data is None else None,
                "scored_source": validate.source, "scored_rows": (scored + 1).tolist()}
        return _Plan("transfer", 1, [(train, validate.subset(scored))], [scored], None, validate, reg, info)
    kfold = opts.kfold
    if isinstance(kfold, bool) or not isinstance(kfold, (int, np.integer)) or kfold < 2:
        raise InputError(f"diagnose: --kfold must be an integer >= 2, got {kfold!r}")
    if kfold > len(train) // 3:
        raise InputError(f"diagnose: {len(train)} measurements are too few for {kfold} folds "
                         f"(each fold needs at least 3 measurements)")
    perm = np.random.default_rng(opts.seed).permutation(len(train))
    parts = np.array_split(perm, int(kfold))
    folds, orders, fold_rows = [], [], []
    for i, te in enumerate(parts):
        tr = np.sort(np.concatenate([f for j, f in enumerate(parts) if j != i]))
        te = np.sort(te)
        folds.append((train.subset(tr), train.subset(te)))
        orders.append(te)
        fold_rows.append((tr, te))
    return _Plan("kfold", int(kfold), folds, orders, fold_rows, train)


def _screen_mismatch(eng: _Engine, geo_fit: _Fit, geo: _Scored, plan: _Plan, notes: list[str]
                     ) -> tuple[_Scored, dict, bool, np.ndarray]:
    """Step 4: held-out rows far beyond any effect (another robot or tracker placement) are named; a
    majority makes the validation a mismatch, a minority is left out of the effect analysis.

    Returns:
        (the geometric score without the rows left out, mismatch details, validation mismatch,
        held-out row numbers in their file (0-based) of the rows kept).
    """
    train_rms = float(geo_fit.result.rms_m)
    floor_all = float(np.sqrt(np.mean(np.sum(geo.S ** 2, axis=1))))
    e0 = np.linalg.norm(geo.R, axis=1)
    limit = MISMATCH_FACTOR * max(train_rms, floor_all)
    far = e0 > limit
    ho_order = np.concatenate(plan.orders)
    mismatch: dict = {"factor": MISMATCH_FACTOR, "limit_m": limit, "train_rms_m": train_rms,
                      "heldout_rms_m": float(np.sqrt(np.mean(e0 ** 2))), "rows": []}
    if not far.any():
        return geo, mismatch, False, ho_order
    rows = (ho_order[far] + 1).tolist()
    mismatch["rows"] = rows
    hint = "" if plan.mode == "transfer" else (" (a session with the tracker elsewhere? re-register the set-up "
                                                "first: --register-rows N)")
    if far.mean() >= 0.5:
        mismatch["message"] = (
            f"{int(far.sum())} of {far.size} held-out rows have errors beyond {limit * 1e3:.3g} mm "
            f"({MISMATCH_FACTOR:g}x the training RMS {train_rms * 1e3:.3g} mm; held-out RMS "
            f"{mismatch['heldout_rms_m'] * 1e3:.4g} mm): far beyond any modelled effect - the validation data "
            f"look like another robot or tracker placement{hint}; no effect is named")
        notes.append(mismatch["message"])
        return geo, mismatch, True, ho_order
    mismatch["message"] = (
        f"{int(far.sum())} held-out row(s) have errors beyond {limit * 1e3:.3g} mm ({MISMATCH_FACTOR:g}x the "
        f"training RMS), far beyond any modelled effect (another robot or tracker placement?): rows "
        f"{', '.join(map(str, rows[:10]))}{' ...' if len(rows) > 10 else ''}; left out of the effect analysis")
    notes.append(mismatch["message"])
    off, keep = 0, []
    for _, te in plan.folds:
        keep.append(~far[off:off + len(te)])
        off += len(te)
    eng.heldout_idx = keep
    return eng.score([], full=geo_fit), mismatch, False, np.concatenate([o[k] for o, k in zip(plan.orders, keep)])


def _single_effects(eng: _Engine, geo_fit: _Fit, geo: _Scored, cands: list[Effect], alpha: float, floor: float,
                    notes: list[str], bar: Any = None) -> tuple[list[EffectResult], dict, dict, list[Effect]]:
    """Step 6: every candidate alone with the geometry; skipped with a note when it cannot be used.

    Returns:
        (results ranked by held-out reduction, skipped last; scored models by name; the effects as
        used (parameters the data cannot determine dropped) by name; the usable candidates).
    """
    n_train_min = min(len(tr) for tr, _ in eng.folds)
    singles: list[EffectResult] = []
    scored: dict[str, _Scored] = {}
    pruned: dict[str, Effect] = {}
    usable: list[Effect] = []
    for eff in cands:
        if bar is not None:
            bar.set_postfix_str(eff.name)
            bar.update()
        note = next((n for n in (eff.check(d) for d in [eng.full_train] + [te for _, te in eng.folds]) if n), None)
        if note:
            singles.append(EffectResult(eff.name, status="skipped", note=note))
            notes.append(note)
            continue
        dof_left = 3 * n_train_min - geo_fit.nx - eff.n_params
        if dof_left < max(10, MIN_DOF_PER_PARAM * eff.n_params):
            need = int(math.ceil((geo_fit.nx + eff.n_params * (1 + MIN_DOF_PER_PARAM) + 10) / 3))
            msg = (f"{eff.name}: skipped, too few training rows ({n_train_min}) for its {eff.n_params} parameters "
                   f"next to {geo_fit.nx} geometric ones (needs at least {need} measurements)")
            singles.append(EffectResult(eff.name, status="skipped", note=msg))
            notes.append(msg)
            continue
        e2, msg = _prune(eng, geo_fit, eff, [])
        if msg:
            notes.append(msg)
        if e2 is None:
            singles.append(EffectResult(eff.name, status="skipped", note=msg))
            continue
        try:
            sc = eng.score([e2])
        except PinKpiOedError as exc:
            m_ = f"{eff.name}: skipped, identification with it failed ({exc})"
            singles.append(EffectResult(eff.name, status="skipped", note=m_))
            notes.append(m_)
            continue
        r = _compare(geo, sc, eff.name, len(cands), alpha, floor)
        if msg:
            r.note = msg
        singles.append(r)
        scored[eff.name] = sc
        pruned[eff.name] = e2
        usable.append(eff)
    ranked = sorted([s for s in singles if s.status == "ok"], key=lambda s: -s.reduction_m) + \
        [s for s in singles if s.status != "ok"]
    return ranked, scored, pruned, usable


def _forward_selection(eng: _Engine, geo: _Scored, singles: list[EffectResult], scored: dict, pruned: dict,
                       usable: list[Effect], alpha: float, floor: float, max_selected: int | None,
                       bar: Any = None) -> tuple[list[dict], list[str], _Scored]:
    """Step 7: add, step by step, the significant effect that reduces the held-out error most.

    Returns:
        (the steps with every candidate scored, the selected names in order, the final model's score).
    """
    selection: list[dict] = []
    selected: list[str] = []
    current, current_effects = geo, []
    step_results = {s.name: s for s in singles if s.status == "ok"}
    remaining = list(usable)
    limit_sel = len(usable) if max_selected is None else int(max_selected)
    while remaining and len(selected) < limit_sel:
        if bar is not None:
            bar.set_postfix_str(f"forward selection step {len(selection) + 1}")
            bar.update()
        if not selected:
            cand_res = {e.name: step_results[e.name] for e in remaining}
            cand_sc = {n: scored[n] for n in cand_res}
        else:
            cand_res, cand_sc = {}, {}
            for eff in remaining:
                e2, _ = _prune(eng, current.full, eff, current_effects)
                if e2 is None:
                    continue
                try:
                    sc = eng.score(current_effects + [e2])
                except PinKpiOedError:
                    continue
                cand_res[eff.name] = _compare(current, sc, eff.name, len(remaining), alpha, floor)
                cand_sc[eff.name] = sc
                pruned[eff.name] = e2
        if not cand_res:
            break
        order = sorted(cand_res.values(), key=lambda s: -s.reduction_m)
        selection.append({"step": len(selection) + 1, "base": list(selected),
                          "candidates": [{"name": c.name, "heldout_rms_after_m": c.heldout_rms_after_m,
                                          "f_pvalue": c.f_pvalue, "delta_bic": c.delta_bic,
                                          "heldout_pvalue": c.heldout_pvalue, "significant": c.significant}
                                         for c in order]})
        best = next((c for c in order if c.significant), None)
        selection[-1]["chosen"] = None if best is None else best.name
        if best is None:
            break
        selected.append(best.name)
        current = cand_sc[best.name]
        current_effects = current.effects
        remaining = [e for e in remaining if e.name != best.name]
    return selection, selected, current


def _verdict(gap: dict, remaining_gap: dict, selected: list[str], mismatch: bool, floor: float, rms_after: float,
             notes: list[str]) -> str:
    """Step 8: the dominant effect (or ``none``) and the notes that explain the verdict."""
    detected = bool(gap["gap_detected"])
    if mismatch:
        return "none"
    if detected and selected:
        if remaining_gap["gap_detected"]:
            notes.append(f"after {', '.join(selected)} a gap remains (RMS {rms_after * 1e6:.1f} µm vs noise floor "
                         f"{floor * 1e6:.1f} µm): part of the error is not any modelled effect")
        return selected[0]
    if detected:
        notes.append("a gap is detected but no candidate effect explains a significant part of it on held-out data: "
                     "the remaining error is not any modelled effect")
    elif selected:
        notes.append(f"{selected[0]} passes the tests, but the held-out residuals are consistent with the noise "
                     "(no gap detected): not named as dominant")
    return "none"


#: Share of the selected transmission-error amplitude (squared) in orders 1–2 above which the terms are
#: the gear_harmonic model (gear / encoder eccentricity) and named so.
LOW_ORDER_SHARE = 0.9


def _name_low_orders(dominant: str, term_selection: dict, candidate_names: list[str], notes: list[str]) -> str:
    """Name selected transmission-error terms that are (almost) only orders 1–2 ``gear_harmonic``.

    :class:`~pin_kpi_oed.effects.library.GearHarmonic` is the model Δq_j = Σ_{o=1,2} a sin(o q_j) + b cos(o q_j)
    (eccentricity of a gear or encoder); a transmission error whose data-chosen terms carry at least
    :data:`LOW_ORDER_SHARE` of their squared amplitude in orders 1–2 is that model, so the verdict names it
    (the note says so). Higher orders (gear meshing) keep the name ``transmission_error``.
    """
    if dominant != "transmission_error" or "gear_harmonic" not in candidate_names or not term_selection:
        return dominant
    amp2 = {True: 0.0, False: 0.0}
    for t in term_selection.get("terms", []):
        if t.get("effect") != "transmission_error" or " order " not in t.get("group", ""):
            continue
        a = t.get("amplitude_rad")
        if a is None or not np.isfinite(a):
            continue
        amp2[int(t["group"].rsplit(" order ", 1)[1]) <= 2] += float(a) ** 2
    total = amp2[True] + amp2[False]
    if total > 0 and amp2[True] / total >= LOW_ORDER_SHARE:
        notes.append(f"the selected transmission-error terms carry {100 * amp2[True] / total:.0f}% of their squared "
                     "amplitude in orders 1-2 of the joints: that is the gear_harmonic model (gear / encoder "
                     "eccentricity), named so")
        return "gear_harmonic"
    return dominant


@limit_threads
def diagnose(model: TrackerModel, train: MeasurementSet, validate: MeasurementSet | None = None,
             options: DiagnoseOptions | None = None, **overrides: Any) -> DiagnosisReport:
    """Diagnose the gap between a geometric model and measured data (see the module docstring).

    Steps: check the options (0), candidate effects (1), folds (2), geometric calibration (3),
    rows far beyond any effect (4), gap test and where (5), every effect alone (6), forward
    selection (7), verdict (8). The figures are drawn from the report by
    :func:`pin_kpi_oed.viz.diagnosis_plots.diagnosis_figures`.

    Args:
        model: measurement model: robot, nominal reflector offset in the tool frame, noise model
            (σ when the data have no sigma columns or ``weights='noise'``). The tracker pose is
            registered from the data (one per station).
        train: measurements to fit on.
        validate: held-out measurements (another file, disjoint from ``train``); or None with ``kfold``.
        options: :class:`DiagnoseOptions`.
        **overrides: fields of :class:`DiagnoseOptions` by name (``kfold=5``, ``register_rows=60``, ...).

    Returns:
        The :class:`DiagnosisReport`.

    Raises:
        InputError: neither or both of ``validate`` / ``kfold``, registration rows without
            validation data, missing joint columns, a bad K, an unknown effect name or option, too
            few training rows for the geometric model, or registration rows that cannot determine
            the set-up.
        IdentifiabilityError, SolverError: the geometric calibration itself is impossible.
    """
    t0 = time.perf_counter()
    opts = DiagnoseOptions.resolve(options, overrides)
    _check_options(model, train, validate, opts)
    notes: list[str] = []
    cands = _candidates(model.robot, train, opts)
    plan = _plan(train, validate, opts)
    eng = _Engine(model, plan, train, [np.ones(len(te), bool) for _, te in plan.folds], opts.weights,
                  dict(opts.identify_options or {}), opts.exact_kfold)

    from pin_kpi_oed.progress import progress

    n_terms = sum(1 for e in (opts.effects or ()) if isinstance(e, str) and e in SELECTED_TERM_EFFECTS)
    bar_cm = progress(total=2 + (1 if n_terms else 0) + len(cands) + n_terms + len(cands) + n_terms,
                      desc="diagnose", unit="step", disable=opts.show_progress is False)
    bar = bar_cm.__enter__()
    try:
        return _diagnose_steps(model, train, validate, opts, notes, cands, plan, eng, bar, t0)
    finally:
        bar_cm.__exit__(None, None, None)


def _diagnose_steps(model: TrackerModel, train: MeasurementSet, validate: MeasurementSet | None,
                    opts: DiagnoseOptions, notes: list[str], cands: list[Effect], plan: _Plan, eng: _Engine,
                    bar: Any, t0: float) -> DiagnosisReport:
    """Steps 3–8 of :func:`diagnose` (``bar``: the progress bar, one update per step / candidate)."""
    # (3) geometric calibration and first held-out residuals
    bar.set_postfix_str("geometric calibration")
    geo_fit = eng.fit(train, [])
    bar.update()
    geo = eng.score([], full=geo_fit)
    res0 = geo_fit.result
    geometry = {"train_rms_m": float(res0.rms_m), "train_chi2_reduced": res0.chi2_reduced,
                "n_params": len(res0.names), "tracker_T_base": res0.tracker_T_base, "reflector_m": res0.reflector_m,
                "stations": {k: v.to_dict() for k, v in res0.setups.items()}, "converged": res0.converged}
    # (3b) transferable terms chosen by sparse selection, then scored like any candidate
    term_names = [e for e in (opts.effects or ()) if isinstance(e, str) and e in SELECTED_TERM_EFFECTS]
    term_selection: dict = {}
    if term_names:
        bar.set_postfix_str("term selection")
        chosen, term_selection = _select_transfer_terms(geo_fit, train, term_names, opts, notes)
        bar.update()
        cands = cands + chosen
    # (4) rows far beyond any effect
    geo, mismatch, validation_mismatch, ho_order = _screen_mismatch(eng, geo_fit, geo, plan, notes)
    ho_data = plan.heldout_source.subset(ho_order)
    # (5) gap test, where
    gap = _gap_test(geo, opts.alpha)
    floor = gap["noise_floor_m"]
    expected = float(np.sqrt(np.mean(np.sum(geo.S ** 2 * (1 + geo.V), axis=1))))
    before = heldout_stats(geo.R)
    where, regs = _where(res0.model, res0.p, ho_data, ho_order, geo.R, geo.S, opts.alpha)
    # (6) every candidate alone, (7) forward selection
    singles, scored, pruned, usable = _single_effects(eng, geo_fit, geo, cands, opts.alpha, floor, notes, bar)
    selection, selected, current = _forward_selection(eng, geo, singles, scored, pruned, usable, opts.alpha, floor,
                                                      opts.max_selected, bar)
    after = heldout_stats(current.R)
    remaining_gap = _gap_test(current, opts.alpha)
    # (7b) where the transfer gap lies (validation data only), with the final model's predicted uncertainty
    transfer = {}
    if validate is not None:
        from pin_kpi_oed.diagnosis.transfer_gap import predicted_sigma, transfer_section

        fin = bool(selected)
        transfer = transfer_section(res0, train, ho_data, ho_order, geo.R, predicted_sigma(geo.V, geo.S), floor,
                                    plan.mode == "transfer", current.R if fin else None,
                                    predicted_sigma(current.V, current.S) if fin else None,
                                    ("geometry + " + ", ".join(selected)) if fin else "",
                                    min([float(current.full.result.rms_m)]
                                        + ([float(term_selection["cv_rms_m"][-1])] if term_selection else [])))
    rb, ra = before["rms_m"], after["rms_m"]
    closed = (rb - ra) / (rb - floor) if rb is not None and rb - floor > 1e-3 * floor else float("nan")
    # (8) verdict
    dominant = _verdict(gap, remaining_gap, selected, validation_mismatch, floor, ra, notes)
    dominant = _name_low_orders(dominant, term_selection, [e.name for e in cands], notes)
    for u in sorted(eng.unconverged):
        notes.append(f"the identification with {u} stopped at its evaluation limit before converging; its numbers "
                     "are those of the last iterate")
    if res0.sigma_source == "data":
        notes.append("weights from the data's sigma columns: the gap test is only as good as they are")
    status = "mismatch" if validation_mismatch else ("gap" if gap["gap_detected"] else "no_gap")
    message = {"mismatch": "the validation data do not match the training set-up; no effect named",
               "gap": f"gap detected; dominant effect: {dominant}",
               "no_gap": "held-out residuals consistent with the noise"}[status]
    return DiagnosisReport(
        success=True, status=status, message=message, nit=len(selection), nfev=eng.n_fits,
        robot=model.robot.name, tool_frame=model.robot.tool_frame, mode=plan.mode, k_folds=plan.k,
        n_train=len(train), n_heldout=int(geo.R.shape[0]), alpha=opts.alpha, weights=res0.sigma_source,
        noise_floor_m=floor, expected_rms_m=expected, gap_detected=bool(gap["gap_detected"]), gap_test=gap,
        dominant_effect=dominant, selected_effects=selected, heldout_before=before, heldout_after=after,
        gap_closed_fraction=closed, remaining_gap=remaining_gap, effects=singles, selection=selection, where=where,
        validation_mismatch=validation_mismatch, mismatch=mismatch, notes=notes, geometry=geometry,
        registration=dict(plan.registration_info), term_selection=term_selection,
        transfer=transfer, plot_data={"residuals_m": geo.R, "regressors": regs},
        time_s=time.perf_counter() - t0)
