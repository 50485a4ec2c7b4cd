r"""Sparse selection of transferable error terms by held-out error, and the transfer check around it.

A geometric calibration leaves, on a real arm, residuals that follow the joint angles: gear
and encoder errors with many cycles per revolution, joint and link deflections that follow
the links' gravity direction. Which of the many possible terms are there is a question for
the data, asked on data the fit has not seen.

Candidate basis
---------------
:func:`transfer_candidates`: every (joint, order) pair of
:class:`~pin_kpi_oed.effects.periodic.TransmissionError` (orders 1 … K, K = 40 by default:
sin(k q_j), cos(k q_j)) and every (joint, angle) pair of
:class:`~pin_kpi_oed.effects.coupled.LinkBending` (cos/sin of q2, q2+q3, q2+q3+q4 on the
arm-plane joints). A group — a cos+sin pair — is selected as a whole. Groups whose terms move
the reflector by less than ``min_lever_m`` per rad (RMS; wrist_3 of a UR arm with the
reflector on its axis) are left out and named.

Selection (:func:`select_terms`)
--------------------------------
Linearise at the fitted model (geometry, set-up per station, the effects already in it):
with the weighted residual b = W (y − ŷ) and the weighted Jacobian A of every parameter the
fit estimated, and C_g the weighted Jacobian of candidate group g (``effect_jacobian``
columns: dŷ/dq · ∂Δq/∂θ), the model with groups S is b ≈ [A, C_S] x. Columns are scaled to
unit norm (X̃ = X D⁻¹) and a tiny ridge λ (default 1e-8) is added. The measurements are
split into K folds (seeded; the 3 rows of a measurement share a fold, and so do near-duplicate configurations —
a pose measured again or jittered around it —, :func:`measurement_folds`). For
fold k, with G = X̃ᵀX̃ and h = X̃ᵀb summed over the training rows (``tr``) or the held-out
rows (``te``)::

    x_k(S) = (G_tr,SS + λI)⁻¹ h_tr,S,      CV(S) = Σ_k  bᵀb|_te − 2 x_kᵀ h_te,S + x_kᵀ G_te,SS x_k

is the exact K-fold held-out sum of squares of the linearised model. Greedy forward
selection adds, step by step, the group g that minimises CV(S ∪ g); the candidates of a
step are scored at once from the Cholesky factor of G_tr,SS by the Schur complement of the
added block (Z = G_tr,SS⁻¹ G_tr,Sg, Σ = G_tr,gg + λI − G_tr,gS Z, x_g = Σ⁻¹(h_tr,g − Zᵀ h_tr,S),
x_S = x_k(S) − Z x_g), so a step costs O(|S|² · #candidates) per fold, not a new fit per
candidate. It stops when the relative gain (CV_old − CV_new) / CV_old < ``min_rel_gain``
(default 0.5 %) or after ``max_terms`` groups (default 60).

Refit: the selected groups (as effect objects, :attr:`SelectionResult.effects`) are fitted
jointly with the geometry and every station's set-up by
:func:`~pin_kpi_oed.identification.identify.identify` (one or several stations: the data's
``station`` column), with an optional Gaussian prior θ ~ N(0, ``prior_rad``²) on their
parameters (``effect_prior_rad``): the penalty
(θ / prior_rad)² is added to the weighted χ² (the residuals are in units of σ, so a prior of
σ_y / lever keeps a term from moving the reflector more than σ_y where the data do not pin
it down). It limits how far a term fitted on one region of joint space extrapolates to
another; the held-out error within the training data does not show that, the transfer check
does.

Transfer
--------
Another day, the tracker moved: :func:`pin_kpi_oed.upkeep.transfer.register_setup`
re-fits only the set-up (tracker pose, reflector, and the set-up-specific effects such as
:class:`~pin_kpi_oed.effects.drift.Drift`) on a few rows of the new data with the robot
(geometry and transferable effects) held. :func:`coverage` says which share of the new rows
lies within a tolerance of a training angle, joint by joint (angles wrapped to 2π).

Units: SI (m, rad, s); summaries print mm and µrad.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any
from collections.abc import Sequence

import numpy as np

from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.discrepancy.gp import grouped_folds
from pin_kpi_oed.diagnosis.forward_selection import MIN_LEVER_M, SelectionOptions, SelectionPath, forward_select
from pin_kpi_oed.effects.coupled import LinkBending
from pin_kpi_oed.effects.library import Effect
from pin_kpi_oed.effects.periodic import DEFAULT_MAX_ORDER, TransmissionError
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.calibrated.coverage import coverage, covered_rows
from pin_kpi_oed.identification.identify import IdentificationResult, identify
from pin_kpi_oed.identification.problem import ResidualModel, align_data
from pin_kpi_oed.results import Result
from pin_kpi_oed.threads import limit_threads

__all__ = [
    "SelectionOptions", "SelectionPath", "SelectionResult", "transfer_candidates", "forward_select", "select_terms",
    "coverage", "covered_rows", "measurement_folds",
]



# --------------------------------------------------------------------------- candidates
def transfer_candidates(robot: Any, max_order: int = DEFAULT_MAX_ORDER, joints: Sequence[str] | None = None,
                        coupled: bool = True) -> list[Effect]:
    """The full candidate basis: Fourier pairs 1 … ``max_order`` per joint, and the arm-plane coupled pairs.

    Args:
        robot: the arm.
        max_order: highest order K of the transmission-error basis (cycles per revolution).
        joints: joints of the Fourier basis (default every revolute joint).
        coupled: add :class:`LinkBending` (full cos+sin pairs, no compliance complement).
    """
    out: list[Effect] = [TransmissionError(robot, joints=joints, max_order=max_order)]
    if coupled:
        try:
            out.append(LinkBending(robot, complement_compliance=False))
        except InputError:
            pass  # no arm plane (no horizontal axis): nothing coupled to offer
    return out


def measurement_folds(Q: np.ndarray, k: int, seed: int, periodic: np.ndarray | None = None) -> np.ndarray:
    """Fold of each measurement at configurations Q (m, n) for K-fold cross-validation, (m,) in 0 … k−1: near-
    duplicate configurations (a pose measured again, or jittered around it) share a fold
    (:func:`~pin_kpi_oed.discrepancy.gp.grouped_folds`, seeded), so a held-out row never has its own repeat among
    the training rows — a term that fits the repeat would otherwise show a held-out gain that new poses do not.

    Args:
        Q: the measurements' joint values (m, n) rad / m.
        k: folds (fewer when there are fewer pose groups).
        seed: seed of the groups' order.
        periodic: (n,) bool, the joints compared modulo 2π (``Robot.periodic_joints``); None: every joint.

    Raises:
        InputError: k < 2 or fewer measurements than folds.
    """
    m = len(np.atleast_2d(Q))
    if k < 2 or m < k:
        raise InputError(f"cross-validation needs 2 <= folds <= measurements, got {k} folds for {m} measurements")
    return grouped_folds(Q, k, seed, periodic)[0]


# --------------------------------------------------------------------------- options
# --------------------------------------------------------------------------- selection on a fit
@dataclass(kw_only=True)
class SelectionResult(Result):
    """Outcome of :func:`select_terms` (common fields of :class:`pin_kpi_oed.results.Result`).

    Attributes:
        terms: the selected groups in order: ``{"effect", "group", "amplitude_rad", "text",
            "cv_rms_m"}`` (amplitude = √(Σ θ²) of the refit, rad; cv_rms_m = held-out RMS after adding it).
        cv_rms_m: held-out 3-D RMS per measurement (m) before the first step and after each.
        effects: the selected terms as effect objects, ready for ``identify(..., effects=...)`` /
            ``theta`` their refitted parameters (rad).
        fit: the refit (:class:`~pin_kpi_oed.identification.identify.IdentificationResult`: geometry,
            every station's set-up, the fit's effects and the selected ones), or None.
        n_candidates: number of candidate groups scored; ``left_out``: groups left out as invisible.
        folds, seed, max_terms, min_rel_gain, ridge, prior_rad, min_lever_m: the settings.
        stop: why the selection stopped.
    """

    terms: list[dict] = field(default_factory=list)
    cv_rms_m: list[float] = field(default_factory=list)
    effects: list[Effect] = field(default_factory=list, repr=False)
    theta: list[np.ndarray] = field(default_factory=list, repr=False)
    fit: IdentificationResult | None = field(default=None, repr=False)
    n_candidates: int = 0
    left_out: list[str] = field(default_factory=list)
    folds: int = 5
    seed: int = 0
    max_terms: int = 60
    min_rel_gain: float = 5e-3
    ridge: float = 1e-8
    prior_rad: float | None = None
    min_lever_m: float = MIN_LEVER_M
    stop: str = ""

    def to_dict(self) -> dict:
        from pin_kpi_oed.data.atomic import to_jsonable

        d = self.result_dict()
        d.update(terms=self.terms, cv_rms_m=self.cv_rms_m, n_candidates=self.n_candidates, left_out=self.left_out,
                 folds=self.folds, seed=self.seed, max_terms=self.max_terms, min_rel_gain=self.min_rel_gain,
                 ridge=self.ridge, prior_rad=self.prior_rad, min_lever_m=self.min_lever_m, stop=self.stop,
                 effects=[{**e.to_dict(), "theta": t} for e, t in zip(self.effects, self.theta)])
        return to_jsonable(d)

    def summary(self) -> str:
        r0 = self.cv_rms_m[0] * 1e3 if self.cv_rms_m else float("nan")
        r1 = self.cv_rms_m[-1] * 1e3 if self.cv_rms_m else float("nan")
        out = [f"term selection: {len(self.terms)} of {self.n_candidates} candidate groups, {self.folds}-fold "
               f"held-out RMS {r0:.4f} -> {r1:.4f} mm ({self.time_s:.1f} s; {self.stop})"]
        for i, t in enumerate(self.terms, 1):
            out.append(f"  {i:2d}. {t['text']}  [held-out RMS {t['cv_rms_m'] * 1e3:.4f} mm]")
        if self.left_out:
            heads = dict.fromkeys(g.split(" order ")[0] for g in self.left_out)
            out.append(f"  {len(self.left_out)} groups left out (they move the reflector less than "
                       f"{self.min_lever_m * 1e3:g} mm per rad): {', '.join(heads)}")
        return "\n".join(out)


def _sigma(fit: IdentificationResult, data: MeasurementSet) -> np.ndarray | None:
    """Position σ per row the fit was weighted with: the data's sigma columns, or None (the noise model)."""
    return np.asarray(data.sigma_m, float) if fit.sigma_source == "data" else None


