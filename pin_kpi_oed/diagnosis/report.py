"""The diagnosis report: one candidate effect's result and the whole report (summary, JSON)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pin_kpi_oed.data.atomic import to_jsonable
from pin_kpi_oed.effects.library import UNOBSERVABLE_NOTES
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.results import Result

__all__ = ["EffectResult", "DiagnosisReport"]


def _f(x: Any) -> Any:
    """JSON-safe float (NaN/inf -> None)."""
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


# --------------------------------------------------------------------------- results
@dataclass
class EffectResult(Result):
    """One candidate effect added (alone, or at a forward-selection step) to a reference model (a
    :class:`~pin_kpi_oed.results.Result`: ``status`` ``ok`` or ``skipped``, ``success`` when ok, ``message`` why it
    was skipped or which parameters were dropped).

    Attributes:
        name: effect name.
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

    def __post_init__(self) -> None:
        self.status = self.status or "ok"
        self.success = self.status == "ok"

    @property
    def reduction_m(self) -> float:
        """Held-out RMS reduction (m); −inf when skipped."""
        if self.status != "ok" or not np.isfinite(self.heldout_rms_after_m):
            return -np.inf
        return self.heldout_rms_before_m - self.heldout_rms_after_m

    def to_dict(self) -> dict:
        """Plain JSON-able dict (SI units)."""
        return {**self.result_dict(), "name": self.name, "n_params": self.n_params,
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
    """Outcome of :func:`~pin_kpi_oed.diagnosis.diagnose.diagnose` (SI units; ``summary()`` prints mm / µm); common
    fields of
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
        transfer: with validation data (:func:`pin_kpi_oed.diagnosis.transfer_gap.transfer_section`; with
            ``--model-out``, ``model_sigma``: the written model's σ scored on the validation rows, the same σ as
            ``predict``):
            per-joint ranges of train and validation (rad / m; a periodic joint wrapped as the coverage), coverage per
            joint and overall, held-out RMS inside / outside the coverage, before / after the
            set-up registration (m), the predicted TCP σ at the validation configurations vs the
            observed error, the classification of the gap (``extrapolation``, ``set-up change``,
            ``unmodelled effect``) with the numbers behind it, and for extrapolation the poses to add.
        term_selection: the sparse selection of transferable terms (``transmission_error``,
            ``link_bending`` candidates): chosen terms in plain words, held-out RMS path (m).
        model_fit: the identification the report describes, fitted on all training rows (geometry and
            the selected effects; not in ``to_dict``): :meth:`calibrated_model` of it is what
            ``diagnose --model-out`` writes.
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
    model_fit: Any = field(default=None, repr=False)

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
            hs = tf.get("model_sigma")
            if hs:
                out.append(f"    the written model's sigma at the validation rows ({hs['model']}): mean 3-D "
                           f"{hs['sigma_mean_m'] * 1e3:.3f} mm for a mean error of {hs['mean_m'] * 1e3:.3f} mm; "
                           f"standardised RMS {hs['z_rms']:.2f} (1 = honest), {hs['inside_95'] * 100:.0f} % inside "
                           f"the 95 % ellipsoid" + (f"; sigma scaled by {hs['sigma_scale']:.2f} at registration"
                                                    if hs.get("sigma_scale", 1.0) > 1.0 else ""))
            if tf.get("poses_to_add", {}).get("text"):
                out.append(f"    to fix it: {tf['poses_to_add']['text']}")
            out.append(f"    {'joint':<22}{'train range':>20}{'validation range':>24}{'covered':>9}  unit"
                       "   (a periodic joint's wrapped to [-pi, pi) as the coverage: smallest arc, may end beyond pi)")
            for j in tf["joints"]:
                out.append(f"    {j['joint']:<22}{j['train_min']:>9.3f} .. {j['train_max']:<7.3f}"
                           f"{j['validate_min']:>11.3f} .. {j['validate_max']:<9.3f}{_pct(j['coverage']):>9}  "
                           f"{j.get('unit', 'rad')}")
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
                out.append(f"    {e.name:<19}{'-':>4}  skipped: {e.message}")
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
