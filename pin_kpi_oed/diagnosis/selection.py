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
split into K folds (seeded permutation; the 3 rows of a measurement share a fold). For
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
Another day, the tracker moved: :func:`pin_kpi_oed.identification.transfer.register_setup`
re-fits only the set-up (tracker pose, reflector, and the set-up-specific effects such as
:class:`~pin_kpi_oed.effects.drift.Drift`) on a few rows of the new data with the robot
(geometry and transferable effects) held. :func:`coverage` says which share of the new rows
lies within a tolerance of a training angle, joint by joint (angles wrapped to 2π).

Units: SI (m, rad, s); summaries print mm and µrad.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np
import scipy.linalg as sla

from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.effects.coupled import LinkBending
from pin_kpi_oed.effects.library import Effect
from pin_kpi_oed.effects.periodic import DEFAULT_MAX_ORDER, TransmissionError
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.identification.identify import IdentificationResult, identify
from pin_kpi_oed.identification.problem import ResidualModel
from pin_kpi_oed.progress import progress
from pin_kpi_oed.results import Result
from pin_kpi_oed.threads import limit_threads

__all__ = [
    "SelectionPath", "SelectionResult", "transfer_candidates", "forward_select", "select_terms", "coverage", "covered_rows", "measurement_folds",
]

#: Candidate groups moving the reflector less than this per rad of their terms (RMS, m/rad) are left out.
MIN_LEVER_M = 1e-3


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


def measurement_folds(m: int, k: int, seed: int) -> np.ndarray:
    """Fold of each of m measurements for K-fold cross-validation (seeded permutation), (m,) in 0 … k−1.

    Raises:
        InputError: k < 2 or fewer measurements than folds.
    """
    if k < 2 or m < k:
        raise InputError(f"cross-validation needs 2 <= folds <= measurements, got {k} folds for {m} measurements")
    fold = np.empty(m, int)
    fold[np.random.default_rng(seed).permutation(m)] = np.arange(m) % k
    return fold


# --------------------------------------------------------------------------- the selection engine
@dataclass
class SelectionPath:
    """Outcome of :func:`forward_select`.

    Attributes:
        selected: chosen group indices, in order.
        cv_sse: K-fold held-out weighted sum of squares before the first step and after each.
        cv_rms_m: the same as a 3-D RMS error per measurement (m) from the held-out residuals.
        x: coefficients of the final model on all rows (unscaled; base columns first, then groups).
        stop: why it stopped.
    """

    selected: list[int]
    cv_sse: list[float]
    cv_rms_m: list[float]
    x: np.ndarray
    stop: str


