"""Timing helpers and simulated cases shared by the benchmarks."""

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


def withheld_ur10(n_rows: int):
    """A simulated UR10 measured with a withheld gear harmonic: geometric errors (0.5 mm / 1 mrad), orders 2 and 3
    of the shoulder lift and the elbow at 0.3 mrad, tracker σ = 10 µm, ``n_rows`` random configurations (seeded).

    Returns:
        (nominal measurement model, simulated measurements).
    """
    import numpy as np

    from pin_kpi_oed import NoiseModel, TrackerModel, load_robot
    from pin_kpi_oed.effects.library import GearHarmonic
    from pin_kpi_oed.identification.simulate import Tolerances, default_tracker_pose, random_truth, simulate
    from pin_kpi_oed.oed.identifiability import analyse

    rb = load_robot("ur10")
    model = TrackerModel(rb, tracker_T_base=default_tracker_pose(rb), reflector_m=np.array([0.03, 0.02, 0.08]),
                         noise=NoiseModel(sigma_xyz_m=(1e-5,) * 3))
    truth = random_truth(model, Tolerances(5e-4, 1e-3), seed=4, only=[i for i in analyse(model).base if i < 36])
    gh = GearHarmonic(rb, joints=["shoulder_lift_joint", "elbow_joint"], orders=(2, 3))
    theta = 3e-4 * np.random.default_rng(5).standard_normal(len(gh.param_names()))
    Q = rb.random_q(np.random.default_rng(6), n_rows)
    return model, simulate(model, Q, truth, effects=[(gh, theta)], seed=7)


def report(label: str, seconds: float, target: float | None = None) -> str:
    """One line: label, time (ms) and the ratio to its target."""
    line = f"{label:<55} {seconds * 1e3:9.3f} ms"
    if target is not None:
        ok = "OK  " if seconds <= target else "MISS"
        line += f"   target {target * 1e3:8.1f} ms   ratio {seconds / target:5.2f}  {ok}"
    print(line, flush=True)
    return line


def figure(label: str, measured: float, target: float, unit: str = "s", baseline: float | None = None,
           baseline_label: str = "", lower_is_better: bool = True) -> str:
    """One line per figure: measured value, target, ratio to the target, verdict, and the baseline beaten.

    Args:
        label: what was measured (with the data size).
        measured: the value (in ``unit``).
        target: the target (same unit); ratio = measured / target.
        unit: unit printed after the values.
        baseline: the baseline's value measured in the same run (same unit), if any.
        baseline_label: what the baseline is.
        lower_is_better: False for figures that must reach at least the target (efficiencies).

    Returns:
        The printed line.
    """
    ok = measured <= target if lower_is_better else measured >= target
    line = (f"{label:<58} {measured:10.4g} {unit:<4} target {'<=' if lower_is_better else '>='} {target:<8.4g} "
            f"ratio {measured / target:6.3f}  {'OK  ' if ok else 'MISS'}")
    if baseline is not None:
        line += f"  | {baseline_label} {baseline:.4g} {unit} (x{measured / baseline:.3f})"
    print(line, flush=True)
    return line


class BusyCore:
    """Context: one extra process spinning on a core (the 'second core busy' condition of the targets)."""

    def __enter__(self) -> "BusyCore":
        import subprocess
        import sys

        self.proc = subprocess.Popen([sys.executable, "-c", "while True: pass"])
        return self

    def __exit__(self, *exc: object) -> None:
        self.proc.kill()
        self.proc.wait()
