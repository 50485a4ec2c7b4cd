"""How fast a command starts and how fast the default ``identify`` runs, in CPU time of the whole process.

Each figure is the CPU time (user + system) of ``python -m pin_kpi_oed ...`` as a process, as a user's script pays
it: the median of ``REPEAT`` runs, with the machine's load at the start (CPU time grows a little under load, wall
time a lot). Targets: ``--help`` and ``info ur10`` ≤ 0.3 s; ``identify --discrepancy auto --validate`` on the real
UR10 Series C (``shared/data/ipa_ur10``, the README's example: 50 % split, seed 0: 1,386 training rows) ≤ 4 s and on
all 2,773 rows ≤ 8 s (validated on the same held-out half). The import sets of ``--help`` and ``info`` are pinned by
``tests/test_cli_startup.py``; whether identify's numbers stay the same, by ``benchmarks.identify_unchanged``.

Run:  python -m benchmarks bench_startup   (``make bench`` runs it with the others)
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from benchmarks.common import figure, ipa_folder_or_say, load_average

ROOT = Path(__file__).resolve().parents[1]
REPEAT = 3
#: (arguments, target CPU s)
STARTUP = ((["--help"], 0.3), (["info", "ur10"], 0.3))


def process_cpu(argv: list[str], cwd: Path | None = None) -> float:
    """CPU seconds (user + system) of ``python -m pin_kpi_oed argv`` run as a process.

    Raises:
        RuntimeError: a non-zero exit code, with its stderr.
    """
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    res = subprocess.run([sys.executable, "-m", "pin_kpi_oed", *argv], cwd=cwd, env=env, capture_output=True,
                         text=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if res.returncode != 0:
        raise RuntimeError(f"pin-kpi-oed {' '.join(argv)}: exit {res.returncode}: {res.stderr.strip()[-300:]}")
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def median_cpu(argv: list[str], cwd: Path | None = None, repeat: int = REPEAT) -> float:
    """The median CPU seconds of ``repeat`` runs (:func:`process_cpu`)."""
    return float(np.median([process_cpu(argv, cwd) for _ in range(repeat)]))


def identify_cases(work: Path, ipa: Path) -> list[tuple[str, list[str], float]]:
    """(label, arguments, target CPU s) of the default identify on Series C: the README's split, and all rows."""
    train, test = work / "c_train.csv", work / "c_test.csv"
    process_cpu(["import-ipa", str(ipa / "Series_C"), "--position-only", "--split", "0.5", "--seed", "0",
                 "--train", str(train), "--test", str(test)], work)
    every = work / "c_all.csv"
    process_cpu(["import-ipa", str(ipa / "Series_C"), "--position-only", "--out", str(every)], work)
    rows = {p: sum(1 for line in p.read_text().splitlines() if line[:1].isdigit() or line[:1] == "-")
            for p in (train, every)}
    common = ["--robot", "ur10", "--validate", str(test), "--reflector", "0,0,0.109", "--discrepancy", "auto"]
    return [(f"identify auto --validate, {rows[train]:,} rows (CPU s)", ["identify", "--data", str(train), *common],
             4.0),
            (f"identify auto --validate, {rows[every]:,} rows (CPU s)", ["identify", "--data", str(every), *common],
             8.0)]


def main() -> None:
    """Print each figure: CPU seconds, target, ratio."""
    for argv, target in STARTUP:
        figure(f"pin-kpi-oed {' '.join(argv)} (CPU s, load {load_average():.1f})", median_cpu(argv), target)
    ipa = ipa_folder_or_say("C")
    if ipa is None:
        return
    with tempfile.TemporaryDirectory() as tmp:
        for label, argv, target in identify_cases(Path(tmp), ipa):
            figure(f"{label}, load {load_average():.1f}", median_cpu(argv, Path(tmp)), target)


if __name__ == "__main__":
    main()
