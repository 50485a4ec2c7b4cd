"""The default ``identify`` of two checkouts on the real UR10: the same printed numbers, and each one's CPU time.

Runs ``pin-kpi-oed identify --discrepancy auto --validate`` (the README's real-data example) once per checkout as a
process and compares what a user reads and keeps:

* every printed line (the fit's time in ms aside): the held-out figures before and after the discrepancy (RMS, max,
  standardised RMS, ...), its decision line with the K-fold figures, the TCP σ, the parameters' values and σ, all at
  the printed precision;
* the identified parameters (to 1e-9 m / 1e-9 rad) and the discrepancy's decision and kind;
* the discrepancy's hyper-parameters by what they are fitted for: the log marginal likelihood of the after's kernel
  and white level on the rows the search used (the seeded subset of the fit's ``n_fit`` rows, recomputed from each
  model file's training rows, kernel and white level with the after's
  :class:`~pin_kpi_oed.discrepancy.marginal.MarginalLikelihood`) must not be lower than the before's by more than
  1e-6 relative. The kernel itself may move: the search stops at an iteration limit, not at an optimum, and a
  search that reaches a likelihood at least as high with every printed figure the same is as good. A posterior
  that keeps no training residuals (the inducing-point kind, above ``max_exact`` rows) has its kernel and K-fold
  figures compared to 1e-6 relative instead::

    python -m benchmarks.identify_unchanged --before ../other-checkout [--series C] [--rows 1386 | --all]
        [--accept-poor-fit] [--repeat 3]

``--before`` is the folder of another checkout of the package (e.g. ``git worktree add /tmp/base <commit>``); the
current checkout is the after. The data: ``shared/data/ipa_ur10/Series_<series>`` (skipped with a note without it),
imported and split 50/50 with seed 0 as in the README, validated on the held-out half; ``--all`` trains on every row
of the series (the held-out half included), ``--rows`` on the first rows of the training half. Exit code 1 when
anything differs.
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


def split_data(ipa: Path, work: Path, rows: int | None, series: str = "C", every: bool = False) -> tuple[Path, Path]:
    """A series imported and split 50/50 (seed 0): (training file, held-out file); the training file cut to its first
    ``rows`` rows if given, or (``every``) all the series' rows."""
    train, test = work / "train.csv", work / "test.csv"
    folder = str(ipa / f"Series_{series}")
    run_cli(ROOT, ["import-ipa", folder, "--position-only", "--split", "0.5", "--seed", "0",
                   "--train", str(train), "--test", str(test)], work)
    if every:
        run_cli(ROOT, ["import-ipa", folder, "--position-only", "--out", str(train)], work)
    elif rows is not None:
        lines = train.read_text().splitlines(keepends=True)
        head = sum(1 for x in lines if not x[:1].isdigit() and not x[:1] == "-")
        train.write_text("".join(lines[:head + rows]))
    return train, test


def log_marginal_likelihood(model: dict) -> float | None:
    """The log marginal likelihood of a model file's discrepancy (kernel, white level) on the rows its search used:
    the seeded subset of ``DiscrepancyOptions().n_fit`` training rows (seed ``DiscrepancyOptions().seed``, identify's
    defaults) of the normalised residuals (the file's ``y`` times ``cv.dof_factor``). None: no exact posterior."""
    from pin_kpi_oed.discrepancy import DiscrepancyOptions
    from pin_kpi_oed.discrepancy.arrays import decode_array
    from pin_kpi_oed.discrepancy.kernel import JointKernel
    from pin_kpi_oed.discrepancy.marginal import MarginalLikelihood

    disc = model.get("discrepancy") or {}
    if disc.get("kind") != "exact":
        return None
    Z = decode_array(disc["Z_rad"], "Z_rad", (None, None))
    Y = decode_array(disc["y"], "y", (len(Z), 3)) * float(disc["cv"].get("dof_factor", 1.0))
    kernel = JointKernel.from_dict(disc["kernel"], Z.shape[1])
    opts = DiscrepancyOptions()
    sub = np.random.default_rng(opts.seed).permutation(len(Z))[:opts.n_fit]
    c, L, a, ell = kernel.parts(Z.shape[1])
    theta = np.log(np.concatenate([[c], a, ell, L, [float(disc["noise"])]]))
    value, _ = MarginalLikelihood(Z[sub], Y[sub], kernel.linear)(theta)
    return -float(value)


