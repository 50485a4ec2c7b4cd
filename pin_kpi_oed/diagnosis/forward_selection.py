"""Sparse forward selection of column groups by K-fold held-out error.

Columns of the always-fitted part A and of every candidate group are scaled to unit norm (X̃ = X D⁻¹); the Gram
sums of the training and held-out rows of every fold are formed once, and each greedy step scores every remaining
group by the exact K-fold held-out sum of squares of the model with it (block updates of the fold Grams, a small
ridge on the scaled columns). The path stops when the relative decrease falls below ``min_rel_gain`` or a cap is
reached; a group whose fold fits need an implausible amplitude (near-collinear terms cancelling) is refused.
Units: the residuals and columns are weighted (units of σ); ``row_sigma`` turns the held-out RMS back into m.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any
from collections.abc import Sequence

import numpy as np
import scipy.linalg as sla

from pin_kpi_oed.effects.periodic import DEFAULT_MAX_ORDER
from pin_kpi_oed.identification.identify import resolve_options
from pin_kpi_oed.progress import progress

__all__ = ["MIN_LEVER_M", "SelectionOptions", "SelectionPath", "forward_select"]

#: Candidate groups moving the reflector less than this per rad of their terms (RMS, m/rad) are left out.
MIN_LEVER_M = 1e-3


@dataclass
class SelectionOptions:
    """Knobs of :func:`select_terms` and :func:`forward_select` (SI units).

    Attributes:
        max_order: highest Fourier order of the default candidates (cycles per revolution).
        folds: number of cross-validation folds (by measurement), or the fold of every measurement
            ((m,) int array, 0 … K−1).
        seed: seed of the fold permutation.
        min_rel_gain: stop when the held-out SSE falls by less than this share.
        max_terms: cap on the number of selected groups.
        ridge: ridge on the unit-scaled columns of the selection.
        prior_rad: σ (rad) of the Gaussian prior of the refit (``effect_prior_rad`` of identify;
            None: plain least squares).
        refit: refit the selected terms nonlinearly with the geometry and the set-ups (identify).
        min_lever_m: leave out groups moving the reflector less than this per rad (RMS, m/rad).
        max_amplitude_rad: refuse a step whose fold fits need a group amplitude above this (rad);
            default each candidate effect's ``plausible_max``.
        show_progress: False: no progress bar (None: a bar on a terminal).
    """

    max_order: int = DEFAULT_MAX_ORDER
    folds: int | np.ndarray = 5
    seed: int = 0
    min_rel_gain: float = 5e-3
    max_terms: int = 60
    ridge: float = 1e-8
    prior_rad: float | None = None
    refit: bool = True
    min_lever_m: float = MIN_LEVER_M
    max_amplitude_rad: float | None = None
    show_progress: bool | None = None

    @classmethod
    def resolve(cls, options: SelectionOptions | None, overrides: dict) -> SelectionOptions:
        """``options`` (or the defaults) with the keyword ``overrides`` applied (``resolve_options``).

        Raises:
            InputError: an unknown option name.
        """
        return resolve_options(cls, options, overrides, "select_terms")


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


class _HeldColumns:
    """A fold's held-out rows at the columns S of its last fit (:func:`_cv_exact`): the first |S| columns of a
    buffer are X̃[rows][:, S]. Along the greedy path S only grows by appending a group, so only the new columns are
    gathered; any other S is gathered whole. The product with the buffer's first |S| columns is the one with the
    gathered block (the same numbers)."""

    def __init__(self, rows: int, capacity: int = 64) -> None:
        self.buf = np.empty((rows, capacity))
        self.S = np.zeros(0, int)

    def at(self, Xk: np.ndarray, S: np.ndarray) -> np.ndarray:
        """X̃[rows][:, S] (a view of the buffer) for this fold's held-out block ``Xk``."""
        have = self.S.size
        if have > S.size or not np.array_equal(self.S, S[:have]):
            have = 0
        if S.size > self.buf.shape[1]:
            grown = np.empty((Xk.shape[0], max(2 * self.buf.shape[1], S.size)))
            grown[:, :have] = self.buf[:, :have]
            self.buf = grown
        self.buf[:, have:S.size] = Xk.take(S[have:], axis=1)
        self.S = np.array(S, int)
        return self.buf[:, :S.size]


