"""The default ``identify`` of two checkouts on the real UR10 Series C: the same numbers, and each one's CPU time.

Runs ``pin-kpi-oed identify --discrepancy auto --validate`` (the README's real-data example) once per checkout as a
process and compares what a user reads and keeps: every printed line (the fit's time in ms aside), the identified
parameters (to 1e-9 m / 1e-9 rad), the held-out figures before and after, the discrepancy's decision, its kernel
and K-fold figures (to 1e-6 relative: an optimiser's rounding), and the predicted TCP σ::

    python -m benchmarks.identify_unchanged --before ../other-checkout [--rows 1387] [--repeat 3]

``--before`` is the folder of another checkout of the package (e.g. ``git worktree add /tmp/base <commit>``); the
current checkout is the after. The data: ``shared/data/ipa_ur10/Series_C`` (skipped with a note without it),
imported and split 50/50 with seed 0 as in the README. Exit code 1 when anything differs.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
#: the fit's own wall time, printed in the summary line: the one figure allowed to differ
TIMING = re.compile(r"\d+(\.\d+)? ms\)")


def ipa_folder() -> Path | None:
    """The IPA dataset's folder (``shared/data/ipa_ur10`` two or three folders above the checkout), or None."""
    for up in (ROOT.parent, ROOT.parent.parent, ROOT.parent.parent.parent):
        p = up / "shared" / "data" / "ipa_ur10"
        if (p / "Series_C").is_dir():
            return p
    return None


def run_cli(root: Path, argv: list[str], cwd: Path) -> tuple[str, float]:
    """(stdout, CPU seconds user + system of the process) of ``python -m pin_kpi_oed argv`` with ``root``'s package.

    Raises:
        RuntimeError: a non-zero exit code (its stderr in the message).
    """
    env = {**os.environ, "PYTHONPATH": str(root)}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    res = subprocess.run([sys.executable, "-m", "pin_kpi_oed", *argv], cwd=cwd, env=env, capture_output=True,
                         text=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if res.returncode != 0:
        raise RuntimeError(f"{root}: pin-kpi-oed {' '.join(argv)} exited {res.returncode}: {res.stderr.strip()}")
    return res.stdout, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def split_data(ipa: Path, work: Path, rows: int | None) -> tuple[Path, Path]:
    """Series C imported and split 50/50 (seed 0), the training file cut to its first ``rows`` rows if given."""
    train, test = work / "c_train.csv", work / "c_test.csv"
    run_cli(ROOT, ["import-ipa", str(ipa / "Series_C"), "--position-only", "--split", "0.5", "--seed", "0",
                   "--train", str(train), "--test", str(test)], work)
    if rows is not None:
        lines = train.read_text().splitlines(keepends=True)
        head = sum(1 for x in lines if not x[:1].isdigit() and not x[:1] == "-")
        train.write_text("".join(lines[:head + rows]))
    return train, test


def differences(a: dict, b: dict) -> list[str]:
    """What differs between two runs' outputs (``text``, ``result`` JSON, ``model`` file)."""
    out = []
    la, lb = (TIMING.sub("X ms)", t).splitlines() for t in (a["text"], b["text"]))
    out += [f"line {i + 1}: {x!r} != {y!r}" for i, (x, y) in enumerate(zip(la, lb)) if x != y]
    if len(la) != len(lb):
        out.append(f"{len(la)} lines != {len(lb)} lines")
    ra, rb = a["result"]["result"], b["result"]["result"]
    pa, pb = (np.asarray([v for _, v in sorted(r["p_raw"].items())]) for r in (ra, rb))
    if sorted(ra["p_raw"]) != sorted(rb["p_raw"]) or np.max(np.abs(pa - pb)) > 1e-9:
        out.append(f"parameters differ by {np.max(np.abs(pa - pb)):.3g} (m or rad)")
    for key in ("mean_m", "rms_m", "p95_m", "max_m", "z_rms", "inside_95", "sigma_mean_m"):
        for side in ("before", "after"):
            x, y = a["result"]["validation"][side][key], b["result"]["validation"][side][key]
            if not np.isclose(x, y, rtol=1e-6, atol=0.0):
                out.append(f"validation {side} {key}: {x!r} != {y!r}")
    da, db = a["model"]["discrepancy"], b["model"]["discrepancy"]
    if da["decision"] != db["decision"] or da["kind"] != db["kind"]:
        out.append(f"discrepancy decision: {da['decision']!r} != {db['decision']!r}")
    for part in ("kernel", "cv"):
        for k, x in da.get(part, {}).items():
            y = db.get(part, {}).get(k)
            if isinstance(x, (int, float, list)) and not np.allclose(x, y, rtol=1e-6, atol=0.0):
                out.append(f"discrepancy {part}.{k}: {x!r} != {y!r}")
    sa, sb = np.asarray(ra["tcp_std_m"], float), np.asarray(rb["tcp_std_m"], float)
    if sa.shape != sb.shape or not np.allclose(sa, sb, rtol=1e-6, atol=0.0):
        out.append("predicted TCP sigma at the working configurations differs")
    return out


def run_one(root: Path, train: Path, test: Path, work: Path, tag: str) -> tuple[dict, float]:
    """One run of the README's identify with ``root``'s package: (its outputs, CPU seconds)."""
    out = work / tag
    out.mkdir(exist_ok=True)
    res, model = out / "result.json", out / "model.json"
    text, cpu = run_cli(root, ["identify", "--robot", "ur10", "--data", str(train), "--validate", str(test),
                               "--reflector", "0,0,0.109", "--discrepancy", "auto", "--json", str(res),
                               "--model-out", str(model)], work)
    return {"text": text.replace(str(out), "OUT"), "result": json.loads(res.read_text()),
            "model": json.loads(model.read_text())}, cpu


def main(argv: list[str] | None = None) -> int:
    """Compare the two checkouts; print the CPU times (median of ``--repeat``, interleaved) and any difference."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", required=True, help="folder of the other checkout (its pin_kpi_oed package)")
    ap.add_argument("--rows", type=int, default=None, help="training rows (default: the whole 50 %% split, 1,386)")
    ap.add_argument("--repeat", type=int, default=1, help="runs per checkout, interleaved (CPU: the median)")
    args = ap.parse_args(argv)
    ipa = ipa_folder()
    if ipa is None:
        print("skipped: the IPA UR10 dataset (shared/data/ipa_ur10) is not there")
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        train, test = split_data(ipa, work, args.rows)
        cpu: dict[str, list[float]] = {"before": [], "after": []}
        runs = {}
        for _ in range(args.repeat):
            for tag, root in (("before", Path(args.before).resolve()), ("after", ROOT)):
                runs[tag], t = run_one(root, train, test, work, tag)
                cpu[tag].append(t)
        n = sum(1 for line in train.read_text().splitlines() if line[:1].isdigit() or line[:1] == "-")
        load = os.getloadavg()[0]
        for tag in ("before", "after"):
            print(f"{tag:<7} identify --discrepancy auto --validate, {n} training rows: "
                  f"CPU {np.median(cpu[tag]):.2f} s "
                  f"(median of {len(cpu[tag])}: {', '.join(f'{t:.2f}' for t in cpu[tag])}; load {load:.1f})")
        diff = differences(runs["before"], runs["after"])
    print("unchanged: every printed line, parameters to 1e-9, held-out figures, decision, kernel, sigma" if not diff
          else "DIFFERENT:\n  " + "\n  ".join(diff))
    return 1 if diff else 0


if __name__ == "__main__":
    sys.exit(main())
