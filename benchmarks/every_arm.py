"""Every serial arm of example-robot-data (and one ROS-Industrial arm) walked with the README's own-robot steps.

Per arm, its URDF as it ships (``benchmarks.urdf_rounding.ARMS``: the UR family, Panda, Z1, xArm7, the Kinova, the
SO-100/101, the TALOS arm, arms on legged bases, the finger and the two-link arm) and an ABB IRB 2400 from
ROS-Industrial's ``abb_irb2400_support`` expanded with ``xacro`` (``--ros-industrial DIR``: a checkout of
ros-industrial/abb; the pip package ``xacro`` on ``--xacro-path``):

1. **the cell, from the README's recipe** (``cell.yaml`` in the work folder): the URDF path, the tool frame, the base
   on a table (half-space z >= 0), a tracker ``max(1.5, reach + 1)`` m in front facing the robot, the reflector at
   (0.03, 0, 0.05) m on the tool frame and the TCP 0.15 m beyond it along the tool axis (the tool frame's z, the
   axis the docs' incidence limit uses), 10 µm per axis, ``robot_capsules: urdf``; as ``skip_pairs`` the capsule
   pairs that touch by construction (closer than the clearance ``design`` requires by default in at least half of
   64 seeded random configurations: neighbour links' fitted capsules, the base on the table), the beam skipping
   the links of the last joint (the reflector sits on them); three ``working_targets`` (the TCP pose of seeded
   configurations 5 mm beyond the clearance ``design`` requires by default, beam included, with the TCP above the
   table, each with its configuration as ``seed_deg``);
2. ``design --cell cell.yaml --criteria kpi_gp --seed S`` (the cell's 35 measurements, every other option default);
3. ``simulate --design d.json --n-test 40 --effects gear_harmonic=5e-5 --seed S``: a true robot with errors on
   **every** joint-placement parameter (all six of every joint, those no reflector sees included: ``random_truth``
   perturbs every raw parameter), the tracker pose, and an unmodelled gear harmonic, measured at the designed poses
   and at 40 held-out poses feasible in the cell;
4. ``identify --robot URDF --data tr.csv --validate te.csv --model-out m.json --seed S`` (default options; a
   refusal is recorded and the walk goes on with ``--accept-poor-fit``, the option the refusal names);
5. ``predict --model m.json --data te.csv`` (the reflector) and ``predict --at tcp`` (the TCP): standardised RMS of
   true − predicted per axis over the σ per axis (1 when the σ is honest; target [0.67, 1.5]) and the share of rows
   whose Σ z² is within χ²₃(0.95) (target 85–99 %); at the reflector the measured point, at the TCP the TRUE
   simulated TCP (noise-free) against the predicted TCP with the σ at the TCP;
6. ``compensate --model m.json --targets t.csv --cell cell.yaml`` (targets in the tracker frame) and the same with
   ``--frame base`` (targets in the robot's base frame): the working configurations' nominal TCP poses placed where
   the cell puts them; the TRUE robot driven to the compensated joints, its TCP error against the 95 % bound
   (sqrt(χ²₃(0.95)/3) × the stated 3-D σ) and against the uncompensated (nominal IK) joints' error, for the
   targets marked ``ok``;
7. the same through the Python API (``load_cell``, ``read_measurements``, ``identify`` with the cell's model,
   ``CalibratedModel.predict_with_sigma`` / ``predict_tcp``, ``compensate``): the largest difference to the CLI's
   predictions, σ and compensated joints.

An arm the loader refuses, or a step that refuses, is a line naming the cause.

Run: ``python -m benchmarks.every_arm [--robots ur5,panda] [--seed S] [--ros-industrial DIR] [--json out.json]``
(about 1–3 minutes per arm and seed on one core). ``--truths K``: K seeded true robots per arm and seed on the same
designed poses, the per-robot honesty of the TCP's σ (:mod:`benchmarks.every_arm_truths`).
"""

from __future__ import annotations

import argparse
import csv
import json
from typing import Any
import shutil
import sys
import tempfile
import time
import types
from pathlib import Path

import numpy as np
import yaml

from benchmarks.unshipped_robots import BOUND_95, heldout_stats, true_point
from benchmarks.urdf_rounding import ARMS

