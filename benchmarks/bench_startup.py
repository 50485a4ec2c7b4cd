"""How fast a command starts and how fast the default ``identify`` runs, in CPU time of the whole process.

Each figure is the CPU time (user + system) of ``python -m pin_kpi_oed ...`` as a process, as a user's script pays
it: the median of ``REPEAT`` runs, with the machine's load at the start of the benchmark and of each figure (CPU time
grows a little under load, wall time a lot). The package's bytecode is compiled first (``compileall``), as an
installed package's is: where ``PYTHONDONTWRITEBYTECODE`` is set, every run would otherwise compile the ~80 modules
identify imports again (about 0.5 s of CPU) and measure the interpreter's compiler rather than the package.

Targets: ``--help`` and ``info ur10`` ≤ 0.3 s; ``identify --discrepancy auto --validate`` on the real UR10 Series C
(``shared/data/ipa_ur10``, the README's example: 50 % split, seed 0: 1,386 training rows) ≤ 4 s, on all 2,773 rows
≤ 8 s and on 12,000 rows (Series A's 11,911 grid poses and the first 89 rows of Series C, two stations, as
``benchmarks.bench_discrepancy`` builds them) ≤ 20 s, each validated on the same held-out half of Series C; the pool
selection of 60 of 1,000 UR5 candidates (``benchmarks.bench_certificate``'s pool, KPI) ≤ 0.3 s, in process (the
selection alone). The import sets of ``--help`` and ``info`` are pinned by ``tests/test_cli_startup.py``; whether
identify's numbers stay the same, by ``benchmarks.identify_unchanged``.

Run:  python -m benchmarks bench_startup   (``make bench`` runs it with the others)
      python -m benchmarks.bench_startup --before OTHER_CHECKOUT [--identify-only]
          (each identify figure also for another checkout's package, the runs interleaved: before, after, before, ...)
"""

from __future__ import annotations

import argparse
import compileall
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.common import figure, ipa_folder_or_say, load_average

ROOT = Path(__file__).resolve().parents[1]
REPEAT = 3
#: (arguments, target CPU s)
STARTUP = ((["--help"], 0.3), (["info", "ur10"], 0.3))
#: target CPU s of the pool selection 1,000 -> 60
POOL_TARGET = 0.3


def process_cpu(argv: list[str], cwd: Path | None = None, root: Path = ROOT) -> float:
    """CPU seconds (user + system) of ``python -m pin_kpi_oed argv`` run as a process with ``root``'s package.

    Raises:
        RuntimeError: a non-zero exit code, with its stderr.
    """
    env = {**os.environ, "PYTHONPATH": str(root) + os.pathsep + os.environ.get("PYTHONPATH", "")}
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


def paired_cpu(argv: list[str], cwd: Path, before: Path, repeat: int = REPEAT) -> tuple[list[float], list[float]]:
    """CPU seconds of ``repeat`` runs with ``before``'s package and as many with this checkout's, interleaved
    (before, after, before, ...): (before's, after's)."""
    pairs = [(process_cpu(argv, cwd, before), process_cpu(argv, cwd)) for _ in range(repeat)]
    return [b for b, _ in pairs], [a for _, a in pairs]


def data_rows(path: Path) -> int:
    """Measurement rows of a CSV (lines starting with a number)."""
    return sum(1 for line in path.read_text().splitlines() if line[:1].isdigit() or line[:1] == "-")


