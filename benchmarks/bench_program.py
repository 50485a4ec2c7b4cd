"""Measurement programs: KR 15/300/500 and UR10 KPI designs (20 mm clearance and 1 deg incidence
margins) ordered by OR-Tools, every move densely checked (<= 1 deg steps, Coal, capsules + 10 mm), colliding
moves repaired through via poses, exported in every format; cycle time against the as-designed order.

Run: ``python -m benchmarks bench_program`` (designs are computed with ``pin-kpi-oed design --certificate`` into
``$PKO_BENCH_DIR/<code hash>/`` (default /tmp/pko_bench_program), reused only by the same package source: a
design cached by older code (the certificate's efficiency is the design's) is never reported for new code).
"""

from __future__ import annotations

import hashlib
import json
import os
import time
from pathlib import Path

import numpy as np

from benchmarks.common import timed
from pin_kpi_oed.cell.feasibility import FeasibilityChecker
from pin_kpi_oed.cli.app import main as cli
from pin_kpi_oed.design.design_file import load_design
from pin_kpi_oed.program.export import FORMATS, ProgramInfo, parse_program, write_program
from pin_kpi_oed.program.ordering import ProgramOptions, plan_program
from pin_kpi_oed.program.transitions import TransitionChecker

CELLS = ("kr15", "kr300", "kr500", "ur10")
#: the shipped UR10 cell's program must plan within this (s); the bench prints the ratio
UR10_PLAN_TARGET_S = 15.0
UR10_POSES = 60


def code_hash() -> str:
    """Hash (12 hex) of the package's source and shipped cells: designs are cached per code state.

    ``program/`` and ``viz/`` are left out: they are downstream of ``design/`` (tests/test_architecture.py), so
    they cannot change a design.
    """
    root = Path(__file__).resolve().parents[1] / "pin_kpi_oed"
    h = hashlib.sha256()
    files = [f for f in root.rglob("*.py") if f.relative_to(root).parts[0] not in ("program", "viz")]
    for f in sorted([*files, *(root / "cell" / "cells").glob("*")]):
        h.update(str(f.relative_to(root)).encode())
        h.update(f.read_bytes())
    return h.hexdigest()[:12]


def design_file(cell: str, folder: Path) -> Path:
    """The KPI design of a cell with the default margins and the certificate (computed once per code state)."""
    path = folder / code_hash() / f"{cell}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    if not path.exists():
        assert cli(["design", "--cell", cell, "--criteria", "random,kpi", "--certificate", "--quiet",
                    "--json", str(path)]) == 0
    return path


def row(cell: str, path: Path) -> dict:
    """Plan, check and export the program of one cell; returns the table row."""
    df = load_design(path)
    raw = json.loads(path.read_text())
    entry = df.design("kpi")
    margin = 0.5 * float(raw.get("clearance_margin_m", 0.0))
    t_plan, prog = timed(lambda: plan_program(df.cell, entry.q_meas, ProgramOptions(margin_m=margin)))
    c_plan = t_plan.cpu_s
    # independent re-check of the exported moves with a fresh checker at 0.5 deg
    tc = TransitionChecker(df.cell, margin, step_rad=np.radians(0.5))
    path_q = prog.path
    col = sum(not tc.check(a, b, stop_early=False).clear for a, b in zip(path_q[:-1], path_q[1:]))
    rep = FeasibilityChecker(df.cell).check(entry.q_meas)
    info = ProgramInfo(cell=df.cell.name, design=f"{path.name} (kpi)", robot=df.robot.name,
                       joint_names=list(df.robot.joint_names), revolute=np.asarray(df.robot.is_revolute, bool),
                       cycle_time_s=prog.cycle_time_s)
    worst = 0.0
    for fmt in FORMATS:
        texts = write_program(fmt, path_q, [w.kind for w in prog.waypoints], [w.pose for w in prog.waypoints], info)
        back, _ = parse_program(fmt, texts, info.revolute)
        worst = max(worst, float(np.max(np.abs(back - path_q))))
    eff = next((d.get("efficiency") for d in raw["designs"] if d["criterion"] == "kpi"), float("nan"))
    return {"cell": cell, "poses": len(entry.q_meas), "moves": prog.n_moves, "vias": prog.n_repaired,
            "colliding": col, "designed_colliding": prog.as_designed_colliding, "cycle_s": prog.cycle_time_s,
            "designed_s": prog.as_designed_time_s, "shorter_pct": 100 * prog.reduction,
            "min_pose_clr_mm": 1e3 * rep.clearance_m.min(), "max_inc_deg": rep.incidence_deg.max(),
            "inc_limit_deg": df.cell.incidence_max_deg, "min_move_clr_mm": 1e3 * prog.min_move_clearance_m,
            "efficiency_pct": 100 * eff if eff is not None else float("nan"), "plan_s": t_plan, "plan_cpu_s": c_plan,
            "load": t_plan.load,
            "roundtrip_rad": worst}


