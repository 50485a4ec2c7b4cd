"""A measurement campaign in three batches on a simulated UR10, driven through the command line as a user would.

The "real" robot is a simulated UR10 of the shipped ``ur10`` cell: random geometric errors (0.5 mm / 1 mrad per
identifiable joint-placement and set-up component) plus a gear harmonic the model does not know (orders 2 and 3 of the shoulder lift and the elbow,
0.3 mrad each: the *withheld* effect), measured by a laser tracker with σ = 10 µm per axis. Only the measurement
files leave the simulation; every other step is a ``pin-kpi-oed`` command:

1. ``design --cell ur10 --criteria kpi_gp --measurements 60`` (the default discrepancy: nothing is measured yet);
   the 60 poses are "measured" (simulated) to ``measured_1.csv``;
2. ``identify --data measured_1.csv --discrepancy on --model-out m1.json`` (geometry + a Gaussian-process
   discrepancy; scored on 100 held-out random poses, ``--validate``);
3. ``design --given measured_1.csv --model m1.json --criteria kpi_gp --measurements 20 --target-sigma T``
   re-fits the discrepancy on the measured batch, reports the predicted TCP σ at the working configurations now
   and after the next batch, how many poses the target needs (or the plateau), and designs batch 2; measured,
   appended to the poses so far, identified again; and once more for batch 3 — or earlier, when the target is met.

Per batch it prints the poses so far, the predicted TCP σ at the cell's working configurations (RMS 3-D, the design
command's number with the discrepancy re-fitted on everything measured), the TRUE TCP error there (known in
simulation: the calibrated model, discrepancy mean included, against the simulated robot, tracker frame) and the
held-out standardised RMS (1 = honest σ).

Run:  python examples/campaign.py [--out folder] [--target-sigma 3.5e-5] [--batch 20]
(--quick or PIN_KPI_OED_QUICK=1: the same commands on fewer held-out rows, smaller candidate pools, a working
region of 10 samples, one IPOPT start from the heuristic design (``--start random``, no pool selection) of at most
6 iterations, two batches)
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

#: --quick (or PIN_KPI_OED_QUICK=1): smaller sizes, the same steps (the tests' run)
QUICK = os.environ.get("PIN_KPI_OED_QUICK") == "1" or "--quick" in sys.argv[1:]
NOISE_M = 1e-5                     # tracker noise of the simulated measurements, per axis (m)
HARMONIC_RAD = 3e-4                # amplitude of each withheld gear-harmonic component (rad)


class SimulatedRobot:
    """The stand-in for the robot and the tracker: measures poses, and knows the true TCP (simulation only)."""

    def __init__(self, cell, seed: int = 0) -> None:
        import dataclasses

        from pin_kpi_oed.model.noise import NoiseModel
        from pin_kpi_oed.studies.kpi_withheld import withheld_truth

        self.model = dataclasses.replace(cell.tracker_model(), noise=NoiseModel(sigma_xyz_m=(NOISE_M,) * 3))
        # geometric errors of the identifiable parameters and the gear harmonic the model never names
        self.p, self.effects = withheld_truth(self.model, HARMONIC_RAD, seed,
                                              joints=("shoulder_lift_joint", "elbow_joint"))
        self.seed = seed
        self.batches = 0

    def measure(self, Q: np.ndarray):
        """Tracker measurements of the poses Q (a new noise draw per batch)."""
        from pin_kpi_oed.simulation.simulator import simulate

        self.batches += 1
        return simulate(self.model, Q, self.p, effects=self.effects, seed=1000 * self.seed + self.batches)

    def tcp(self, Q: np.ndarray) -> np.ndarray:
        """True TCP positions (tracker frame, m) at Q: the true geometry with the withheld effect."""
        from pin_kpi_oed.studies.kpi_withheld import true_tcp

        return true_tcp(self.model, self.p, self.effects, Q)


def predicted_tcp(model_file: str, Q: np.ndarray, tcp_m: np.ndarray) -> np.ndarray:
    """TCP positions (tracker frame, m) a calibrated model file predicts at Q: geometry + the discrepancy's mean."""
    from pin_kpi_oed.calibrated.model_file import load_model_file
    from pin_kpi_oed.studies import kpi_withheld

    return kpi_withheld.predicted_tcp(load_model_file(model_file), Q, tcp_m=tcp_m)


