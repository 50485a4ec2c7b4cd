"""Trust map of a calibration: predicted TCP σ over the configurations of use, and where the robot was measured.

A UR10 with geometric errors and a gear harmonic the model does not know (0.3 mrad on shoulder and elbow, the
"withheld" effect) is measured on 300 simulated rows (σ = 10 µm) with the shoulder pan within ±1.5 rad. The
calibration fits the geometry and a Gaussian-process model discrepancy (identify(..., discrepancy="on")); the
trust map then shows, over 200 configurations of use (half of them with the pan beyond the measured range), the
predicted σ of ``predict`` (colour), the rows outside the measured coverage (crosses) and the measured
configurations (grey). The same figure comes from the command line::

    pin-kpi-oed predict --model model.json --data use.csv --out pred.csv --figure trust.png

Run:  python examples/trust_map.py [--out trust.png]   (PIN_KPI_OED_QUICK=1: fewer rows)
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

from pin_kpi_oed import NoiseModel, TrackerModel, load_robot
from pin_kpi_oed.effects.library import GearHarmonic
from pin_kpi_oed.identification.identify import identify
from pin_kpi_oed.simulation.simulator import Tolerances, default_tracker_pose, random_truth, simulate
from pin_kpi_oed.oed.identifiability import analyse
from pin_kpi_oed.viz.trust_map import plot_trust_map

#: --quick (or PIN_KPI_OED_QUICK=1): smaller sizes, the same steps (the tests' run)
QUICK = os.environ.get("PIN_KPI_OED_QUICK") == "1" or "--quick" in sys.argv[1:]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smaller sizes, the same steps")
    ap.add_argument("--out", default=None, help="PNG to write (default: trust_map.png in a temporary folder)")
    ap.add_argument("--n", type=int, default=100 if QUICK else 300, help="measured (training) rows")
    a = ap.parse_args(argv)

    robot = load_robot("ur10")
    model = TrackerModel(robot, tracker_T_base=default_tracker_pose(robot), reflector_m=np.array([0.03, 0.02, 0.08]),
                         noise=NoiseModel(sigma_xyz_m=(1e-5,) * 3))
    truth = random_truth(model, Tolerances(5e-4, 1e-3), seed=4, only=[i for i in analyse(model).base if i < 36])
    gh = GearHarmonic(robot, joints=["shoulder_lift_joint", "elbow_joint"], orders=(2, 3))  # withheld from the fit
    theta = 3e-4 * np.random.default_rng(5).standard_normal(len(gh.param_names()))
    rng = np.random.default_rng(6)
    Q = robot.random_q(rng, a.n)
    Q[:, 0] = rng.uniform(-1.5, 1.5, a.n)                      # measured: shoulder pan within ±1.5 rad
    train = simulate(model, Q, truth, effects=[(gh, theta)], seed=7)

    cm = identify(model, train, discrepancy="on").calibrated_model()
    print(cm.discrepancy.decision)

    Q_use = robot.random_q(np.random.default_rng(8), 200)     # configurations of use
    Q_use[:100, 0] = rng.uniform(-1.5, 1.5, 100)              # half within the measured pan range
    Q_use[100:, 0] = rng.choice([-1, 1], 100) * rng.uniform(2.2, 3.0, 100)  # half beyond it

    with tempfile.TemporaryDirectory(prefix="pin_kpi_oed_") as tmp:
        out = Path(a.out) if a.out else Path(tmp) / "trust_map.png"
        tm = plot_trust_map(cm, Q_use, out=out)
        inside = ~tm.extrapolation
        print(f"predicted TCP sigma, median: inside the measured coverage {np.median(tm.sigma_m[inside]) * 1e3:.4f} mm "
              f"({int(inside.sum())} rows), outside {np.median(tm.sigma_m[~inside]) * 1e3:.4f} mm "
              f"({tm.n_extrapolated} rows flagged extrapolation)")
        print(f"wrote {out}" + ("" if a.out else " (temporary file)"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
