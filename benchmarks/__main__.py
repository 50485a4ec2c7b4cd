"""Run every benchmark: ``python -m benchmarks`` (``make bench``).

Each benchmark starts with the machine's load average; each time figure is its wall time followed by its CPU time
(this process and its children) and the load average at its start, so a figure taken while other work held the
cores is recognisable (its wall time grows, its CPU time barely).
"""

from __future__ import annotations

import importlib
import sys

MODULES = ("bench_startup", "bench_core", "bench_identify", "bench_collision", "bench_design", "bench_diagnosis",
           "bench_certificate", "bench_study", "bench_program", "bench_extended", "bench_kpi_gp", "bench_discrepancy",
           "bench_checks", "bench_report", "unshipped_robots", "bench_layer", "bench_paths", "urdf_rounding",
           "every_arm")

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
        from benchmarks.common import machine_line

        print(f"== {name}: {machine_line()} at the start", flush=True)
        mod.main()
