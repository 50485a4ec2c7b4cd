"""Robots the package ships no cell for, walked as a newcomer would with the README's commands and default options.

Two arms: the Franka Panda (7 joints, ``panda`` loads by name; tool frame panda_link8, a gripper TCP) and the Unitree
Z1 (6 joints of another layout; its URDF from example-robot-data 6.0.0 beside the cell). Their cells
(``benchmarks/data/panda_cell.yaml``, ``z1_cell.yaml``) are written from the README's recipe. Per robot:

1. ``design --cell CELL --criteria kpi_gp`` (the cell's 35 measurements);
2. ``simulate --design d.json --n-test 40 --effects gear_harmonic=5e-5 --truth truth.json``: a true robot with
   random geometric errors and an unmodelled gear harmonic, measured at the designed poses, and at 40 held-out
   poses feasible in the cell;
3. ``identify --robot ROBOT --data tr.csv --validate te.csv --model-out m.json`` (the tool, reflector, TCP and
   working configurations from the data's tool header);
4. ``predict --model m.json --data te.csv``: held-out standardised RMS of measured - predicted (1 when the sigma is
   honest; target [0.67, 1.5]) and share inside the 95 % ellipsoid (target 85-99 %);
5. ``compensate --model m.json --targets targets.csv --cell CELL``: the working targets (the TCP of every working
   configuration, in the true tracker frame) compensated; the TRUE simulated robot driven to the compensated joints,
   its TCP error against the predicted 95 % bound (sqrt(chi2_3(0.95)/3) x the 3-D sigma), and whether the compensated
   configuration is on the working configuration's branch (largest joint difference, deg). The same at the
   reflector (``--tcp`` = the fitted reflector): the point the calibration measured.

Then the same numbers through the Python API (``read_measurements``, ``identify``, ``CalibratedModel``,
``compensate``) on the same files.

Run: ``python -m benchmarks.unshipped_robots [--robots panda,z1] [--out DIR] [--json out.json]`` (``make bench``;
about 2 minutes per robot on one core).
"""

from __future__ import annotations

import argparse
import csv
import json
import tempfile
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parent / "data"
#: robot -> (cell file, robot spec as a newcomer gives it to identify)
ROBOTS = {"panda": (DATA / "panda_cell.yaml", "panda"), "z1": (DATA / "z1_cell.yaml", str(DATA / "z1.urdf"))}
#: 95 % bound of a 3-D Gaussian error with isotropic per-axis sigma: sqrt(chi2_3(0.95) / 3) x the 3-D sigma
BOUND_95 = float(np.sqrt(7.8147 / 3.0))
#: a compensated configuration within this of the working configuration is on its branch (deg)
BRANCH_DEG = 5.0


def _cli(*argv: object) -> str:
    """Run one pin-kpi-oed command in-process; its stdout. Raises RuntimeError with its stderr on a refusal."""
    from benchmarks.common import cli_in_process

    rc, out, err = cli_in_process(*argv)
    if rc != 0:
        raise RuntimeError(f"pin-kpi-oed {' '.join(map(str, argv[:1]))} exited {rc}: {err.strip()}")
    return out


def true_point(truth: tuple, point_m: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """A point of the tool (tool frame, m) on the TRUE simulated robot (geometric errors + effects), in its true
    tracker frame, (m, 3) m."""
    from pin_kpi_oed.data.measurements import MeasurementSet
    from pin_kpi_oed.identification.identify import predict
    from pin_kpi_oed.model.tracker import TrackerModel

    model, p, effects = truth
    mt = TrackerModel(model.robot, tracker_T_base=model.tracker_T_base, reflector_m=np.asarray(point_m, float),
                      noise=model.noise)
    p = p.copy()
    p[mt.layout.reflector] = 0.0
    aux = MeasurementSet(list(model.robot.joint_names), Q, np.zeros((len(Q), 3)))
    return predict(mt, p, Q, [e for e, _ in effects], [t for _, t in effects], aux)[:, :3]


def working_targets(truth: tuple, cm, point_m: np.ndarray) -> np.ndarray:
    """(k, 6) targets x, y, z (m), rx, ry, rz (rad): ``point_m`` of the nominal robot at the model's working
    configurations, placed in the true tracker frame (where the cell puts them)."""
    import pinocchio as pin

    T = truth[0].tracker_pose(truth[1])
    rows = []
    for q in cm.q_work:
        M = cm.robot.oMtool(q)
        rows.append(np.r_[T.act(M.act(point_m)), pin.log3(T.rotation @ M.rotation)])
    return np.array(rows)


def _write_targets(path: Path, X: np.ndarray) -> None:
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["name", "x", "y", "z", "rx", "ry", "rz"])
        w.writerows([[f"w{k}", *map(repr, map(float, x))] for k, x in enumerate(X)])


