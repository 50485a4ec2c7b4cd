"""Validate measurement designs: Monte-Carlo identification (simulated KR 15) and real UR10 data.

1. Monte-Carlo: 200 simulated identifications of the KR 15 cell's 60-pose KPI design; realised vs predicted TCP
   covariance.
2. Real data (if the IPA UR10 data are present): working poses held out, 60 calibration poses chosen from the
   rest by the KPI criterion, by D-optimality and at random; identify from each; real errors at the working poses.

Run: python examples/validate_designs.py [--splits 20] [--series ../shared/data/ipa_ur10/Series_C] [--json out.json]
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np
from pin_kpi_oed import NoiseModel, TrackerModel, load_robot
from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.design.optimize import run_designs
from pin_kpi_oed.data.atomic import atomic_write_json
from pin_kpi_oed.data.ipa import import_ipa
from pin_kpi_oed.studies.validation import monte_carlo, real_data_validation

SERIES_C = Path(__file__).resolve().parents[2] / "shared" / "data" / "ipa_ur10" / "Series_C"
QUICK = os.environ.get("PIN_KPI_OED_QUICK") == "1"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--splits", type=int, default=2 if QUICK else 20)
    ap.add_argument("--reps", type=int, default=40 if QUICK else 200)
    ap.add_argument("--series", type=Path, default=SERIES_C)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args()
    out = {}

    # the KPI design of the KR 15 cell (60 poses), then simulated identifications of it
    cell = load_cell("kr15")
    kpi = run_designs(cell, ["kpi"], 30 if QUICK else 60, a.seed)[-1]
    model = cell.tracker_model()
    model.noise = NoiseModel(sigma_xyz_m=(1e-5,) * 3)  # a 10 um tracker (ratios do not depend on sigma)
    mc = monte_carlo(model, kpi.q_meas, cell.q_work, n_rep=a.reps, seed=a.seed)
    print("KPI design of the KR 15 cell:")
    print(mc.summary())
    out["monte_carlo_kpi_design"] = mc.to_dict()

    if a.series.exists():
        data = import_ipa(a.series)
        data.sigma_m = None  # the IPA std columns are reading scatter, not tracker accuracy
        ur10 = TrackerModel(load_robot("ur10"), reflector_m=np.array([0.0, 0.0, 0.109]),
                            noise=NoiseModel(sigma_xyz_m=(5e-5,) * 3))
        if QUICK:
            data = data.subset(np.arange(400))
        rd = real_data_validation(ur10, data, n_splits=a.splits, seed=a.seed)
        print(rd.summary())
        out["real_data"] = rd.to_dict()
    else:
        print(f"IPA UR10 data not found at {a.series}: real-data part skipped")
    if a.json:
        atomic_write_json(a.json, out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