@dataclass
class _FoldGrams:
    """Unit-scaled columns X̃ = X D⁻¹ of [A, groups] and their Gram sums per fold (training / held-out rows).

    The held-out rows of each fold are kept as one contiguous block (``Xte``, ``bte``, ``sigte``): a fold's columns S
    are then gathered from its block (:func:`_cv_exact`) instead of from rows scattered over all of X̃, the same
    numbers at about a third of the cost."""

    b: np.ndarray
    Xte: list[np.ndarray]
    bte: list[np.ndarray]
    sigte: list[np.ndarray]
    n_cols: int
    sc: np.ndarray
    cols: list[np.ndarray]
    by_size: dict[int, list[int]]
    G: np.ndarray
    h: np.ndarray
    te_rows: list[np.ndarray]
    Gte: list[np.ndarray]
    hte: list[np.ndarray]
    bbte: list[float]
    Gtr: list[np.ndarray]
    htr: list[np.ndarray]
    n_meas: float
    ridge: float
    held: list[_HeldColumns]

    @property
    def K(self) -> int:
        return len(self.te_rows)


def _fold_grams(b: np.ndarray, A: np.ndarray, groups: Sequence[np.ndarray], fold: np.ndarray, ridge: float,
                row_sigma: np.ndarray | None, rows_per_measurement: int) -> _FoldGrams:
    """Scale the columns to unit norm and sum G = X̃ᵀX̃, h = X̃ᵀb over every fold's held-out and training rows."""
    b = np.asarray(b, float)
    n = b.size
    X = np.hstack([A] + list(groups))
    sc = np.linalg.norm(X, axis=0)
    sc[sc == 0] = 1.0
    X = X / sc
    cols: list[np.ndarray] = []
    c0 = int(A.shape[1])
    for g in groups:
        cols.append(np.arange(c0, c0 + g.shape[1]))
        c0 += g.shape[1]
    by_size: dict[int, list[int]] = {}
    for gi, c in enumerate(cols):
        by_size.setdefault(c.size, []).append(gi)
    K = int(fold.max()) + 1
    G = X.T @ X
    h = X.T @ b
    te_rows = [np.flatnonzero(fold == k) for k in range(K)]
    Xte = [X[r] for r in te_rows]                     # each fold's held-out rows, one contiguous block
    Gte = [Xk.T @ X[r] for Xk, r in zip(Xte, te_rows)]  # two operands (gemm): the same sums as X[r].T @ X[r]
    del X
    hte = [Xk.T @ b[r] for Xk, r in zip(Xte, te_rows)]
    sig = np.ones(n) if row_sigma is None else np.asarray(row_sigma, float)
    return _FoldGrams(b=b, Xte=Xte, bte=[b[r] for r in te_rows], sigte=[sig[r] for r in te_rows],
                      n_cols=int(sc.size), sc=sc, cols=cols, by_size=by_size, G=G, h=h, te_rows=te_rows, Gte=Gte,
                      hte=hte, bbte=[float(b[r] @ b[r]) for r in te_rows], Gtr=[G - Gk for Gk in Gte],
                      htr=[h - hk for hk in hte], n_meas=n / rows_per_measurement, ridge=ridge,
                      held=[_HeldColumns(len(r)) for r in te_rows])


def _cv_exact(fg: _FoldGrams, S: np.ndarray) -> tuple[float, float]:
    """K-fold held-out weighted SSE of the columns S and the 3-D RMS per measurement (m), by explicit fold fits."""
    sse, sse_m = 0.0, 0.0
    for k in range(fg.K):
        M = _block(fg.Gtr[k], S, S) + fg.ridge * np.eye(S.size)
        x = sla.solve(M, fg.htr[k][S], assume_a="pos", check_finite=False)
        r = fg.bte[k] - fg.held[k].at(fg.Xte[k], S) @ x   # as X̃[np.ix_(rows, S)] @ x: the same product
        sse += float(r @ r)
        sse_m += float(np.sum((r * fg.sigte[k]) ** 2))
    return sse, float(np.sqrt(sse_m / fg.n_meas))