def heldout_stats(pred_csv: Path) -> dict:
    """Standardised RMS and share inside the 95 % ellipsoid from ``predict``'s table (measured x, y, z; sigma)."""
    rows = list(csv.DictReader(open(pred_csv)))
    E = np.array([[float(r[a]) - float(r[f"{a}_pred"]) for a in "xyz"] for r in rows])
    S = np.array([[float(r[f"sigma_{a}"]) for a in "xyz"] for r in rows])
    z2 = (E / S) ** 2
    return {"n": len(rows), "z_rms": float(np.sqrt(z2.mean())), "inside_95": float(np.mean(z2.sum(axis=1) <= 7.8147)),
            "sigma_mean_m": float(np.sqrt((S ** 2).sum(axis=1)).mean()),
            "extrapolated": float(np.mean([float(r["extrapolation"]) for r in rows]))}


def compensation_table(truth: tuple, cm, res: dict, point_true_m: np.ndarray, X: np.ndarray) -> list[dict]:
    """Per working target: the true robot's error at the compensated joints, the 95 % bound, the branch."""
    Q, Qn = np.array(res["q"]), np.array(res["q_nominal"])
    err = np.linalg.norm(true_point(truth, point_true_m, Q) - X[:, :3], axis=1)
    err_nom = np.linalg.norm(true_point(truth, point_true_m, Qn) - X[:, :3], axis=1)
    bound = np.array(res["sigma_m"]) * BOUND_95
    branch = np.degrees(np.abs(Q - cm.q_work).max(axis=1))
    return [{"target": f"w{k}", "status": res["target_status"][k], "start": res["start"][k],
             "true_error_m": float(err[k]), "uncompensated_error_m": float(err_nom[k]), "bound95_m": float(bound[k]),
             "within_bound": bool(err[k] <= bound[k]), "branch_deg": float(branch[k]),
             "unseen_bound95_m": float(np.asarray(res.get("tcp_unobservable_m") or np.zeros(len(Q)))[k] * BOUND_95),
             "on_branch": bool(branch[k] <= BRANCH_DEG)} for k in range(len(Q))]


def walk_cli(name: str, work: Path, seed: int = 0) -> dict:
    """The README's commands on one robot (module docstring, steps 1-5)."""
    from pin_kpi_oed.calibrated.model_file import load_model_file
    from pin_kpi_oed.simulation.simulator import load_truth

    cell, spec = ROBOTS[name]
    w = work / name
    w.mkdir(parents=True, exist_ok=True)
    f = {k: w / v for k, v in dict(d="d.json", tr="tr.csv", te="te.csv", truth="truth.json", m="m.json",
                                   pred="pred.csv", t="targets.csv", j="joints.csv", jj="joints.json").items()}
    _cli("design", "--cell", cell, "--criteria", "kpi_gp", "--seed", seed, "--json", f["d"], "--quiet")
    _cli("simulate", "--design", f["d"], "--n-test", 40, "--effects", "gear_harmonic=5e-5", "--seed", seed,
         "--truth", f["truth"], "--out", f["tr"], "--test-out", f["te"])
    ident = _cli("identify", "--robot", spec, "--data", f["tr"], "--validate", f["te"], "--model-out", f["m"],
                 "--accept-poor-fit", "--seed", seed)
    _cli("predict", "--model", f["m"], "--data", f["te"], "--out", f["pred"], "--quiet")
    out: dict = {"robot": name, "identify_lines": [ln for ln in ident.splitlines() if ln.startswith(("after", "fit",
                                                                                                      "tool:"))]}
    out["heldout"] = heldout_stats(f["pred"])
    truth, cm = load_truth(str(f["truth"])), load_model_file(f["m"])
    out["tool_frame"], out["tcp_m"] = cm.robot.tool_frame, cm.tcp_m.tolist()
    for label, point, true_point_m, tcp_opt in (
            ("tcp", cm.tcp_m, cm.tcp_m, []),
            ("reflector", cm.setups[cm.station()].reflector_m, truth[0].reflector(truth[1]),
             ["--tcp", ",".join(repr(float(v)) for v in cm.setups[cm.station()].reflector_m)])):
        X = working_targets(truth, cm, point)
        _write_targets(f["t"], X)
        _cli("compensate", "--model", f["m"], "--targets", f["t"], "--cell", cell, *tcp_opt, "--out", f["j"],
             "--json", f["jj"], "--quiet")
        res = json.loads(f["jj"].read_text())
        out[f"compensation_{label}"] = compensation_table(truth, cm, res, true_point_m, X)
    return out