def identify_cases(work: Path, ipa: Path) -> list[tuple[str, list[str], float]]:
    """(label, arguments, target CPU s) of the default identify on Series C: the README's split and all rows; and on
    12,000 rows of Series A + C (two stations, the held-out file labelled with Series C's station)."""
    train, test = work / "c_train.csv", work / "c_test.csv"
    process_cpu(["import-ipa", str(ipa / "Series_C"), "--position-only", "--split", "0.5", "--seed", "0",
                 "--train", str(train), "--test", str(test)], work)
    every = work / "c_all.csv"
    process_cpu(["import-ipa", str(ipa / "Series_C"), "--position-only", "--out", str(every)], work)
    common = ["--robot", "ur10", "--reflector", "0,0,0.109", "--discrepancy", "auto"]
    cases = [(f"identify auto --validate, {data_rows(train):,} rows (CPU s)",
              ["identify", "--data", str(train), "--validate", str(test), *common], 4.0),
             (f"identify auto --validate, {data_rows(every):,} rows (CPU s)",
              ["identify", "--data", str(every), "--validate", str(test), *common], 8.0)]
    if not (ipa / "Series_A").is_dir():
        return cases
    grid, rest, test_c = work / "a_all.csv", work / "c_rest.csv", work / "c_test_station.csv"
    process_cpu(["import-ipa", str(ipa / "Series_A"), "--position-only", "--out", str(grid)], work)
    lines = every.read_text().splitlines(keepends=True)
    head = sum(1 for x in lines if not (x[:1].isdigit() or x[:1] == "-"))
    rest.write_text("".join(lines[:head + max(0, 12_000 - data_rows(grid))]))
    held = test.read_text().splitlines()
    top = sum(1 for x in held if not (x[:1].isdigit() or x[:1] == "-"))
    test_c.write_text("\n".join(held[:top - 1] + [held[top - 1] + ",station"]
                                + [x + "," + rest.stem for x in held[top:]]) + "\n")
    cases.append((f"identify auto --validate, {data_rows(grid) + data_rows(rest):,} rows, 2 stations (CPU s)",
                  ["identify", "--data", str(grid), "--data", str(rest), "--validate", str(test_c), *common], 20.0))
    return cases


def pool_cpu(repeat: int = REPEAT) -> float:
    """Median CPU seconds of the pool selection of 60 of 1,000 UR5 candidates (KPI; the selection alone, in process,
    one BLAS thread)."""
    from benchmarks.bench_certificate import ur5_pool
    from pin_kpi_oed.oed.pool import select
    from pin_kpi_oed.threads import limited_threads

    Fp, E = ur5_pool(1000)
    times = []
    with limited_threads():
        for _ in range(repeat):
            c0 = time.process_time()
            select(Fp, 60, E)
            times.append(time.process_time() - c0)
    return float(np.median(times))


def main(argv: list[str] | None = None) -> None:
    """Print the load, then each figure: CPU seconds, target, ratio (with ``--before``: the identify figures of both
    checkouts, interleaved, and how many pairs the after won)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", type=Path, default=None, help="another checkout: its identify figures interleaved")
    ap.add_argument("--identify-only", action="store_true", help="the identify figures only")
    args = ap.parse_args([] if argv is None else argv)  # ``python -m benchmarks`` calls main() with its own argv
    print(f"load average {', '.join(f'{x:.2f}' for x in os.getloadavg())} on {os.cpu_count()} cores at the start; "
          f"bytecode compiled first", flush=True)
    compileall.compile_dir(str(ROOT / "pin_kpi_oed"), quiet=1)
    if args.before is not None:
        compileall.compile_dir(str(args.before / "pin_kpi_oed"), quiet=1)
    if not args.identify_only:
        for cmd, target in STARTUP:
            figure(f"pin-kpi-oed {' '.join(cmd)} (CPU s, load {load_average():.1f})", median_cpu(cmd), target)
        figure(f"pool selection 1,000 -> 60, UR5, KPI, in process (CPU s, load {load_average():.1f})", pool_cpu(),
               POOL_TARGET)
    ipa = ipa_folder_or_say("C")
    if ipa is None:
        return
    with tempfile.TemporaryDirectory() as tmp:
        for label, cmd, target in identify_cases(Path(tmp), ipa):
            if args.before is None:
                figure(f"{label}, load {load_average():.1f}", median_cpu(cmd, Path(tmp)), target)
                continue
            load = load_average()
            b, a = paired_cpu(cmd, Path(tmp), args.before.resolve())
            print(f"  before: {', '.join(f'{x:.2f}' for x in b)} s; after: {', '.join(f'{x:.2f}' for x in a)} s; "
                  f"after faster in {sum(x < y for x, y in zip(a, b))} of {len(a)} pairs", flush=True)
            figure(f"{label}, before {np.median(b):.2f} s, load {load:.1f} -> {load_average():.1f}",
                   float(np.median(a)), target)


if __name__ == "__main__":
    main(sys.argv[1:])
