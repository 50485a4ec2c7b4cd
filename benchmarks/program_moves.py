"""The UR10 cell's move checks as the program tests run them: CPU of three planning workloads and of the smallest
pair distance per configuration, with a hash of what they produce (equal hashes: the same programs).

The workloads are those of ``tests/test_program.py``: ten poses of a KPI design changed by 1e-9 rad (two seeds,
a planning budget of 1600 checks, a via pool of 20, three rounds) and the pocket pose without its 2π-equivalents
(no route exists; a budget of 1000 checks). Each figure is the smallest CPU time of three runs in one process (the
machine's speed varies by ±20 % under other work: the smallest is the least disturbed).

Run: ``python -m benchmarks.program_moves``.
"""

from __future__ import annotations

import hashlib

import numpy as np

from benchmarks.common import cpu_time, machine_line
from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.cell.feasibility import FeasibilityChecker
from pin_kpi_oed.program.ordering import ProgramOptions, plan_program

#: ten poses of a UR10 KPI design (rad): tests/test_program.py's UR10_TEN
UR10_TEN = np.array([
    [-1.16457098, -0.00690381, 0.87020137, -4.03202327, -1.83410043, -4.51519816],
    [-0.48369823, -0.44938347, 2.45057794, -2.2208667, -4.09830123, -3.53655392],
    [1.75663254, -1.51920194, 0.92908398, -0.04470306, -1.58238909, 1.52716684],
    [1.30814339, -1.28797202, -2.77451641, -1.95126074, 4.70789329, -1.58135575],
    [0.56317894, -0.72424407, 1.27269797, -0.74452413, 4.21350826, 4.15678191],
    [0.82416927, -0.52601222, 1.27246493, -0.80175219, -1.83286105, -1.94486025],
    [-1.26577243, -1.03924212, 1.53031901, 2.91317656, 4.70612781, 1.54715300],
    [-0.54818871, -0.84847114, 1.57574651, -0.86698734, 2.32504328, 2.28772818],
    [0.55982624, -0.17228357, 0.37931206, -2.84655843, 2.02405288, -1.76608686],
    [-0.67422932, -3.13779339, 1.69393026, 4.71066755, -1.79697397, 2.03713730],
])
#: the pocket pose (deg): tests/test_program.py's UR10_POCKET
UR10_POCKET_DEG = [76.06, -149.554, 11.564, -90.812, -226.516, -1.974]


def smallest_cpu(fn, repeat: int = 3) -> tuple[float, object]:
    """(the smallest CPU time (s) of ``repeat`` calls, the last call's result)."""
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = cpu_time()
        out = fn()
        best = min(best, cpu_time() - t0)
    return best, out


def main() -> None:
    cell = load_cell("ur10")
    digest = hashlib.sha256()
    work = {f"ten poses, seed {s}": (UR10_TEN + np.random.default_rng(s).uniform(-1e-9, 1e-9, (10, 6)),
                                     ProgramOptions(margin_m=0.01, plan_checks=1600, via_pool=20, max_rounds=3))
            for s in (0, 1)}
    work["pocket pose, no equivalents"] = (np.radians([UR10_POCKET_DEG]), ProgramOptions(
        margin_m=0.01, time_limit_s=0.3, via_pool=100, equivalents=False, plan_checks=1000))
    print(machine_line())
    for name, (Q, opt) in work.items():
        cpu, prog = smallest_cpu(lambda Q=Q, opt=opt: plan_program(cell, Q, opt))
        digest.update(prog.path.tobytes() + prog.summary().encode())
        print(f"  {name:30s} plan {cpu:6.2f} s CPU")
    X = cell.robot.random_q(np.random.default_rng(5), 2000)
    X = np.vstack([X, *(np.linspace(a, b, 50) for a, b in zip(UR10_TEN[:-1], UR10_TEN[1:]))])
    chk = FeasibilityChecker(cell)
    cpu, d = smallest_cpu(lambda: np.array([chk.min_pair_distance(q) for q in X]))
    digest.update(np.asarray(d).tobytes())
    print(f"  smallest pair distance       {cpu / len(X) * 1e6:6.1f} us CPU per configuration ({len(X)})")
    print(f"  hash of the programs and distances: {digest.hexdigest()[:16]}")


if __name__ == "__main__":
    main()