def _block(G: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """G[np.ix_(rows, cols)], C-contiguous as that is, by rows then columns (a fifth of its time on the Grams here)."""
    return np.ascontiguousarray(G[rows][:, cols])


def _score_block(fg: _FoldGrams, k: int, S: np.ndarray, cf: Any, xS: np.ndarray, C: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Held-out cost in fold k of S ∪ g for the equally sized groups g of C (ng, s) by the Schur complement.

    Returns:
        (cost (ng,), x_g (ng, s), change of x_S (ng, |S|)), in unit-scaled coordinates.
    """
    Gtr, htr, Gte, hte = fg.Gtr[k], fg.htr[k], fg.Gte[k], fg.hte[k]
    ng, s = C.shape
    p = S.size
    Bt = _block(Gtr, S, C.ravel())  # (p, ng*s)
    Z = sla.cho_solve(cf, Bt, check_finite=False).reshape(p, ng, s)
    Bt = Bt.reshape(p, ng, s)
    Zg = Z.transpose(1, 0, 2)  # (ng, p, s)
    Sg = Gtr[C[:, :, None], C[:, None, :]] + fg.ridge * np.eye(s) - np.einsum("pgi,pgj->gij", Bt, Z)
    rhs = htr[C] - np.einsum("pgi,p->gi", Z, htr[S])
    xg = np.linalg.solve(Sg, rhs[..., None])[..., 0]
    dS = -(Zg @ xg[:, :, None])[:, :, 0]  # change of x_S, (ng, p)
    # held-out cost of [xS + dS, xg]
    GteS = Gte[S]
    GteSS = np.ascontiguousarray(GteS[:, S])
    c = fg.bbte[k] - 2.0 * xS @ hte[S] - 2.0 * (dS @ hte[S] + np.sum(xg * hte[C], axis=1))
    c += 2.0 * (dS @ (GteSS @ xS)) + np.sum((dS @ GteSS) * dS, axis=1)
    GteSC = np.ascontiguousarray(GteS[:, C.ravel()]).reshape(p, ng, s)
    T = (GteSC.transpose(1, 0, 2) @ xg[:, :, None])[:, :, 0]  # Gte,Sg x_g of every g, (ng, p)
    c += 2.0 * (T @ xS) + 2.0 * np.sum(dS * T, axis=1)
    c += np.einsum("gi,gij,gj->g", xg, Gte[C[:, :, None], C[:, None, :]], xg)
    c += float(xS @ GteSS @ xS)
    return c, xg, dS


def _stacked_bounds(chosen_pos: list[tuple[np.ndarray, float]]) -> list[tuple[np.ndarray, np.ndarray]]:
    """The selected groups' positions in S and amplitude bounds, stacked by group size: [(positions (k, s), bounds
    (k,))], so that one array expression checks every selected group of a size (:func:`_scores`)."""
    by: dict[int, list[tuple[np.ndarray, float]]] = {}
    for pos, mx in chosen_pos:
        by.setdefault(pos.size, []).append((pos, mx))
    return [(np.array([p for p, _ in v]), np.array([m for _, m in v], float)) for v in by.values()]


def _scores(fg: _FoldGrams, S: np.ndarray, remaining: np.ndarray, gmax: np.ndarray,
            chosen_pos: list[tuple[np.ndarray, float]]) -> np.ndarray:
    """CV(S ∪ g) of every remaining group g (inf: not remaining, or an implausible amplitude in some fold).

    The remaining groups of each size (and their columns) and the selected groups' bounds are gathered once for all
    folds; each selected group's amplitude is the norm over its own s columns, as one group at a time."""
    n_groups = len(fg.cols)
    tot = np.zeros(n_groups)
    bad = np.zeros(n_groups, bool)
    rem = set(remaining.tolist())
    sized = [(gl, np.array([fg.cols[g] for g in gl])) for gl in ([g for g in gs if g in rem]
                                                                    for gs in fg.by_size.values()) if gl]
    bounds = _stacked_bounds(chosen_pos)
    for k in range(fg.K):
        cf = sla.cho_factor(_block(fg.Gtr[k], S, S) + fg.ridge * np.eye(S.size), check_finite=False)
        xS = sla.cho_solve(cf, fg.htr[k][S], check_finite=False)
        for gl, C in sized:  # C: (ng, s)
            c, xg, dS = _score_block(fg, k, S, cf, xS, C)
            tot[gl] += c
            # plausibility: the candidate's and the selected groups' amplitudes in this fold's fit
            over = np.sqrt(np.sum((xg / fg.sc[C]) ** 2, axis=1)) > gmax[gl]
            for P, mx in bounds:  # (k, s), (k,)
                v = (xS[P][None, :, :] + dS[:, P]) / fg.sc[S[P]]
                over |= np.any(np.sqrt(np.sum(v ** 2, axis=2)) > mx, axis=1)
            bad[np.asarray(gl)[over]] = True
    out = np.full(n_groups, np.inf)
    ok = remaining[~bad[remaining]]
    out[ok] = tot[ok]
    return out


