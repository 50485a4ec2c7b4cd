"""Is the default σ honest across sessions on the real UR10 with few poses? Small calibrations of one IPA series
scored on another.

For each directed pair X → Y of the IPA UR10 series and each number of poses m: seeded random sets of m poses of
X are calibrated with the Python API's defaults (``identify(model, data)``: discrepancy ``auto``, the gate flagged;
σ = 0.1 mm uniform weights with the noise level unknown, as ``identify`` without ``--sigma``), Y's set-up is
re-registered on 60 seeded rows of Y (robot and discrepancy held, ``register_setup``, which scales the station's
σ by its registration rows' standardised errors when above 1), and the other rows of Y are predicted with their σ
(``CalibratedModel.predict_with_sigma``). Printed per (pair, m): the median and range over the sets of the
standardised RMS (honest within [0.67, 1.5]) and of the share inside the 95 % ellipsoid (honest 85-99 %), the
pooled figures, the share of rows flagged as extrapolation and what the discrepancy became.

Run:  OMP_NUM_THREADS=1 python -m benchmarks.sigma_real [--pairs "B->C,C->B,C->D,D->C"] [--sizes 35,70] [--sets 3]
      [--json out.json]   (IPA data: $PIN_KPI_OED_IPA_DATA or shared/data/ipa_ur10 beside the repository)
"""

from __future__ import annotations

import argparse
import os
import sys
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from benchmarks.common import ipa_folder_or_say, ipa_ur10_model, load_ipa_series  # noqa: E402

PAIRS = ("B->C", "C->B", "C->D", "D->C")


def one_set(model, src, tgt, m: int, seed: int) -> dict:
    """Calibrate m seeded random rows of ``src``, register on 60 rows of ``tgt``, score the rest of ``tgt``."""
    from pin_kpi_oed.identification.identify import identify
    from pin_kpi_oed.upkeep.transfer import register_setup, registration_split

    rows = np.sort(np.random.default_rng([seed, m]).permutation(len(src))[:m])
    fit = identify(model, src.subset(rows), scale_covariance=True, raise_on_failure=False, seed=seed)
    reg_idx, held_idx = registration_split(len(tgt), 60, seed)
    rr = register_setup(fit.calibrated_model(), tgt.subset(reg_idx), station="target")
    held = tgt.subset(held_idx)
    Y, sig, extra = rr.model.predict_with_sigma(held.q, held, station="target")
    z2 = ((held.position_m - Y) / sig) ** 2
    return {"seed": seed, "kind": None if fit.discrepancy is None else fit.discrepancy.kind,
            "verdict": None if fit.fit_quality is None else fit.fit_quality.verdict,
            "z_rms": float(np.sqrt(z2.mean())), "inside_95": float(np.mean(z2.sum(1) <= 7.8147)),
            "extrapolation": float(np.mean(extra)), "mean_mm": float(np.linalg.norm(held.position_m - Y, axis=1).mean()
                                                                     * 1e3),
            "sigma_mm": float(np.sqrt((sig ** 2).sum(1)).mean() * 1e3), "sigma_scale": rr.setups["target"].sigma_scale,
            "z2": z2}


def main(argv: list[str] | None = None) -> int:
    from pin_kpi_oed.data.atomic import atomic_write_json

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", default=",".join(PAIRS))
    ap.add_argument("--sizes", default="35,70")
    ap.add_argument("--sets", type=int, default=3, help="seeded random sets per (pair, m)")
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    folder = ipa_folder_or_say()
    if folder is None:
        return 0
    pairs = [p.strip() for p in a.pairs.split(",") if p.strip()]
    S = {s: load_ipa_series(folder, s) for s in sorted({c for p in pairs for c in p.split("->")})}
    model = ipa_ur10_model()
    print(f"{'pair':<6} {'m':>4} {'kind':>12} {'z RMS median (range)':>22} {'in 95 % median (range)':>24} "
          f"{'pooled z':>8} {'pooled in':>9} {'extrap':>7} {'mean err':>9} {'sigma':>7}   (mm; honest: z 0.67-1.5, "
          f"85-99 % inside)", flush=True)
    out = []
    for pair in pairs:
        src, tgt = pair.split("->")
        for m in [int(x) for x in a.sizes.split(",")]:
            t0 = time.perf_counter()
            runs = [one_set(model, S[src], S[tgt], m, seed) for seed in range(a.sets)]
            z = np.array([r["z_rms"] for r in runs])
            ins = np.array([r["inside_95"] for r in runs])
            z2 = np.vstack([r.pop("z2") for r in runs])
            kinds = ",".join(sorted({str(r["kind"]) for r in runs}))
            row = {"pair": pair, "m": m, "runs": runs, "z_rms_pooled": float(np.sqrt(z2.mean())),
                   "inside_pooled": float(np.mean(z2.sum(1) <= 7.8147)), "time_s": time.perf_counter() - t0}
            out.append(row)
            print(f"{pair:<6} {m:>4} {kinds:>12} {np.median(z):>8.2f} ({z.min():.2f}-{z.max():.2f}){'':>7} "
                  f"{np.median(ins) * 100:>8.1f} % ({ins.min() * 100:.0f}-{ins.max() * 100:.0f} %){'':>4} "
                  f"{row['z_rms_pooled']:>8.2f} {row['inside_pooled'] * 100:>8.1f}% "
                  f"{np.mean([r['extrapolation'] for r in runs]) * 100:>6.1f}% "
                  f"{np.mean([r['mean_mm'] for r in runs]):>9.4f} {np.mean([r['sigma_mm'] for r in runs]):>7.4f}",
                  flush=True)
    if a.json:
        atomic_write_json(a.json, {"rows": out, "args": vars(a)})
    return 0


if __name__ == "__main__":
    sys.exit(main())
