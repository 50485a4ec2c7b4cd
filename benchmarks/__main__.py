"""Run every benchmark: ``python -m benchmarks`` (``make bench``)."""

from __future__ import annotations

import importlib
import sys

MODULES = ("bench_core", "bench_identify", "bench_collision", "bench_design", "bench_diagnosis", "bench_certificate",
           "bench_study", "bench_program", "bench_extended", "bench_kpi_gp", "bench_discrepancy", "bench_checks")

if __name__ == "__main__":
    wanted = sys.argv[1:] or MODULES
    for name in wanted:
        try:
            mod = importlib.import_module(f"benchmarks.{name}")
        except ModuleNotFoundError as exc:
            if exc.name == f"benchmarks.{name}":
                print(f"== {name}: not present")
                continue
            raise
        mod.main()