#: the TCP this far beyond the reflector along the tool axis (m)
TCP_BEYOND_M = 0.15
#: the reflector in the tool frame (m)
REFLECTOR_M = np.array([0.03, 0.0, 0.05])
#: the ROS-Industrial arm: label -> (support package, xacro file under it, tool frame)
ROS_ARMS = {"abb_irb2400": ("abb_irb2400_support", "urdf/irb2400.xacro", "tool0")}
CHI2_3_95 = 7.8147
N_TEST, M_WORK, HARMONIC = 40, 3, "gear_harmonic=5e-5"


def run_cli(*argv: object) -> str:
    """Run one pin-kpi-oed command in-process; its stdout.

    Raises:
        RuntimeError: the command exited non-zero (its stderr's last line).
    """
    from benchmarks.common import cli_in_process

    rc, out, err = cli_in_process(*argv)
    if rc != 0:
        msg = err.strip().splitlines()
        raise RuntimeError(f"{argv[0]} exited {rc}: {msg[-1] if msg else ''}")
    return out


# ---------------------------------------------------------------------------------------------- URDFs
def expand_xacro(support_root: Path, package: str, xacro_rel: str, out: Path, xacro_path: str | None) -> Path:
    """Expand a ROS-Industrial support package's xacro into a plain URDF with the pip package ``xacro``.

    ``$(find PKG)`` resolves to ``support_root/PKG`` (no ROS installation: a stand-in ``ament_index_python``);
    the URDF is written inside the package folder so that its ``package://`` meshes resolve.

    Raises:
        RuntimeError: xacro is not importable or the expansion fails (the cause named).
    """
    if xacro_path:
        sys.path.insert(0, xacro_path)
    pkgs = types.ModuleType("ament_index_python.packages")
    pkgs.get_package_share_directory = lambda p: str(support_root / p)  # type: ignore[attr-defined]
    root = types.ModuleType("ament_index_python")
    root.packages = pkgs  # type: ignore[attr-defined]
    sys.modules.setdefault("ament_index_python", root)
    sys.modules.setdefault("ament_index_python.packages", pkgs)
    try:
        import xacro  # type: ignore[import-not-found]
    except ImportError as exc:
        raise RuntimeError(f"xacro is not installed ({exc}): pip install xacro, then --xacro-path") from exc
    src = support_root / package / xacro_rel
    if not src.is_file():
        raise RuntimeError(f"{src} not found: --ros-industrial must be a checkout of ros-industrial/abb")
    doc = xacro.process_file(str(src))
    out = support_root / package / "urdf" / out.name
    out.write_text(doc.toprettyxml(indent="  "))
    return out


def arm_urdf(label: str, work: Path, args: argparse.Namespace) -> tuple[Path, str]:
    """The URDF path and tool frame of one arm. Raises RuntimeError when the ROS-Industrial arm is unavailable."""
    from pin_kpi_oed.model.robot import erd_root

    if label in ARMS:
        rel, tool = ARMS[label]
        return erd_root() / rel, tool
    pkg, rel, tool = ROS_ARMS[label]
    if not args.ros_industrial:
        raise RuntimeError("no --ros-industrial checkout given (ros-industrial/abb): not run")
    root = work / "ros"
    if not root.exists():
        shutil.copytree(Path(args.ros_industrial), root, ignore=shutil.ignore_patterns(".git", "*.dae"))
    return expand_xacro(root, pkg, rel, Path(f"{label}_expanded.urdf"), args.xacro_path), tool


# ---------------------------------------------------------------------------------------------- the cell
def base_cell(urdf: Path, tool: str, reach: float) -> dict:
    """The README recipe's cell without skip pairs and working targets (module docstring, step 1)."""
    d = max(1.5, reach + 1.0)
    refl = REFLECTOR_M
    return {"name": urdf.stem, "robot": str(urdf), "tool_frame": tool,
            "base": {"xyz_m": [0.0, 0.0, 0.0], "rpy_deg": [0.0, 0.0, 0.0]},
            "tracker": {"xyz_m": [d, 0.2, 0.5 * reach], "rpy_deg": [0.0, 0.0, 180.0]},
            "reflector_m": refl.tolist(), "tcp_m": (refl + [0.0, 0.0, TCP_BEYOND_M]).tolist(),
            "noise": {"sigma_xyz_m": [1e-5, 1e-5, 1e-5]}, "robot_capsules": "urdf",
            "obstacles": {"half_spaces": [{"name": "table", "normal": [0.0, 0.0, 1.0], "offset_m": 0.0}]},
            "measurements": 35}


