"""Real data: a UR10 calibration used on another day — several stations, model file, register, predict.

The IPA UR10 series B, C and D were measured in different sessions (Series D with the tracker placed
elsewhere). For each directed pair X→Y this script does what ``pin-kpi-oed`` does with three commands:

    pin-kpi-oed identify --robot ur10 --data X.csv --reflector 0,0,0.109 --sigma 1e-4 --model-out X_model.json
    pin-kpi-oed register --model X_model.json --data Y_reg60.csv --model-out X_on_Y.json
    pin-kpi-oed predict  --model X_on_Y.json --data Y_held.csv --out X_on_Y_pred.csv

(``Y_reg60.csv`` / ``Y_held.csv``: ``pin-kpi-oed import-ipa Series_Y --position-only --split 60 --seed 0``):
calibrate on all rows of X (geometry only, σ = 0.1 mm as ``identify_ur10.py``), re-fit only the set-up
(tracker pose, reflector; robot held) on 60 seeded random rows of Y, and score the other rows of Y. Then
it calibrates B + C + D jointly (three stations, one robot) and prints that fit's own residual. These
are the geometric baselines of the transfer study (docs/results.md) (≈ 0.55 / 0.84 / 0.71–0.76 / 0.54 mm mean).

Run:  python examples/identify_transfer_ur10.py [--data DIR] [--rows 60] [--seed 0]
(``--quick`` or PIN_KPI_OED_QUICK=1: the same steps on 80 seeded random rows of each series, for the tests)
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np

from pin_kpi_oed import NoiseModel, TrackerModel, load_robot
from pin_kpi_oed.data.ipa import import_ipa
from pin_kpi_oed.data.measurements import MeasurementSet, concat_measurements
from pin_kpi_oed.identification.identify import error_stats, identify
from pin_kpi_oed.upkeep.transfer import register_setup, registration_split

_HERE = Path(__file__).resolve()
DATA = next((p / "shared" / "data" / "ipa_ur10" for p in (_HERE.parents[2], _HERE.parents[3])
             if (p / "shared" / "data" / "ipa_ur10").is_dir()), _HERE.parents[2] / "shared" / "data" / "ipa_ur10")
PAIRS = (("B", "C"), ("C", "B"), ("C", "D"), ("D", "C"))
QUICK_ROWS = 80  # rows kept of each series by --quick (60 register the set-up, 20 are held out)


def load(folder: Path, series: str) -> MeasurementSet:
    """Position-only measurements of one series, uniform weights, labelled as its own station."""
    ms = import_ipa(folder / f"Series_{series}")
    return MeasurementSet(ms.joint_names, ms.q, ms.position_m, temperature_c=ms.temperature_c,
                          source=f"{series}.csv")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(DATA), help="folder with Series_B, Series_C, Series_D")
    ap.add_argument("--rows", type=int, default=60, help="registration rows of the second series")
    ap.add_argument("--seed", type=int, default=0, help="seed of the registration rows")
    ap.add_argument("--quick", action="store_true", default=os.environ.get("PIN_KPI_OED_QUICK") == "1",
                    help=f"the same steps on {QUICK_ROWS} seeded random rows of each series")
    a = ap.parse_args(argv)
    folder = Path(a.data)
    if not (folder / "Series_C").is_dir():
        print(f"IPA UR10 data not found at {folder}: nothing to do (pass --data DIR)")
        return 0
    robot = load_robot("ur10")
    model = TrackerModel(robot, reflector_m=np.array([0.0, 0.0, 0.109]), noise=NoiseModel(sigma_xyz_m=(1e-4,) * 3))
    series = {s: load(folder, s) for s in "BCD"}
    if a.quick:
        rng = np.random.default_rng(a.seed)
        series = {s: ms.subset(np.sort(rng.choice(len(ms), min(QUICK_ROWS, len(ms)), replace=False)))
                  for s, ms in series.items()}
        print(f"quick run: {QUICK_ROWS} seeded random rows of each series (the figures below are not the study's)")
    calibrated = {s: identify(model, series[s], scale_covariance=True).calibrated_model() for s in "BCD"}

    print(f"geometric calibration on all rows of X; set-up re-registered (robot held) on {a.rows} seeded random "
          f"rows of Y (seed {a.seed}); held-out error on the other rows of Y:")
    print(f"{'pair':<8}{'n':>6}{'mean mm':>10}{'RMS mm':>10}{'max mm':>10}{'registration RMS mm':>22}")
    results = {}
    for x, y in PAIRS:
        reg_idx, held_idx = registration_split(len(series[y]), a.rows, a.seed)
        reg, held = series[y].subset(reg_idx), series[y].subset(held_idx)
        rr = register_setup(calibrated[x], reg)
        st = error_stats(np.linalg.norm(held.position_m - rr.model.predict(held.q, held), axis=1))
        results[f"{x}->{y}"] = st
        print(f"{x + '->' + y:<8}{st['n']:>6}{st['mean_m'] * 1e3:>10.3f}{st['rms_m'] * 1e3:>10.3f}"
              f"{st['max_m'] * 1e3:>10.3f}{rr.rms_m * 1e3:>22.3f}")
    mean = np.mean([r["mean_m"] for r in results.values()])
    print(f"mean over the four directed pairs of the held-out mean error: {mean * 1e3:.3f} mm")

    joint = identify(model, concat_measurements([series[s] for s in "BCD"]), scale_covariance=True)
    e = joint.errors_m
    print(f"joint B+C+D fit (3 stations, {joint.n_measurements} rows, {len(joint.names)} parameters): own residual "
          f"mean {e.mean() * 1e3:.3f} mm, RMS {np.sqrt(np.mean(e ** 2)) * 1e3:.3f} mm, max {e.max() * 1e3:.3f} mm")
    for lab, rows in zip(joint.stations, joint.station_rows):
        print(f"  station {lab}: {rows.size} rows, mean {e[rows].mean() * 1e3:.3f} mm")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
