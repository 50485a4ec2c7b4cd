"""Timing helpers shared by the benchmarks."""

from __future__ import annotations

import time
from typing import Callable


def median_time(fn: Callable[[], object], repeat: int = 30, warmup: int = 3) -> float:
    """Median wall time of ``fn()`` in seconds over ``repeat`` runs (after ``warmup``)."""
    for _ in range(warmup):
        fn()
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    ts.sort()
    return ts[len(ts) // 2]


def report(label: str, seconds: float, target: float | None = None) -> str:
    """One line: label, time (ms) and the ratio to its target."""
    line = f"{label:<55} {seconds * 1e3:9.3f} ms"
    if target is not None:
        ok = "OK  " if seconds <= target else "MISS"
        line += f"   target {target * 1e3:8.1f} ms   ratio {seconds / target:5.2f}  {ok}"
    print(line, flush=True)
    return line
