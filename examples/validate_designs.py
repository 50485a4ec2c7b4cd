"""Validate measurement designs: Monte-Carlo identification (simulated KR 15) and real UR10 data.

1. Monte-Carlo: 200 simulated identifications of the KR 15 cell's 60-pose KPI design; realised vs predicted TCP
   covariance.
2. Real data (if the IPA UR10 data are present): working poses held out, 60 calibration poses chosen from the
   rest by the KPI criterion, by D-optimality and at random; identify from each; real errors at the working poses.
3. Designs over the extended model (with --extended): Series C within the session and the directed pairs
   B -> C, C -> B, C -> D, D -> C (chosen and calibrated on the first series, set-up re-registered on 60 rows of the
   second); random, D and A on C_p (extended), KPI geometric, KPI extended, KPI extended bias-aware, D geometric;
   every set calibrated with geometry + the terms selected on the training pool; errors of the held-out rows
   within 0.5 rad (joints 1-5) of 5 working configurations; paired Wilcoxon / t-tests against random.
   --figure writes the figure (docs/extended_designs.png), --simulation-json adds the simulation panel.
   --cases picks the cases ("C", "C->D", "B->C", "C->B", "D->C"; default all), --case-dir keeps one JSON per case
   as it completes (a case already there is read, not re-run), --extended-only skips parts 1 and 2.

Run: python examples/validate_designs.py [--splits 20] [--series ../shared/data/ipa_ur10/Series_C] [--json out.json]
     python -m benchmarks.bench_extended --only simulation --reps 200 --json runs/sim.json
     python examples/validate_designs.py --extended --extended-only --splits 20 --case-dir runs \
         --simulation-json runs/sim.json --figure docs/extended_designs.png
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np
from pin_kpi_oed import NoiseModel, TrackerModel, load_robot
from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.design.optimize import DesignOptions, ipopt_options, run_designs
from pin_kpi_oed.data.atomic import atomic_write_json
from pin_kpi_oed.data.ipa import import_ipa
from pin_kpi_oed.studies.design_trials import monte_carlo, real_data_validation

SERIES_C = Path(__file__).resolve().parents[2] / "shared" / "data" / "ipa_ur10" / "Series_C"
#: --quick (or PIN_KPI_OED_QUICK=1): smaller sizes, the same steps (the tests' run)
QUICK = os.environ.get("PIN_KPI_OED_QUICK") == "1" or "--quick" in sys.argv[1:]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smaller sizes, the same steps")
    ap.add_argument("--splits", type=int, default=2 if QUICK else 20)
    ap.add_argument("--reps", type=int, default=10 if QUICK else 200)
    ap.add_argument("--series", type=Path, default=SERIES_C)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--extended", action="store_true", help="also the designs over the extended model")
    ap.add_argument("--figure", type=Path, default=None, help="figure of the extended-model comparison (PNG)")
    ap.add_argument("--cases", default=",".join(CASES), help="extended-model cases, comma-separated")
    ap.add_argument("--case-dir", type=Path, default=None, help="one JSON per extended-model case (resumable)")
    ap.add_argument("--extended-only", action="store_true", help="only the extended-model part")
    ap.add_argument("--simulation-json", type=Path, default=None,
                    help="JSON of `python -m benchmarks.bench_extended --only simulation --json ...`: adds its panel")
    a = ap.parse_args()
    out = {}
    if a.extended:
        sim = json.loads(a.simulation_json.read_text())["simulation"] if a.simulation_json else None
        out["extended"] = extended(a.series.parent, a.splits, a.seed, a.figure,
                                   [c.strip() for c in a.cases.split(",") if c.strip()], a.case_dir, sim)
        if a.extended_only:
            if a.json:
                atomic_write_json(a.json, out)
            return 0

    # the KPI design of the KR 15 cell (60 poses), then simulated identifications of it
    cell = load_cell("kr15")
    # quick: 30 poses, a pool of 150 candidates for the first start, at most 20 Ipopt iterations
    opts = DesignOptions(pool_size=150, ipopt=ipopt_options(max_iter=20)) if QUICK else None
    kpi = run_designs(cell, ["kpi"], 30 if QUICK else 60, a.seed, opts)[-1]
    model = cell.tracker_model()
    model.noise = NoiseModel(sigma_xyz_m=(1e-5,) * 3)  # a 10 um tracker (ratios do not depend on sigma)
    mc = monte_carlo(model, kpi.q_meas, cell.q_work, n_rep=a.reps, seed=a.seed)
    print("KPI design of the KR 15 cell:")
    print(mc.summary())
    out["monte_carlo_kpi_design"] = mc.to_dict()

    if a.series.exists():
        data = import_ipa(a.series)
        data.sigma_m = None  # the IPA std columns are reading scatter, not tracker accuracy
        ur10 = TrackerModel(load_robot("ur10"), reflector_m=np.array([0.0, 0.0, 0.109]),
                            noise=NoiseModel(sigma_xyz_m=(5e-5,) * 3))
        if QUICK:
            data = data.subset(np.arange(200))
        rd = real_data_validation(ur10, data, n_splits=a.splits, seed=a.seed)
        print(rd.summary())
        out["real_data"] = rd.to_dict()
    else:
        print(f"IPA UR10 data not found at {a.series}: real-data part skipped")
    if a.json:
        atomic_write_json(a.json, out)
    return 0


CASES = ("C", "C->D", "B->C", "C->B", "D->C")
METHODS = ("random", "D", "param", "kpi_geo", "kpi_ext", "kpi_bias", "D_geo")


def extended(data_dir: Path, splits: int, seed: int, figure: Path | None, cases: list[str] | None = None,
             case_dir: Path | None = None, simulation: dict | None = None) -> dict:
    """Within Series C and the directed pairs, designs over the extended model (module docstring).

    Args:
        data_dir: folder of the IPA series (Series_B, Series_C, Series_D).
        splits: seeded splits per case; seed: first seed.
        figure: PNG of the per-split errors of every case, or None.
        cases: "C" (within Series C) or "S->T" (chosen and calibrated on S, scored on T after re-registering).
        case_dir: folder of one JSON per case, written as each case completes; a case found there is read.
        simulation: the benchmark's simulation results for the figure's last panel, or None.

    Returns:
        {case: ExtendedDesignValidation.to_dict()}.
    """
    from pin_kpi_oed.data.measurements import MeasurementSet
    from pin_kpi_oed.studies.design_trials import extended_design_validation

    def load(s: str) -> MeasurementSet:
        ms = import_ipa(data_dir / f"Series_{s}")
        return MeasurementSet(ms.joint_names, ms.q, ms.position_m, source=f"Series {s}")

    if not (data_dir / "Series_C").exists():
        print(f"IPA UR10 data not found at {data_dir}: extended-model part skipped")
        return {}
    ur10 = TrackerModel(load_robot("ur10"), reflector_m=np.array([0.0, 0.0, 0.109]),
                        noise=NoiseModel(sigma_xyz_m=(1e-4,) * 3))
    res = {}
    for case in cases or CASES:
        f = None if case_dir is None else case_dir / f"extended_{case.replace('->', '_to_')}_{splits}.json"
        if f is not None and f.exists():
            res[case] = json.loads(f.read_text())
            print(f"{case}: read {f}")
            continue
        src, _, tgt = case.partition("->")
        r = extended_design_validation(ur10, load(src.strip()), load(tgt.strip()) if tgt else None,
                                       n_splits=splits, seed=seed, methods=METHODS)
        print(r.summary(), flush=True)
        res[case] = r.to_dict()
        if f is not None:
            atomic_write_json(f, res[case])
    if figure is not None:
        extended_figure(res, figure, simulation)
    return res


def extended_figure(res: dict, figure: Path, simulation: dict | None = None) -> None:
    """Per-split held-out errors (mm) of every method, one panel per case, written as PNG.

    The y axis ends at 1.6 × the largest median of a panel; splits above it are drawn at the top
    edge as triangles with their count and largest value (e.g. the failed random sets of D -> C).
    ``simulation`` (the ``simulation`` part of ``python -m benchmarks.bench_extended --json``) adds a panel:
    the paired gap geometric − extended KPI design (µm, ± standard error) against the effect size.
    """
    from pin_kpi_oed.viz.figures import agg_figure, save_png

    n = len(res) + (simulation is not None)
    cols = min(n, 3)
    rows = (n + cols - 1) // cols
    fig = agg_figure(5.0 * cols, 3.8 * rows)
    for i, (case, d) in enumerate(res.items(), 1):
        ax = fig.add_subplot(rows, cols, i)
        meths = list(d["methods"])
        v = [np.asarray(d["methods"][k]["per_split_m"]) * 1e3 for k in meths]
        top = 1.6 * max(float(np.median(y)) for y in v)
        ax.boxplot([np.minimum(y, top) for y in v], showfliers=False)
        ax.set_xticks(range(1, len(meths) + 1), meths, fontsize=8)
        for j, y in enumerate(v, 1):
            x = np.full(y.size, j) + np.linspace(-0.15, 0.15, y.size)
            ok = y <= top
            ax.plot(x[ok], y[ok], ".", color="0.4", ms=3)
            if np.any(~ok):
                ax.plot(x[~ok], np.full(int(np.sum(~ok)), top), "^", color="C3", ms=5)
                ax.annotate(f"{int(np.sum(~ok))} above (max {y.max():.1f})", (j, top), textcoords="offset points",
                            xytext=(6, -4), ha="left", fontsize=7, color="C3")
        ax.set_ylim(0.0, top * 1.02)
        ax.set_title(f"UR10 {case}: {d['nit']} splits, 60 poses each", fontsize=9)
        ax.set_ylabel("held-out error near the work (mm)", fontsize=8)
    if simulation is not None:
        ax = fig.add_subplot(rows, cols, n)
        for j, (nz, sim) in enumerate(simulation.items()):
            a = np.asarray(sim["sizes_rad"]) * 1e6
            for cal, ls in (("map", "-"), ("ls", "--")):
                g = np.array([c[cal]["gap_mean_m"] for c in sim["cases"]]) * 1e6
                e = np.array([c[cal]["gap_sem_m"] for c in sim["cases"]]) * 1e6
                ax.errorbar(a, g, yerr=e, fmt="o" + ls, color=f"C{j}", ms=3, capsize=2,
                            label=f"sigma {float(nz) * 1e6:g} um, {'MAP (prior %g urad)' % (sim['prior_rad'] * 1e6) if cal == 'map' else 'least squares'}")
        ax.axhline(0.0, color="0.6", lw=0.8)
        ax.set_xscale("symlog", linthresh=100.0)
        ax.set_xlabel("effect size a (urad)", fontsize=8)
        ax.set_ylabel("TCP error, geometric - extended KPI design (um)", fontsize=8)
        ax.set_title(f"simulation: {sim['reps']} repetitions per size", fontsize=9)
        ax.legend(fontsize=6)
    save_png(fig, figure)


if __name__ == "__main__":
    raise SystemExit(main())
