"""Rerun every hostile input as a real ``pin-kpi-oed`` subprocess and print a table.

    .venv/bin/python -m tests.hostile.run_hostile [--keep DIR]

Per case: exit code, time (s), files changed, and whether the refusal is one clear line naming the
expected option/field (no traceback). Exit code 0 when every case passes.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from tests.hostile.cases import CASES, argv_of, build_inputs, snapshot


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
    bad = 0
    cases = [c for c in CASES if not a.k or a.k in c.id]
    print(f"{'case':<40}{'rc':>4}{'time s':>8}  {'changed':<8} verdict / last stderr line")
    for c in cases:
        work = root / "work"
        if work.exists():
            shutil.rmtree(work)
        shutil.copytree(base, work, symlinks=False)
        (work / "link.csv").unlink()
        (work / "link.csv").symlink_to(work / "tr.csv")
        before = snapshot(work)
        t0 = time.perf_counter()
        p = subprocess.run(exe + argv_of(c, work), capture_output=True, text=True, timeout=600)
        dt = time.perf_counter() - t0
        changed = [k for k in set(before) | set(snapshot(work)) if before.get(k) != snapshot(work).get(k)]
        lines = [ln for ln in p.stderr.strip().splitlines() if ln.strip()]
        last = lines[-1] if lines else ""
        ok = p.returncode == 2 and "Traceback" not in p.stderr and not changed and c.expect in last
        bad += not ok
        print(f"{c.id:<40}{p.returncode:>4}{dt:>8.2f}  {len(changed):<8} {'ok  ' if ok else 'FAIL'} {last[:110]}")
    print(f"{len(cases) - bad}/{len(cases)} cases: one clear line, exit 2, nothing written")
    if not a.keep:
        shutil.rmtree(root, ignore_errors=True)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