def forward_select(b: np.ndarray, A: np.ndarray, groups: Sequence[np.ndarray], fold: np.ndarray, *,
                   max_groups: int = 60, min_rel_gain: float = 5e-3, ridge: float = 1e-8,
                   row_sigma: np.ndarray | None = None, rows_per_measurement: int = 3,
                   group_max: Sequence[float] | None = None, desc: str = "term selection",
                   show_progress: bool | None = None) -> SelectionPath:
    """Greedy forward selection of column groups minimising the K-fold held-out sum of squares (Gram updates).

    Args:
        b: weighted residuals (n,).
        A: weighted columns always in the model (n, p0).
        groups: weighted candidate columns, one (n, s_g) array per group.
        fold: fold index of every row (n,), 0 … K−1.
        max_groups: cap on the number of groups.
        min_rel_gain: stop when the relative decrease of the held-out SSE falls below it.
        ridge: ridge on the unit-scaled columns.
        row_sigma: σ of every row (n,) m, to report the held-out RMS in metres (default 1).
        rows_per_measurement: rows of one measurement (3: x, y, z) for the RMS per measurement.
        group_max: largest plausible amplitude √(Σ x²) of each group's coefficients (unscaled units);
            a candidate whose fold fits need a larger one for itself or for a group already selected
            is refused (near-collinear terms cancelling each other). Default: no bound.
        desc: progress-bar label; show_progress: False = no bar (None: on a terminal).

    Returns:
        The :class:`SelectionPath`.
    """
    b = np.asarray(b, float)
    n = b.size
    X = np.hstack([A] + list(groups))
    sc = np.linalg.norm(X, axis=0)
    sc[sc == 0] = 1.0
    X = X / sc
    p0 = A.shape[1]
    cols, c0 = [], p0
    for g in groups:
        cols.append(np.arange(c0, c0 + g.shape[1]))
        c0 += g.shape[1]
    K = int(fold.max()) + 1
    G = X.T @ X
    h = X.T @ b
    te_rows = [np.flatnonzero(fold == k) for k in range(K)]
    Gte = [X[r].T @ X[r] for r in te_rows]
    hte = [X[r].T @ b[r] for r in te_rows]
    bbte = [float(b[r] @ b[r]) for r in te_rows]
    Gtr = [G - Gk for Gk in Gte]
    htr = [h - hk for hk in hte]
    sig = np.ones(n) if row_sigma is None else np.asarray(row_sigma, float)
    n_meas = n / rows_per_measurement

    def cv_exact(S: np.ndarray) -> tuple[float, float]:
        sse, sse_m = 0.0, 0.0
        for k in range(K):
            M = Gtr[k][np.ix_(S, S)] + ridge * np.eye(S.size)
            x = sla.solve(M, htr[k][S], assume_a="pos")
            r = b[te_rows[k]] - X[np.ix_(te_rows[k], S)] @ x
            sse += float(r @ r)
            sse_m += float(np.sum((r * sig[te_rows[k]]) ** 2))
        return sse, float(np.sqrt(sse_m / n_meas))

    gmax = np.full(len(groups), np.inf) if group_max is None else np.asarray(group_max, float)
    chosen_pos: list[tuple[np.ndarray, float]] = []  # (positions in S, bound) of the selected groups

    by_size: dict[int, list[int]] = {}
    for g, c in enumerate(cols):
        by_size.setdefault(c.size, []).append(g)

    def scores(S: np.ndarray, remaining: np.ndarray) -> np.ndarray:
        tot = np.zeros(len(groups))
        bad = np.zeros(len(groups), bool)
        rem = set(remaining.tolist())
        for k in range(K):
            cf = sla.cho_factor(Gtr[k][np.ix_(S, S)] + ridge * np.eye(S.size))
            xS = sla.cho_solve(cf, htr[k][S])
            GteSS = Gte[k][np.ix_(S, S)]
            base_c = bbte[k] - 2.0 * xS @ hte[k][S]
            for s, gl in by_size.items():
                gl = [g for g in gl if g in rem]
                if not gl:
                    continue
                C = np.array([cols[g] for g in gl])  # (ng, s)
                ng, p = len(gl), S.size
                Bt = Gtr[k][np.ix_(S, C.ravel())]  # (p, ng*s)
                Z = sla.cho_solve(cf, Bt).reshape(p, ng, s)
                Bt = Bt.reshape(p, ng, s)
                Sg = Gtr[k][C[:, :, None], C[:, None, :]] + ridge * np.eye(s) - np.einsum("pgi,pgj->gij", Bt, Z)
                rhs = htr[k][C] - np.einsum("pgi,p->gi", Z, htr[k][S])
                xg = np.linalg.solve(Sg, rhs[..., None])[..., 0]
                dS = -np.einsum("pgi,gi->gp", Z, xg)  # change of x_S, (ng, p)
                # held-out cost of [xS + dS, xg]
                c = base_c - 2.0 * (dS @ hte[k][S] + np.sum(xg * hte[k][C], axis=1))
                c += 2.0 * (dS @ (GteSS @ xS)) + np.einsum("gp,pq,gq->g", dS, GteSS, dS, optimize=True)
                GteSC = Gte[k][np.ix_(S, C.ravel())].reshape(p, ng, s)
                c += 2.0 * np.einsum("p,pgi,gi->g", xS, GteSC, xg) + 2.0 * np.einsum("gp,pgi,gi->g", dS, GteSC, xg)
                c += np.einsum("gi,gij,gj->g", xg, Gte[k][C[:, :, None], C[:, None, :]], xg)
                c += float(xS @ GteSS @ xS)
                tot[gl] += c
                # plausibility: the candidate's and the selected groups' amplitudes in this fold's fit
                over = np.sqrt(np.sum((xg / sc[C]) ** 2, axis=1)) > gmax[gl]
                for pos, mx in chosen_pos:
                    v = (xS[pos][None, :] + dS[:, pos]) / sc[S[pos]]
                    over |= np.sqrt(np.sum(v ** 2, axis=1)) > mx
                bad[np.asarray(gl)[over]] = True
        out = np.full(len(groups), np.inf)
        ok = remaining[~bad[remaining]]
        out[ok] = tot[ok]
        return out

    S = np.arange(p0)
    sse0, rms0 = cv_exact(S)
    path_sse, path_rms, selected = [sse0], [rms0], []
    stop = f"cap of {max_groups} groups reached"
    best = sse0
    with progress(total=max_groups, desc=desc, unit="term", disable=show_progress is False) as bar:
        while len(selected) < max_groups:
            remaining = np.array([g for g in range(len(groups)) if g not in set(selected)], int)
            if remaining.size == 0:
                stop = "every candidate selected"
                break
            sc_ = scores(S, remaining)
            if not np.isfinite(sc_).any():
                stop = "every remaining candidate needs an implausible amplitude"
                break
            g = int(np.argmin(sc_))
            S_new = np.concatenate([S, cols[g]])
            sse, rms = cv_exact(S_new)
            if not (best - sse) / best >= min_rel_gain:
                stop = (f"relative gain {(best - sse) / best:.2%} of the best next group "
                        f"below {min_rel_gain:.2%}")
                break
            selected.append(g)
            if np.isfinite(gmax[g]):
                chosen_pos.append((np.arange(S.size, S_new.size), float(gmax[g])))
            S = S_new
            best = sse
            path_sse.append(sse)
            path_rms.append(rms)
            bar.update()
            bar.set_postfix_str(f"held-out RMS {rms * 1e3:.4f} mm")
    x = np.zeros(X.shape[1])
    x[S] = sla.solve(G[np.ix_(S, S)] + ridge * np.eye(S.size), h[S], assume_a="pos")
    return SelectionPath(selected, path_sse, path_rms, x / sc, stop)


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


