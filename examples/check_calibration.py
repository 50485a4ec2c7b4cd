"""Keep a calibration: design a 10-pose check, then judge three events on it — nothing changed, the tracker moved,
the elbow's placement changed by 0.5 mrad.

A simulated UR10 calibration (σ = 20 µm per axis, a tool 50 mm off the flange axis) is checked:
``design_check`` chooses the 10 poses of most power against a change of 0.1 mm RMS at the working configurations
(set-up re-registered on the same poses), printed against 10 random poses; ``check_calibration`` gives the verdict
on the noisy rows of each event (χ² on 3·10 − 6 degrees of freedom at α = 0.05) and, for the changed robot, the
re-fitted change with its standard deviation. Ten rows near one pose are judged too and name the poses to add;
``monitor`` follows 300 rows measured during work while the tracker drifts by 20 µm per hour (each row predicted
before it is used, the set-up filter's drift level estimated from the rows).

Run:  python examples/check_calibration.py [--seed 0]   (``--quick`` or PIN_KPI_OED_QUICK=1: the same steps, 60 rows
monitored)
(the same with the command line: ``pin-kpi-oed check design --model M --out poses.csv``, then
``pin-kpi-oed check --model M --data rows.csv --json verdict.json --model-out refit.json``)
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys

import numpy as np
import pinocchio as pin

from pin_kpi_oed import load_robot
from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.upkeep.check import check_calibration
from pin_kpi_oed.upkeep.check_design import design_check
from pin_kpi_oed.upkeep.monitoring import monitor
from pin_kpi_oed.studies.check_events import simulated_model

SIGMA = 2e-5
#: --quick (or PIN_KPI_OED_QUICK=1): smaller sizes, the same steps (the tests' run)
QUICK = os.environ.get("PIN_KPI_OED_QUICK") == "1" or "--quick" in sys.argv[1:]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--quick", action="store_true", help="smaller sizes, the same steps")
    ap.add_argument("--monitored", type=int, default=60 if QUICK else 300, help="rows measured during work")
    args = ap.parse_args(argv)
    rb = load_robot("ur10")
    rng = np.random.default_rng(args.seed)
    model = simulated_model(rb, 0.5 * rng.uniform(rb.q_lower, rb.q_upper, size=(5, rb.nq)), SIGMA, args.seed)
    d = design_check(model, m=10, tolerance_m=1e-4, pool_size=200, seed=args.seed, n_random=10)
    print(d.summary())
    moved = model.with_setup("A", dataclasses.replace(
        model.setups["A"], tracker_T_base=(pin.SE3(model.setups["A"].tracker_T_base)
                                           * pin.exp6(np.r_[0.05, -0.02, 0.01, 0.0, 0.0, 0.02])).homogeneous))
    jp = model.joint_p.copy()
    jp[6 * 2 + 4] += 5e-4                       # the elbow's placement: 0.5 mrad about its y axis (its motion axis)
    events = {"nothing changed": model, "tracker moved": moved,
              "elbow changed": dataclasses.replace(model, joint_p=jp)}
    for name, truth in events.items():
        Y = truth.predict(d.Q, station="A") + rng.normal(size=(len(d.Q), 3)) * SIGMA
        rows = MeasurementSet(list(rb.joint_names), d.Q, Y, source=name)
        r = check_calibration(model, rows, alpha=0.05, tolerance_m=1e-4, seed=args.seed)
        print(f"{name}: {r.summary()}")
    # ten rows near one pose: judged, and the poses to add named (designed with the rows given)
    Qn = d.Q[:1] + 0.03 * rng.standard_normal((10, rb.nq))
    near = MeasurementSet(list(rb.joint_names), Qn, model.predict(Qn) + rng.normal(size=(10, 3)) * SIGMA,
                          source="near one pose")
    r = check_calibration(model, near, seed=args.seed)
    print(f"rows near one pose: {r.summary()}")
    # monitoring during work: --monitored rows (300), the tracker drifting 20 µm per hour in x, one row a minute
    n = args.monitored
    Qm = 0.7 * rng.uniform(rb.q_lower, rb.q_upper, size=(n, rb.nq))
    t = 60.0 * np.arange(n)
    Ym = np.vstack([model.with_setup("A", dataclasses.replace(model.setups["A"], tracker_T_base=(
        pin.SE3(model.setups["A"].tracker_T_base) * pin.exp6(np.r_[2e-5 * ti / 3600, 0, 0, 0, 0, 0])).homogeneous))
        .predict(q[None], station="A") for q, ti in zip(Qm, t)]) + rng.normal(size=(n, 3)) * SIGMA
    log = monitor(model, MeasurementSet(list(rb.joint_names), Qm, Ym, time_s=t, source="work"), every=10)
    print(log.summary())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