def differences(a: dict, b: dict) -> list[str]:
    """What differs between two runs' outputs (``text``, ``result`` JSON, ``model`` file, ``lml``)."""
    out = []
    la, lb = (TIMING.sub("X ms)", t).splitlines() for t in (a["text"], b["text"]))
    out += [f"line {i + 1}: {x!r} != {y!r}" for i, (x, y) in enumerate(zip(la, lb)) if x != y]
    if len(la) != len(lb):
        out.append(f"{len(la)} lines != {len(lb)} lines")
    ra, rb = a["result"]["result"], b["result"]["result"]
    pa, pb = (np.asarray([v for _, v in sorted(r["p_raw"].items())]) for r in (ra, rb))
    if sorted(ra["p_raw"]) != sorted(rb["p_raw"]) or np.max(np.abs(pa - pb)) > 1e-9:
        out.append(f"parameters differ by {np.max(np.abs(pa - pb)):.3g} (m or rad)")
    # the kernel may move when the likelihood is not lower: then the printed lines judge the figures at their
    # printed precision; without a likelihood to compare, the numbers to 1e-6 relative as well
    strict = a["lml"] is None or b["lml"] is None
    for key in (("mean_m", "rms_m", "p95_m", "max_m", "z_rms", "inside_95", "sigma_mean_m") if strict else ()):
        for side in ("before", "after"):
            x, y = a["result"]["validation"][side][key], b["result"]["validation"][side][key]
            if not np.isclose(x, y, rtol=1e-6, atol=0.0):
                out.append(f"validation {side} {key}: {x!r} != {y!r}")
    da, db = a["model"]["discrepancy"], b["model"]["discrepancy"]
    if da["decision"] != db["decision"] or da["kind"] != db["kind"]:
        out.append(f"discrepancy decision: {da['decision']!r} != {db['decision']!r}")
    if not strict and b["lml"] < a["lml"] - 1e-6 * abs(a["lml"]):
        out.append(f"log marginal likelihood {b['lml']!r} lower than before's {a['lml']!r}")
    for part in (("kernel", "cv") if strict else ()):
        for k, x in da.get(part, {}).items():
            y = db.get(part, {}).get(k)
            if isinstance(x, (int, float, list)) and not np.allclose(x, y, rtol=1e-6, atol=0.0):
                out.append(f"discrepancy {part}.{k}: {x!r} != {y!r}")
    sa, sb = np.asarray(ra["tcp_std_m"], float), np.asarray(rb["tcp_std_m"], float)
    if sa.shape != sb.shape or (strict and not np.allclose(sa, sb, rtol=1e-6, atol=0.0)):
        out.append("predicted TCP sigma at the working configurations differs")
    return out


def run_one(root: Path, train: Path, test: Path, work: Path, tag: str, extra: tuple = ()) -> tuple[dict, float]:
    """One run of the README's identify with ``root``'s package: (its outputs, CPU seconds)."""
    out = work / tag
    out.mkdir(exist_ok=True)
    res, model = out / "result.json", out / "model.json"
    text, cpu = run_cli(root, ["identify", "--robot", "ur10", "--data", str(train), "--validate", str(test),
                               "--reflector", "0,0,0.109", "--discrepancy", "auto", "--json", str(res),
                               "--model-out", str(model), *extra], work)
    kept = json.loads(model.read_text())
    return {"text": text.replace(str(out), "OUT"), "result": json.loads(res.read_text()), "model": kept,
            "lml": log_marginal_likelihood(kept)}, cpu


def main(argv: list[str] | None = None) -> int:
    """Compare the two checkouts; print the CPU times (median of ``--repeat``, interleaved) and any difference."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", required=True, help="folder of the other checkout (its pin_kpi_oed package)")
    ap.add_argument("--rows", type=int, default=None, help="training rows (default: the whole 50 %% split, 1,386)")
    ap.add_argument("--all", action="store_true", help="train on every row of the series (the held-out half too)")
    ap.add_argument("--series", default="C", choices=("A", "B", "C", "D"), help="the IPA series (default C)")
    ap.add_argument("--accept-poor-fit", action="store_true", help="pass --accept-poor-fit to identify")
    ap.add_argument("--repeat", type=int, default=1, help="runs per checkout, interleaved (CPU: the median)")
    args = ap.parse_args(argv)
    ipa = ipa_folder()
    if ipa is None or not (ipa / f"Series_{args.series}").is_dir():
        print(f"skipped: the IPA UR10 dataset's Series {args.series} (shared/data/ipa_ur10) is not there")
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        train, test = split_data(ipa, work, args.rows, args.series, args.all)
        extra = ("--accept-poor-fit",) if args.accept_poor_fit else ()
        cpu: dict[str, list[float]] = {"before": [], "after": []}
        runs = {}
        for _ in range(args.repeat):
            for tag, root in (("before", Path(args.before).resolve()), ("after", ROOT)):
                runs[tag], t = run_one(root, train, test, work, tag, extra)
                cpu[tag].append(t)
        n = sum(1 for line in train.read_text().splitlines() if line[:1].isdigit() or line[:1] == "-")
        load = os.getloadavg()[0]
        for tag in ("before", "after"):
            lml = runs[tag]["lml"]
            print(f"{tag:<7} identify --discrepancy auto --validate, Series {args.series}, {n} training rows: "
                  f"CPU {np.median(cpu[tag]):.2f} s "
                  f"(median of {len(cpu[tag])}: {', '.join(f'{t:.2f}' for t in cpu[tag])}; load {load:.1f}); "
                  + (f"log marginal likelihood {lml:.6f}" if lml is not None else "no exact posterior"))
        diff = differences(runs["before"], runs["after"])
    print("unchanged: every printed line, parameters to 1e-9, held-out figures, decision, sigma; log marginal "
          "likelihood not lower" if not diff
          else "DIFFERENT:\n  " + "\n  ".join(diff))
    return 1 if diff else 0


if __name__ == "__main__":
    sys.exit(main())
