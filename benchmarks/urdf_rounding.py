"""Rounding-proof identifiability: every serial arm of example-robot-data with its URDF's numbers exact and rounded.

A URDF states its numbers rounded (the xArm7's ``rpy="1.5708 0 0"`` is not π/2). The identifiable set and every
design figure must not depend on it. Per arm (its URDF as it ships, found in the installed example-robot-data):

1. three copies of the URDF: **exact** (every ``rpy`` angle within 1e-4 rad of a multiple of π/2 written as that
   multiple to the last bit), **shipped** (as it ships), **rounded** (every number of every attribute rounded to
   4 decimals: angles and lengths off by up to 5e-5 rad / m);
2. on each, a laser-tracker model (reflector off the tool axis, TCP beyond it, tracker 2 reaches in front; lengths
   scaled with the arm's reach; noise 10 µm per axis): the identifiable set (``analyse``), the scores of a seeded
   random design of 35 configurations at 3 seeded working configurations (``score_design``: tr C_s and every
   criterion of the information), and the KPI pool selection of 35 of 2,000 seeded candidates (the relaxation,
   rounding and exchange of ``pool.select``) with its tr C_s;
3. exact against shipped and against rounded: identifiable set equal, every figure within 0.1 %, the same
   selected poses; the residual shares on either side of the rank tolerance (smallest kept, largest dropped).

An arm the loader refuses (a tool frame no joint moves, a multi-DoF joint on the chain) is listed with the refusal's
cause; continuous joints are read as revolute of ±2π rad and limbs branching off the chain locked at neutral, as
``load_robot`` does for every command. No cell (no
obstacles): the figures are those of the information, which is what rounding could change.

Run: ``python -m benchmarks.urdf_rounding [--arms xarm7,panda] [--json out.json]`` (about 1 minute on one core).
"""

from __future__ import annotations

import argparse
import json
import math
import re
import tempfile
import time
from pathlib import Path

import numpy as np

#: label -> (URDF path under example-robot-data's robots folder, tool frame): every serial arm it ships, arms on a
#: mobile base included (their legs and head are locked by the loader)
ARMS: dict[str, tuple[str, str]] = {
    "ur3": ("ur_description/urdf/ur3_robot.urdf", "tool0"),
    "ur3_joint_limited": ("ur_description/urdf/ur3_joint_limited_robot.urdf", "tool0"),
    "ur3_gripper": ("ur_description/urdf/ur3_gripper.urdf", "tool0"),
    "ur5": ("ur_description/urdf/ur5_robot.urdf", "tool0"),
    "ur5_joint_limited": ("ur_description/urdf/ur5_joint_limited_robot.urdf", "tool0"),
    "ur5_gripper": ("ur_description/urdf/ur5_gripper.urdf", "tool0"),
    "ur10": ("ur_description/urdf/ur10_robot.urdf", "tool0"),
    "ur10_joint_limited": ("ur_description/urdf/ur10_joint_limited_robot.urdf", "tool0"),
    "panda": ("panda_description/urdf/panda.urdf", "panda_link8"),
    "z1": ("z1_description/urdf/z1.urdf", "link06"),
    "xarm7": ("xarm_description/urdf/xarm7.urdf", "link7"),
    "kinova": ("kinova_description/robots/kinova.urdf", "j2s6s200_end_effector"),
    "so100": ("so_arm_description/urdf/so100.urdf", "gripper"),
    "so101": ("so_arm_description/urdf/so101.urdf", "gripper_frame_link"),
    "talos_left_arm": ("talos_data/robots/talos_left_arm.urdf", "arm_left_7_link"),
    "baxter_right": ("baxter_description/urdf/baxter.urdf", "right_gripper"),
    "b1_z1": ("b1_description/urdf/b1-z1.urdf", "link06"),
    "anymal_kinova": ("anymal_b_simple_description/robots/anymal-kinova.urdf", "j2s6s200_end_effector"),
    "finger_edu": ("finger_edu_description/robots/finger_edu.urdf", "finger_tip_link"),
    "twodofs": ("asr_twodof_description/urdf/TwoDofs.urdf", "Tip"),
}
#: rpy angles within this of a multiple of π/2 are the rounded form of that multiple (rad)
SNAP_RAD = 1e-4
#: the agreement every figure must show (relative)
REL_TOL = 1e-3
M_MEAS, T_WORK, POOL = 35, 3, 2000

