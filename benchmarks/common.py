"""Timing helpers and simulated cases shared by the benchmarks."""

from __future__ import annotations

import argparse
import math
import os
import resource
import time
from contextlib import contextmanager
from pathlib import Path
from collections.abc import Callable, Iterator


def cli_in_process(*argv: object) -> tuple[int, str, str]:
    """Run one ``pin-kpi-oed`` command in this process: (exit code, stdout, stderr)."""
    import contextlib
    import io

    from pin_kpi_oed.cli.app import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = main([str(a) for a in argv])
        except SystemExit as exc:
            rc = int(exc.code or 0)
    return rc, out.getvalue(), err.getvalue()


def cpu_time() -> float:
    """CPU time (s) of this process and its finished children (user + system)."""
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def load_average() -> float:
    """The machine's 1-minute load average (``os.getloadavg``)."""
    return float(os.getloadavg()[0])


class Timing(float):
    """A wall time in seconds (the float's value) with the CPU time of the same run and the machine's load average
    at its start: a wall time taken while other work held the cores is recognisable by the load, and its CPU time
    is still the figure's cost. Scaling (``t * 1e3``) scales both times."""

    cpu_s: float
    load: float

    def __new__(cls, wall_s: float, cpu_s: float, load: float) -> Timing:
        obj = super().__new__(cls, wall_s)
        obj.cpu_s, obj.load = float(cpu_s), float(load)
        return obj

    def __mul__(self, k: object) -> Timing | float:
        if isinstance(k, (int, float)) and not isinstance(k, Timing):
            return Timing(float(self) * k, self.cpu_s * k, self.load)
        return float(self) * k  # type: ignore[operator]

    __rmul__ = __mul__

    def words(self, unit: str = "s") -> str:
        """'wall W, CPU C, load L at the start' (``unit`` as the figure's)."""
        return f"wall {float(self):.4g} {unit}, CPU {self.cpu_s:.4g} {unit}, load {self.load:.1f} at the start"


class Stopwatch:
    """Wall and CPU time of a block (:func:`stopwatch`); ``timing`` is set when the block ends."""

    def __init__(self) -> None:
        self.load, self.t0, self.c0 = load_average(), time.perf_counter(), cpu_time()
        self.timing: Timing | None = None

    def stop(self) -> Timing:
        self.timing = Timing(time.perf_counter() - self.t0, cpu_time() - self.c0, self.load)
        return self.timing


@contextmanager
def stopwatch() -> Iterator[Stopwatch]:
    """``with stopwatch() as sw: ...``, then ``sw.timing`` (a :class:`Timing`)."""
    sw = Stopwatch()
    try:
        yield sw
    finally:
        sw.stop()


def timed(fn: Callable[[], object]) -> tuple[Timing, object]:
    """(Timing of one call of ``fn``, its result)."""
    sw = Stopwatch()
    out = fn()
    return sw.stop(), out