@limit_threads
def select_terms(fit: IdentificationResult, data: MeasurementSet, *,
                 candidates: Sequence[Effect] | None = None, max_order: int = DEFAULT_MAX_ORDER, folds: int = 5,
                 seed: int = 0, min_rel_gain: float = 5e-3, max_terms: int = 60, ridge: float = 1e-8,
                 prior_rad: float | None = None, refit: bool = True, min_lever_m: float = MIN_LEVER_M,
                 max_amplitude_rad: float | None = None, show_progress: bool | None = None) -> SelectionResult:
    """Choose, by K-fold held-out error, which transferable terms a fitted model lacks, and refit them.

    See the module docstring for the method. The candidate groups are those of ``candidates``
    (each effect's :meth:`~pin_kpi_oed.effects.library.Effect.groups`; default
    :func:`transfer_candidates` with ``max_order``).

    Args:
        fit: the fitted model to extend (:func:`~pin_kpi_oed.identification.identify.identify` on
            ``data``; one station or several).
        data: the training measurements of ``fit``.
        candidates: candidate effects (their groups are the candidates).
        max_order: highest Fourier order of the default candidates (cycles per revolution).
        folds: number of cross-validation folds (by measurement); seed: their seed.
        min_rel_gain: stop when the held-out SSE falls by less than this share.
        max_terms: cap on the number of selected groups.
        ridge: ridge on the unit-scaled columns of the selection.
        prior_rad: σ (rad) of the Gaussian prior of the refit (``effect_prior_rad`` of identify;
            None: plain least squares).
        refit: refit the selected terms nonlinearly with the geometry and the set-ups (identify).
        min_lever_m: leave out groups moving the reflector less than this per rad (RMS, m/rad).
        max_amplitude_rad: refuse a step whose fold fits need a group amplitude above this (rad);
            default each candidate effect's ``plausible_max`` (2 mrad for the transmission error and
            link bending). Over a narrow angle range neighbouring high orders are nearly collinear and
            can "fit" with large cancelling amplitudes that hold nowhere else.
        show_progress: False: no progress bar (None: a bar on a terminal).

    Returns:
        The :class:`SelectionResult`.

    Raises:
        InputError: ``data`` missing for an identification result, bad folds.
    """
    t0 = time.perf_counter()
    if not isinstance(fit, IdentificationResult) or data is None:
        raise InputError("select_terms: give an identification result and its training data")
    robot = fit.model.robot
    cands = list(candidates) if candidates is not None else transfer_candidates(robot, max_order)
    b, A, C, sig, lever = _linear_system(fit, data, cands)
    m = len(data)
    if isinstance(folds, np.ndarray):
        fold_m = np.asarray(folds, int)
        folds = int(fold_m.max()) + 1
    else:
        fold_m = measurement_folds(m, folds, seed)
    fold = np.repeat(fold_m, 3)
    # candidate groups: (effect index, group index, label, columns)
    groups, left_out, c0 = [], [], 0
    for ei, e in enumerate(cands):
        for gi, (label, idx) in enumerate(e.groups()):
            idx = np.asarray(idx, int)
            if np.max(lever[c0 + idx]) < min_lever_m:
                left_out.append(f"{e.name}: {label}")
            else:
                groups.append((ei, gi, label, c0 + idx))
        c0 += e.n_params
    gmax = [cands[g[0]].plausible_max if max_amplitude_rad is None else max_amplitude_rad for g in groups]
    path = forward_select(b, A, [C[:, g[3]] for g in groups], fold, max_groups=max_terms,
                          min_rel_gain=min_rel_gain, ridge=ridge, row_sigma=sig, group_max=gmax,
                          show_progress=show_progress)
    chosen = [groups[g] for g in path.selected]
    # effect objects of the selected groups, in candidate order; start values from the linear solution
    effects, theta0 = [], []
    x_groups = path.x[A.shape[1]:]
    offs = np.cumsum([0] + [g[3].size for g in groups])
    for ei, e in enumerate(cands):
        ks = sorted((groups[k][1], k) for k in path.selected if groups[k][0] == ei)  # (group of e, candidate k)
        if ks:
            effects.append(e.restrict([gi for gi, _ in ks]))
            theta0.append(np.concatenate([x_groups[offs[k]:offs[k + 1]] for _, k in ks]))
    final = None
    theta = theta0
    if refit and effects:
        final = refit_with(fit, data, effects, theta0, prior_rad)
        theta = final.theta[len(fit.effects):]
    # plain words per selected group, in selection order
    texts: dict[tuple[int, int], tuple[str, float]] = {}
    for eff, th in zip(effects, theta):
        for (label, idx), line in zip(eff.groups(), eff.describe(th)):
            texts[(eff.name, label)] = (line, float(np.sqrt(np.sum(np.asarray(th)[idx] ** 2))))
    terms = []
    for step, (ei, gi, label, _) in enumerate(chosen, 1):
        line, amp = texts.get((cands[ei].name, label), (label, float("nan")))
        terms.append({"effect": cands[ei].name, "group": label, "amplitude_rad": amp, "text": line,
                      "cv_rms_m": path.cv_rms_m[step]})
    msg = (f"{len(chosen)} groups selected; {folds}-fold held-out RMS {path.cv_rms_m[0] * 1e3:.4f} -> "
           f"{path.cv_rms_m[-1] * 1e3:.4f} mm")
    return SelectionResult(success=True, status="selected" if chosen else "none", message=msg,
                           nit=len(chosen), nfev=final.nfev if final is not None else 0,
                           time_s=time.perf_counter() - t0, terms=terms, cv_rms_m=path.cv_rms_m, effects=effects,
                           theta=[np.asarray(t, float) for t in theta], fit=final, n_candidates=len(groups),
                           left_out=left_out, folds=folds, seed=seed, max_terms=max_terms, min_rel_gain=min_rel_gain,
                           ridge=ridge, prior_rad=prior_rad, min_lever_m=min_lever_m, stop=path.stop)


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
    kw = {"weights": "data" if fit.sigma_source == "data" else "noise",
          "reflector_per_station": fit.reflector_per_station, "held_effects": fit.held, "theta0": th0,
          "effect_prior_rad": prior_rad, "use_orientation": fit.residuals_rad is not None,
          "raise_on_failure": False}
    if len(fit.stations) == 1 and data.station is None:
        kw["station"] = fit.stations[0]
    kw.update(options)
    return identify(fit.model, data, effects=list(fit.effects) + list(effects), **kw)


