"""Which effect: the candidates, every one alone, then forward selection (with undeterminable parameters dropped)."""

from __future__ import annotations

import math
from typing import Any
from collections.abc import Sequence

import numpy as np

from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.diagnosis.diagnose_options import DiagnoseOptions
from pin_kpi_oed.diagnosis.engine import Engine, Fit, Scored
from pin_kpi_oed.diagnosis.gap_test import compare_nested
from pin_kpi_oed.diagnosis.report import EffectResult
from pin_kpi_oed.effects.library import EFFECT_NAMES, Effect, SubsetEffect, candidate_effects
from pin_kpi_oed.errors import InputError, PinKpiOedError

__all__ = ["SELECTED_TERM_EFFECTS", "candidate_list", "select_transfer_terms", "prune", "single_effects",
           "forward_selection"]

#: Minimum residual degrees of freedom per effect parameter (too-few-rows guard).
MIN_DOF_PER_PARAM = 2
#: An effect parameter is kept when the part of its (unit) column orthogonal to the model's exceeds this.
PRUNE_TOL = 1e-3


#: Candidates whose terms are chosen from the data by sparse selection (:func:`select_transfer_terms`).
SELECTED_TERM_EFFECTS: tuple[str, ...] = ("transmission_error", "link_bending")


def select_transfer_terms(geo_fit: Any, train: MeasurementSet, names: Sequence[str], opts: DiagnoseOptions,
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
        raise InputError(f"diagnose: parameter 'harmonics' must be an integer >= 1, got {opts.harmonics!r}")
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
            raise InputError(f"diagnose: transfer_prior_rad must be a positive number of rad, got "
                             f"{opts.transfer_prior_rad}")
        for e in sel.effects:
            e.prior_rad = float(opts.transfer_prior_rad)  # type: ignore[attr-defined]  # identify's per-effect prior (effect_prior_rad)
        info["prior_rad"] = float(opts.transfer_prior_rad)
    if not sel.terms:
        notes.append(f"term selection ({', '.join(names)}): no term lowers the {sel.folds}-fold held-out error")
    return list(sel.effects), info


def candidate_list(robot: Any, train: MeasurementSet, opts: DiagnoseOptions) -> list[Effect]:
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


def prune(engine: Engine, ref: Fit, effect: Effect, ref_effects: list) -> tuple[Effect | None, str]:
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


def single_effects(eng: Engine, geo_fit: Fit, geo: Scored, cands: list[Effect], alpha: float, floor: float,
                    notes: list[str], bar: Any = None) -> tuple[list[EffectResult], dict, dict, list[Effect]]:
    """Step 6: every candidate alone with the geometry; skipped with a note when it cannot be used.

    Returns:
        (results ranked by held-out reduction, skipped last; scored models by name; the effects as
        used (parameters the data cannot determine dropped) by name; the usable candidates).
    """
    n_train_min = min(len(tr) for tr, _ in eng.folds)
    singles: list[EffectResult] = []
    scored: dict[str, Scored] = {}
    pruned: dict[str, Effect] = {}
    usable: list[Effect] = []
    for eff in cands:
        if bar is not None:
            bar.set_postfix_str(eff.name)
            bar.update()
        note = next((n for n in (eff.check(d) for d in [eng.full_train] + [te for _, te in eng.folds]) if n), None)
        if note:
            singles.append(EffectResult(eff.name, status="skipped", message=note))
            notes.append(note)
            continue
        dof_left = 3 * n_train_min - geo_fit.nx - eff.n_params
        if dof_left < max(10, MIN_DOF_PER_PARAM * eff.n_params):
            need = int(math.ceil((geo_fit.nx + eff.n_params * (1 + MIN_DOF_PER_PARAM) + 10) / 3))
            msg = (f"{eff.name}: skipped, too few training rows ({n_train_min}) for its {eff.n_params} parameters "
                   f"next to {geo_fit.nx} geometric ones (needs at least {need} measurements)")
            singles.append(EffectResult(eff.name, status="skipped", message=msg))
            notes.append(msg)
            continue
        e2, msg = prune(eng, geo_fit, eff, [])
        if msg:
            notes.append(msg)
        if e2 is None:
            singles.append(EffectResult(eff.name, status="skipped", message=msg))
            continue
        try:
            sc = eng.score([e2])
        except PinKpiOedError as exc:
            m_ = f"{eff.name}: skipped, identification with it failed ({exc})"
            singles.append(EffectResult(eff.name, status="skipped", message=m_))
            notes.append(m_)
            continue
        r = compare_nested(geo, sc, eff.name, len(cands), alpha, floor)
        if msg:
            r.message = msg
        singles.append(r)
        scored[eff.name] = sc
        pruned[eff.name] = e2
        usable.append(eff)
    ranked = sorted([s for s in singles if s.status == "ok"], key=lambda s: -s.reduction_m) + \
        [s for s in singles if s.status != "ok"]
    return ranked, scored, pruned, usable


def forward_selection(eng: Engine, geo: Scored, singles: list[EffectResult], scored: dict, pruned: dict,
                       usable: list[Effect], alpha: float, floor: float, max_selected: int | None,
                       bar: Any = None) -> tuple[list[dict], list[str], Scored]:
    """Step 7: add, step by step, the significant effect that reduces the held-out error most.

    Returns:
        (the steps with every candidate scored, the selected names in order, the final model's score).
    """
    selection: list[dict] = []
    selected: list[str] = []
    current, current_effects = geo, list[Any]()
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
                e2, _ = prune(eng, current.full, eff, current_effects)
                if e2 is None:
                    continue
                try:
                    sc = eng.score(current_effects + [e2])
                except PinKpiOedError:
                    continue
                cand_res[eff.name] = compare_nested(current, sc, eff.name, len(remaining), alpha, floor)
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
