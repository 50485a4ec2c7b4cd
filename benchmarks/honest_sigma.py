"""Is the predicted σ honest on real held-out data? The IPA UR10 series, calibrated with the discrepancy.

For each case the robot is calibrated (geometry, tracker pose and reflector per series; σ = 0.1 mm uniform weights, the
noise level unknown as without ``--sigma``) with ``discrepancy="auto"`` (a Gaussian process over the joint angles on the
residuals), then the held-out rows are predicted with their σ per axis (:meth:`CalibratedModel.predict_with_sigma`):

* ``C halves``: Series C, seeded random halves (same session, nothing re-fitted);
* ``X->Y``: calibrated on all rows of X, the set-up re-registered on 60 seeded rows of Y (robot and
  discrepancy held), the other rows of Y scored;
* ``BCD 5-fold``: B + C + D fitted together (one station per series), 5 seeded folds;
* ``A halves``: Series A (11,911 grid rows), seeded random halves;
* ``BCD->A``: B + C + D calibrated, re-registered on 60 rows of A, the rest of A scored.

Columns: held-out mean error (mm) without and with the discrepancy's mean, the mean predicted 3-D σ (mm),
the RMS of the standardised errors z = error/σ per axis (honest: within [0.67, 1.5]), the share of rows
inside their 95 % ellipsoid (honest: 85-99 %), the share flagged as extrapolation, and for contrast the
standardised RMS of the noise-only model (the paper's σ).

Run:  python -m benchmarks.honest_sigma [--cases "C halves,B->C"] [--json out.json]   (IPA data: $PIN_KPI_OED_IPA_DATA
or shared/data/ipa_ur10 beside the repository)
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from benchmarks.common import ipa_folder_or_say, ipa_ur10_model, load_ipa_series
from pin_kpi_oed.data.atomic import atomic_write_json
from pin_kpi_oed.data.measurements import MeasurementSet, concat_measurements
from pin_kpi_oed.identification.identify import identify, validate
from pin_kpi_oed.upkeep.transfer import register_setup, registration_split

CASES = ["C halves", "B->C", "C->B", "C->D", "D->C", "BCD 5-fold", "A halves", "BCD->A"]


def score(cm, held: MeasurementSet, station=None) -> dict:
    plain = cm.noise_only()
    v = validate(cm, held) if station is None else _validate_station(cm, held, station)
    v0 = validate(plain, held) if station is None else _validate_station(plain, held, station)
    return {"n": v["n"], "mean_plain_mm": v0["mean_m"] * 1e3, "mean_mm": v["mean_m"] * 1e3,
            "sigma_mm": v["sigma_mean_m"] * 1e3, "z_rms": v["z_rms"], "inside_95": v["inside_95"],
            "extrapolation": v["extrapolation_share"], "z_rms_noise_only": v0["z_rms"]}


def _validate_station(cm, held, station):
    lab = MeasurementSet(held.joint_names, held.q, held.position_m, station=np.array([station] * len(held)),
                         temperature_c=held.temperature_c, source=held.source)
    return validate(cm, lab)


def calibrate(model, data, seed=0):
    # σ = 0.1 mm is a uniform weight, not a stated noise (the data state none): the covariance is scaled by the
    # reduced chi2, as identify without --sigma does, and no white level is floored at it
    return identify(model, data, discrepancy="auto", seed=seed, raise_on_failure=False,
                    scale_covariance=True).calibrated_model()


def run_case(case: str, S: dict, model, seed: int) -> dict:
    t0 = time.perf_counter()
    if case.endswith("halves"):
        tr, te = S[case[0]].split(0.5, seed=seed)
        cm = calibrate(model, tr, seed)
        out = score(cm, te)
    elif case == "BCD 5-fold":
        allx = concat_measurements([S[s] for s in "BCD"], ["B", "C", "D"])
        fold = np.random.default_rng(seed).permutation(len(allx)) % 5
        rows = []
        for k in range(5):
            cm = calibrate(model, allx.subset(np.flatnonzero(fold != k)), seed)
            rows.append(score(cm, allx.subset(np.flatnonzero(fold == k))))
        n = np.array([r["n"] for r in rows], float)
        out = {key: (float(np.sum(n)) if key == "n" else float(np.sum([r[key] * w for r, w in zip(rows, n)]) / n.sum()))
               for key in rows[0] if key not in ("z_rms", "z_rms_noise_only")}
        out["z_rms"] = float(np.sqrt(np.sum([r["z_rms"] ** 2 * w for r, w in zip(rows, n)]) / n.sum()))
        out["z_rms_noise_only"] = float(np.sqrt(np.sum([r["z_rms_noise_only"] ** 2 * w for r, w in zip(rows, n)])
                                                / n.sum()))
    else:
        src, tgt = case.split("->")
        data = S[src] if len(src) == 1 else concat_measurements([S[s] for s in src], list(src))
        cm = calibrate(model, data, seed)
        reg_idx, held_idx = registration_split(len(S[tgt]), 60, seed)
        rr = register_setup(cm, S[tgt].subset(reg_idx), station="target")
        out = score(rr.model, S[tgt].subset(held_idx), station="target")
    out["case"] = case
    out["time_s"] = time.perf_counter() - t0
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=",".join(CASES), help="comma-separated cases (default all)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    folder = ipa_folder_or_say()
    if folder is None:
        return 0
    cases = [c.strip() for c in a.cases.split(",") if c.strip()]
    need = {ch for c in cases for ch in c.split()[0].replace("->", "") if ch in "ABCD"}
    S = {s: load_ipa_series(folder, s) for s in sorted(need)}
    model = ipa_ur10_model()
    print(f"{'case':<11} {'n':>6} {'mean plain':>10} {'mean +GP':>9} {'sigma':>7} {'z RMS':>6} {'in 95%':>7} "
          f"{'extrap':>6} {'z noise-only':>12} {'time':>7}   (mm; z honest within 0.67-1.5, 85-99 % inside)")
    rows = []
    for c in cases:
        r = run_case(c, S, model, a.seed)
        rows.append(r)
        print(f"{c:<11} {r['n']:>6.0f} {r['mean_plain_mm']:>10.4f} {r['mean_mm']:>9.4f} {r['sigma_mm']:>7.4f} "
              f"{r['z_rms']:>6.2f} {r['inside_95'] * 100:>6.1f}% {r['extrapolation'] * 100:>5.1f}% "
              f"{r['z_rms_noise_only']:>12.2f} {r['time_s']:>6.1f}s", flush=True)
    if a.json:
        atomic_write_json(a.json, {"cases": rows, "seed": a.seed})
    return 0


if __name__ == "__main__":
    sys.exit(main())
