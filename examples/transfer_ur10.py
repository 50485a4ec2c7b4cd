"""Real data: does a UR10 calibration with selected transferable effects hold on another series?

IPA UR10 data (Series B, C, D: three sessions, the tracker placed anew, different parts of
joint space). For each case the robot is calibrated on the source series (geometry: the
identifiable DH-type corrections, tracker pose and reflector per series), the transferable
terms are selected by 5-fold held-out error (:func:`pin_kpi_oed.diagnosis.selection.select_terms`:
Fourier pairs of orders 1–40 per joint and the arm-plane gravity terms) and refitted, then:

* within Series C: a seeded random half is held out (same session, nothing re-fitted);
* directed pairs B→C, C→B, C→D, D→C and the two-series fits B+C→D, B+D→C, C+D→B: the set-up
  (tracker pose + reflector) is re-fitted on 60 seeded random rows of the target with the robot
  held (:func:`~pin_kpi_oed.upkeep.transfer.register_setup`, the ``register``
  command), and the remaining target rows are predicted.

Several source series are one :func:`~pin_kpi_oed.identification.identify.identify` with a
``station`` column (robot shared, a tracker pose and reflector per series).

Columns: held-out error (3-D, mm) mean / RMS / max of the geometric model, with the selected
terms (plain least squares), and with the selected terms under a Gaussian prior of 100 µrad
per coefficient (fixed beforehand, limits extrapolation). With several registration seeds,
mean and RMS are averaged over the seeds and max is the largest. "coverage" is the share of
target rows whose wrapped joint angle lies within 0.05 rad of a source angle, joints 1–5, and
on all five at once. Series B drift: B, C, D have no time stamps, so the row number stands for
time (s) in the drift line.

Set-up as ``examples/identify_ur10.py``: robot ``ur10`` (CB3), T-Mac reflector ~109 mm out on
the flange axis (start), uniform σ = 0.1 mm (only relative weights matter), position only.

Run:  python examples/transfer_ur10.py [--data DIR] [--json out.json]   (about 2–4 min;
--quick or PIN_KPI_OED_QUICK=1: the same steps on 100 seeded rows of each series, orders 1–10, one
registration seed, the directed pair B→C and the two-series fit B+C→D)
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

from pin_kpi_oed.data.atomic import atomic_write_json
from pin_kpi_oed.data.ipa import import_ipa
from pin_kpi_oed.data.measurements import MeasurementSet, concat_measurements
from pin_kpi_oed.diagnosis.selection import coverage, refit_with, select_terms
from pin_kpi_oed.effects.drift import Drift
from pin_kpi_oed.identification.identify import IdentificationResult, identify
from pin_kpi_oed.identification.problem import align_data
from pin_kpi_oed.upkeep.transfer import register_setup
from pin_kpi_oed.model.noise import NoiseModel
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.model.robot import load_robot

#: --quick (or PIN_KPI_OED_QUICK=1): smaller sizes, the same steps (the tests' run)
QUICK = os.environ.get("PIN_KPI_OED_QUICK") == "1" or "--quick" in sys.argv[1:]
ROOT = Path(__file__).resolve().parents[1]
REFLECTOR = np.array([0.0, 0.0, 0.109])  # T-Mac origin on tool0's z axis (Trafo_TM_F_init.txt)
SIGMA = 1e-4  # m, uniform weights
PRIOR_RAD = 1e-4  # σ of the Gaussian prior of the third column (rad)
N_REG = 60  # registration rows of the target
PAIRS = [("B", "C"), ("C", "B"), ("C", "D"), ("D", "C")]
LOO = [("BC", "D"), ("BD", "C"), ("CD", "B")]


def find_data() -> Path | None:
    """The IPA UR10 folder: $PIN_KPI_OED_IPA_DATA, else ``shared/data/ipa_ur10`` beside an ancestor of the repo."""
    env = os.environ.get("PIN_KPI_OED_IPA_DATA")
    if env:
        return Path(env)
    for up in ROOT.parents:
        d = up / "shared" / "data" / "ipa_ur10"
        if d.is_dir():
            return d
    return None


def load(data_dir: Path, series: str, n: int | None = None, seed: int = 0) -> MeasurementSet:
    """Position-only rows of one series (std columns dropped), the row number as time (s); n: a seeded subset."""
    ms = import_ipa(data_dir / f"Series_{series}")
    out = MeasurementSet(ms.joint_names, ms.q, ms.position_m, time_s=np.arange(len(ms), dtype=float),
                         source=f"Series {series}")
    if n is not None and n < len(out):
        out = out.subset(np.sort(np.random.default_rng(seed).permutation(len(out))[:n]))
    return out


def norms_mm(R: np.ndarray) -> np.ndarray:
    return np.linalg.norm(R, axis=1) * 1e3


def stats(err_lists: list[np.ndarray]) -> dict:
    """mean / RMS averaged over registration seeds, max over all, mean's spread over seeds (mm)."""
    means = [float(e.mean()) for e in err_lists]
    return {"mean_mm": float(np.mean(means)), "rms_mm": float(np.mean([np.sqrt(np.mean(e ** 2)) for e in err_lists])),
            "max_mm": float(max(e.max() for e in err_lists)), "mean_spread_mm": float(np.ptp(means))}


