"""Meshes read once per process: ``load_cell("ur10")`` and the viewer's ``visual_model`` of the UR10, each called
twice in one fresh process, wall time of the first and of the second call, the median over ``--repeat`` processes.

With ``--before PATH`` the same runs are made with another checkout's package first on ``PYTHONPATH``, interleaved
(before, after, before, ...) so both see the same load. Only the package's public functions are called, so any
checkout can be measured.

Measured (2 shared cores, load 4.7, median of 5 processes, interleaved with the checkout before the per-process
mesh caches): ``load_cell("ur10")`` first call 1.42 s before / 1.66 s after (imports included, noise), second call
0.190 -> 0.147 s (what is left is the working targets' IK and the collision rows, no mesh); ``visual_model`` of the
UR10 first call 0.98 / 1.07 s, second call 0.876 -> 0.005 s.

Run:  python -m benchmarks.mesh_cache [--repeat 5] [--before OTHER_CHECKOUT]
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

from .common import checkout_roots, load_average

#: the child process: the four timings (s) as one JSON line
CHILD = """
import json, time
from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.model.robot import load_robot
from pin_kpi_oed.viz.robot_geometry import visual_model
out = {}
for k in (1, 2):
    t = time.perf_counter(); load_cell("ur10"); out[f"load_cell #{k}"] = time.perf_counter() - t
rb = load_robot("ur10")
for k in (1, 2):
    t = time.perf_counter(); visual_model(rb); out[f"visual_model #{k}"] = time.perf_counter() - t
print(json.dumps(out))
"""


def run_once(root: Path) -> dict[str, float]:
    """The four timings (s) of one fresh process with ``root``'s package first on the path."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep))
    res = subprocess.run([sys.executable, "-c", CHILD], env=env, capture_output=True, text=True, check=True, cwd=root)
    return json.loads(res.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> None:
    """Prints the median timings of the checkout (and of ``--before``'s).

    Args:
        argv: command-line arguments (``--repeat N``, ``--before PATH``).
    """
    a, roots = checkout_roots("python -m benchmarks.mesh_cache", argv)
    runs: dict[str, list[dict[str, float]]] = {k: [] for k in roots}
    print(f"load average {load_average():.2f} at the start; {a.repeat} processes per checkout", flush=True)
    for _ in range(a.repeat):
        for name, root in roots.items():
            runs[name].append(run_once(root))
    keys = list(runs["after"][0])
    print(f"{'median wall time (s)':<22}" + "".join(f"{k:>16}" for k in roots))
    for key in keys:
        print(f"{key:<22}" + "".join(f"{statistics.median(r[key] for r in runs[k]):>16.3f}" for k in roots))


if __name__ == "__main__":
    main()
