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

Modules: options (:mod:`~pin_kpi_oed.diagnosis.diagnose_options`), report
(:mod:`~pin_kpi_oed.diagnosis.report`), engine: folds, fits and held-out scores
(:mod:`~pin_kpi_oed.diagnosis.engine`), gap test and nested-model tests
(:mod:`~pin_kpi_oed.diagnosis.gap_test`), where (:mod:`~pin_kpi_oed.diagnosis.locate`), which
effect (:mod:`~pin_kpi_oed.diagnosis.search`); every public name is importable from here too.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.diagnosis.diagnose_options import DiagnoseOptions, check_options
from pin_kpi_oed.diagnosis.engine import Engine, Plan, plan_folds
from pin_kpi_oed.diagnosis.gap_test import MISMATCH_FACTOR, chi2_gap_test, heldout_stats, screen_mismatch
from pin_kpi_oed.diagnosis.locate import locate
from pin_kpi_oed.diagnosis.report import DiagnosisReport, EffectResult
from pin_kpi_oed.diagnosis.search import (SELECTED_TERM_EFFECTS, candidate_list, forward_selection,
                                          select_transfer_terms, single_effects)
from pin_kpi_oed.effects.library import Effect
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.threads import limit_threads

__all__ = ["DiagnosisReport", "DiagnoseOptions", "EffectResult", "diagnose", "MISMATCH_FACTOR", "heldout_stats"]


def _verdict(gap: dict, remaining_gap: dict, selected: list[str], mismatch: bool, floor: float, rms_after: float,
             notes: list[str], tried: bool = True) -> str:
    """Step 8: the dominant effect (or ``none``) and the notes that explain the verdict."""
    detected = bool(gap["gap_detected"])
    if mismatch:
        return "none"
    if detected and selected:
        if remaining_gap["gap_detected"]:
            notes.append(f"after {', '.join(selected)} a gap remains (RMS {rms_after * 1e6:.1f} µm vs noise floor "
                         f"{floor * 1e6:.1f} µm): part of the error is not any modelled effect")
        return selected[0]
    if detected and not tried:
        notes.append("a gap is detected and no candidate effect was tried (effects=[]: geometry only): the "
                     "remaining error is left to the model discrepancy (parameter 'discrepancy')")
    elif detected:
        notes.append("a gap is detected but no candidate effect explains a significant part of it on held-out data: "
                     "the remaining error is not any modelled effect")
    elif selected:
        notes.append(f"{selected[0]} passes the tests, but the held-out residuals are consistent with the noise "
                     "(no gap detected): not named as dominant")
    return "none"


def unconfirmed_terms(term_selection: dict, chosen: list[str], selected: list[str], singles: list,
                       notes: list[str]) -> str:
    """The verdict's words when the terms chosen on the training rows (step 3b) are not selected on the held-out
    rows (step 7): a note with the numbers, and a clause for the one-line message ("" when they are, or none were)."""
    if not term_selection or not term_selection.get("terms") or any(c in selected for c in chosen):
        return ""
    n = len(term_selection["terms"])
    cv = term_selection.get("cv_rms_m") or [float("nan")]
    held = [e for e in singles if e.name in chosen and e.status == "ok"]
    how = "; ".join(f"{e.name}: held-out RMS {e.heldout_rms_before_m * 1e6:.1f} -> {e.heldout_rms_after_m * 1e6:.1f} "
                    f"µm, p_heldout {e.heldout_pvalue:.2g}" for e in held) or "not scored"
    notes.append(f"the term selection chose {n} term(s) on the training rows ({cv[0] * 1e6:.1f} -> {cv[-1] * 1e6:.1f} "
                 f"µm, K-fold) but the held-out rows do not confirm them ({how}): they are not named as dominant and "
                 "describe the training session only (check the validation rows' coverage)")
    return f"; the {n} term(s) chosen on the training rows are not confirmed held-out"


#: Share of the selected transmission-error amplitude (squared) in orders 1–2 above which the terms are
#: the gear_harmonic model (gear / encoder eccentricity) and named so.
LOW_ORDER_SHARE = 0.9


def name_low_orders(dominant: str, term_selection: dict, candidate_names: list[str], notes: list[str]) -> str:
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


def _state_tcp_sigma(fit: Any, train: MeasurementSet, opts: DiagnoseOptions) -> None:
    """The TCP σ of the fit the report describes, as ``identify`` states it (the engine's many fits state none)."""
    from pin_kpi_oed.identification.identify import restate_tcp_sigma, working_configurations

    restate_tcp_sigma(fit, train, working_configurations(fit.model.robot, train,
                                                         (opts.identify_options or {}).get("Q_work")))


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
    check_options(model, train, validate, opts)
    notes: list[str] = []
    cands = candidate_list(model.robot, train, opts)
    plan = plan_folds(train, validate, opts, model.robot)
    eng = Engine(model, plan, train, [np.ones(len(te), bool) for _, te in plan.folds], opts.weights,
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
                    opts: DiagnoseOptions, notes: list[str], cands: list[Effect], plan: Plan, eng: Engine,
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
    chosen: list = []
    if term_names:
        bar.set_postfix_str("term selection")
        chosen, term_selection = select_transfer_terms(geo_fit, train, term_names, opts, notes)
        bar.update()
        cands = cands + chosen
    # (4) rows far beyond any effect
    geo, mismatch, validation_mismatch, ho_order = screen_mismatch(eng, geo_fit, geo, plan, notes)
    ho_data = plan.heldout_source.subset(ho_order)
    # (5) gap test, where
    gap = chi2_gap_test(geo, opts.alpha)
    floor = gap["noise_floor_m"]
    expected = float(np.sqrt(np.mean(np.sum(geo.S ** 2 * (1 + geo.V), axis=1))))
    before = heldout_stats(geo.R)
    where, regs = locate(res0.model, res0.p, ho_data, ho_order, geo.R, geo.S, opts.alpha)
    # (6) every candidate alone, (7) forward selection
    singles, scored, pruned, usable = single_effects(eng, geo_fit, geo, cands, opts.alpha, floor, notes, bar)
    selection, selected, current = forward_selection(eng, geo, singles, scored, pruned, usable, opts.alpha, floor,
                                                      opts.max_selected, bar)
    after = heldout_stats(current.R)
    remaining_gap = chi2_gap_test(current, opts.alpha)
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
    dominant = _verdict(gap, remaining_gap, selected, validation_mismatch, floor, ra, notes, tried=bool(cands))
    dominant = name_low_orders(dominant, term_selection, [e.name for e in cands], notes)
    unconfirmed = unconfirmed_terms(term_selection, [e.name for e in chosen], selected, singles, notes)
    for u in sorted(eng.unconverged):
        notes.append(f"the identification with {u} stopped at its evaluation limit before converging; its numbers "
                     "are those of the last iterate")
    if res0.sigma_source == "data":
        notes.append("weights from the data's sigma columns: the gap test is only as good as they are")
    model_fit = current.full.result if selected and current.full is not None else res0
    _state_tcp_sigma(model_fit, train, opts)
    status = "mismatch" if validation_mismatch else ("gap" if gap["gap_detected"] else "no_gap")
    message = {"mismatch": "the validation data do not match the training set-up; no effect named",
               "gap": f"gap detected; dominant effect: {dominant}",
               "no_gap": "held-out residuals consistent with the noise"}[status] + unconfirmed
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
        model_fit=model_fit,
        time_s=time.perf_counter() - t0)