_NUMBER = re.compile(r"(?<![\w.])[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?(?![\w.])")
_ATTR = re.compile(r'(\s[\w:]+=)"([^"]*)"')


def rounded_urdf_text(text: str, decimals: int = 4) -> str:
    """The URDF text with every number of every attribute rounded to ``decimals`` decimals (comments and names with
    digits untouched: a number must stand alone)."""

    def one(mo: re.Match) -> str:
        v = round(float(mo.group(0)), decimals)
        return repr(0.0 if v == 0 else v)

    return _ATTR.sub(lambda a: f'{a.group(1)}"{_NUMBER.sub(one, a.group(2))}"', text)


def exact_urdf_text(text: str, snap_rad: float = SNAP_RAD) -> str:
    """The URDF text with every ``rpy`` angle within ``snap_rad`` of a non-zero multiple of π/2 written as that
    multiple (``repr`` of k·π/2: exact to the last bit)."""

    def one(mo: re.Match) -> str:
        v = float(mo.group(0))
        k = round(v / (math.pi / 2))
        return repr(k * math.pi / 2) if k != 0 and abs(v - k * math.pi / 2) <= snap_rad else mo.group(0)

    return re.sub(r'(\srpy=)"([^"]*)"', lambda a: f'{a.group(1)}"{_NUMBER.sub(one, a.group(2))}"', text)


def tracker_model(robot):
    """A laser-tracker model of ``robot``: reflector off the tool axis and the TCP beyond it, scaled with the reach;
    the tracker 2 reaches in front of the base, facing it; 10 µm per axis."""
    import pinocchio as pin

    from pin_kpi_oed.model.noise import NoiseModel
    from pin_kpi_oed.model.tracker import TrackerModel

    s = max(float(robot.reach()), 0.2)
    R = pin.utils.rpyToMatrix(0.0, 0.0, math.pi)  # tracker x axis towards the base
    T = pin.SE3(R, np.array([2.0 * s, 0.1 * s, 0.3 * s])).inverse()  # base pose in the tracker frame
    return TrackerModel(robot, tracker_T_base=T, reflector_m=s * np.array([0.06, 0.04, 0.08]),
                        tcp_m=s * np.array([0.0, 0.0, 0.15]), noise=NoiseModel(sigma_xyz_m=np.full(3, 1e-5)))


def residual_margins(model, seed: int = 0) -> tuple[float, float]:
    """(smallest residual share of a kept column, largest of a dropped one) of the identifiability analysis's
    ordered selection on its default excitation: the margins on either side of ``RANK_TOL``."""
    from pin_kpi_oed.oed import identifiability as idf

    L = model.layout
    F = model.weighted_jacobian(np.zeros(L.n), idf.excitation(model, seed=seed)).reshape(-1, L.n)
    norms = np.linalg.norm(F, axis=0)
    cand = [i for i in np.flatnonzero(~L.fixed) if norms[i] > 1e-12 * norms.max()]
    setup = L.is_setup()
    order = sorted(range(len(cand)), key=lambda c: (not setup[cand[c]], cand[c]))
    kept, res = idf.ordered_selection(F[:, cand] / norms[cand], order)
    dropped = [c for c in range(len(cand)) if c not in kept]
    return float(res[kept].min()), float(res[dropped].max()) if dropped else 0.0


def configurations(robot, seed: int = 0) -> dict[str, np.ndarray]:
    """The seeded configurations every copy of one arm is scored at (drawn within the exact copy's limits): the
    random design ``Q``, the working configurations ``W``, the candidate pool ``pool`` (rad)."""
    rng = np.random.default_rng(seed)
    return {"Q": robot.random_q(rng, M_MEAS), "W": robot.random_q(rng, T_WORK), "pool": robot.random_q(rng, POOL)}