def _greedy_path(fg: _FoldGrams, p0: int, gmax: np.ndarray, max_groups: int, min_rel_gain: float, desc: str,
                 show_progress: bool | None) -> tuple[np.ndarray, list[int], list[float], list[float], str]:
    """Add, step by step, the group minimising CV(S ∪ g) until the gain or the cap stops it.

    Returns:
        (final columns S, selected groups, CV SSE path, held-out RMS path (m), stop reason).
    """
    n_groups = len(fg.cols)
    chosen_pos: list[tuple[np.ndarray, float]] = []  # (positions in S, bound) of the selected groups
    S = np.arange(p0)
    sse0, rms0 = _cv_exact(fg, S)
    path_sse, path_rms, selected = [sse0], [rms0], list[int]()
    stop = f"cap of {max_groups} groups reached"
    best = sse0
    with progress(total=max_groups, desc=desc, unit="term", disable=show_progress is False) as bar:
        while len(selected) < max_groups:
            taken = set(selected)
            remaining = np.array([g for g in range(n_groups) if g not in taken], int)
            if remaining.size == 0:
                stop = "every candidate selected"
                break
            sc_ = _scores(fg, S, remaining, gmax, chosen_pos)
            if not np.isfinite(sc_).any():
                stop = "every remaining candidate needs an implausible amplitude"
                break
            g = int(np.argmin(sc_))
            S_new = np.concatenate([S, fg.cols[g]])
            sse, rms = _cv_exact(fg, S_new)
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
    return S, selected, path_sse, path_rms, stop


def forward_select(b: np.ndarray, A: np.ndarray, groups: Sequence[np.ndarray], fold: np.ndarray,
                   options: SelectionOptions | None = None, *, max_groups: int | None = None,
                   row_sigma: np.ndarray | None = None, rows_per_measurement: int = 3,
                   group_max: Sequence[float] | None = None, desc: str = "term selection",
                   **overrides: Any) -> SelectionPath:
    """Greedy forward selection of column groups minimising the K-fold held-out sum of squares (Gram updates).

    Args:
        b: weighted residuals (n,).
        A: weighted columns always in the model (n, p0).
        groups: weighted candidate columns, one (n, s_g) array per group.
        fold: fold index of every row (n,), 0 … K−1.
        options: :class:`SelectionOptions`; used here: ``min_rel_gain`` (stop when the relative
            decrease of the held-out SSE falls below it), ``ridge`` (on the unit-scaled columns),
            ``max_terms`` (cap on the number of groups) and ``show_progress``.
        max_groups: cap on the number of groups (default ``options.max_terms``).
        row_sigma: σ of every row (n,) m, to report the held-out RMS in metres (default 1).
        rows_per_measurement: rows of one measurement (3: x, y, z) for the RMS per measurement.
        group_max: largest plausible amplitude √(Σ x²) of each group's coefficients (unscaled units);
            a candidate whose fold fits need a larger one for itself or for a group already selected
            is refused (near-collinear terms cancelling each other). Default: no bound.
        desc: progress-bar label.
        **overrides: :class:`SelectionOptions` fields by name (``min_rel_gain=``, ``ridge=``, ``show_progress=``).

    Returns:
        The :class:`SelectionPath`.

    Raises:
        InputError: an unknown option name.
    """
    opts = SelectionOptions.resolve(options, overrides)
    cap = opts.max_terms if max_groups is None else int(max_groups)
    fg = _fold_grams(b, A, groups, fold, opts.ridge, row_sigma, rows_per_measurement)
    gmax = np.full(len(groups), np.inf) if group_max is None else np.asarray(group_max, float)
    S, selected, path_sse, path_rms, stop = _greedy_path(fg, A.shape[1], gmax, cap, opts.min_rel_gain, desc,
                                                         opts.show_progress)
    x = np.zeros(fg.n_cols)
    x[S] = sla.solve(fg.G[np.ix_(S, S)] + opts.ridge * np.eye(S.size), fg.h[S], assume_a="pos")
    return SelectionPath(selected, path_sse, path_rms, x / fg.sc, stop)
