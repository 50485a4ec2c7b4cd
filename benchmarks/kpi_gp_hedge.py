"""The hedged kpi_gp design against the noise-only KPI and random when the assumed discrepancy is wrong.

``design`` with ``kpi_gp`` and no fitted discrepancy assumes the robot class's default; the hedged criterion
(:mod:`pin_kpi_oed.oed.hedged_kpi`) averages the KPI over a family of priors around it, the noise-only KPI among
them. This benchmark compares, on robots whose discrepancy is not the assumed one
(:mod:`pin_kpi_oed.studies.hedged_design`):

* **simulated**: the UR5 cell of ``examples/ur5_cell.yaml`` and its collaborative class default; per seed a
  200-pose sub-pool of 1,000 feasible poses (seeded), 8 working configurations (the cell's and seeded ±0.3 rad
  perturbations), and robots of every kind of ``TRUTH_KINDS`` (no discrepancy, short / long length scales, small /
  large levels, a gear harmonic), tracker noise 20 µm per axis;
* **IPA UR10** (real data): the prior fitted on one series (geometry + a Gaussian-process discrepancy on up to 600
  seeded rows), the designs chosen from a 200-row pool of another series and scored at 8 seeded rows of it.

m ∈ {12, 20}. Every set is calibrated the same way (geometry + the discrepancy's mean under the assumed prior); the
score is the RMS 3-D TCP error at the working configurations (mm). Per case and m: the mean over the seeds of each
method, and the paired difference hedged − kpi with its standard error (the noise of the comparison): "ok" when
the hedged design is not worse than the noise-only KPI by more than two standard errors.

Run: ``OMP_NUM_THREADS=1 python -m benchmarks.kpi_gp_hedge [--reps 16] [--ipa-reps 6] [--kinds ...] [--pairs B-C,...]
[--json out.json]`` (progress on stderr; --reps 2 --ipa-reps 2 for a quick look)
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SIZES = (12, 20)
PAIRS = ("B-C", "C-B", "C-D", "D-C")


def _table(title: str, cases: dict[str, list[dict]], key: str = "error_m") -> list[dict]:
    """Print one table (mean per method, paired hedged − kpi with its standard error) and return its rows."""
    from pin_kpi_oed.studies.hedged_design import METHODS

    print(f"\n{title}")
    head = ("| case | m | " + " | ".join(f"{m} (mm)" for m in METHODS)
            + " | hedged − kpi (mm) ± s.e. | hedged vs kpi | kpi_gp − kpi (mm) |")
    print(head)
    print("|" + "---|" * (head.count("|") - 1))
    rows = []
    for case, runs in cases.items():
        for m in SIZES:
            col = {meth: np.array([r[key][meth][m] for r in runs if m in r[key].get(meth, {})]) for meth in METHODS}
            if not len(col["kpi"]):
                continue
            d = col["kpi_gp_hedged"] - col["kpi"]
            d0 = col["kpi_gp"] - col["kpi"]
            se = float(np.std(d, ddof=1) / np.sqrt(len(d))) if len(d) > 1 else float("nan")
            ok = bool(np.mean(d) <= 2 * se) if np.isfinite(se) else bool(np.mean(d) <= 0)
            row = {"case": case, "m": m, "n": int(len(d)), **{f"{k}_m": float(v.mean()) for k, v in col.items()},
                   "hedged_minus_kpi_m": float(np.mean(d)), "se_m": se, "ok": ok,
                   "kpi_gp_minus_kpi_m": float(np.mean(d0))}
            rows.append(row)
            print(f"| {case} | {m} | " + " | ".join(f"{col[k].mean() * 1e3:.4f}" for k in METHODS)
                  + f" | {np.mean(d) * 1e3:+.4f} ± {se * 1e3:.4f} | {'ok' if ok else 'WORSE'} | "
                  f"{np.mean(d0) * 1e3:+.4f} |")
    return rows


def simulated(reps: int, kinds: list[str], log, noise_weight: float | None = None) -> dict[str, list[dict]]:
    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.design.optimize import DesignProblem
    from pin_kpi_oed.studies.hedged_design import choose_sets, simulated_case
    from pin_kpi_oed.studies.kpi_withheld import working_region

    cell = load_cell(str(ROOT / "examples" / "ur5_cell.yaml"))
    problem = DesignProblem(cell)
    assumed = problem.discrepancy_prior()
    big, _ = problem.random_design(1000, seed=np.random.SeedSequence([0, 1]))
    W = working_region(cell.q_work, 7, 0.3, seed=3)
    log(f"UR5 cell: 1000 feasible poses, {len(W)} working configurations; assumed: {assumed.source[:60]}...")
    cases: dict[str, list[dict]] = {k: [] for k in kinds}
    for rep in range(reps):
        t0 = time.perf_counter()
        pool = big[np.random.default_rng([rep, 5]).permutation(len(big))[:200]]
        sets = {m: choose_sets(problem.model, assumed, pool, W, m, rep, noise_weight=noise_weight) for m in SIZES}
        for k in kinds:
            cases[k].append(simulated_case(problem.model, pool, W, k, rep, sets, assumed))
        log(f"simulated rep {rep}: {time.perf_counter() - t0:.0f} s")
    return cases


def measured(ipa_reps: int, pairs: list[str], log, noise_weight: float | None = None) -> dict[str, list[dict]]:
    from benchmarks.common import find_ipa_data, load_ipa_series
    from pin_kpi_oed import NoiseModel, TrackerModel, load_robot
    from pin_kpi_oed.data.measurements import MeasurementSet
    from pin_kpi_oed.identification.identify import identify
    from pin_kpi_oed.discrepancy.prior import DiscrepancyPrior
    from pin_kpi_oed.studies.hedged_design import measured_case

    folder = find_ipa_data()
    if folder is None or not folder.is_dir():
        log("IPA data not found: the measured part is skipped")
        return {}
    robot = load_robot("ur10")
    model = TrackerModel(robot, reflector_m=np.array([0.0, 0.0, 0.109]), noise=NoiseModel(sigma_xyz_m=(1e-4,) * 3))
    series: dict[str, MeasurementSet] = {}
    priors: dict[str, DiscrepancyPrior] = {}

    def load(s: str) -> MeasurementSet:
        if s not in series:
            series[s] = load_ipa_series(folder, s)
        return series[s]

    cases: dict[str, list[dict]] = {}
    for pair in pairs:
        src, tgt = pair.split("-")
        if src not in priors:
            d = load(src)
            sub = d.subset(np.sort(np.random.default_rng(0).permutation(len(d))[:600]))
            fit = identify(model, sub, discrepancy="on", seed=0, raise_on_failure=False)
            priors[src] = DiscrepancyPrior.from_discrepancy(fit.discrepancy, f"fitted on Series {src}")
            log(f"prior from Series {src}: {priors[src].describe()[:110]}...")
        key = f"IPA prior {src} -> design on {tgt}"
        cases[key] = []
        for rep in range(ipa_reps):
            t0 = time.perf_counter()
            cases[key].append(measured_case(model, load(tgt), priors[src], rep, SIZES, noise_weight=noise_weight))
            log(f"{key} rep {rep}: {time.perf_counter() - t0:.0f} s")
    return cases


def main(argv: list[str] | None = None) -> dict:
    from pin_kpi_oed.studies.hedged_design import TRUTH_KINDS

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=16, help="simulated pools and robots per kind (seeds 0 .. reps-1)")
    ap.add_argument("--ipa-reps", dest="ipa_reps", type=int, default=6, help="seeded splits per IPA pair (0: skip)")
    ap.add_argument("--kinds", default=",".join(TRUTH_KINDS), help="simulated robot kinds, comma-separated")
    ap.add_argument("--pairs", default=",".join(PAIRS), help="IPA prior -> design series, e.g. B-C,D-C")
    ap.add_argument("--noise-weight", dest="noise_weight", type=float, default=None,
                    help="the hedged criterion's weight on noise only (default the package's, 0.5)")
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)

    def log(msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    t0 = time.perf_counter()
    kinds = [k.strip() for k in a.kinds.split(",") if k.strip()]
    sim = simulated(a.reps, kinds, log, a.noise_weight) if a.reps > 0 else {}
    ipa = measured(a.ipa_reps, [p.strip().upper() for p in a.pairs.split(",") if p.strip()], log, a.noise_weight) \
        if a.ipa_reps > 0 else {}
    out = {"sizes": list(SIZES), "reps": a.reps, "ipa_reps": a.ipa_reps, "tables": {}}
    if sim:
        out["tables"]["simulated"] = _table(f"Simulated UR5 robots ({a.reps} seeds each): RMS TCP error at 8 working "
                                           "configurations, geometry + discrepancy mean (assumed prior)", sim)
        out["tables"]["simulated_geometry"] = _table("the same, geometry alone", sim, "error_geo_m")
    if ipa:
        out["tables"]["ipa"] = _table(f"IPA UR10 ({a.ipa_reps} splits each): RMS error at 8 held-out rows, geometry + "
                                      "discrepancy mean (prior of the other series)", ipa)
        out["tables"]["ipa_geometry"] = _table("the same, geometry alone", ipa, "error_geo_m")
    out["runs"] = {"simulated": sim, "ipa": ipa}
    out["time_s"] = time.perf_counter() - t0
    rows = [r for t in out["tables"].values() for r in t]
    print(f"\nhedged kpi_gp not worse than the noise-only KPI beyond two standard errors in "
          f"{sum(r['ok'] for r in rows)} of {len(rows)} rows ({out['time_s']:.0f} s)")
    if a.json:
        from pin_kpi_oed.data.atomic import atomic_write_json

        atomic_write_json(a.json, out)
    return out


if __name__ == "__main__":
    main(sys.argv[1:])
