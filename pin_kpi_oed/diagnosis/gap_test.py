r"""The statistics of the diagnosis: the χ² gap test, nested-model tests of an added effect, rows far off.

Gap test: T = Σ_i Σ_axes r_ia² / (σ_ia² (1 + v_ia)) ~ χ²(3 n) under "the model is right and σ is
the noise"; nested models: F-test and ΔBIC on training, one-sided t-test of the per-measurement
held-out improvement (see :mod:`pin_kpi_oed.diagnosis.diagnose`).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats as _st

from pin_kpi_oed.diagnosis.engine import Engine, Fit, Plan, Scored
from pin_kpi_oed.diagnosis.report import EffectResult

__all__ = ["MISMATCH_FACTOR", "heldout_stats", "chi2_gap_test", "compare_nested", "screen_mismatch"]

#: Held-out residuals beyond this factor × max(training RMS, noise floor) are "far beyond any effect".
MISMATCH_FACTOR = 20.0


def heldout_stats(R: np.ndarray) -> dict:
    """Mean / RMS / max / median of the 3-D error norms of residuals R (n, 3), m."""
    e = np.linalg.norm(np.asarray(R, float), axis=1)
    if e.size == 0:
        return {"n": 0, "mean_m": None, "rms_m": None, "max_m": None, "median_m": None}
    return {"n": int(e.size), "mean_m": float(e.mean()), "rms_m": float(np.sqrt(np.mean(e ** 2))),
            "max_m": float(e.max()), "median_m": float(np.median(e))}


def chi2_gap_test(sc: Scored, alpha: float) -> dict:
    """The χ² gap test of a scored model's held-out residuals at level ``alpha``.

    Returns:
        ``chi2``, ``dof``, ``chi2_per_dof``, ``p_value``, ``gap_detected``, ``rms_m`` and ``noise_floor_m`` (m),
        ``ratio_rms_to_floor`` (no held-out rows: NaN statistics, no gap).
    """
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


def compare_nested(ref: Scored, new: Scored, name: str, n_tests: int, alpha: float, floor: float) -> EffectResult:
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


def screen_mismatch(eng: Engine, geo_fit: Fit, geo: Scored, plan: Plan, notes: list[str]
                     ) -> tuple[Scored, dict, bool, np.ndarray]:
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
                                                "first: register_rows N)")
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
