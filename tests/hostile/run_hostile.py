"""Rerun every hostile input as a real ``pin-kpi-oed`` subprocess, print a table and the counts.

    .venv/bin/python -m tests.hostile.run_hostile [--keep DIR] [-k TEXT]

Per case: exit code, time (s), files changed, and the verdict (``ok``; else ``traceback``, ``input changed``,
``hang``, ``exit 0`` where a refusal is due, ``silent`` where a warning is due, ``written`` when a refusal left
files, ``unclear`` when the refusal does not name the expected option/field in one line). The last lines count
each verdict; the target is 0 of every kind but ``ok``. Exit code 0 when every case passes.
"""

from __future__ import annotations

import argparse
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

from tests.hostile.cases import CASES, Outcome, argv_of, build_inputs, prepare, snapshot

#: the verdicts counted, worst first
VERDICTS = ("traceback", "input changed", "hang", "exit 0", "silent", "written", "unclear")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--keep", default=None, help="work folder to keep (default: a temporary one)")
    ap.add_argument("-k", default=None, help="only cases whose id contains this text")
    a = ap.parse_args()
    root = Path(a.keep or tempfile.mkdtemp(prefix="hostile_"))
    base = root / "inputs"
    if not base.exists():
        build_inputs(base)
    exe = [sys.executable, "-m", "pin_kpi_oed"]
    counts: Counter[str] = Counter()
    cases = [c for c in CASES if not a.k or a.k in c.id]
    print(f"{'case':<44}{'rc':>4}{'cpu s':>8}  {'changed':<8} verdict / last stderr line")
    for c in cases:
        work = root / "work"
        prepare(c, base, work)
        before = snapshot(work)
        t0, r0 = time.perf_counter(), resource.getrusage(resource.RUSAGE_CHILDREN)
        try:
            p = subprocess.run(exe + argv_of(c, work), capture_output=True, text=True, timeout=max(10 * c.max_s, 600))
            rc, out, err = p.returncode, p.stdout, p.stderr
        except subprocess.TimeoutExpired as exc:
            rc, out, err = -9, str(exc.stdout or ""), str(exc.stderr or "")
        dt, r1 = time.perf_counter() - t0, resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
        after = snapshot(work)
        changed = sorted(k for k in set(before) | set(after) if before.get(k) != after.get(k))
        o = Outcome(rc, err, dt, changed, "Traceback" in err, out, tuple(k for k in changed if k in before), cpu)
        v = o.verdict(c)
        counts[v] += 1
        lines = [ln for ln in err.strip().splitlines() if ln.strip()]
        last = lines[-1] if lines else ""
        print(f"{c.id:<44}{rc:>4}{cpu:>8.2f}  {len(changed):<8} {v:<6} {last[:110]}")
    print(f"{counts['ok']}/{len(cases)} cases right: refused in one clear line (exit 2, nothing written) or warned")
    print(", ".join(f"{counts[v]} {v if v != 'exit 0' else 'exit 0 where a refusal is due'}" for v in VERDICTS))
    if not a.keep:
        shutil.rmtree(root, ignore_errors=True)
    return 0 if counts["ok"] == len(cases) else 1


if __name__ == "__main__":
    sys.exit(main())