def tool_links(robot) -> list[str]:
    """The links with capsules moved by the last joint (the reflector is mounted on them)."""
    import pinocchio as pin

    from pin_kpi_oed.cell.cell import capsules_from_urdf

    last = robot.model.getJointId(robot.joint_names[-1])
    caps = {c.link for c in capsules_from_urdf(robot)}
    return sorted({f.name for f in robot.model.frames
                   if f.type == pin.FrameType.BODY and f.parentJoint == last and f.name in caps})


def write_cell(label: str, urdf: Path, tool: str, folder: Path) -> Path:
    """Write the arm's cell (module docstring, step 1); its path."""
    from pin_kpi_oed.cell.cell import cell_from_dict
    from pin_kpi_oed.cell.feasibility import FeasibilityChecker
    from pin_kpi_oed.design.margins import DEFAULT_CLEARANCE_MARGIN_M
    from pin_kpi_oed.model.robot import load_robot

    robot = load_robot(str(urdf), tool_frame=tool)
    d = base_cell(urdf, tool, float(robot.reach()))
    links = tool_links(robot)
    d["beam"] = {"radius_m": 0.005, "skip": links}
    d["working_configurations_rad"] = [[0.5 * (a + b) for a, b in zip(robot.q_lower, robot.q_upper)]]
    chk = FeasibilityChecker(cell_from_dict(d, str(folder / "cell.yaml"), robot=robot))
    rng = np.random.default_rng(0)
    Q = robot.random_q(rng, 64)
    D = np.array([chk.pair_distances(q) for q in Q])
    clr = chk.cell.clearance_m + DEFAULT_CLEARANCE_MARGIN_M  # what design requires with its default margin
    d["skip_pairs"] = [list(p) for p, share in zip(chk.pair_names, np.mean(D < clr, axis=0)) if share >= 0.5]
    chk = FeasibilityChecker(cell_from_dict(d, str(folder / "cell.yaml"), robot=robot))
    del d["working_configurations_rad"]
    tcp = np.asarray(d["tcp_m"])
    work: list = []
    for q in robot.random_q(rng, 2000):
        M = robot.oMtool(q)
        p = M.act(tcp)
        if p[2] > 0.05 * robot.reach() + 0.02 and chk.check(q[None]).clearance_m[0] > clr + 0.005:
            import pinocchio as pin

            rpy = np.degrees(pin.rpy.matrixToRpy(M.rotation))
            work.append({"xyz_m": [round(float(v), 6) for v in p], "rpy_deg": [round(float(v), 4) for v in rpy],
                         "seed_deg": [round(float(v), 4) for v in np.degrees(q)]})
            if len(work) == M_WORK:
                break
    if len(work) < M_WORK:
        raise RuntimeError(f"only {len(work)} collision-free working configurations above the table in 2000 draws")
    d["working_targets"] = work
    path = folder / "cell.yaml"
    path.write_text(f"# {label}: written by benchmarks.every_arm from the README's own-robot recipe\n"
                    + yaml.safe_dump(d, sort_keys=False))
    return path


# ---------------------------------------------------------------------------------------------- measures
def write_targets(path: Path, X: np.ndarray, orientation: bool = True) -> Path:
    """A targets CSV (name, x, y, z m, rx, ry, rz rad; without the orientation: positions only, the targets of an
    arm of fewer than six joints)."""
    cols = ["x", "y", "z", "rx", "ry", "rz"][:6 if orientation else 3]
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["name", *cols])
        w.writerows([[f"w{k}", *map(repr, map(float, x[:len(cols)]))] for k, x in enumerate(X)])
    return path


def limits(robot) -> list[float]:
    """Per joint, the largest magnitude the readers' unit guard allows (rad / m): the robot's own
    :attr:`~pin_kpi_oed.model.robot.Robot.unit_guard`."""
    return robot.unit_guard.tolist()


def targets(truth: tuple, cm, frame: str) -> np.ndarray:
    """(k, 6) targets: the nominal robot's TCP pose at the model's working configurations, in the true tracker frame
    (``cell``) or the base frame (``base``): where the cell puts them."""
    import pinocchio as pin

    T = truth[0].tracker_pose(truth[1]) if frame == "cell" else pin.SE3.Identity()
    rows = []
    for q in cm.q_work:
        M = cm.robot.oMtool(q)
        rows.append(np.r_[T.act(M.act(cm.tcp_m)), pin.log3(T.rotation @ M.rotation)])
    return np.array(rows)