def figures(path: Path, tool: str, conf: dict[str, np.ndarray], chosen_ref: np.ndarray | None = None,
            seed: int = 0) -> dict:
    """Identifiable set, the random design's scores and the KPI pool selection of one URDF at the configurations
    ``conf`` (clipped into this copy's limits; SI units); with ``chosen_ref`` (another copy's selection) also its
    tr C_s on this copy."""
    from pin_kpi_oed.model.robot import load_robot
    from pin_kpi_oed.oed.evaluate import score_design
    from pin_kpi_oed.oed.identifiability import analyse
    from pin_kpi_oed.oed.objective import DesignCriterion

    robot = load_robot(str(path), tool_frame=tool)
    model = tracker_model(robot)
    ident = analyse(model, seed=seed)
    Q, W, pool = (np.clip(conf[k], robot.q_lower, robot.q_upper) for k in ("Q", "W", "pool"))
    score = score_design(model, Q, W, ident=ident)
    E = model.kpi_jacobian(np.zeros(model.n_params), W)[:, ident.base]
    sel = DesignCriterion(model, ident.base, "kpi", E).select(pool, M_MEAS, seed=seed)
    chosen = np.sort(np.asarray(sel.indices, int))
    ref = chosen if chosen_ref is None else chosen_ref
    vals = {"random tr C_s": score.trace_cs_m2, **{f"random {k}": v for k, v in score.criteria.items()},
            "pool bound tr C_s": sel.approx.lower_bound / M_MEAS,
            "pool poses tr C_s": score_design(model, pool[ref], W, ident=ident).trace_cs_m2}
    own = score_design(model, pool[chosen], W, ident=ident).trace_cs_m2
    kept_min, dropped_max = residual_margins(model, seed)
    return {"n_joints": robot.nq, "rank": ident.rank, "identifiable": ident.base_names, "kept_min": kept_min,
            "dropped_max": dropped_max,
            "values": {k: float(v) for k, v in vals.items() if np.isfinite(v)}, "selected": chosen.tolist(),
            "own_selection_tr_cs": float(own), "robot": robot}


def compare(a: dict, b: dict) -> dict:
    """Differences of ``b`` against ``a``: identifiable set, the largest relative difference of a figure (and
    which; ``ok`` when within :data:`REL_TOL`), and the pool selection made on each (the same poses, and the
    relative difference of their tr C_s: the exchange heuristic's own spread, not part of ``ok``)."""
    common = [k for k in a["values"] if k in b["values"]]
    logs = ("random O1", "random O2", "random O3", "random O4", "random O5")
    rel = {k: abs(b["values"][k] - a["values"][k]) / max(abs(a["values"][k]), 1e-300) for k in common
           if k not in logs + ("random D",)}
    # criteria in log units compared as the ratio of what they are the log of: O1-O5 (a singular value or a mean of
    # them), D = -log det M as its efficiency per parameter (det M ratio ^ (1/rank), the usual D-efficiency)
    rel.update({k: abs(math.expm1(b["values"][k] - a["values"][k])) for k in common if k in logs})
    if "random D" in common:
        rel["random D"] = abs(math.expm1((b["values"]["random D"] - a["values"]["random D"]) / a["rank"]))
    worst = max(rel, key=rel.__getitem__) if rel else ""
    missing = sorted(set(a["values"]) ^ set(b["values"]))
    own = (b["own_selection_tr_cs"] - a["own_selection_tr_cs"]) / a["own_selection_tr_cs"]
    return {"same_set": a["identifiable"] == b["identifiable"], "worst": worst,
            "worst_rel": rel.get(worst, float("nan")), "missing": missing,
            "same_selection": a["selected"] == b["selected"], "own_selection_rel": float(own),
            "ok": a["identifiable"] == b["identifiable"] and not missing and rel.get(worst, 0.0) <= REL_TOL}