def pool_candidates(path: Path, n: int = 100_000, seed: int = 0) -> None:
    """n user candidates for the KR 15 cell: 1,000 feasible poses, each taught 100 times with 0.5 deg noise."""
    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.design.optimize import DesignProblem

    cell = load_cell("kr15")
    Q0, _ = DesignProblem(cell).random_design(n // 100, seed=seed, max_tries=10 ** 6)
    rng = np.random.default_rng(seed)
    Q = np.clip(np.repeat(Q0, 100, axis=0) + rng.normal(0.0, np.radians(0.5), (len(Q0) * 100, 6)),
                cell.q_lower, cell.q_upper)
    lines = [",".join(cell.robot.joint_names)] + [",".join(f"{x:.10f}" for x in q) for q in Q]
    path.write_text("\n".join(lines) + "\n")


def pool_run(csv: str) -> None:
    """``design --pool`` on the candidates, timed by stage (wall and CPU); prints its lines (run in a fresh process
    for its peak RSS)."""
    import os
    import resource

    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.design.margins import with_margins
    from pin_kpi_oed.design.optimize import DesignProblem
    from pin_kpi_oed.design.user_pool import design_from_pool, read_poses

    t0, c0 = time.perf_counter(), time.process_time()
    cell = with_margins(load_cell("kr15"), 0.02, 1.0)
    problem = DesignProblem(cell)
    t1 = time.perf_counter()
    Q = read_poses(csv, cell.robot)
    t2 = time.perf_counter()
    st: dict = {}
    crits = ["random", "param", "D", "kpi"]
    res, cert, n_ok = design_from_pool(problem, Q, crits, 60, 0, timings=st)
    t3, c3 = time.perf_counter(), time.process_time()
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    sel_s = sum(st[f"select_{c}_s"] for c in crits[1:])
    print(f"pool: {len(Q)} candidates ({n_ok} feasible with the margins), m = 60: set-up {t1 - t0:.1f} s, read "
          f"{t2 - t1:.1f} s, check {st['check_s']:.1f} s, Jacobians {st['jacobians_s']:.1f} s, selections "
          f"{sel_s:.1f} s; total {t3 - t0:.1f} s wall, {c3 - c0:.1f} s CPU, "
          f"peak RSS {rss:.0f} MB (target 1024); load average {load} on {os.cpu_count()} cores")
    by = {r.criterion: r for r in res}
    for c in crits:
        r = by[c]
        if c == "random":
            print(f"pool {c:<6}: sampling {r.time_s * 1e3:.1f} ms; tr(C_s) {r.trace_cs_m2 * 1e6:.6e} mm^2, "
                  f"{100 * cert.efficiency(r.trace_cs_m2):.1f} % of the KPI certificate")
            continue
        s_, cpu = st[f"select_{c}_s"], st[f"select_{c}_cpu_s"]
        kind = "D-efficiency" if c == "D" else "efficiency"
        print(f"pool {c:<6}: selection {s_:.2f} s wall, {cpu:.2f} s CPU, ratio {s_ / 10.0:.2f} to the 10 s target; "
              f"{kind} {100 * st[f'efficiency_{c}']:.2f} % against its certificate; tr(C_s) "
              f"{r.trace_cs_m2 * 1e6:.6e} mm^2")
    print(f"pool: KPI tr(C_s) {by['kpi'].trace_cs_m2 * 1e6:.6e} mm^2, certificate bound "
          f"{cert.lower_bound_trace_cs_m2 * 1e6:.6e} mm^2")


def ur10() -> float:
    """Only the UR10 program: plan it (timed in CPU seconds), re-check it, print the ratio to the target; returns
    the CPU time (s).

    Run: ``python -c "from benchmarks.bench_program import ur10; ur10()"``.
    """
    folder = Path(os.environ.get("PKO_BENCH_DIR", "/tmp/pko_bench_program"))
    r = row("ur10", design_file("ur10", folder))
    print(f"program: UR10 cell, {r['poses']}-pose KPI design planned in {r['plan_cpu_s']:.1f} s CPU "
          f"({r['plan_s']:.1f} s wall), ratio {r['plan_cpu_s'] / UR10_PLAN_TARGET_S:.2f} to the "
          f"{UR10_PLAN_TARGET_S:g} s target; {r['moves']} moves, "
          f"{r['vias']} via routes, {r['colliding']} colliding at the 0.5 deg re-check, cycle {r['cycle_s']:.1f} s "
          f"(as designed {r['designed_s']:.1f} s), min move clearance {r['min_move_clr_mm']:.1f} mm; load average "
          f"{r['load']:.1f} at the start on {os.cpu_count()} cores")
    return r["plan_cpu_s"]


def main() -> None:
    folder = Path(os.environ.get("PKO_BENCH_DIR", "/tmp/pko_bench_program"))
    folder.mkdir(parents=True, exist_ok=True)
    import subprocess
    import sys

    csv = folder / "pool_100k.csv"
    if not csv.exists():
        pool_candidates(csv)
    subprocess.run([sys.executable, "-c", f"from benchmarks.bench_program import pool_run; pool_run({str(csv)!r})"],
                   check=True)
    print("== measurement programs: KPI designs (margins 20 mm / 1 deg), moves checked with 10 mm margin")
    head = (f"{'cell':<7}{'poses':>6}{'moves':>6}{'vias':>5}{'coll.':>6}{'as-des. coll.':>14}{'cycle s':>9}"
            f"{'as-des. s':>10}{'shorter %':>10}{'pose clr mm':>12}{'max inc':>8}{'move clr mm':>12}"
            f"{'effic. %':>9}{'plan s CPU':>11}{'rt rad':>9}")
    print(head)
    print("-" * len(head))
    plan_ur10 = None
    for cell in CELLS:
        r = row(cell, design_file(cell, folder))
        if cell == "ur10":
            plan_ur10, wall_ur10, load_ur10 = r["plan_cpu_s"], r["plan_s"], r["load"]
        print(f"{r['cell']:<7}{r['poses']:>6}{r['moves']:>6}{r['vias']:>5}{r['colliding']:>6}"
              f"{r['designed_colliding']:>14}{r['cycle_s']:>9.1f}{r['designed_s']:>10.1f}{r['shorter_pct']:>10.1f}"
              f"{r['min_pose_clr_mm']:>12.1f}{r['max_inc_deg']:>8.1f}{r['min_move_clr_mm']:>12.1f}"
              f"{r['efficiency_pct']:>9.1f}{r['plan_cpu_s']:>11.1f}{r['roundtrip_rad']:>9.1e}")
    if plan_ur10 is not None:
        print(f"program: UR10 cell, {UR10_POSES}-pose KPI design planned (ordered, every move densely checked, "
              f"repaired) in {plan_ur10:.1f} s CPU ({wall_ur10:.1f} s wall), "
              f"ratio {plan_ur10 / UR10_PLAN_TARGET_S:.2f} to the {UR10_PLAN_TARGET_S:g} s target; "
              f"load average {load_ur10:.1f} at the start on {os.cpu_count()} cores")


if __name__ == "__main__":
    main()