def true_tcp(truth: tuple, tcp_m: np.ndarray, Q: np.ndarray, frame: str) -> np.ndarray:
    """The TRUE robot's TCP at Q, (m, 3) m, in its true tracker frame or its base frame."""
    P = true_point(truth, tcp_m, Q)
    if frame == "cell":
        return P
    T = truth[0].tracker_pose(truth[1])
    return (P - T.translation) @ T.rotation


def tcp_heldout(pred_csv: Path, truth: tuple, tcp_m: np.ndarray, Q: np.ndarray) -> dict:
    """The TRUE TCP against ``predict --at tcp``'s table: standardised RMS per axis, share inside the 95 %
    ellipsoid, mean predicted 3-D σ, RMS true error (m)."""
    rows = list(csv.DictReader(open(pred_csv)))
    P = np.array([[float(r[f"{a}_pred"]) for a in "xyz"] for r in rows])
    S = np.array([[float(r[f"sigma_{a}"]) for a in "xyz"] for r in rows])
    E = true_tcp(truth, tcp_m, Q, "cell") - P
    z2 = (E / S) ** 2
    return {"n": len(rows), "z_rms": float(np.sqrt(z2.mean())),
            "inside_95": float(np.mean(z2.sum(axis=1) <= CHI2_3_95)),
            "sigma_mean_m": float(np.mean([float(r["sigma_tcp"]) for r in rows])),
            "held_mean_m": float(np.mean([float(r["sigma_held"]) for r in rows])),
            "error_rms_m": float(np.sqrt(np.mean(np.sum(E ** 2, axis=1))))}


def held_draws(cm, truth: tuple, te) -> list[dict]:
    """The parameters the σ at the TCP holds at their tolerance, each with its RMS 3-D σ at the TCP over the
    held-out rows and its TRUE simulated value in units of that tolerance (one draw per simulated robot: the TCP's
    standardised error over one robot's poses follows these few draws, not an average over robots)."""
    from pin_kpi_oed.model.tolerances import Tolerances

    ts = cm.predict_tcp(te.q, aux=te)
    model, p, _ = truth
    s = Tolerances().sigma_vector(model)
    L = model.layout
    return [{"name": n, "sigma_at_tcp_m": float(c),
             "true_over_tolerance": float(p[L.names.index(n)] / s[L.names.index(n)])}
            for n, c in sorted(zip(ts.held_names, ts.held_contrib_m), key=lambda x: -x[1])[:3]]


def compensation(truth: tuple, cm, res: dict, X: np.ndarray, frame: str) -> dict:
    """The true robot's TCP at the compensated joints against the targets: per target error, uncompensated error,
    95 % bound, status; and the verdicts over the targets marked ok."""
    Q, Qn = np.array(res["q"], float), np.array(res["q_nominal"], float)
    err = np.linalg.norm(true_tcp(truth, cm.tcp_m, Q, frame) - X[:, :3], axis=1)
    nom = np.linalg.norm(true_tcp(truth, cm.tcp_m, Qn, frame) - X[:, :3], axis=1)
    bound = np.array(res["sigma_m"], float) * BOUND_95
    ok = np.array([s == "ok" for s in res["target_status"]])
    return {"status": list(res["target_status"]), "error_m": err.tolist(), "uncompensated_m": nom.tolist(),
            "bound95_m": bound.tolist(), "n_ok": int(ok.sum()), "q": Q.tolist(),
            "within_bound": bool(np.all(err[ok] <= bound[ok])),
            "not_worse": bool(np.all(err[ok] <= nom[ok]))}


def work_files(w: Path) -> dict[str, Path]:
    """The walk's files in the work folder ``w``, by key."""
    names = dict(cell="cell.yaml", d="d.json", tr="tr.csv", te="te.csv", truth="truth.json", m="m.json",
                 pr="pred.csv", pt="pred_tcp.csv", t="t.csv", tb="t_base.csv", j="j.csv", jj="j.json",
                 jb="jb.csv", jjb="jb.json")
    return {k: w / v for k, v in names.items()}


