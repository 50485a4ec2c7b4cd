"""Study benchmark: the 90-arm study with 60 measurements per design in <= 10 minutes on 2 cores,
and its scaling with workers (1 vs 2 processes on a subset). Writes to ``out/bench_notional90`` (fresh)."""

from __future__ import annotations

import os
import shutil
import time
from pathlib import Path

from pin_kpi_oed.studies.study import format_notional_summary, notional_study


def main(out: str = "out/bench_notional90", scaling_arms: int = 6) -> None:
    workers = os.cpu_count() or 1
    print(f"== study: 90 notional arms x (heuristic, A on C_p, A on C_s), 60 measurements, {workers} workers")
    for w in (1, workers):
        d = Path(f"{out}_scaling_w{w}")
        shutil.rmtree(d, ignore_errors=True)
        t0 = time.perf_counter()
        notional_study(d, m=60, seed=0, arms=scaling_arms, workers=w)
        print(f"{scaling_arms} arms with {w} worker(s): {time.perf_counter() - t0:8.1f} s")
    d = Path(out)
    shutil.rmtree(d, ignore_errors=True)
    t0 = time.perf_counter()
    s = notional_study(d, m=60, seed=0, workers=workers)
    dt = time.perf_counter() - t0
    print(format_notional_summary(s))
    print(f"90-arm study wall time {dt:8.1f} s   target 300 s   ratio {dt / 300:5.2f}  {'OK' if dt <= 300 else 'MISS'}")


if __name__ == "__main__":
    main()
