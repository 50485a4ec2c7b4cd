"""Validate measurement designs: Monte-Carlo identification (simulated KR 15) and real UR10 data.

1. Monte-Carlo: 200 simulated identifications of a 60-pose design; realised vs predicted TCP covariance.
2. Real data (if the IPA UR10 data are present): working poses held out, 60 calibration poses chosen from the
   rest by the KPI criterion, by D-optimality and at random; identify from each; real errors at the working poses.

Run: python examples/validate_designs.py [--splits 20] [--series ../shared/data/ipa_ur10/Series_C] [--json out.json]
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np
import pinocchio as pin

from pin_kpi_oed import NoiseModel, TrackerModel, load_robot
from pin_kpi_oed.io import atomic_write_json
from pin_kpi_oed.ipa import import_ipa
from pin_kpi_oed.validation import monte_carlo, real_data_validation

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

    robot = load_robot("kr15")
    model = TrackerModel(robot, tracker_T_base=pin.SE3(pin.rpy.rpyToMatrix(0, 0, np.pi), np.array([3.0, 0.0, -0.5])),
                         reflector_m=np.array([0.05, 0.02, 0.05]), noise=NoiseModel(sigma_xyz_m=(1e-5,) * 3))
    rng = np.random.default_rng(a.seed)
    mc = monte_carlo(model, robot.random_q(rng, 60), robot.neutral()[None], n_rep=a.reps, seed=a.seed)
    print(mc.summary())
    out["monte_carlo"] = mc.to_dict()

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
