"""Is the default σ honest on a newcomer's path? Designed poses, an unmodelled gear harmonic, identify's defaults.

Per robot (the shipped UR10 cell, and a Franka Panda, for which the package ships no cell: the cell below is
written as a user would, robot by name, tracker, floor, two working configurations) and number of poses m:

1. the design: ``kpi_gp`` over the working region drawn as ``design`` draws it (default radius and samples, the
   robot class's default discrepancy), selected from a seeded pool of feasible poses of the cell
   (``DesignProblem.criterion("kpi_gp").select``; the pool start of ``run_designs``);
2. per seeded simulated robot: random geometric errors (0.5 mm / 1 mrad on the identifiable parameters) and a gear
   harmonic the model never names (orders 2 and 3 of three joints, ``--amplitude`` rad per component, random
   phases), tracker noise 10 µm per axis; the designed poses measured;
3. ``identify(model, data)`` with the Python API's defaults (discrepancy ``auto``, the fit-quality gate flagged);
4. held-out poses: seeded random poses feasible in the cell, measured on the same simulated robot, predicted with
   ``CalibratedModel.predict_with_sigma`` (``validate``): the RMS of the standardised errors z = error / σ per axis
   (honest within [0.67, 1.5]) and the share of rows inside their 95 % ellipsoid (honest 85-99 %).

Printed per (robot, m): the median and range over the simulated robots, and the pooled figures over all their
held-out rows. With ``--real`` the IPA UR10 series too (see :mod:`benchmarks.sigma_real`).

Run:  OMP_NUM_THREADS=1 python -m benchmarks.sigma_paths [--robots ur10,panda] [--sizes 35,70] [--reps 5]
      [--amplitude 3e-4] [--json out.json]
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

#: A Panda cell as a user writes it from the README (no cell ships for it): the robot by name on the floor, the
#: tracker 2 m in front facing it, the gripper's TCP, the reflector on a holder beyond the fingers (the hand's
#: capsule would block the beam nearer the flange), two working configurations.
PANDA_CELL = {
    "name": "panda_cell", "robot": "panda", "tool_frame": "panda_link8",
    "base": {"xyz_m": [0.0, 0.0, 0.0], "rpy_deg": [0.0, 0.0, 0.0]},
    "tracker": {"xyz_m": [2.0, 0.0, 0.6], "rpy_deg": [0.0, 0.0, 180.0]},
    "reflector_m": [0.04, 0.0, 0.14], "tcp_m": [0.0, 0.0, 0.1034],
    "noise": {"sigma_xyz_m": [1.0e-5, 1.0e-5, 1.0e-5]},
    "robot_capsules": "urdf",
    "obstacles": {"half_spaces": [{"name": "floor", "normal": [0.0, 0.0, 1.0], "offset_m": 0.0}]},
    "skip_pairs": [["panda_link0", "floor"]],
    "incidence_max_deg": 60.0,
    "working_configurations_deg": [[0.0, -20.0, 0.0, -120.0, 0.0, 100.0, 45.0],
                                   [0.0, 30.0, 0.0, -90.0, 0.0, 120.0, 45.0]],
    "measurements": 35,
}
#: The withheld harmonic's joints per robot.
HARMONIC = {"ur10": ("shoulder_lift_joint", "elbow_joint", "wrist_1_joint"),
            "panda": ("panda_joint2", "panda_joint4", "panda_joint6")}


def load_case_cell(name: str):
    from pin_kpi_oed.cell.cell import cell_from_dict, load_cell
    return cell_from_dict(PANDA_CELL, "panda_cell.yaml") if name == "panda" else load_cell(name)


def designed_poses(problem, m: int, pool: int, seed: int) -> np.ndarray:
    """``kpi_gp`` over the working region (the command line's defaults) from a seeded pool of feasible poses."""
    from pin_kpi_oed.design.region import DEFAULT_WORK_RADIUS_RAD, DEFAULT_WORK_SAMPLES, region_in_cell

    if problem.region is None:
        problem = problem.replaced(region=region_in_cell(problem.cell, DEFAULT_WORK_RADIUS_RAD, DEFAULT_WORK_SAMPLES,
                                                         seed))
    Q_pool, _ = problem.random_design(pool, seed=np.random.SeedSequence([seed, 1]))
    return Q_pool[problem.criterion("kpi_gp").select(Q_pool, m).indices]


def one_robot(model, robot_name: str, Q: np.ndarray, Q_held: np.ndarray, amplitude: float, seed: int) -> dict:
    """Simulate, identify with the API's defaults, score the held-out rows (plain numbers)."""
    from pin_kpi_oed.identification.identify import identify, validate
    from pin_kpi_oed.simulation.simulator import simulate
    from pin_kpi_oed.studies.kpi_withheld import withheld_truth

    p_true, effects = withheld_truth(model, amplitude, seed, joints=HARMONIC[robot_name])
    train = simulate(model, Q, p_true, effects=effects, seed=seed + 100)
    held = simulate(model, Q_held, p_true, effects=effects, seed=seed + 200)
    t0 = time.perf_counter()
    fit = identify(model, train)
    cm = fit.calibrated_model()
    v = validate(cm, held)
    Y, sig, extra = cm.predict_with_sigma(held.q, held)
    z2 = ((held.position_m - Y) / sig) ** 2
    return {"seed": seed, "kind": None if fit.discrepancy is None else fit.discrepancy.kind,
            "decision": None if fit.discrepancy is None else fit.discrepancy.decision,
            "verdict": None if fit.fit_quality is None else fit.fit_quality.verdict,
            "mean_m": v["mean_m"], "sigma_m": v["sigma_mean_m"], "z_rms": v["z_rms"], "inside_95": v["inside_95"],
            "extrapolation": v["extrapolation_share"], "z2": z2.tolist(), "time_s": time.perf_counter() - t0}


def run(robots: list[str], sizes: list[int], reps: int, amplitude: float, pool: int, n_held: int) -> list[dict]:
    from pin_kpi_oed.design.optimize import DesignProblem
    from pin_kpi_oed.model.noise import NoiseModel

    rows = []
    print(f"{'robot':<6} {'m':>4} {'kind':>6} {'z RMS median (range)':>24} {'in 95 % median (range)':>26} "
          f"{'pooled z RMS':>12} {'pooled in 95 %':>14} {'extrap':>7} {'mean err':>9} {'sigma':>7}   "
          f"(mm; honest: z 0.67-1.5, 85-99 % inside)", flush=True)
    for name in robots:
        cell = load_case_cell(name)
        problem = DesignProblem(cell)
        model = dataclasses.replace(problem.model, noise=NoiseModel(sigma_xyz_m=(1e-5,) * 3))
        Q_held, _ = problem.random_design(n_held, seed=np.random.SeedSequence([0, 3]))
        for m in sizes:
            t0 = time.perf_counter()
            Q = designed_poses(problem, m, pool, 0)
            runs = [one_robot(model, name, Q, Q_held, amplitude, seed) for seed in range(reps)]
            z = np.array([r["z_rms"] for r in runs])
            ins = np.array([r["inside_95"] for r in runs])
            z2 = np.vstack([np.asarray(r["z2"]) for r in runs])
            kinds = ",".join(sorted({str(r["kind"]) for r in runs}))
            row = {"robot": name, "m": m, "amplitude_rad": amplitude, "kinds": kinds,
                   "z_rms_median": float(np.median(z)), "z_rms_range": [float(z.min()), float(z.max())],
                   "inside_median": float(np.median(ins)), "inside_range": [float(ins.min()), float(ins.max())],
                   "z_rms_pooled": float(np.sqrt(z2.mean())), "inside_pooled": float(np.mean(z2.sum(1) <= 7.8147)),
                   "extrapolation": float(np.mean([r["extrapolation"] for r in runs])),
                   "mean_mm": float(np.mean([r["mean_m"] for r in runs]) * 1e3),
                   "sigma_mm": float(np.mean([r["sigma_m"] for r in runs]) * 1e3),
                   "decisions": [r["decision"] for r in runs], "verdicts": [r["verdict"] for r in runs],
                   "time_s": time.perf_counter() - t0}
            rows.append(row)
            print(f"{name:<6} {m:>4} {kinds:>6} {row['z_rms_median']:>8.2f} ({z.min():.2f}-{z.max():.2f}){'':>9} "
                  f"{row['inside_median'] * 100:>9.1f} % ({ins.min() * 100:.0f}-{ins.max() * 100:.0f} %){'':>6} "
                  f"{row['z_rms_pooled']:>12.2f} {row['inside_pooled'] * 100:>13.1f}% "
                  f"{row['extrapolation'] * 100:>6.1f}% "
                  f"{row['mean_mm']:>9.4f} {row['sigma_mm']:>7.4f}", flush=True)
    return rows


def main(argv: list[str] | None = None) -> int:
    from pin_kpi_oed.data.atomic import atomic_write_json

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", default="ur10,panda")
    ap.add_argument("--sizes", default="35,70")
    ap.add_argument("--reps", type=int, default=5, help="simulated robots per case (seeds 0 .. reps-1)")
    ap.add_argument("--amplitude", type=float, default=3e-4, help="withheld harmonic, rad per component")
    ap.add_argument("--pool", type=int, default=600, help="feasible candidate poses the design selects from")
    ap.add_argument("--held", type=int, default=200, help="held-out random feasible poses")
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    rows = run([r.strip() for r in a.robots.split(",") if r.strip()], [int(s) for s in a.sizes.split(",")],
               a.reps, a.amplitude, a.pool, a.held)
    if a.json:
        atomic_write_json(a.json, {"rows": rows, "args": vars(a)})
    return 0


if __name__ == "__main__":
    sys.exit(main())