def fmt(s: dict) -> str:
    return f"{s['mean_mm']:.3f}/{s['rms_mm']:.3f}/{s['max_mm']:.2f}"


def calibrate(model: TrackerModel, sources: list[MeasurementSet], max_order: int) -> dict:
    """Geometric fit, selection, refits (plain and with the prior); timings."""
    t0 = time.perf_counter()
    data = sources[0] if len(sources) == 1 else concat_measurements(sources, [s.source for s in sources])
    geo = identify(model, data, raise_on_failure=False)
    t1 = time.perf_counter()
    sel = select_terms(geo, data, max_order=max_order, seed=0)
    t2 = time.perf_counter()
    pri = refit_with(geo, data, sel.effects, sel.theta, PRIOR_RAD) if sel.effects else geo
    return {"geo": geo, "sel": sel, "fits": {"geometric": geo, "selected": sel.fit or geo, "selected+prior": pri},
            "time_geo_s": t1 - t0, "time_select_s": t2 - t1, "time_total_s": time.perf_counter() - t0}


def residuals(fit: IdentificationResult, held: MeasurementSet, reg: MeasurementSet | None = None) -> np.ndarray:
    """Measured − predicted positions (m) of ``held``; with ``reg`` after re-registering the set-up on it."""
    cm = fit.calibrated_model()
    station = None
    if reg is not None:
        cm, station = register_setup(cm, reg, station="target").model, "target"
    return held.position_m - cm.predict(align_data(cm.robot, held), held, station=station)


def transfer(cal: dict, target: MeasurementSet, seeds: list[int]) -> dict:
    """Register each model on N_REG seeded rows of the target and predict the rest."""
    errs = {k: [] for k in cal["fits"]}
    for s in seeds:
        idx = np.random.default_rng(s).permutation(len(target))
        reg, held = target.subset(np.sort(idx[:N_REG])), target.subset(np.sort(idx[N_REG:]))
        for k, f in cal["fits"].items():
            errs[k].append(norms_mm(residuals(f, held, reg)))
    return {k: stats(v) for k, v in errs.items()}


