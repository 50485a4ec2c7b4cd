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

The README's worked example (a UR5: design, export, simulate, identify, diagnose, identify --effects, compensate),
each command as a process in a temporary folder holding the example's files, in order, each command's outputs feeding
the next: CPU (user + system of the whole process) and wall time of each, the median of ``--repeat`` runs of the whole
sequence, every exit code checked. With ``--before PATH`` the same sequence runs on that checkout too (its folder
first on ``PYTHONPATH``), interleaved (before, after, before, after ...), so both see the same load; a command the
before checkout cannot run (an option it lacked) is named in its row. Each checkout's ``pin_kpi_oed`` and ``urdf``
are copied to the temporary folder and compiled there (nothing is written into either checkout); ``--cache FILE``
keeps each finished sequence, so an interrupted run resumes where it stopped.

Run:  python -m benchmarks bench_startup   (``make bench`` runs it with the others)
      python -m benchmarks.bench_startup --before OTHER_CHECKOUT [--identify-only]
          (each identify figure also for another checkout's package, the runs interleaved: before, after, before, ...)
      python -m benchmarks.bench_startup --readme-only --before ../other-checkout --repeat 3
"""

from __future__ import annotations

import argparse
import compileall
import json
import os
import re
import shlex
import shutil
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.common import figure, ipa_folder_or_say, load_average, sign_test_p

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


#: What any command that loads a robot pays before the package's own work: the interpreter, NumPy with one BLAS
#: thread (as the command line sets it) and Pinocchio, which loads the URDF.
FLOOR = "import numpy, pinocchio"
FLOOR_LABEL = "the import floor: python -c 'import numpy, pinocchio', one BLAS thread"


def floor_cpu() -> float:
    """CPU seconds (user + system) of a process that only imports :data:`FLOOR`, with the thread variables the
    command line sets (those already set are kept)."""
    env = {**os.environ, **{k: os.environ.get(k, "1") for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS",
                                                               "MKL_NUM_THREADS")}}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run([sys.executable, "-c", FLOOR], env=env, check=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def info_and_floor(argv: list[str], repeat: int = 2 * REPEAT + 1) -> tuple[list[float], list[float]]:
    """``repeat`` runs of the command and of the import floor (:func:`floor_cpu`), interleaved so that both see the
    same machine: (the command's CPU seconds, the floor's)."""
    runs, floors = [], []
    for _ in range(repeat):
        runs.append(process_cpu(argv))
        floors.append(floor_cpu())
    return runs, floors


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


def startup_figures(before: Path | None = None, identify_only: bool = False) -> None:
    """Print the load, then each start-up figure: CPU seconds, target, ratio (with ``before``: the identify figures of
    both checkouts, interleaved, and how many pairs the after won; ``identify_only``: those alone)."""
    print(f"load average {', '.join(f'{x:.2f}' for x in os.getloadavg())} on {os.cpu_count()} cores at the start; "
          f"bytecode compiled first", flush=True)
    compileall.compile_dir(str(ROOT / "pin_kpi_oed"), quiet=1)
    if before is not None:
        compileall.compile_dir(str(before / "pin_kpi_oed"), quiet=1)
    if not identify_only:
        for cmd, target in STARTUP:
            if cmd[0] != "info":
                figure(f"pin-kpi-oed {' '.join(cmd)} (CPU s, load {load_average():.1f})", median_cpu(cmd), target)
                continue
            load = load_average()
            runs, floors = info_and_floor(cmd)
            figure(f"pin-kpi-oed {' '.join(cmd)} (CPU s, load {load:.1f})", float(np.median(runs)), target,
                   baseline=float(np.median(floors)), baseline_label=FLOOR_LABEL)
            print(f"  the package's own share (info minus the import floor, pair by pair): median "
                  f"{np.median(np.subtract(runs, floors)):.3f} s; info {', '.join(f'{x:.2f}' for x in runs)} s, "
                  f"floor {', '.join(f'{x:.2f}' for x in floors)} s", flush=True)
        figure(f"pool selection 1,000 -> 60, UR5, KPI, in process (CPU s, load {load_average():.1f})", pool_cpu(),
               POOL_TARGET)
    ipa = ipa_folder_or_say("C")
    if ipa is None:
        return
    with tempfile.TemporaryDirectory() as tmp:
        for label, cmd, target in identify_cases(Path(tmp), ipa):
            if before is None:
                figure(f"{label}, load {load_average():.1f}", median_cpu(cmd, Path(tmp)), target)
                continue
            load = load_average()
            b, a = paired_cpu(cmd, Path(tmp), before.resolve())
            print(f"  before: {', '.join(f'{x:.2f}' for x in b)} s; after: {', '.join(f'{x:.2f}' for x in a)} s; "
                  f"after faster in {sum(x < y for x, y in zip(a, b))} of {len(a)} pairs", flush=True)
            figure(f"{label}, before {np.median(b):.2f} s, load {load:.1f} -> {load_average():.1f}",
                   float(np.median(a)), target)


# ---------------------------------------------------------------------- the README's worked example, before and after
#: The README's block that the example is read from (the first ```bash block after this text).
README_EXAMPLE = "**Worked example: a UR5**"


def readme_commands(readme: Path = ROOT / "README.md") -> list[list[str]]:
    """The worked example's ``pin-kpi-oed`` commands (arguments only), continuations joined, comments dropped, shell
    variables substituted; a path under the example's variable (``$EX/x``) becomes ``x`` (the file is copied to the
    run's folder, :func:`example_files`).

    Raises:
        ValueError: no such block, or a line that is neither a variable nor a ``pin-kpi-oed`` command.
    """
    text = readme.read_text()
    m = re.compile(r"^```bash\n(.*?)^```", re.S | re.M).search(text, text.index(README_EXAMPLE))
    if m is None:
        raise ValueError(f"README.md: no bash block after {README_EXAMPLE!r}")
    cmds = []
    for line in m.group(1).replace("\\\n", " ").splitlines():
        words = shlex.split(line, comments=True)
        if len(words) == 1 and re.fullmatch(r"[A-Z_]+=\S+", words[0]):
            continue  # the examples folder's variable: its files are copied to the run's folder
        if words and words[0] == "pin-kpi-oed":
            cmds.append([re.sub(r"^\$[A-Z_]+/", "", w) for w in words[1:]])
        elif words:
            raise ValueError(f"README.md's worked example: unexpected line {line!r}")
    return cmds


def example_files(readme: Path = ROOT / "README.md") -> list[str]:
    """The examples folder's files the worked example reads (``$EX/name``)."""
    text = readme.read_text()
    block = text[text.index(README_EXAMPLE):].split("```bash", 1)[1].split("```", 1)[0]
    return sorted(set(re.findall(r"\$[A-Z_]+/([\w.\-]+)", block)))


def step_labels(cmds: list[list[str]]) -> list[str]:
    """A row label per command: its name, and ``--effects`` where the same command ran before without it."""
    labels: list[str] = []
    for c in cmds:
        label = c[0] + (" --effects" if "--effects" in c and c[0] in labels else "")
        labels.append(label + (f" ({labels.count(label) + 1})" if label in labels else ""))
    return labels


def checkout_copy(src: Path, dst: Path) -> Path:
    """``src``'s ``pin_kpi_oed`` and ``urdf`` copied to ``dst`` and compiled there (as an installed package's
    bytecode is; nothing is written into ``src``); returns ``dst``."""
    skip = shutil.ignore_patterns("__pycache__", "*.pyc")
    for part in ("pin_kpi_oed", "urdf"):
        if (src / part).is_dir():
            shutil.copytree(src / part, dst / part, ignore=skip, dirs_exist_ok=True)
    compileall.compile_dir(str(dst / "pin_kpi_oed"), quiet=1)
    return dst


def run_sequence(code: Path, cmds: list[list[str]], work: Path) -> list[dict]:
    """Every command in ``work`` (the example's files copied in), in order, as a process on the checkout ``code``:
    per command its CPU s (user + system of the process), wall s, load at its start, exit code and error line."""
    work.mkdir(parents=True)
    for name in example_files():
        shutil.copy(ROOT / "examples" / name, work / name)
    env = {**os.environ, "PYTHONPATH": str(code) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    rows = []
    for argv in cmds:
        load, before, t0 = load_average(), resource.getrusage(resource.RUSAGE_CHILDREN), time.perf_counter()
        res = subprocess.run([sys.executable, "-m", "pin_kpi_oed", *argv], cwd=work, env=env, capture_output=True,
                             text=True)
        wall, after = time.perf_counter() - t0, resource.getrusage(resource.RUSAGE_CHILDREN)
        err = [x for x in res.stderr.strip().splitlines() if x.strip()]
        rows.append({"cpu_s": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
                     "wall_s": wall, "load": load, "rc": res.returncode,
                     "error": err[-1][:160] if res.returncode != 0 and err else ""})
    return rows


def readme_runs(checkouts: dict[str, Path], repeat: int, cache: Path | None, tmp: Path) -> dict[str, list[list]]:
    """The sequence ``repeat`` times per checkout, interleaved (one of each in turn); finished sequences are read
    from and written to ``cache`` (JSON, keyed by checkout label and run) so an interrupted run resumes.

    Returns:
        {label: [the rows of each run (:func:`run_sequence`)]}.
    """
    cmds = readme_commands()
    done = json.loads(cache.read_text()) if cache is not None and cache.exists() else {}
    key = " ".join(shlex.join(c) for c in cmds)
    if done.get("commands") != key:
        done = {"commands": key}  # another README: nothing kept applies
    copies = {label: checkout_copy(path, tmp / "code" / label) for label, path in checkouts.items()}
    runs: dict[str, list[list]] = {label: [] for label in checkouts}
    for i in range(repeat):
        for label in checkouts:
            name = f"{label} {i}"
            if name not in done:
                done[name] = run_sequence(copies[label], cmds, tmp / "runs" / f"{label}_{i}")
                if cache is not None:
                    cache.write_text(json.dumps(done, indent=1))
            runs[label].append(done[name])
            print(f"  {label} run {i + 1} of {repeat}: {sum(r['cpu_s'] for r in done[name]):.1f} s CPU, "
                  f"{sum(r['wall_s'] for r in done[name]):.1f} s wall, load {done[name][0]['load']:.1f} at its "
                  f"start", flush=True)
    return runs


def cell_text(rows: list[dict]) -> str:
    """One table cell: 'CPU s / wall s' (medians over the runs), or the error of a run that failed."""
    failed = [r for r in rows if r["rc"] != 0]
    if failed:
        return f"failed ({len(failed)} of {len(rows)} runs, exit {failed[0]['rc']}): {failed[0]['error']}"
    return f"{np.median([r['cpu_s'] for r in rows]):.2f} / {np.median([r['wall_s'] for r in rows]):.2f}"


def paired_wins(before: list[dict], after: list[dict]) -> tuple[int, int]:
    """(pairs whose after CPU time is below the before's, pairs), the runs paired in order (interleaved), where
    both ran."""
    pairs = [(b["cpu_s"], a["cpu_s"]) for b, a in zip(before, after) if b["rc"] == 0 and a["rc"] == 0]
    return sum(a < b for b, a in pairs), len(pairs)


def readme_table(runs: dict[str, list[list]], cmds: list[list[str]]) -> list[str]:
    """The table's lines (Markdown): per command, per checkout 'CPU s / wall s' (medians), with a before the
    interleaved pairs in which after took less CPU, the loads at the starts of its runs; then the whole sequence
    (where every command ran) and the sign test over every command's pairs."""
    labels = list(runs)
    paired = labels == ["before", "after"]
    lines = ["| command | " + " | ".join(f"{x}: CPU / wall s" for x in labels)
             + (" | after less CPU |" if paired else " |") + " load at the starts |",
             "|---|" + "---|" * (len(labels) + paired) + "---|"]
    wins = n = 0
    for k, label in enumerate(step_labels(cmds)):
        per = {x: [run[k] for run in runs[x]] for x in labels}
        loads = [r["load"] for x in labels for r in per[x]]
        pair = ""
        if paired:
            w, m = paired_wins(per["before"], per["after"])
            wins, n, pair = wins + w, n + m, f" {w} of {m} pairs |"
        lines.append(f"| `{label}` | " + " | ".join(cell_text(per[x]) for x in labels) + " |" + pair
                     + f" {min(loads):.1f}–{max(loads):.1f} |")
    total = []
    for x in labels:
        ok = [run for run in runs[x] if all(r["rc"] == 0 for r in run)]
        total.append(f"{np.median([sum(r['cpu_s'] for r in run) for run in ok]):.2f} / "
                     f"{np.median([sum(r['wall_s'] for r in run) for run in ok]):.2f}" if ok else "—")
    lines.append("| whole example | " + " | ".join(total) + " |"
                 + (f" {wins} of {n} pairs (sign test p = {sign_test_p(wins, n):.2g}) |" if paired else "") + " |")
    return lines


def readme_figures(before: Path | None, repeat: int, cache: Path | None) -> None:
    """Print the README example's table: this checkout, and ``before`` interleaved with it when given."""
    checkouts = {"after": ROOT} if before is None else {"before": before.resolve(), "after": ROOT}
    print(f"README worked example (UR5), {repeat} run(s) per checkout, load {load_average():.1f} at the start",
          flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        runs = readme_runs(checkouts, repeat, cache, Path(tmp))
    print("\n".join(readme_table(runs, readme_commands())))
    if before is None:
        print("before: python -m benchmarks.bench_startup --readme-only --before OTHER_CHECKOUT (a checkout of the "
              "package before a change, run interleaved with this one)")


def main(argv: list[str] | None = None) -> None:
    """The start-up figures, then the README example's table (``--readme-only``: the table alone).

    Args:
        argv: command-line arguments (none when ``python -m benchmarks`` runs every benchmark).
    """
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_startup", description=__doc__.split("\n")[0])
    ap.add_argument("--before", type=Path, help="a checkout of the package before a change (its folder)")
    ap.add_argument("--repeat", type=int, default=REPEAT, help="runs of the README example per checkout (median)")
    ap.add_argument("--readme-only", action="store_true", help="the README example's table alone")
    ap.add_argument("--identify-only", action="store_true", help="the identify figures alone")
    ap.add_argument("--cache", type=Path, help="JSON file keeping finished runs of the README example (resume; "
                    "another README starts it afresh, a changed checkout does not: delete the file)")
    args = ap.parse_args(argv or [])
    if args.before is not None and not (args.before / "pin_kpi_oed" / "__init__.py").is_file():
        ap.error(f"--before {args.before}: no pin_kpi_oed package in that folder")
    if args.repeat < 1:
        ap.error(f"--repeat {args.repeat}: at least 1")
    if not args.readme_only:
        startup_figures(args.before, args.identify_only)
    if not args.identify_only:
        readme_figures(args.before, args.repeat, args.cache)


if __name__ == "__main__":
    main(sys.argv[1:])