def _linear_system(fit: IdentificationResult, data: MeasurementSet, candidates: Sequence[Effect]
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """b, A (estimated unknowns of the fit), C (candidate columns), σ per row, lever per candidate column.

    One :class:`ResidualModel` over every station of the fit, its estimated effects followed by the
    candidates (θ = 0), its held effects held: A, C are the weighted position Jacobian's columns.
    """
    k_c = int(sum(e.n_params for e in candidates))
    prob = ResidualModel(fit.station_set, data, np.asarray(fit.identifiability.base, int),
                         list(fit.effects) + list(candidates), sigma=_sigma(fit, data), p_ref=fit.P, held=fit.held)
    x = np.concatenate([np.asarray(fit.values, float), np.zeros(k_c)])
    J = prob.jacobian_full(x)[:, :3, :]
    W = prob.W[:, :3]
    n_fit = x.size - k_c
    Jr = J.reshape(-1, prob.nx)
    b = -prob.weighted_rows(x)[:, :3].ravel()
    lev = J[:, :, n_fit:] / W[:, :, None]  # (m, 3, k_c) unweighted, m per rad
    lever = np.sqrt(np.mean(np.sum(lev ** 2, axis=1), axis=0))
    return b, Jr[:, :n_fit], Jr[:, n_fit:], (1.0 / W).ravel(), lever


def _fold_of_measurements(folds: int | np.ndarray, seed: int, fit: IdentificationResult, data: MeasurementSet
                          ) -> tuple[np.ndarray, int]:
    """Fold of every measurement ((m,) int) and the number of folds: ``folds`` as given, or a seeded split that
    keeps near-duplicate poses together (:func:`measurement_folds`)."""
    if isinstance(folds, np.ndarray):
        fold_m = np.asarray(folds, int)
        return fold_m, int(fold_m.max()) + 1
    robot = fit.model.robot
    fold_m = measurement_folds(align_data(robot, data, need_position=False), folds, seed, robot.periodic_joints)
    return fold_m, int(fold_m.max()) + 1


_Group = tuple[int, int, str, np.ndarray]  # (effect index, group index, label, columns)


def _visible_groups(cands: Sequence[Effect], lever: np.ndarray, min_lever_m: float) -> tuple[list[_Group], list[str]]:
    """Candidate groups moving the reflector at least ``min_lever_m`` per rad, and the labels of those left out."""
    groups: list[_Group] = []
    left_out: list[str] = []
    c0 = 0
    for ei, e in enumerate(cands):
        for gi, (label, group_idx) in enumerate(e.groups()):
            idx = np.asarray(group_idx, int)
            if np.max(lever[c0 + idx]) < min_lever_m:
                left_out.append(f"{e.name}: {label}")
            else:
                groups.append((ei, gi, label, c0 + idx))
        c0 += e.n_params
    return groups, left_out


def _selected_effects(cands: Sequence[Effect], groups: Sequence[_Group], path: SelectionPath, p0: int
                      ) -> tuple[list[Effect], list[np.ndarray]]:
    """Effect objects of the selected groups, in candidate order, with start values from the linear solution."""
    effects, theta0 = [], []
    x_groups = path.x[p0:]
    offs = np.cumsum([0] + [g[3].size for g in groups])
    for ei, e in enumerate(cands):
        ks = sorted((groups[k][1], k) for k in path.selected if groups[k][0] == ei)  # (group of e, candidate k)
        if ks:
            effects.append(e.restrict([gi for gi, _ in ks]))
            theta0.append(np.concatenate([x_groups[offs[k]:offs[k + 1]] for _, k in ks]))
    return effects, theta0


def _describe_terms(cands: Sequence[Effect], chosen: Sequence[_Group], effects: Sequence[Effect],
                    theta: Sequence[np.ndarray], cv_rms_m: Sequence[float]) -> list[dict]:
    """Plain words and amplitude (rad) per selected group, in selection order, with the held-out RMS after it."""
    texts: dict[tuple[str, str], tuple[str, float]] = {}
    for eff, th in zip(effects, theta):
        for (label, idx), line in zip(eff.groups(), eff.describe(th)):
            texts[(eff.name, label)] = (line, float(np.sqrt(np.sum(np.asarray(th)[idx] ** 2))))
    terms = []
    for step, (ei, _gi, label, _) in enumerate(chosen, 1):
        line, amp = texts.get((cands[ei].name, label), (label, float("nan")))
        terms.append({"effect": cands[ei].name, "group": label, "amplitude_rad": amp, "text": line,
                      "cv_rms_m": cv_rms_m[step]})
    return terms


@limit_threads
def select_terms(fit: IdentificationResult, data: MeasurementSet, options: SelectionOptions | None = None, *,
                 candidates: Sequence[Effect] | None = None, **overrides: Any) -> SelectionResult:
    """Choose, by K-fold held-out error, which transferable terms a fitted model lacks, and refit them.

    See the module docstring for the method. The candidate groups are those of ``candidates``
    (each effect's :meth:`~pin_kpi_oed.effects.library.Effect.groups`; default
    :func:`transfer_candidates` with ``max_order``).

    Args:
        fit: the fitted model to extend (:func:`~pin_kpi_oed.identification.identify.identify` on
            ``data``; one station or several).
        data: the training measurements of ``fit``.
        options: :class:`SelectionOptions` (default: the defaults): max_order, folds, seed,
            min_rel_gain, max_terms, ridge, prior_rad, refit, min_lever_m, max_amplitude_rad
            (default each candidate effect's ``plausible_max``, 2 mrad for the transmission error and
            link bending: over a narrow angle range neighbouring high orders are nearly collinear and
            can "fit" with large cancelling amplitudes that hold nowhere else), show_progress.
        candidates: candidate effects (their groups are the candidates).
        **overrides: :class:`SelectionOptions` fields given by name (``max_order=40``, ``seed=0``, ...).

    Returns:
        The :class:`SelectionResult`.

    Raises:
        InputError: ``data`` missing for an identification result, bad folds, an unknown option name.
    """
    t0 = time.perf_counter()
    opts = SelectionOptions.resolve(options, overrides)
    if not isinstance(fit, IdentificationResult) or data is None:
        raise InputError("select_terms: give an identification result and its training data")
    cands = list(candidates) if candidates is not None else transfer_candidates(fit.model.robot, opts.max_order)
    b, A, C, sig, lever = _linear_system(fit, data, cands)
    fold_m, folds = _fold_of_measurements(opts.folds, opts.seed, fit, data)
    groups, left_out = _visible_groups(cands, lever, opts.min_lever_m)
    gmax = [cands[g[0]].plausible_max if opts.max_amplitude_rad is None else opts.max_amplitude_rad for g in groups]
    path = forward_select(b, A, [C[:, g[3]] for g in groups], np.repeat(fold_m, 3), opts, row_sigma=sig,
                          group_max=gmax)
    chosen = [groups[g] for g in path.selected]
    effects, theta = _selected_effects(cands, groups, path, A.shape[1])
    final = None
    if opts.refit and effects:
        final = refit_with(fit, data, effects, theta, opts.prior_rad)
        theta = final.theta[len(fit.effects):]
    terms = _describe_terms(cands, chosen, effects, theta, path.cv_rms_m)
    msg = (f"{len(chosen)} groups selected; {folds}-fold held-out RMS {path.cv_rms_m[0] * 1e3:.4f} -> "
           f"{path.cv_rms_m[-1] * 1e3:.4f} mm")
    return SelectionResult(success=True, status="selected" if chosen else "none", message=msg,
                           nit=len(chosen), nfev=final.nfev if final is not None else 0,
                           time_s=time.perf_counter() - t0, terms=terms, cv_rms_m=path.cv_rms_m, effects=effects,
                           theta=[np.asarray(t, float) for t in theta], fit=final, n_candidates=len(groups),
                           left_out=left_out, folds=folds, seed=opts.seed, max_terms=opts.max_terms,
                           min_rel_gain=opts.min_rel_gain, ridge=opts.ridge, prior_rad=opts.prior_rad,
                           min_lever_m=opts.min_lever_m, stop=path.stop)


def refit_with(fit: IdentificationResult, data: MeasurementSet, effects: Sequence[Effect],
               theta0: Sequence[np.ndarray] | None = None, prior_rad: float | None = None,
               **options: Any) -> IdentificationResult:
    """Identify ``fit``'s model again on ``data`` with ``effects`` added to its own (robot shared by the stations).

    Starts from the fit's working model (nominal geometry, every tracker pose registered
    afresh), its effects' θ and ``theta0`` for the new ones, with the same weights and
    reflector-per-station choice; ``prior_rad`` is identify's ``effect_prior_rad`` (on every rad-valued effect).

    Args:
        fit: the fit to extend; data: its training data; effects: effects to add; theta0: their
            start values (default zeros); prior_rad: σ (rad) of the Gaussian prior, None = none.
        **options: further :class:`~pin_kpi_oed.identification.identify.IdentifyOptions` fields.

    Returns:
        The new :class:`~pin_kpi_oed.identification.identify.IdentificationResult` (effects: the
        fit's, then ``effects``).
    """
    th0 = [np.asarray(t, float) for t in fit.theta] + (
        [np.zeros(e.n_params) for e in effects] if theta0 is None else [np.asarray(t, float) for t in theta0])
    kw: dict[str, Any] = {"weights": "data" if fit.sigma_source == "data" else "noise",
          "reflector_per_station": fit.reflector_per_station, "held_effects": fit.held, "theta0": th0,
          "effect_prior_rad": prior_rad, "use_orientation": fit.residuals_rad is not None,
          "raise_on_failure": False, "discrepancy": "none", "on_poor_fit": "ignore", "loss": "linear"}
    if len(fit.stations) == 1 and data.station is None:
        kw["station"] = fit.stations[0]
    kw.update(options)
    return identify(fit.model, data, effects=list(fit.effects) + list(effects), **kw)