def report_terms(sel, n: int = 6) -> str:
    return "; ".join(t["text"].split(" (phase")[0] for t in sel.terms[:n])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smaller sizes, the same steps")
    ap.add_argument("--data", default=None, help="folder with Series_B, Series_C, Series_D")
    ap.add_argument("--max-order", type=int, default=10 if QUICK else 40, help="highest Fourier order")
    ap.add_argument("--reg-seeds", default="0" if QUICK else "0,1,2,3,4", help="seeds of the registration rows")
    ap.add_argument("--json", default=None, help="write the table as JSON")
    a = ap.parse_args(argv)
    data_dir = Path(a.data) if a.data else find_data()
    if data_dir is None or not (data_dir / "Series_C").is_dir():
        print(f"IPA UR10 data not found ({data_dir}): nothing to do (pass --data DIR)")
        return 0
    seeds = [int(s) for s in a.reg_seeds.split(",")]
    sub = 100 if QUICK else None
    S = {s: load(data_dir, s, sub) for s in "BCD"}
    model = TrackerModel(load_robot("ur10"), reflector_m=REFLECTOR, noise=NoiseModel(sigma_xyz_m=(SIGMA,) * 3))
    cols = list(["geometric", "selected", "selected+prior"])
    print(f"UR10 transfer, held-out error mean/RMS/max (mm); registration on {N_REG} rows (seeds {a.reg_seeds}); "
          f"Fourier orders 1-{a.max_order}; prior {PRIOR_RAD * 1e6:.0f} µrad{'; QUICK subsets' if QUICK else ''}")
    print(f"{'case':<8} {'geometric':>19} {'+ selected':>19} {'+ sel., prior':>19}  terms  coverage j1..j5 / all"
          f"  time (select / total)")
    table = []

    # within Series C: random halves (same session: nothing re-fitted)
    train, test = S["C"].split(0.5, seed=0)
    cal = calibrate(model, [train], a.max_order)
    row = {k: stats([norms_mm(residuals(f, test))]) for k, f in cal["fits"].items()}
    per, allj = coverage(train.q[:, :5], test.q[:, :5])
    table.append({"case": "C halves", **row, "terms": len(cal["sel"].terms), "coverage": per[:5].tolist(),
                  "coverage_all": allj, "time_select_s": cal["time_select_s"], "time_total_s": cal["time_total_s"],
                  "selected_terms": [t["text"] for t in cal["sel"].terms]})

    def show(r: dict) -> None:
        cov = " ".join(f"{c:.2f}" for c in r["coverage"])
        print(f"{r['case']:<8} {fmt(r['geometric']):>19} {fmt(r['selected']):>19} {fmt(r['selected+prior']):>19}  "
              f"{r['terms']:5d}  {cov} / {r['coverage_all']:.2f}  {r['time_select_s']:.1f} / "
              f"{r['time_total_s']:.1f} s", flush=True)

    show(table[-1])
    print(f"         C halves, first terms: {report_terms(cal['sel'])}")
    cases = PAIRS[:1] + LOO[:1] if QUICK else PAIRS + LOO  # quick: one directed pair, one two-series fit
    for src, tgt in cases:
        cal = calibrate(model, [S[s] for s in src], a.max_order)
        row = transfer(cal, S[tgt], seeds)
        per, allj = coverage(np.vstack([S[s].q[:, :5] for s in src]), S[tgt].q[:, :5])
        table.append({"case": f"{'+'.join(src)}->{tgt}", **row, "terms": len(cal["sel"].terms),
                      "coverage": per[:5].tolist(), "coverage_all": allj, "time_select_s": cal["time_select_s"],
                      "time_total_s": cal["time_total_s"], "selected_terms": [t["text"] for t in cal["sel"].terms]})
        show(table[-1])
    pairs = [r for r in table if r["case"] in {f"{s}->{t}" for s, t in PAIRS}]
    if len(pairs) == len(PAIRS):
        print("mean of the 4 directed pairs (held-out mean, mm): " + ", ".join(
            f"{k} {np.mean([r[k]['mean_mm'] for r in pairs]):.3f}" for k in cols))

    # Series B drift within the session (row number as time): geometric halves with and without a drift term
    trB, teB = S["B"].split(0.5, seed=0)
    rb = model.robot
    g = identify(model, trB)
    d = identify(model, trB, effects=[Drift.from_data(rb, trB)])
    e0, e1 = norms_mm(residuals(g, teB)), norms_mm(residuals(d, teB))
    words = d.effects[0].describe(d.theta[0])
    print(f"Series B halves, drift (row number as time, s): geometric {e0.mean():.3f} mm -> with drift "
          f"{e1.mean():.3f} mm held-out mean; {words[0].replace('per hour', 'per 3600 rows')}")
    table.append({"case": "B halves drift", "geometric_mean_mm": float(e0.mean()), "drift_mean_mm": float(e1.mean()),
                  "drift": words})
    if a.json:
        atomic_write_json(Path(a.json), {"prior_rad": PRIOR_RAD, "n_reg": N_REG, "reg_seeds": seeds,
                                         "max_order": a.max_order, "quick": QUICK, "table": table})
        print(f"wrote {a.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