def walk_cli(f: dict[str, Path], urdf: Path, seed: int) -> dict:
    """Steps 2-6 through the command line (module docstring)."""
    from pin_kpi_oed.calibrated.model_file import load_model_file
    from pin_kpi_oed.data.measurements import read_measurements
    from pin_kpi_oed.simulation.simulator import load_truth

    out: dict = {}
    run_cli("design", "--cell", f["cell"], "--criteria", "kpi_gp", "--seed", seed, "--json", f["d"], "--quiet")
    run_cli("simulate", "--design", f["d"], "--n-test", N_TEST, "--effects", HARMONIC, "--seed", seed,
            "--truth", f["truth"], "--out", f["tr"], "--test-out", f["te"])
    ident = ["identify", "--robot", urdf, "--data", f["tr"], "--validate", f["te"], "--model-out", f["m"],
             "--seed", seed]
    try:
        text = run_cli(*ident)
    except RuntimeError as exc:
        out["identify_refused"] = str(exc)
        text = run_cli(*ident, "--accept-poor-fit")
    out["identify_lines"] = [ln for ln in text.splitlines() if ln.startswith(("fit", "held-out", "TCP", "predicted"))]
    run_cli("predict", "--model", f["m"], "--data", f["te"], "--out", f["pr"], "--quiet")
    run_cli("predict", "--model", f["m"], "--data", f["te"], "--out", f["pt"], "--at", "tcp", "--quiet")
    truth, cm = load_truth(str(f["truth"])), load_model_file(f["m"])
    te = read_measurements(f["te"], joint_names=cm.robot.joint_names, joint_guard=limits(cm.robot))
    out["reflector"] = heldout_stats(f["pr"])
    out["tcp"] = tcp_heldout(f["pt"], truth, cm.tcp_m, te.q)
    out["held"] = held_draws(cm, truth, te)
    for frame, (_, c) in compensate_both_frames(f, truth, cm).items():
        out[f"compensate_{frame}"] = c
    return out


def compensate_both_frames(f: dict, truth: Any, cm: Any) -> dict[str, tuple[dict, dict]]:
    """``compensate`` the true TCPs' targets in the cell (tracker) and the base frame: frame -> (the command's JSON,
    :func:`compensation` of it against the truth)."""
    out = {}
    for frame, t, j, jj in (("cell", "t", "j", "jj"), ("base", "tb", "jb", "jjb")):
        X = targets(truth, cm, frame)
        write_targets(f[t], X, cm.robot.nq >= 6)
        run_cli("compensate", "--model", f["m"], "--targets", f[t], "--cell", f["cell"],
                "--frame", "tracker" if frame == "cell" else frame,
                "--out", f[j], "--json", f[jj], "--quiet")
        res = json.loads(f[jj].read_text())
        out[frame] = (res, compensation(truth, cm, res, X, frame))
    return out


def walk_api(f: dict[str, Path], cli: dict) -> dict:
    """Step 7: the same files through the Python API; the largest differences to the CLI's numbers."""
    import pin_kpi_oed as pko
    from pin_kpi_oed.simulation.simulator import load_truth

    cell = pko.load_cell(f["cell"])
    lim = limits(cell.robot)
    train = pko.read_measurements(f["tr"], joint_names=cell.robot.joint_names, joint_guard=lim)
    test = pko.read_measurements(f["te"], joint_names=cell.robot.joint_names, joint_guard=lim)
    cm = pko.identify(cell.tracker_model(), train).calibrated_model()
    Y, S, _ = cm.predict_with_sigma(test.q, test)
    ts = cm.predict_tcp(test.q, aux=test)
    sd = np.sqrt(np.einsum("maa->ma", ts.covariance_m2))
    pr = np.array([[float(r[k]) for k in ("x_pred", "y_pred", "z_pred", "sigma_x", "sigma_y", "sigma_z")]
                   for r in csv.DictReader(open(f["pr"]))])
    pt = np.array([[float(r[k]) for k in ("x_pred", "y_pred", "z_pred", "sigma_x", "sigma_y", "sigma_z")]
                   for r in csv.DictReader(open(f["pt"]))])
    truth = load_truth(str(f["truth"]))
    X = targets(truth, cm, "cell")
    res = pko.compensate(cm, pko.read_targets(f["t"], cell.robot.joint_names), pko.CompensationOptions(cell=cell))
    q_api = np.array(json.loads(json.dumps(res.to_dict()))["q"], float)
    return {"reflector_pred_m": float(np.abs(Y - pr[:, :3]).max()),
            "reflector_sigma_rel": float(np.abs(S / pr[:, 3:] - 1).max()),
            "tcp_pred_m": float(np.abs(ts.position_m - pt[:, :3]).max()),
            "tcp_sigma_rel": float(np.abs(sd / pt[:, 3:] - 1).max()),
            "compensated_q_rad": float(np.abs(q_api - np.array(cli["compensate_cell"]["q"])).max()),
            "n_targets": len(X)}