def cli(args: list[str], log: Path | None = None, show: tuple[str, ...] = ()) -> str:
    """Run ``pin-kpi-oed ARGS`` in this process; print the command and the lines starting with ``show``."""
    from pin_kpi_oed.cli.app import main

    print("$ pin-kpi-oed " + " ".join(args))
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        rc = main(args)
    out = buf.getvalue()
    if log is not None:
        with open(log, "a") as fh:
            fh.write("$ pin-kpi-oed " + " ".join(args) + "\n" + out + "\n")
    if rc != 0:
        raise SystemExit(f"pin-kpi-oed {args[0]} failed (exit {rc}):\n{out}")
    for line in out.splitlines():
        if line.startswith(show):
            print("    " + line)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smaller sizes, the same steps")
    ap.add_argument("--out", default=None, help="folder of the campaign's files (default: a temporary folder)")
    ap.add_argument("--target-sigma", dest="target", type=float, default=3.5e-5,
                    help="target TCP sigma at the working configurations (m, default 3.5e-5)")
    ap.add_argument("--first", type=int, default=60, help="poses of batch 1 (>= 60: the Gaussian process needs 60)")
    ap.add_argument("--batch", type=int, default=20, help="poses of each later batch")
    ap.add_argument("--batches", type=int, default=2 if QUICK else 3, help="most batches")
    ap.add_argument("--seed", type=int, default=0, help="seed of the simulated robot and every design")
    a = ap.parse_args(argv)

    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.data.measurements import write_measurements
    from pin_kpi_oed.design.design_file import load_design
    from pin_kpi_oed.design.optimize import DesignProblem
    from pin_kpi_oed.identification.identify import validate
    from pin_kpi_oed.calibrated.model_file import load_model_file

    cell = load_cell("ur10")
    robot = SimulatedRobot(cell, seed=a.seed)
    W = cell.q_work
    refl = ",".join(f"{v:g}" for v in cell.tracker_model().reflector_m)
    pool = ["--pool-size", "50" if QUICK else "1000"]
    knobs = ["--starts", "1", "--seed", str(a.seed)]
    if QUICK:  # the same commands, smaller: a start from the heuristic design, fewer iterations, a smaller region
        knobs += ["--start", "random", "--max-iter", "6", "--work-samples", "10"]

    with tempfile.TemporaryDirectory(prefix="pin_kpi_oed_campaign_") as tmp:
        out = Path(a.out) if a.out else Path(tmp)
        out.mkdir(parents=True, exist_ok=True)
        log = out / "campaign.log"
        # held-out poses (feasible in the cell, never designed): the honest-sigma check of every calibration
        Q_held, _ = DesignProblem(cell).random_design(30 if QUICK else 100, seed=np.random.SeedSequence([a.seed, 9]))
        write_measurements(robot.measure(Q_held), out / "held.csv")
        rows, measured = [], []
        design_args = ["design", "--cell", "ur10", "--criteria", "kpi_gp", "--measurements", str(a.first),
                       "--json", str(out / "d1.json")] + knobs
        cli(design_args, log, show=("discrepancy (", "kpi_gp "))
        predicted_design = None
        for k in range(1, a.batches + 1):
            d = json.loads((out / f"d{k}.json").read_text())
            # only the poses are needed here: the stored C_s is not recomputed (an identifiability analysis)
            entry = load_design(out / f"d{k}.json", criteria=["kpi_gp"], compute_missing=False).design("kpi_gp")
            predicted_design = [x["discrepancy"]["tcp_sigma_m"] for x in d["designs"] if x["criterion"] == "kpi_gp"][0]
            measured.append(robot.measure(np.asarray(entry.q_meas, float)))
            so_far = out / f"measured_{k}.csv"
            write_measurements(joined(measured), so_far)       # one session: every batch with the same tracker
            print(f"batch {k}: measured {len(entry.q_meas)} poses (simulated) -> {so_far.name}")
            model_file = out / f"m{k}.json"
            cli(["identify", "--robot", "ur10", "--data", str(so_far), "--validate", str(out / "held.csv"),
                 "--reflector", refl, "--discrepancy", "on", "--accept-poor-fit",
                 "--model-out", str(model_file), "--quiet"], log, show=("after",))
            err = np.linalg.norm(predicted_tcp(str(model_file), W, cell.tracker_model().tcp_m) - robot.tcp(W), axis=1)
            v = validate(load_model_file(model_file), load_measurements(out / "held.csv"))
            # the next batch's design re-fits the discrepancy on everything measured: its sigma "now" is the
            # predicted sigma after this batch
            nxt = out / f"d{k + 1}.json"
            res = cli(["design", "--cell", "ur10", "--given", str(so_far), "--model", str(model_file), "--criteria",
                       "kpi_gp", "--measurements", str(a.batch), "--target-sigma", f"{a.target:g}",
                       "--json", str(nxt)] + knobs + pool, log,
                      show=("measured poses alone", "--target-sigma", "kpi_gp "))
            dn = json.loads(nxt.read_text())
            now = dn["poses_needed"]["sigma_now_m"]
            nxt_sigma = [x["discrepancy"]["tcp_sigma_m"] for x in dn["designs"] if x["criterion"] == "kpi_gp"][0]
            rows.append({"batch": k, "poses": sum(len(m) for m in measured), "predicted_at_design_m": predicted_design,
                         "predicted_m": now, "true_rms_m": float(np.sqrt(np.mean(err ** 2))),
                         "true_max_m": float(err.max()), "z_rms": v["z_rms"], "held_mean_m": v["mean_m"],
                         "next_batch_sigma_m": nxt_sigma, "n_for_target": dn["poses_needed"]["n_for_target"],
                         "plateau_m": dn["poses_needed"]["plateau_m"]})
            if now <= a.target:
                print(f"target {a.target * 1e3:.3f} mm reached after batch {k}")
                break
            if dn["poses_needed"]["n_for_target"] is None:
                print(f"plateau after batch {k}: the target {a.target * 1e3:.3f} mm is out of reach of more poses "
                      f"(the --target-sigma line above)" + ("; measuring the next batch anyway (it still lowers "
                                                             "sigma)" if k < a.batches else ""))
        print()
        print(f"campaign: UR10 cell, withheld gear harmonic {HARMONIC_RAD * 1e3:g} mrad, tracker sigma "
              f"{NOISE_M * 1e6:g} um, {len(W)} working configurations, target {a.target * 1e3:.3f} mm, seed {a.seed}")
        head = (f"{'batch':>5}{'poses':>7}{'pred. at design mm':>20}{'pred. sigma mm':>16}{'TRUE TCP err mm':>17}"
                f"{'held-out z RMS':>16}{'held-out mean mm':>18}{'next batch sigma mm':>21}")
        print(head)
        print("-" * len(head))
        for r in rows:
            print(f"{r['batch']:>5}{r['poses']:>7}{r['predicted_at_design_m'] * 1e3:>20.4f}{r['predicted_m'] * 1e3:>16.4f}"
                  f"{r['true_rms_m'] * 1e3:>17.4f}{r['z_rms']:>16.2f}{r['held_mean_m'] * 1e3:>18.4f}"
                  f"{r['next_batch_sigma_m'] * 1e3:>21.4f}")
        (out / "campaign.json").write_text(json.dumps({"rows": rows, "target_sigma_m": a.target, "seed": a.seed},
                                                      indent=1))
        print(f"files and every command's output: {out}" + ("" if a.out else " (temporary folder)"))
    return 0


def joined(sets: list):
    """The batches measured so far as one measurement set (one station: the tracker has not moved)."""
    from pin_kpi_oed.data.measurements import MeasurementSet

    return MeasurementSet(sets[0].joint_names, np.vstack([s.q for s in sets]),
                          np.vstack([s.position_m for s in sets]), sigma_m=np.vstack([s.sigma_m for s in sets]))


def load_measurements(path):
    from pin_kpi_oed.data.measurements import read_measurements

    return read_measurements(path)


if __name__ == "__main__":
    raise SystemExit(main())
