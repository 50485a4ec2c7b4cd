"""Loading cells and model files, and the feasibility distances: CPU time per call in fresh processes.

Each child process (one per checkout and repeat) loads every shipped cell twice (the first load reads the meshes
and fits the capsules, the second finds them in the process's caches: what most callers pay), checks each cell's
parsed file against its schema, loads a calibrated model file, and times ``FeasibilityChecker.pair_distances`` and
``min_pair_distance`` over 1,000 seeded configurations of the kr15 and UR10 cells. Only public functions are called,
so any checkout can be measured: with ``--before PATH`` the other checkout's package runs first on ``PYTHONPATH``,
interleaved (before, after, before, ...) so both see the same load; the table gives the medians, the pairs in which
the checkout was faster, and the sign test's two-sided p.

The model file (a simulated UR10 with random geometric errors, 240 rows, identified with ``--model-out``) is made
once per run by this checkout, in a temporary folder, and read by both.

Measured (2 shared cores, load 3.9, 5 processes per checkout, interleaved with the checkout before the parse cache,
the compiled schema check, the result references of the distances and the early stop of the always-blocked check;
median CPU per call, before -> after; with 5 pairs the smallest two-sided sign-test p is 0.062): a cached load of
kr15 9.9 -> 4.1 ms (5/5 pairs faster), kr300 7.0 -> 4.2 ms (4/5), kr500 7.0 -> 3.9 ms (5/5), ur10 44.9 -> 19.9 ms
(5/5; working targets), kr15_seam 65 -> 50 ms (4/5; its path's IK is most of it); a first load (meshes read and
fitted) of ur10 685 -> 618 ms (3/5: the fits are most of it); the ur10 cell's schema check 1.40 -> 0.18 ms (5/5);
a model file's load 8.2 -> 5.8 ms (5/5; the rest is mostly the robot's model built from its URDF);
``pair_distances`` kr15 38 -> 15 µs (5/5), ur10 175 -> 148 µs (4/5; Coal's mesh distances are most of it);
``min_pair_distance`` kr15 7 -> 5 µs (5/5), ur10 209 -> 196 µs (2/5: Coal's work, unchanged).

Run:  python -m benchmarks.cell_load [--repeat 5] [--before OTHER_CHECKOUT]
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from .common import checkout_roots, cli_in_process, load_average, sign_test_p

#: the child process: {timing name: CPU s} as one JSON line; argv[1] is the model file
CHILD = """
import json, sys, time
import numpy as np, yaml
from pin_kpi_oed.cell.cell import CELL_DIR, load_cell
from pin_kpi_oed.cell.feasibility import FeasibilityChecker
from pin_kpi_oed.calibrated.model_file import load_model_file
from pin_kpi_oed.validation.schema import validate_cell_dict
load_cell("kr15")  # imports and the kr15 meshes out of the way
out = {}
def cpu(key, f, n=1):
    t = time.process_time()
    for _ in range(n):
        r = f()
    out[key] = (time.process_time() - t) / n
    return r
for name in ("kr15_seam", "kr300", "kr500", "ur10"):
    cpu(f"load_cell {name} first", lambda: load_cell(name))
for name in ("kr15", "kr15_seam", "kr300", "kr500", "ur10"):
    cpu(f"load_cell {name}", lambda: load_cell(name), 5)
d = yaml.safe_load((CELL_DIR / "ur10.yaml").read_text())
cpu("validate_cell_dict ur10", lambda: validate_cell_dict(d, "ur10.yaml"), 100)
load_model_file(sys.argv[1])
cpu("load_model_file", lambda: load_model_file(sys.argv[1]), 20)
for name in ("kr15", "ur10"):
    cell = load_cell(name)
    chk = FeasibilityChecker(cell)
    Q = np.random.default_rng(0).uniform(cell.q_lower, cell.q_upper, (1000, cell.robot.nq))
    cpu(f"pair_distances {name}", lambda: [chk.pair_distances(q) for q in Q])
    out[f"pair_distances {name}"] /= len(Q)
    cpu(f"min_pair_distance {name}", lambda: [chk.min_pair_distance(q) for q in Q])
    out[f"min_pair_distance {name}"] /= len(Q)
print(json.dumps(out))
"""


def make_model_file(folder: Path) -> Path:
    """A calibrated model file of a simulated UR10 (seeded random geometric errors, 240 rows, 20 µm noise)."""
    import numpy as np

    from pin_kpi_oed import NoiseModel, TrackerModel, load_robot
    from pin_kpi_oed.data.measurements import write_measurements
    from pin_kpi_oed.oed.identifiability import analyse
    from pin_kpi_oed.simulation.simulator import Tolerances, default_tracker_pose, random_truth, simulate

    robot = load_robot("ur10")
    tm = TrackerModel(robot, tracker_T_base=default_tracker_pose(robot), reflector_m=np.array([0.02, 0.01, 0.1]),
                      noise=NoiseModel((2e-5,) * 3))
    truth = random_truth(tm, Tolerances(5e-4, 1e-3, 0.01, 0.01), seed=4,
                         only=[i for i in analyse(tm).base if i < 6 * robot.nq])
    write_measurements(simulate(tm, robot.random_q(np.random.default_rng(2), 240), truth, seed=5,
                                record_sigma=False), folder / "train.csv")
    rc, _, err = cli_in_process("identify", "--robot", "ur10", "--data", folder / "train.csv", "--reflector",
                                "0.02,0.01,0.1", "--sigma", "2e-5", "--model-out", folder / "model.json", "--quiet")
    if rc != 0:
        raise RuntimeError(f"identify failed: {err.strip()}")
    return folder / "model.json"


def run_once(root: Path, model: Path) -> dict[str, float]:
    """The timings (CPU s per call) of one fresh process with ``root``'s package first on the path."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep))
    res = subprocess.run([sys.executable, "-c", CHILD, str(model)], env=env, capture_output=True, text=True,
                         check=True, cwd=root)
    return json.loads(res.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> None:
    """Prints the median CPU times of the checkout (and of ``--before``'s, with the pairs won and the sign test).

    Args:
        argv: command-line arguments (``--repeat N``, ``--before PATH``).
    """
    a, roots = checkout_roots("python -m benchmarks.cell_load", argv)
    runs: dict[str, list[dict[str, float]]] = {k: [] for k in roots}
    with tempfile.TemporaryDirectory() as tmp:
        model = make_model_file(Path(tmp))
        print(f"load average {load_average():.2f} at the start; {a.repeat} processes per checkout", flush=True)
        for _ in range(a.repeat):
            for name, root in roots.items():
                runs[name].append(run_once(root, model))
    keys = list(runs["after"][0])
    head = f"{'median CPU per call (ms)':<34}" + "".join(f"{k:>10}" for k in roots)
    print(head + ("   change  faster  sign p" if "before" in roots else ""))
    for key in keys:
        med = {k: statistics.median(r[key] for r in runs[k]) for k in roots}
        line = f"{key:<34}" + "".join(f"{med[k] * 1e3:>10.3f}" for k in roots)
        if "before" in roots:
            diffs = [b[key] - c[key] for b, c in zip(runs["before"], runs["after"]) if b[key] != c[key]]
            wins = sum(x > 0 for x in diffs)
            line += f"  {100 * (med['after'] / med['before'] - 1):+6.0f} %  {wins:>2}/{len(diffs):<2}  " \
                    f"{sign_test_p(wins, len(diffs)):.3f}"
        print(line)
    print(f"load average {load_average():.2f} at the end")


if __name__ == "__main__":
    main()
