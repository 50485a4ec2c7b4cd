"""The design layer against a baseline of the package, in the same run: every design figure unchanged within noise.

The same figures are computed by this tree and by a baseline tree (``git archive`` of a commit, default: the
parent of the first commit of the one criterion interface), one after the other in this run (pool selections also
in CPU time, which the machine's load barely changes):

* the demo's table: ``run_designs`` on the KR 15 cell, random / param / kpi, 60 poses, pool start (5,000
  candidates), seed 0: tr(C_s) and the TCP σ of each design (target: within 1 %);
* pool selection of 60 of 1,000 feasible KR 15 candidates for every criterion (noise only, the GLS forms, kpi_gp):
  wall time (target ≤ 1 s) and φ of the selection;
* the KR 15 60-pose IPOPT design of kpi_gp against the plain kpi, one start (target ≤ 2× the plain design's time);
* the certificate: the relaxation's lower bound of tr(C_s) over the 1,000 candidates and the kpi selection's
  efficiency.

Run: ``python -m benchmarks.bench_layer [--baseline REV] [--json out.json]`` (a few minutes on 2 cores; the baseline
needs git and the repository).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

#: The first commit of the one criterion interface; the baseline is its parent (the package before it).
FIRST_COMMIT_SUBJECT = "No private name is reached across modules"
CRITERIA = ("kpi", "param", "D", "E", "cond", "O1", "O5", "D_gp", "param_gp", "E_gp", "O1_gp", "kpi_gp")

CHILD = r'''
import json, sys, time
import numpy as np
from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.design.optimize import DesignOptions, DesignProblem, ipopt_options, run_designs
from pin_kpi_oed.oed import pool as pool_mod
from pin_kpi_oed.oed.criteria import get_criterion
from pin_kpi_oed.threads import limited_threads

names = sys.argv[1].split(",")
out = {}
with limited_threads():
    cell = load_cell("kr15")
    problem = DesignProblem(cell)
    res = run_designs(cell, ["random", "param", "kpi"], 60, 0, DesignOptions(start="pool", pool_size=5000), problem)
    out["demo"] = {r.criterion: {"trace_cs_m2": r.trace_cs_m2, "tcp_sigma_m": r.tcp_sigma_m, "time_s": r.time_s,
                                 "feasible": bool(r.feasible)} for r in res}
    Q, _ = problem.random_design(1000, seed=np.random.SeedSequence([0, 1]), max_tries=400_000)
    Fp = problem.model.weighted_jacobian(problem.p0, Q)[:, :, problem.base]
    out["pool"] = {}
    for c in names:
        obj = problem.criterion(c)
        t0, c0 = time.perf_counter(), time.process_time()
        if hasattr(type(obj), "select") and not hasattr(obj, "F_given") and type(obj).__name__ != "DesignCriterion":
            sel = obj.select(Q, 60)
        elif type(obj).__name__ == "DesignCriterion" and hasattr(type(obj), "select"):
            sel = obj.select(Q, 60, Fp=Fp)
        else:
            sel = pool_mod.select(Fp, 60, get_criterion(c).pool_form(problem.E, problem.base.size))
        dt, dc = time.perf_counter() - t0, time.process_time() - c0
        idx = np.asarray(sel.indices, int)
        out["pool"][c] = {"time_s": dt, "cpu_s": dc, "value": float(obj.value(Q[idx]))}
        if c == "kpi":
            a = sel.approx
            out["certificate"] = {"lower_bound_trace_cs_m2": a.lower_bound / 60,
                                  "efficiency": a.lower_bound / 60 / float(obj.value(Q[idx]))}
    des = run_designs(cell, ["kpi", "kpi_gp"], 60, 0, DesignOptions(n_starts=1, start="pool"), problem)
    by = {r.criterion: r for r in des}
    out["kpi_gp_design"] = {"kpi_time_s": by["kpi"].time_s, "kpi_gp_time_s": by["kpi_gp"].time_s,
                            "ratio": by["kpi_gp"].time_s / by["kpi"].time_s,
                            "kpi_gp_value": by["kpi_gp"].value, "feasible": bool(by["kpi_gp"].feasible)}
print("RESULT " + json.dumps(out))
'''


def _figures(tree: Path) -> dict:
    env = {**os.environ, "PYTHONPATH": str(tree), "OMP_NUM_THREADS": "1"}
    run = subprocess.run([sys.executable, "-c", CHILD, ",".join(CRITERIA)], env=env, capture_output=True, text=True,
                         cwd=str(tree))
    line = next((x for x in run.stdout.splitlines() if x.startswith("RESULT ")), None)
    if line is None:
        raise RuntimeError(f"{tree}: no figures ({run.stderr.strip().splitlines()[-1:]})")
    return json.loads(line[len("RESULT "):])


def default_baseline() -> str | None:
    """The parent of the first commit of the one criterion interface (None without the repository's history)."""
    repo = Path(__file__).resolve().parents[1]
    log = subprocess.run(["git", "-C", str(repo), "log", "-1", "--format=%H", "--fixed-strings",
                          f"--grep={FIRST_COMMIT_SUBJECT}"], capture_output=True, text=True)
    return f"{log.stdout.strip()}~1" if log.returncode == 0 and log.stdout.strip() else None


def _baseline_tree(rev: str, dest: Path) -> Path | None:
    repo = Path(__file__).resolve().parents[1]
    arch = subprocess.run(["git", "-C", str(repo), "archive", rev, "pin_kpi_oed", "urdf"], capture_output=True)
    if arch.returncode != 0:
        return None
    subprocess.run(["tar", "-x", "-C", str(dest)], input=arch.stdout, check=True)
    return dest


def _compare(new: dict, old: dict | None) -> None:
    def rel(a: float, b: float) -> str:
        return f"{100 * (a / b - 1):+.2f} %" if b else "n/a"

    print("demo table (KR 15, 60 poses, pool start): tr(C_s) mm^2, this tree" + (" vs baseline" if old else ""))
    for c, r in new["demo"].items():
        b = old["demo"][c]["trace_cs_m2"] if old else None
        base = f"  baseline {b * 1e6:.5e}  {rel(r['trace_cs_m2'], b)}" if b else ""
        print(f"  {c:<7} {r['trace_cs_m2'] * 1e6:.5e}{base}  (target: within 1 %)")
    print("pool 1,000 -> 60 (target <= 1 s): wall s / CPU s, value")
    for c, r in new["pool"].items():
        o = old["pool"].get(c) if old else None
        base = (f"  baseline {o['time_s']:.3f} / {o.get('cpu_s', float('nan')):.3f} s, value "
                f"{rel(r['value'], o['value'])}" if o else "")
        print(f"  {c:<9} {r['time_s']:.3f} / {r['cpu_s']:.3f} s  {r['value']:.6g}{base}")
    cert = new["certificate"]
    print(f"certificate: tr(C_s) >= {cert['lower_bound_trace_cs_m2'] * 1e6:.5e} mm^2, kpi selection efficiency "
          f"{cert['efficiency']:.4f}" + (f" (baseline {old['certificate']['efficiency']:.4f})" if old else ""))
    g = new["kpi_gp_design"]
    print(f"kpi_gp 60-pose design: {g['kpi_gp_time_s']:.1f} s = {g['ratio']:.2f} x the plain design (target <= 2)"
          + (f"; baseline {old['kpi_gp_design']['ratio']:.2f} x, value "
             f"{rel(g['kpi_gp_value'], old['kpi_gp_design']['kpi_gp_value'])}" if old else ""))


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", default=None, help="git revision of the baseline (default: the parent of the first "
                    "commit of the one criterion interface)")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv if argv is not None else [])
    here = Path(__file__).resolve().parents[1]
    new = _figures(here)
    old = None
    rev = args.baseline or default_baseline()
    with tempfile.TemporaryDirectory() as tmp:
        tree = _baseline_tree(rev, Path(tmp)) if rev else None
        if tree is None:
            print(f"baseline {rev}: not available (no git repository); this tree's figures only")
        else:
            old = _figures(tree)
    _compare(new, old)
    out = {"this_tree": new, "baseline": old, "baseline_rev": rev}
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1))
    return out


if __name__ == "__main__":
    main(sys.argv[1:])
