"""The README's four commands on directed pairs of IPA UR10 series: registered and honest, or refused for the cause.

For each pair X→Y the commands a user runs, through the command line with their default options:

1. ``pin-kpi-oed diagnose --robot ur10 --train X.csv --kfold 5 --reflector 0,0,0.109 --sigma 1e-4 --model-out mX.json``
   (geometry + the effects the diagnosis selects + the discrepancy);
2. ``pin-kpi-oed register --model mX.json --data Y_reg.csv --model-out mXY.json`` (60 seeded rows of Y,
   ``import-ipa --split 60 --seed S``);
3. ``pin-kpi-oed predict --model mXY.json --data Y_rest.csv --out pred.csv`` (the other rows of Y);
4. ``pin-kpi-oed compensate --model mXY.json --program Y_prog.csv --frame base --out joints.csv`` (10 held-out
   configurations of Y as a program: each pose's nominal TCP pose is a target).

A pair *runs* when register accepts and predict's standardised RMS on the held-out rows (z = (measured −
predicted) / σ per axis) lies in [0.67, 1.5]; it is *refused* when register exits 2, and the refusal must name the
cause (coverage / extrapolation) and the fix. For a refused pair the fix the message names is run as well: the
geometry-only model (``diagnose --effects none``), through the same four commands.

Columns: outcome, standardised RMS, share inside the 95 % ellipsoid, share flagged as extrapolation, held-out
mean error (mm), mean predicted σ (mm, 3-D), the registration's σ factor, compensate's statuses; then the
refusal's message.

Run:  python -m benchmarks.register_pairs [--pairs B-C,C-B,C-D,D-C] [--out DIR] [--seed 0]
      (IPA data: $PIN_KPI_OED_IPA_DATA or shared/data/ipa_ur10 beside the repository; the diagnose runs take
      2-4 min per series and are kept in --out, so a second run takes seconds)
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks.common import find_ipa_data

ROOT = Path(__file__).resolve().parents[1]
PAIRS = ["B-C", "C-B", "C-D", "D-C"]
REG_ROWS = 60
DIAGNOSE = ["--robot", "ur10", "--kfold", "5", "--reflector", "0,0,0.109", "--sigma", "1e-4", "--quiet"]


def cli(*argv: object) -> subprocess.CompletedProcess:
    """``python -m pin_kpi_oed ARGV`` in a subprocess (this repository's package), output captured."""
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    return subprocess.run([sys.executable, "-m", "pin_kpi_oed", *map(str, argv)], capture_output=True, text=True,
                          env=env, cwd=ROOT)


def _ok(p: subprocess.CompletedProcess, what: str) -> None:
    if p.returncode != 0:
        raise SystemExit(f"{what} failed (exit {p.returncode}): {(p.stderr or p.stdout).strip()[-400:]}")


def prepare(data: Path, out: Path, series: str, seed: int) -> None:
    """X.csv (all rows), X_reg.csv (60 seeded rows), X_rest.csv (the others), X_prog.csv (10 rest rows' joints)."""
    if (out / f"{series}_prog.csv").is_file():
        return
    _ok(cli("import-ipa", data / f"Series_{series}", "--position-only", "--out", out / f"{series}.csv",
            "--split", REG_ROWS, "--seed", seed, "--train", out / f"{series}_reg.csv", "--test",
            out / f"{series}_rest.csv"), f"import-ipa {series}")
    with open(out / f"{series}_rest.csv", newline="") as f:
        rows = list(csv.reader(f))
    head = rows[0]
    joints = [i for i, h in enumerate(head) if h.endswith("_joint")]
    pick = np.random.default_rng(seed).choice(len(rows) - 1, 10, replace=False) + 1
    with open(out / f"{series}_prog.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow([head[i] for i in joints])
        for r in sorted(pick):
            w.writerow([rows[r][i] for i in joints])


def model_of(out: Path, series: str, variant: str) -> Path:
    """The diagnose model of a series: ``default`` (selected effects) or ``geometry`` (--effects none), cached."""
    path = out / f"m{series}_{variant}.json"
    if not path.is_file():
        extra = ["--effects", "none"] if variant == "geometry" else []
        t0 = time.perf_counter()
        _ok(cli("diagnose", "--train", out / f"{series}.csv", *DIAGNOSE, *extra, "--model-out", path),
            f"diagnose {series} ({variant})")
        print(f"  diagnose {series} ({variant}): {time.perf_counter() - t0:.0f} s", flush=True)
    return path


def standardised(pred: Path) -> dict:
    """Standardised RMS, share inside the 95 % ellipsoid, extrapolation share, mean error and σ of predict's CSV."""
    t = np.genfromtxt(pred, delimiter=",", names=True)
    E = np.c_[t["x"] - t["x_pred"], t["y"] - t["y_pred"], t["z"] - t["z_pred"]]
    S = np.c_[t["sigma_x"], t["sigma_y"], t["sigma_z"]]
    z2 = np.sum((E / S) ** 2, axis=1)
    return {"z_rms": float(np.sqrt(np.mean(z2) / 3)), "inside_95": float(np.mean(z2 <= 7.8147)),
            "extrapolation": float(np.mean(t["extrapolation"])), "mean_error_m": float(np.mean(t["error"])),
            "sigma_3d_m": float(np.mean(np.linalg.norm(S, axis=1))), "n": int(len(t))}


def run_pair(out: Path, src: str, tgt: str, variant: str) -> dict:
    """The four commands for one pair and one model variant."""
    model = model_of(out, src, variant)
    tag = f"{src}{tgt}_{variant}"
    reg = cli("register", "--model", model, "--data", out / f"{tgt}_reg.csv", "--model-out", out / f"m{tag}.json",
              "--json", out / f"reg{tag}.json")
    res = {"pair": f"{src}->{tgt}", "model": variant, "register_exit": reg.returncode}
    if reg.returncode != 0:
        res["outcome"] = "refused"
        res["message"] = reg.stderr.strip().splitlines()[-1] if reg.stderr.strip() else ""
        return res
    rj = json.loads((out / f"reg{tag}.json").read_text())
    res["sigma_scale"] = float(next(iter(rj["setups"].values()))["sigma_scale"])
    _ok(cli("predict", "--model", out / f"m{tag}.json", "--data", out / f"{tgt}_rest.csv", "--out",
            out / f"pred{tag}.csv", "--quiet"), f"predict {tag}")
    res.update(standardised(out / f"pred{tag}.csv"))
    comp = cli("compensate", "--model", out / f"m{tag}.json", "--program", out / f"{tgt}_prog.csv", "--frame",
               "base", "--out", out / f"joints{tag}.csv", "--quiet")
    res["compensate_exit"] = comp.returncode
    if comp.returncode == 0:
        with open(out / f"joints{tag}.csv", newline="") as f:
            status = [r.get("status", "") for r in csv.DictReader(f)]
        res["compensate"] = {s: status.count(s) for s in sorted(set(status))}
    else:
        res["compensate"] = {"error": (comp.stderr or comp.stdout).strip().splitlines()[-1]}
    res["outcome"] = "runs" if 0.67 <= res["z_rms"] <= 1.5 else "runs, sigma NOT honest"
    return res


def line(r: dict) -> str:
    """One table row."""
    if r["outcome"] == "refused":
        return f"| {r['pair']} | {r['model']} | refused | | | | | | | |"
    comp = ", ".join(f"{k} {v}" for k, v in r["compensate"].items())
    return (f"| {r['pair']} | {r['model']} | {r['outcome']} | {r['z_rms']:.2f} | {100 * r['inside_95']:.1f} % | "
            f"{100 * r['extrapolation']:.0f} % | {r['mean_error_m'] * 1e3:.3f} | {r['sigma_3d_m'] * 1e3:.3f} | "
            f"{r['sigma_scale']:.2f} | {comp} |")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", default=",".join(PAIRS), help="directed pairs, e.g. B-C,C-B (default: %(default)s)")
    ap.add_argument("--out", default=str(ROOT / ".register_pairs"), help="working folder (models are cached here)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the registration rows and the program rows")
    ap.add_argument("--json", default=None, help="write the results here")
    args = ap.parse_args(argv)
    data = find_ipa_data()
    if data is None or not data.is_dir():
        print("IPA UR10 data not found: set PIN_KPI_OED_IPA_DATA")
        return 2
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    pairs = [tuple(p.strip().upper().split("-")) for p in args.pairs.split(",") if p.strip()]
    for s in sorted({x for p in pairs for x in p}):
        prepare(data, out, s, args.seed)
    results = []
    for src, tgt in pairs:
        r = run_pair(out, src, tgt, "default")
        results.append(r)
        if r["outcome"] == "refused":  # the fix the refusal names: the geometry-only model
            results.append(run_pair(out, src, tgt, "geometry"))
    print(f"\nREADME's four commands, {REG_ROWS} registration rows (seed {args.seed}), the rest of the target held out")
    print("| pair | model | outcome | standardised RMS | inside 95 % | extrapolation | mean error (mm) | "
          "σ 3-D (mm) | σ factor | compensate |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in results:
        print(line(r))
    for r in results:
        if r["outcome"] == "refused":
            print(f"\n{r['pair']} ({r['model']}) refused: {r['message']}")
    bad = [r for r in results if r["outcome"] not in ("runs", "refused")
           or (r["outcome"] == "refused" and not any(w in r["message"] for w in ("coverage", "extrapolat")))]
    if args.json:
        from pin_kpi_oed.data.atomic import atomic_write_json

        atomic_write_json(args.json, {"pairs": results, "seed": args.seed, "register_rows": REG_ROWS})
    print(f"\n{len(results) - len(bad)} of {len(results)} runs honest or refused for a named cause")
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