def walk_api(name: str, work: Path) -> dict:
    """The same files through the Python API: read, identify (its defaults), held-out sigma, compensate."""
    import pin_kpi_oed as pko
    from pin_kpi_oed.identification.heldout import calibration_stats
    from pin_kpi_oed.simulation.simulator import load_truth

    cell_path, _ = ROBOTS[name]
    w = work / name
    cell = pko.load_cell(cell_path)
    train = pko.read_measurements(w / "tr.csv", joint_names=cell.robot.joint_names)
    test = pko.read_measurements(w / "te.csv", joint_names=cell.robot.joint_names)
    result = pko.identify(cell.tracker_model(), train)  # the cell's tool frame, reflector, TCP; the API's defaults
    cm = result.calibrated_model()
    stats = calibration_stats(cm, test.q, test)
    truth = load_truth(str(w / "truth.json"))
    X = working_targets(truth, cm, cm.tcp_m)
    ts = pko.read_targets(_write_api_targets(w / "targets_api.csv", X), cell.robot.joint_names)
    res = pko.compensate(cm, ts, pko.CompensationOptions(cell=cell))
    d = json.loads(json.dumps(res.to_dict()))
    return {"robot": name, "discrepancy": None if cm.discrepancy is None else cm.discrepancy.decision,
            "heldout": {"n": len(test), "z_rms": stats["z_rms"], "inside_95": stats["inside_95"],
                        "sigma_mean_m": stats["sigma_mean_m"], "extrapolated": stats["extrapolation_share"]},
            "compensation_tcp": compensation_table(truth, cm, d, cm.tcp_m, X)}


def _write_api_targets(path: Path, X: np.ndarray) -> Path:
    _write_targets(path, X)
    return path


def _lines(name: str, how: str, r: dict) -> list[str]:
    h = r["heldout"]
    ok_z = 0.67 <= h["z_rms"] <= 1.5
    ok_in = 0.85 <= h["inside_95"] <= 0.99
    lines = [f"{name} ({how}): held-out n={h['n']}: standardised RMS {h['z_rms']:.2f} (target 0.67-1.5: "
             f"{'met' if ok_z else 'NOT met'}), {h['inside_95'] * 100:.0f} % inside the 95 % ellipsoid "
             f"(target 85-99 %: {'met' if ok_in else 'NOT met'}), predicted 3-D sigma mean "
             f"{h['sigma_mean_m'] * 1e3:.4f} mm, "
             f"{h['extrapolated'] * 100:.0f} % of the rows flagged outside the coverage"]
    for label in ("tcp", "reflector"):
        for t in r.get(f"compensation_{label}", []):
            lines.append(f"  {label:<9} {t['target']}: {t['status']:<13} start {t['start']:<8} true error "
                         f"{t['true_error_m'] * 1e3:.4f} mm (uncompensated {t['uncompensated_error_m'] * 1e3:.4f} mm) "
                         f"vs 95 % bound {t['bound95_m'] * 1e3:.4f} mm: {'within' if t['within_bound'] else 'OUTSIDE'};"
                         f" {t['branch_deg']:.3f} deg from the working configuration: "
                         f"{'on its branch' if t['on_branch'] else 'OFF its branch'}")
    return lines


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", default="panda,z1", help="comma-separated: " + ", ".join(ROBOTS))
    ap.add_argument("--out", default=None, help="work folder (default: a temporary one)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv if argv is not None else [])
    names = [n.strip() for n in args.robots.split(",") if n.strip()]
    results: dict = {}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(args.out) if args.out else Path(tmp)
        for name in names:
            cli = walk_cli(name, work, args.seed)
            for ln in cli["identify_lines"]:
                print(f"{name} identify: {ln}")
            print("\n".join(_lines(name, "CLI", cli)), flush=True)
            api = walk_api(name, work)
            print("\n".join(_lines(name, "Python API, identify's defaults", api)), flush=True)
            results[name] = {"cli": cli, "api": api}
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1))
    return results


if __name__ == "__main__":
    main(__import__("sys").argv[1:])