def run_arm(label: str, seed: int, work: Path, args: argparse.Namespace) -> dict:
    """One arm at one seed: the walk, or the cause of its refusal."""
    from pin_kpi_oed.errors import PinKpiOedError
    from pin_kpi_oed.model.robot import erd_root

    w = work / f"{label}_s{seed}"
    shutil.rmtree(w, ignore_errors=True)  # simulate --truth reads an existing truth file: start clean
    w.mkdir(parents=True)
    f = work_files(w)
    t0 = time.process_time()
    step = "URDF"
    try:
        urdf, tool = arm_urdf(label, work, args)
        step = "cell"
        write_cell(label, urdf, tool, w)
        step = "walk"
        out = {"arm": label, "seed": seed, **walk_cli(f, urdf, seed)}
        step = "API"
        out["api_vs_cli"] = walk_api(f, out)
    except (PinKpiOedError, RuntimeError) as exc:
        return {"arm": label, "seed": seed, "refused_at": step,
                "refused": str(exc).replace(str(erd_root()) + "/", "").replace(str(work) + "/", "")}
    out["cpu_s"] = time.process_time() - t0
    return out


def _verdict(v: float, lo: float, hi: float) -> str:
    return f"{v:.2f}" + ("" if lo <= v <= hi else "!")


def line(r: dict) -> str:
    """One row of the table (``!`` marks a figure outside its target)."""
    if "refused" in r:
        return f"{r['arm']:<19} s{r['seed']}  refused ({r['refused_at']}): {r['refused']}"
    a, t = r["reflector"], r["tcp"]
    cells = [f"{_verdict(a['z_rms'], 0.67, 1.5):>6} {_verdict(a['inside_95'] * 100, 85, 99):>5}",
             f"{_verdict(t['z_rms'], 0.67, 1.5):>6} {_verdict(t['inside_95'] * 100, 85, 99):>5} "
             f"{t['sigma_mean_m'] * 1e6:7.1f} {t['error_rms_m'] * 1e6:7.1f}"]
    for fr in ("cell", "base"):
        c = r[f"compensate_{fr}"]
        worst = max((e / b for e, b, s in zip(c["error_m"], c["bound95_m"], c["status"]) if s == "ok"), default=0.0)
        every = sum(e <= b for e, b in zip(c["error_m"], c["bound95_m"]))
        a, b = ("-", "-") if not c["n_ok"] else (
            "yes" if c["within_bound"] else "NO", "yes" if c["not_worse"] else "NO")
        cells.append(f"{c['n_ok']}/{len(c['status'])} {worst:5.2f} {a:>3} {b:>3} ({every} in b)")
    api = r["api_vs_cli"]
    diff = max(api["reflector_pred_m"], api["tcp_pred_m"])
    sdiff = max(api["reflector_sigma_rel"], api["tcp_sigma_rel"])
    fit = " (poor fit refused; --accept-poor-fit)" if "identify_refused" in r else ""
    held = "; ".join(f"{h['name']} {h['sigma_at_tcp_m'] * 1e6:.0f} µm drawn at {h['true_over_tolerance']:+.2f} tol"
                     for h in r["held"][:1])
    return (f"{r['arm']:<19} s{r['seed']}  " + "  ".join(cells)
            + f"  {diff:.1e} {sdiff:.1e} {api['compensated_q_rad']:.1e}  {r['cpu_s']:5.0f}{fit}  held: {held}")