def run_arm(label: str, folder: Path) -> dict:
    """The three copies of one arm's URDF, their figures and the comparisons; a refusal's cause when refused."""
    from pin_kpi_oed.errors import PinKpiOedError
    from pin_kpi_oed.model.robot import erd_root, load_robot

    rel, tool = ARMS[label]
    src = erd_root() / rel
    text = src.read_text()
    paths = {"exact": folder / f"{label}_exact.urdf", "rounded": folder / f"{label}_rounded.urdf"}
    paths["exact"].write_text(exact_urdf_text(text))
    paths["rounded"].write_text(rounded_urdf_text(text))
    t0 = time.process_time()
    try:
        load_robot(str(src), tool_frame=tool)  # a refusal names the file as it ships
        ref = figures(paths["exact"], tool, configurations(load_robot(str(paths["exact"]), tool_frame=tool)))
        conf = configurations(ref.pop("robot"))
        fig = {"exact": ref, **{k: figures(p, tool, conf, np.asarray(ref["selected"], int))
                                for k, p in (("shipped", src), ("rounded", paths["rounded"]))}}
    except PinKpiOedError as exc:
        return {"arm": label, "urdf": rel, "refused": str(exc).replace(str(erd_root()) + "/", "")}
    for f in fig.values():
        f.pop("robot", None)
    return {"arm": label, "urdf": rel, "tool": tool, "n_joints": fig["exact"]["n_joints"],
            "rank": fig["exact"]["rank"], "ranks": {k: f["rank"] for k, f in fig.items()},
            "snapped": exact_urdf_text(text) != text, "shipped": compare(fig["exact"], fig["shipped"]),
            "rounded": compare(fig["exact"], fig["rounded"]), "cpu_s": time.process_time() - t0,
            "figures": fig}


def _line(r: dict) -> str:
    if "refused" in r:
        return f"{r['arm']:<19} refused: {r['refused']}"
    cells = []
    for k in ("shipped", "rounded"):
        c = r[k]
        sel = "same" if c["same_selection"] else f"{c['own_selection_rel'] * 100:+.2f}%"
        cells.append(f"{'=' if c['same_set'] else '≠'} {c['worst_rel'] * 100:8.4f} % {sel:<7} "
                     f"{'ok' if c['ok'] else 'FAIL'}")
    f = r["figures"]
    margins = (f"{min(x['kept_min'] for x in f.values()):.3f} "
               f"{max(x['dropped_max'] for x in f.values()):8.1e}")
    return (f"{r['arm']:<19} {r['n_joints']:>2} {r['rank']:>4}  {'yes' if r['snapped'] else 'no ':<4}  "
            + "   ".join(cells) + f"  {margins}  {r['cpu_s']:5.1f}")


def main(argv: list[str] | None = None) -> list[dict]:
    """Run the walk and print one line per arm; returns the rows (and writes them with ``--json``)."""
    ap = argparse.ArgumentParser(prog="python -m benchmarks.urdf_rounding", description=__doc__.splitlines()[0])
    ap.add_argument("--arms", default=",".join(ARMS), help="comma-separated labels (default: all)")
    ap.add_argument("--json", default=None, help="write the rows to this JSON file")
    args = ap.parse_args(argv if argv is not None else [])
    print(f"exact vs shipped / vs 4-decimal rounded URDF at the same configurations: identifiable set (= same); "
          f"largest relative difference of tr C_s and every criterion of a seeded {M_MEAS}-pose random design, of the "
          f"KPI pool selection's certified bound ({M_MEAS} of {POOL} candidates) and of tr C_s at the poses it selects "
          f"on the exact copy; ok = same set, every figure within {REL_TOL * 100:g} %. 'poses': the selection made on "
          "each copy itself, the same poses or the difference of its tr C_s (the exchange heuristic's own spread); "
          "kept/dropped: the smallest residual share of a kept column and the largest of a dropped one over the "
          "three copies (the rank tolerance 1e-2 lies between)")
    head = ("shipped: set  worst diff  poses", "rounded: set  worst diff  poses")
    print(f"{'arm':<19} nq rank snap  {head[0]:<31}    {head[1]:<31}  kept  dropped  cpu s")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for label in [a.strip() for a in args.arms.split(",") if a.strip()]:
            if label not in ARMS:
                raise SystemExit(f"unknown arm '{label}' (arms: {', '.join(ARMS)})")
            rows.append(run_arm(label, Path(tmp)))
            print(_line(rows[-1]), flush=True)
    ran = [r for r in rows if "refused" not in r]
    bad = [r["arm"] for r in ran if not (r["shipped"]["ok"] and r["rounded"]["ok"])]
    print(f"{len(ran)} of {len(rows)} arms ran, {len(rows) - len(ran)} refused with their cause; "
          f"{len(ran) - len(bad)} of {len(ran)} ok" + (f"; not ok: {', '.join(bad)}" if bad else ""))
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1, default=float))
    return rows


if __name__ == "__main__":
    main(__import__("sys").argv[1:])
