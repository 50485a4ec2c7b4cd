"""Sim-to-real gap diagnosis on real data: the IPA UR10 (Series B and C, Leica tracker + T-Mac).

For each series: calibrate on a random half, validate on the other (disjoint) half, run the
diagnosis with the library's candidate effects, then once more with an exploratory
joint-angle error table (:class:`pin_kpi_oed.effects.library.JointAngleTable`), and collect the
evidence on what the remaining error is:

* repeatability: Series B measures many configurations twice a few rows apart; their
  difference shows what is noise (tracker + robot repeatability) and what is systematic;
* a periodogram of the training residuals against each joint angle (joint-angle error
  sin/cos(h·q_j) of order h, after the geometry): which joint, which period;
* the diagnosis' "where" associations (joint angles, measurement order = time).

Finally it calibrates on Series C and validates on Series D, which was measured with the
tracker elsewhere: compared in C's tracker frame the diagnosis says the validation data do not
match; with the set-up re-registered on 60 seeded rows of D (robot held, ``register_rows=60``)
it diagnoses the transfer gap on the other rows.

Noise model (the files' std columns are the scatter of the averaged reading, not the
accuracy): Leica AT960 + T-Mac MPE ±(15 µm + 6 µm/m), σ = MPE/2 = 7.5 µm + 3 µm/m per axis.

Run: python examples/diagnose_ur10.py   (about 3–5 min; PIN_KPI_OED_QUICK=1: the same steps on Series C alone,
240 of its rows, table knots 0.2 rad apart, every 10th row of C and 5th of D, periodogram orders 1–10, one
residual-vs-regressor figure)
Writes ur10_diagnosis.json and ur10_figures/ into the current folder.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np

from pin_kpi_oed.diagnosis.diagnose import diagnose
from pin_kpi_oed.viz.diagnosis_plots import diagnosis_figures
from pin_kpi_oed.effects.library import EFFECT_NAMES, JointAngleTable, position_dq
from pin_kpi_oed.identification.identify import ResidualModel, identify
from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.data.atomic import atomic_write_json
from pin_kpi_oed.data.ipa import import_ipa
from pin_kpi_oed.model.noise import NoiseModel
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.model.robot import load_robot

#: --quick (or PIN_KPI_OED_QUICK=1): smaller sizes, the same steps (the tests' run)
QUICK = os.environ.get("PIN_KPI_OED_QUICK") == "1" or "--quick" in sys.argv[1:]
_HERE = Path(__file__).resolve()
DATA = next((p / "shared" / "data" / "ipa_ur10" for p in (_HERE.parents[2], _HERE.parents[3])
             if (p / "shared" / "data" / "ipa_ur10").is_dir()), _HERE.parents[2] / "shared" / "data" / "ipa_ur10")
REFLECTOR = np.array([0.0, 0.0, 0.109])  # T-Mac ~109 mm in front of the flange (Trafo_TM_F_init.txt)
NOISE = NoiseModel(range_a_m=7.5e-6, range_b=3e-6)
TABLE_STEP = 0.2 if QUICK else 0.05  # rad between knots of the joint-angle table
EXPLORATORY_MEAN_M = {"Series_B": 0.33e-3, "Series_C": 0.43e-3}  # ABOUT.md: geometry + gravity + harmonics


def load(series: str) -> MeasurementSet:
    """Position-only measurements (m, rad) with temperature; the std columns are dropped."""
    ms = import_ipa(DATA / series)
    return MeasurementSet(ms.joint_names, ms.q, ms.position_m, temperature_c=ms.temperature_c, source=ms.source)


def repeatability(ms: MeasurementSet) -> dict | None:
    """Pairs of (nearly) identical configurations (< 1 mrad): median / p90 |Δy| and the implied σ per axis."""
    from scipy.spatial import cKDTree

    pairs = cKDTree(ms.q).query_pairs(1e-3, output_type="ndarray")
    if len(pairs) == 0:
        return None
    d = ms.position_m[pairs[:, 0]] - ms.position_m[pairs[:, 1]]
    n = np.linalg.norm(d, axis=1)
    keep = n < 5 * np.median(n)  # a few pairs straddle a long pause (drift); the bulk is a few rows apart
    return {"pairs": int(len(pairs)), "median_rows_apart": float(np.median(np.abs(pairs[:, 0] - pairs[:, 1]))),
            "median_m": float(np.median(n)), "p90_m": float(np.percentile(n, 90)),
            "sigma_per_axis_m": float(np.sqrt(np.mean(d[keep] ** 2) / 2))}


def periodogram(model: TrackerModel, train: MeasurementSet, orders=range(1, 41)) -> list[dict]:
    """Share of the training residual (after geometry) explained by a joint-angle error of order h, per joint."""
    res = identify(model, train, weights="noise", use_orientation=False)
    S = np.full((len(train), 3), 1e-5)
    rm = ResidualModel(res.model, train, res.identifiability.base, [], sigma=S, p_ref=res.p)
    A = rm.jacobian_full(res.values)[:, :3, :].reshape(-1, len(res.values))
    U, s, _ = np.linalg.svd(A / np.linalg.norm(A, axis=0), full_matrices=False)
    U = U[:, s > 1e-9 * s[0]]
    r = res.residuals_m.ravel() / 1e-5
    Ydq = position_dq(res.model, res.p, train.q) / 1e-5
    out = []
    for j, name in enumerate(model.robot.joint_names):
        best = (0.0, 0, 0.0)
        for h in orders:
            q = train.q[:, j]
            C = np.stack([(Ydq[:, :, j] * np.sin(h * q)[:, None]).ravel(),
                          (Ydq[:, :, j] * np.cos(h * q)[:, None]).ravel()], 1)
            C = C - U @ (U.T @ C)
            x = np.linalg.lstsq(C, r, rcond=None)[0]
            share = 1 - np.sum((r - C @ x) ** 2) / (r @ r)
            if share > best[0]:
                best = (float(share), int(h), float(np.hypot(*x)))
        out.append({"joint": name, "order": best[1], "period_rad": 2 * np.pi / best[1] if best[1] else None,
                    "share_of_residual": best[0], "amplitude_rad": best[2]})
    return out


def run_series(rb, series: str, figures: Path) -> dict:
    ms = load(series)
    if QUICK:
        ms = ms.subset(np.sort(np.random.default_rng(0).permutation(len(ms))[:240]))
    train, test = ms.split(0.5, seed=0)
    model = TrackerModel(rb, reflector_m=REFLECTOR, noise=NOISE)
    print(f"\n===== {series}: {len(train)} training / {len(test)} held-out measurements (random disjoint halves)")
    rep = diagnose(model, train, test, weights="noise")
    rep.figures = diagnosis_figures(rep, figures / series, n_top=1 if QUICK else 4)
    print(rep.summary())
    table = JointAngleTable.from_data(rb, train, step_rad=TABLE_STEP, joints=rb.joint_names[:5])
    rep_t = diagnose(model, train, test, weights="noise", effects=list(EFFECT_NAMES) + [table])
    t = rep_t.effect("joint_angle_table")
    print(f"-- with the exploratory joint-angle table ({TABLE_STEP} rad knots, {t.n_params} parameters): "
          f"held-out RMS {t.heldout_rms_after_m * 1e6:.1f} µm, mean {t.heldout_mean_after_m * 1e6:.1f} µm, "
          f"max {t.heldout_max_after_m * 1e6:.1f} µm; gap closed {100 * t.gap_closed_fraction:.0f} %; "
          f"significant: {t.significant}; selection: {', '.join(rep_t.selected_effects) or 'none'}")
    print(f"   with the selection: mean {rep_t.heldout_after['mean_m'] * 1e3:.4f} mm, RMS "
          f"{rep_t.heldout_after['rms_m'] * 1e3:.4f} mm (exploratory fit with geometry + gravity + harmonics: "
          f"{EXPLORATORY_MEAN_M[series] * 1e3:.2f} mm mean)")
    rpt = repeatability(ms)
    if rpt:
        print(f"-- repeatability: {rpt['pairs']} pairs of identical configurations (median "
              f"{rpt['median_rows_apart']:.0f} rows apart) differ by {rpt['median_m'] * 1e6:.1f} µm median, {rpt['p90_m'] * 1e6:.1f} µm p90 "
              f"(σ ≈ {rpt['sigma_per_axis_m'] * 1e6:.1f} µm per axis): the 0.4 mm residual is systematic, not noise")
    per = periodogram(model, train, orders=range(1, 11) if QUICK else range(1, 41))
    for p in sorted(per, key=lambda d: -d["share_of_residual"])[:3]:
        print(f"-- periodogram: {p['joint']}: order {p['order']} (period {p['period_rad']:.3f} rad) explains "
              f"{100 * p['share_of_residual']:.0f} % of the geometric training residual on its own")
    effects = {e.name: {"heldout_rms_after_m": e.heldout_rms_after_m, "heldout_mean_after_m": e.heldout_mean_after_m,
                        "gap_closed_fraction": e.gap_closed_fraction, "significant": e.significant,
                        "n_params": e.n_params} for e in rep_t.effects if e.status == "ok"}
    return {"series": series, "n_train": len(train), "n_heldout": len(test), "report": rep.to_dict(),
            "with_table": {"selected": rep_t.selected_effects, "heldout_after": rep_t.heldout_after,
                           "effects": effects, "knot_step_rad": TABLE_STEP},
            "repeatability": rpt, "periodogram": per}


def main() -> None:
    if not DATA.is_dir():
        print(f"IPA UR10 data not found at {DATA}: nothing to do")
        return
    rb = load_robot("ur10")
    figures = Path("ur10_figures")
    results = [run_series(rb, s, figures) for s in (["Series_C"] if QUICK else ["Series_B", "Series_C"])]

    print("\n===== calibrate on Series C, validate on Series D (tracker placed elsewhere)")
    c, d = load("Series_C"), load("Series_D")
    if QUICK:
        c, d = c.subset(np.arange(0, len(c), 10)), d.subset(np.arange(0, len(d), 5))
    model = TrackerModel(rb, reflector_m=REFLECTOR, noise=NOISE)
    rep = diagnose(model, c, d, weights="noise", effects=["joint_compliance"])
    print(f"validation_mismatch = {rep.validation_mismatch}; dominant_effect = {rep.dominant_effect}")
    print(rep.mismatch.get("message", ""))
    tr = diagnose(model, c, d, weights="noise", effects=["joint_compliance"], register_rows=60, seed=0)
    print(f"with the set-up re-registered on 60 rows of D: held-out mean {tr.heldout_before['mean_m'] * 1e3:.3f} mm "
          f"(geometry) -> {tr.heldout_after['mean_m'] * 1e3:.3f} mm ({', '.join(tr.selected_effects) or 'no effect'}"
          f"); dominant_effect = {tr.dominant_effect}")

    print("\n===== summary: held-out error mean / RMS / max (mm)")
    print(f"{'series':<10}{'geometry only':>22}{'+ library selection':>36}{'+ joint-angle table':>24}"
          f"{'exploratory mean':>18}")

    def fmt(d):
        return f"{d['mean_m'] * 1e3:.3f} / {d['rms_m'] * 1e3:.3f} / {d['max_m'] * 1e3:.2f}"

    for r in results:
        rep_r = r["report"]
        sel = "+".join(rep_r["selected_effects"]) or "none"
        print(f"{r['series']:<10}{fmt(rep_r['heldout_before']):>22}{sel:>14} {fmt(rep_r['heldout_after']):>21}"
              f"{fmt(r['with_table']['heldout_after']):>24}{EXPLORATORY_MEAN_M[r['series']] * 1e3:>18.2f}")
    c_to_d = {"validation_mismatch": rep.validation_mismatch, "message": rep.mismatch.get("message"),
              "transfer": {"registration": tr.registration, "heldout_before": tr.heldout_before,
                           "heldout_after": tr.heldout_after, "selected": tr.selected_effects}}
    atomic_write_json("ur10_diagnosis.json", {"series": results, "c_to_d": c_to_d, "noise": NOISE.to_dict(),
                                              "reflector_m": REFLECTOR})
    print(f"wrote ur10_diagnosis.json and {figures}/")


if __name__ == "__main__":
    main()
