"""Design benchmark: KR 15 KPI design with collision avoidance by Ipopt.

Target: the KR 15 KPI design with 60 measurements and the full constraint set in <= 5 s (median of
repeated runs, 2 cores). Also reported: where the time goes (naive formulation with one Ipopt row per
capsule pair vs the aggregated one: ms per iteration, Ipopt vs our callbacks), the objective reached
compared with a long, tight run, and the growth with 30/60/120/240 measurements.

Run: ``python -m benchmarks bench_design`` (``OMP_NUM_THREADS=1`` is set here).
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

import statistics  # noqa: E402
import time  # noqa: E402

from pin_kpi_oed.cell.cell import load_cell  # noqa: E402
from pin_kpi_oed.design.optimize import DesignProblem, design_ipopt, ipopt_options, solve_ipopt  # noqa: E402

TARGET_S = 5.0


def _timed(fn):
    t0, c0 = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - t0, time.process_time() - c0


def _line(label: str, value: str, target: float | None = None, seconds: float | None = None) -> None:
    s = f"{label:<58} {value}"
    if target is not None and seconds is not None:
        s += f"   target {target:.1f} s   ratio {seconds / target:5.2f}  {'OK' if seconds <= target else 'MISS'}"
    print(s, flush=True)


def main(repeats: int = 5) -> None:
    cell = load_cell("kr15")
    (problem, t_setup, _) = _timed(lambda: DesignProblem(cell))
    rows = problem.coll.info.count()
    print("== design (KR 15 cell, KPI criterion = A on C_s, Ipopt limited-memory, full constraint set)")
    _line("set-up (identifiability, constraint model, checker)", f"{t_setup:8.3f} s")
    _line("constraint rows per configuration (after pruning)",
          f"{problem.coll.n_rows} ({', '.join(f'{k} {v}' for k, v in rows.items() if v)}); "
          f"{problem.coll_full.rows_all['rows'].n} before pruning; Ipopt rows {problem.cons.n_rows}")

    # --- headline: 60 measurements, single start from the seed's feasible heuristic design
    walls, cpus, its, vals, totals = [], [], [], [], []
    for seed in range(repeats):
        (start, ns), t_rand, _ = _timed(lambda: problem.random_design(60, seed))
        r, w, c = _timed(lambda: solve_ipopt(problem, "kpi", start))
        rep = problem.checker.check(r.Q)
        assert rep.all_feasible, rep.violations()
        walls.append(w)
        cpus.append(c)
        its.append(r.nit)
        vals.append(r.f)
        totals.append(w + t_rand)
    med = statistics.median(walls)
    _line(f"KPI design, 60 meas., 1 start (median of {repeats} seeds) wall", f"{med:8.3f} s", TARGET_S, med)
    _line("  same, CPU time (median)", f"{statistics.median(cpus):8.3f} s")
    _line("  same, incl. rejection sampling of the start (median)", f"{statistics.median(totals):8.3f} s")
    _line("  iterations (median, min-max)", f"{statistics.median(its):8.0f}   ({min(its)}-{max(its)})")
    _line("  tr(C_s) / tr(C_s) of the heuristic start (median)", f"{statistics.median(vals):8.3f}")
    start = problem.random_design(60, 0)[0]
    res, w2, _ = _timed(lambda: design_ipopt(problem, "kpi", 60, seed=0, n_starts=3, start=start))
    _line("KPI design, 60 meas., 3 starts + independent check (seed 0)",
          f"{w2:8.3f} s   tr(C_s) ratio {res.trace_cs_m2 / problem.kpi_criterion.value(start):.3f}, "
          f"feasible {res.feasible}")

    # --- where the time goes: naive (one row per pair) vs aggregated formulation, per iteration
    naive = DesignProblem(cell, aggregate="none")
    for label, prob in (("naive: one Ipopt row per pair", naive), ("aggregated: 2 rows per configuration", problem)):
        r, w, c = _timed(lambda: solve_ipopt(prob, "kpi", start, ipopt_options(max_iter=40), stall_window=0))
        per = w / max(r.nit, 1)
        _line(f"{label} ({r.n_constraints} rows)",
              f"{per * 1e3:8.1f} ms/iteration (Ipopt {100 * (1 - r.eval_time_s / w):3.0f} %, callbacks "
              f"{100 * r.eval_time_s / w:3.0f} %)")

    # --- objective reached vs a long, tight run from the same start
    long_opts = ipopt_options(max_iter=2000, tol=1e-6, acceptable_tol=1e-6, acceptable_iter=50)
    r_def, w_def, _ = _timed(lambda: solve_ipopt(problem, "kpi", start))
    r_long, w_long, _ = _timed(lambda: solve_ipopt(problem, "kpi", start, long_opts, stall_window=0))
    _line("default stopping vs tol 1e-6 / 2000 iterations (seed 0)",
          f"f {r_def.f:.4f} in {r_def.nit} it. ({w_def:.2f} s) vs f {r_long.f:.4f} in "
          f"{r_long.nit} it. ({w_long:.2f} s): {100 * (r_def.f / r_long.f - 1):+.1f} %")

    # --- growth with the number of measurements
    base_t = None
    for m in (30, 60, 120, 240):
        st = problem.random_design(m, 0)[0]
        r, w, c = _timed(lambda: solve_ipopt(problem, "kpi", st))
        base_t = w if m == 60 else base_t
        ratio = f"   x{w / base_t:.2f} of 60" if base_t else ""
        _line(f"KPI design, {m} measurements (seed 0)",
              f"{w:8.3f} s  CPU {c:6.3f} s  {r.nit:4d} it.  {w / max(r.nit, 1) * 1e3:6.1f} "
              f"ms/it.  f {r.f:.3f}{ratio}")


if __name__ == "__main__":
    main()
