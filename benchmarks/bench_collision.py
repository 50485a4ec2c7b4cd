"""Constraint-evaluation benchmark: 60 poses of the KR 15 cell, values + gradients, Coal vs closed form.

Figures (CPU time per evaluation, median of repeated runs — CPU time, because wall time on a machine shared
with other jobs mostly measures the other processes; wall time printed alongside):

* closed form (NumPy, the optimiser's default) — the baseline;
* Coal through one ``pin.computeDistances`` per pose on a ``pin.GeometryModel`` (``backend="geometry"``), with
  the KS band (witness points of the pairs within 40ℓ of the closest one) — target <= 2x the closed form;
* the same reading every pair's witness points;
* ``coal.distance`` per pair from Python (the previous Coal path), 6 poses, scaled to 60.

Run: ``python -m benchmarks bench_collision``.
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.design.optimize import DesignProblem
from pin_kpi_oed.threads import limited_threads

from .common import figure


def _cpu_wall(fn, repeat: int = 30) -> tuple[float, float]:
    fn()
    cpu, wall = [], []
    for _ in range(repeat):
        c0, w0 = time.process_time(), time.perf_counter()
        fn()
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - w0)
    return statistics.median(cpu), statistics.median(wall)


def main() -> None:
    problem = DesignProblem(load_cell("kr15"))
    coll = problem.coll
    Q = problem.random_design(60, 0)[0]
    band = 40 * 2e-3
    print(f"== constraint evaluation with gradients, KR 15 cell, 60 poses, {coll.n_rows} rows per pose "
          f"({len(coll.pairs)} capsule pairs)")
    with limited_threads():
        c_np, w_np = _cpu_wall(lambda: coll.evaluate(Q))
        c_gb, w_gb = _cpu_wall(lambda: coll.evaluate(Q, backend="geometry", band=band))
        c_ga, w_ga = _cpu_wall(lambda: coll.evaluate(Q, backend="geometry"), 10)
        c_py, w_py = _cpu_wall(lambda: coll.evaluate(Q[:6], backend="coal"), 3)
        g1, G1 = coll.evaluate(Q)
        g2, G2 = coll.evaluate(Q, backend="geometry")
    print(f"  closed form: {c_np * 1e3:.3f} ms CPU ({w_np * 1e3:.3f} ms wall); Coal/closed form max |dg| "
          f"{np.abs(g1 - g2).max():.1e} m, max |dG| {np.abs(G1 - G2).max():.1e}")
    figure("Coal (GeometryModel, KS band) / closed form, CPU", c_gb / c_np, 2.0, "x", w_gb / w_np,
           "wall-time ratio")
    figure("Coal (GeometryModel, every witness point) / closed form, CPU", c_ga / c_np, 2.0, "x", w_ga / w_np,
           "wall-time ratio")
    figure("Coal per pair from Python (previous path) / closed form, CPU", c_py * 10 / c_np, 2.0, "x",
           c_py * 10 * 1e3, "ms CPU for 60 poses:")


if __name__ == "__main__":
    main()