def pooled(rows: list[dict]) -> str:
    """The standardised RMS and the share inside over every simulated robot (arm and seed) that ran: the σ's
    honesty over robots, where each robot's own rows share one draw of the held parameters."""
    ran = [r for r in rows if "refused" not in r]
    if not ran:
        return "no arm ran"
    parts = []
    for k in ("reflector", "tcp"):
        z = np.sqrt(np.mean([r[k]["z_rms"] ** 2 for r in ran]))
        inside = np.mean([r[k]["inside_95"] for r in ran])
        parts.append(f"{k}: standardised RMS {z:.2f}, {inside * 100:.0f} % inside")
    comp = [(r[f"compensate_{fr}"]["within_bound"], r[f"compensate_{fr}"]["not_worse"]) for r in ran
            for fr in ("cell", "base") if r[f"compensate_{fr}"]["n_ok"]]
    return (f"pooled over {len(ran)} simulated robots ({len({r['arm'] for r in ran})} arms): " + "; ".join(parts)
            + f"; compensation: {sum(a for a, _ in comp)} of {len(comp)} runs with an ok target had every ok "
            f"target within its bound, "
            f"{sum(b for _, b in comp)} of {len(comp)} with none farther than uncompensated; "
            f"{len(rows) - len(ran)} rows refused")


HEADER = ("arm                 seed  refl: z   in%  TCP: z   in%  σ µm   err µm  comp cell: ok "
          "e/b95 in≤b ≤unc  comp base: ok e/b95 in≤b ≤unc  API-CLI: pos m, σ rel, q rad  cpu s")


def main(argv: list[str] | None = None) -> list[dict]:
    """Walk the arms; print one row per arm and seed; returns the rows (``--json`` writes them)."""
    ap = argparse.ArgumentParser(prog="python -m benchmarks.every_arm", description=__doc__.splitlines()[0])
    ap.add_argument("--robots", default=",".join([*ARMS, *ROS_ARMS]), help="comma-separated labels (default: all)")
    ap.add_argument("--seed", default="0,1", help="comma-separated seeds (default 0,1)")
    ap.add_argument("--ros-industrial", default=None, help="a checkout of ros-industrial/abb (for abb_irb2400)")
    ap.add_argument("--xacro-path", default=None, help="folder holding the pip package xacro, if not importable")
    ap.add_argument("--out", default=None, help="work folder (default: a temporary one)")
    ap.add_argument("--json", default=None, help="write the rows to this JSON file")
    ap.add_argument("--truths", type=int, default=0,
                    help="K > 0: K seeded true robots per arm and seed on the same designed poses, the per-robot TCP "
                         "honesty (benchmarks.every_arm_truths)")
    args = ap.parse_args(argv if argv is not None else [])
    seeds = [int(s) for s in str(args.seed).split(",") if s.strip()]
    if args.truths > 0:
        from benchmarks.every_arm_truths import main_truths

        labels = [a.strip() for a in args.robots.split(",") if a.strip()]
        unknown = [a for a in labels if a not in ARMS and a not in ROS_ARMS]
        if unknown:
            raise SystemExit(f"unknown arm '{unknown[0]}' (arms: {', '.join([*ARMS, *ROS_ARMS])})")
        with tempfile.TemporaryDirectory() as tmp:
            return main_truths(labels, seeds, args.truths, Path(args.out) if args.out else Path(tmp), args)
    print(f"{len(seeds)} seed(s); z = standardised RMS (target 0.67-1.5), in% = share inside the 95 % ellipsoid "
          "(85-99); σ = mean predicted 3-D TCP σ, err = RMS true 3-D TCP error; comp: targets ok of all, worst "
          "true error / 95 % bound over the ok ones, every ok one within its bound, every ok one no farther than "
          "uncompensated ('-': none ok), (targets of any status within their bound); "
          "! = outside the target", flush=True)
    print(HEADER, flush=True)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(args.out) if args.out else Path(tmp)
        for label in [a.strip() for a in args.robots.split(",") if a.strip()]:
            if label not in ARMS and label not in ROS_ARMS:
                raise SystemExit(f"unknown arm '{label}' (arms: {', '.join([*ARMS, *ROS_ARMS])})")
            for seed in seeds:
                rows.append(run_arm(label, seed, work, args))
                print(line(rows[-1]), flush=True)
                if "refused" in rows[-1] and rows[-1]["refused_at"] in ("URDF", "cell"):
                    break  # the same cause at every seed
                if args.json:
                    Path(args.json).write_text(json.dumps(rows, indent=1, default=float))
    print(pooled(rows), flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1, default=float))
    return rows


if __name__ == "__main__":
    main(sys.argv[1:])