def median_time(fn: Callable[[], object], repeat: int = 30, warmup: int = 3) -> Timing:
    """Median wall time of ``fn()`` over ``repeat`` runs (after ``warmup``), with the median CPU time of the runs and
    the load average before the first (a :class:`Timing`, s)."""
    for _ in range(warmup):
        fn()
    load = load_average()
    ts, cs = [], []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), cpu_time()
        fn()
        ts.append(time.perf_counter() - t0)
        cs.append(cpu_time() - c0)
    ts.sort()
    cs.sort()
    return Timing(ts[len(ts) // 2], cs[len(cs) // 2], load)


def machine_line() -> str:
    """'load average a, b, c on n cores' (printed at the start of each benchmark)."""
    return f"load average {', '.join(f'{x:.2f}' for x in os.getloadavg())} on {os.cpu_count()} cores"


def withheld_ur10(n_rows: int):
    """A simulated UR10 measured with a withheld gear harmonic: geometric errors (0.5 mm / 1 mrad), orders 2 and 3
    of the shoulder lift and the elbow at 0.3 mrad, tracker σ = 10 µm, ``n_rows`` random configurations (seeded).

    Returns:
        (nominal measurement model, simulated measurements).
    """
    import numpy as np

    from pin_kpi_oed import NoiseModel, TrackerModel, load_robot
    from pin_kpi_oed.effects.library import GearHarmonic
    from pin_kpi_oed.simulation.simulator import Tolerances, default_tracker_pose, random_truth, simulate
    from pin_kpi_oed.oed.identifiability import analyse

    rb = load_robot("ur10")
    model = TrackerModel(rb, tracker_T_base=default_tracker_pose(rb), reflector_m=np.array([0.03, 0.02, 0.08]),
                         noise=NoiseModel(sigma_xyz_m=(1e-5,) * 3))
    truth = random_truth(model, Tolerances(5e-4, 1e-3), seed=4, only=[i for i in analyse(model).base if i < 36])
    gh = GearHarmonic(rb, joints=["shoulder_lift_joint", "elbow_joint"], orders=(2, 3))
    theta = 3e-4 * np.random.default_rng(5).standard_normal(len(gh.param_names()))
    Q = rb.random_q(np.random.default_rng(6), n_rows)
    return model, simulate(model, Q, truth, effects=[(gh, theta)], seed=7)


IPA_MISSING = "IPA UR10 data not found: nothing to do (set PIN_KPI_OED_IPA_DATA)"


def find_ipa_data():
    """The IPA UR10 folder (``Series_A`` … ``Series_D``): $PIN_KPI_OED_IPA_DATA, else ``shared/data/ipa_ur10`` beside
    an ancestor of the repository; None when neither exists."""
    from pathlib import Path

    env = os.environ.get("PIN_KPI_OED_IPA_DATA")
    if env:
        return Path(env)
    for up in Path(__file__).resolve().parents[1].parents:
        if (up / "shared" / "data" / "ipa_ur10").is_dir():
            return up / "shared" / "data" / "ipa_ur10"
    return None


def ipa_folder_or_say(series: str = "C"):
    """The IPA UR10 folder (:func:`find_ipa_data`) when it holds ``Series_<series>``; else None, :data:`IPA_MISSING`
    printed."""
    folder = find_ipa_data()
    if folder is None or not (folder / f"Series_{series}").is_dir():
        print(IPA_MISSING)
        return None
    return folder


def ipa_ur10_model():
    """The nominal UR10 of the IPA series: reflector 0.109 m along the flange axis, σ 0.1 mm per axis (a uniform
    weight: the data state no noise)."""
    import numpy as np

    from pin_kpi_oed import NoiseModel, TrackerModel, load_robot

    return TrackerModel(load_robot("ur10"), reflector_m=np.array([0.0, 0.0, 0.109]),
                        noise=NoiseModel(sigma_xyz_m=(1e-4,) * 3))


def load_ipa_series(folder, series: str, *, with_time: bool = False):
    """Series ``series`` (A, B, C or D) of the IPA UR10 data as position rows (what ``import-ipa --position-only``
    writes): joints (rad), position (m), temperature (°C), the time (s) with ``with_time``; source ``<series>.csv``."""
    from pin_kpi_oed.data.ipa import import_ipa
    from pin_kpi_oed.data.measurements import MeasurementSet

    ms = import_ipa(folder / f"Series_{series}")
    return MeasurementSet(ms.joint_names, ms.q, ms.position_m, temperature_c=ms.temperature_c,
                          time_s=ms.time_s if with_time else None, source=f"{series}.csv")


def paired_by_size(recs: list[dict], sizes, methods: tuple[str, ...], scores: tuple[str, ...]) -> dict:
    """Per m of ``sizes``: the means over the splits of every method's scores and, from two splits on, the paired
    tests (:func:`~pin_kpi_oed.studies.kpi_withheld.paired_summary`) of ``methods[0]`` against each other method
    (``<first>_vs_<other>_<score>``); ``recs[i]["sizes"][m][method][score]`` holds one split's value."""
    import numpy as np

    from pin_kpi_oed.studies.kpi_withheld import paired_summary

    first = methods[0]
    out: dict = {}
    for m in sizes:
        col = {(meth, k): np.array([r["sizes"][m][meth][k] for r in recs]) for meth in methods for k in scores}
        out[m] = {"means": {meth: {k: float(col[(meth, k)].mean()) for k in scores} for meth in methods}}
        if len(recs) >= 2:
            out[m]["paired"] = {f"{first}_vs_{b}_{k}": paired_summary(col[(first, k)].tolist(), col[(b, k)].tolist())
                                for b in methods[1:] for k in scores}
    return out


def paired_lines(summary: dict) -> list[str]:
    """One line per paired test of :func:`paired_by_size`'s summary: m, the test, the paired median change with
    wins and the sign test, then the Wilcoxon p and the change of the means
    (:func:`~pin_kpi_oed.studies.paired.paired_text`)."""
    from pin_kpi_oed.studies.paired import paired_text

    return [f"m={m} {name}: {paired_text(p)}" for m, s in summary.items() for name, p in s.get("paired", {}).items()]


def report(label: str, seconds: float, target: float | None = None) -> str:
    """One line: label, time (ms) and the ratio to its target."""
    line = f"{label:<55} {seconds * 1e3:9.3f} ms"
    if target is not None:
        ok = "OK  " if seconds <= target else "MISS"
        line += f"   target {target * 1e3:8.1f} ms   ratio {seconds / target:5.2f}  {ok}"
    line += _cpu_words(seconds, 1e3, "ms")
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
    line += _cpu_words(measured, 1.0, unit)
    print(line, flush=True)
    return line


def _cpu_words(value: object, k: float, unit: str) -> str:
    """The CPU time and start load of a :class:`Timing` figure (wall is the figure itself); for a figure that is no
    time (a ratio, an error), nothing."""
    if isinstance(value, Timing):
        return f"  | CPU {value.cpu_s * k:.4g} {unit}, load {value.load:.1f} at the start"
    return ""


class BusyCore:
    """Context: one extra process spinning on a core (the 'second core busy' condition of the targets)."""

    def __enter__(self) -> BusyCore:
        import subprocess
        import sys

        self.proc = subprocess.Popen([sys.executable, "-c", "while True: pass"])
        return self

    def __exit__(self, *exc: object) -> None:
        self.proc.kill()
        self.proc.wait()


def sign_test_p(wins: int, n: int) -> float:
    """Two-sided sign test: the probability of a split at least as uneven as ``wins`` of ``n`` pairs under no
    difference."""
    k = min(wins, n - wins)
    return min(1.0, 2.0 * sum(math.comb(n, i) for i in range(k + 1)) / 2.0 ** n) if n else 1.0


def checkout_roots(prog: str, argv: list[str] | None, repeat: int = 5) -> tuple[argparse.Namespace, dict[str, Path]]:
    """The options of a before/after benchmark (``--repeat N``, ``--before PATH``) and the checkouts to run:
    ``{"after": this one}``, with ``"before"`` first when given.

    Args:
        prog: the benchmark's command, for its help.
        argv: command-line arguments (None: the process's).
        repeat: the default of ``--repeat``.
    """
    ap = argparse.ArgumentParser(prog=prog)
    ap.add_argument("--repeat", type=int, default=repeat)
    ap.add_argument("--before", type=Path, default=None)
    a = ap.parse_args(argv)
    here = Path(__file__).resolve().parents[1]
    return a, ({"after": here} if a.before is None else {"before": a.before.resolve(), "after": here})