# --------------------------------------------------------------------------- coverage
def coverage(source_q: np.ndarray, target_q: np.ndarray, tol_rad: float = 0.05) -> tuple[np.ndarray, float]:
    """Share of target rows whose joint angle lies within ``tol_rad`` of a source angle, per joint (wrapped mod 2π).

    Args:
        source_q: training configurations (m_s, n) rad.
        target_q: validation configurations (m_t, n) rad.
        tol_rad: tolerance (rad).

    Returns:
        (fraction per joint (n,), fraction of target rows covered on every joint at once).
    """
    covered = covered_rows(source_q, target_q, tol_rad)
    return covered.mean(axis=0), float(np.all(covered, axis=1).mean())


def covered_rows(source_q: np.ndarray, target_q: np.ndarray, tol_rad: float = 0.05) -> np.ndarray:
    """Which target angles lie within ``tol_rad`` of a source angle of the same joint (wrapped mod 2π).

    Args:
        source_q: training configurations (m_s, n) rad.
        target_q: validation configurations (m_t, n) rad.
        tol_rad: tolerance (rad).

    Returns:
        (m_t, n) bool: covered per row and joint.
    """
    S = np.mod(np.asarray(source_q, float) + np.pi, 2 * np.pi) - np.pi
    T = np.mod(np.asarray(target_q, float) + np.pi, 2 * np.pi) - np.pi
    covered = np.zeros(T.shape, bool)
    for j in range(T.shape[1]):
        s = np.sort(S[:, j])
        s_ext = np.concatenate([s - 2 * np.pi, s, s + 2 * np.pi])
        i = np.clip(np.searchsorted(s_ext, T[:, j]), 1, s_ext.size - 1)
        d = np.minimum(np.abs(T[:, j] - s_ext[i - 1]), np.abs(T[:, j] - s_ext[i]))
        covered[:, j] = d <= tol_rad
    return covered
