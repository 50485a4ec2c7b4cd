"""Learning curves on the real UR10: held-out error near the work against the number of calibration poses.

For m in {12, 20, 30, 60, 120} poses chosen from the training pool by the discrepancy-aware KPI (``kpi_gp``), the
paper's KPI, D-optimal and random (nested random sets), and the discrepancy-aware KPI over the working region
(``kpi_gp_region``: the working configurations plus up to 100 pool rows within the scoring radius), over seeded splits,
every set calibrated the same way (geometry + set-up by least squares, then the discrepancy's posterior mean on the m
residuals with the kernel, the per-axis scale and the white level FIXED to a prior model fitted on another series),
scored as the mean 3-D error of the held-out rows within 0.5 rad (joints 1-5) of 5 working configurations
(:func:`pin_kpi_oed.studies.learning_curves.curve_split`).

Cases (the prior's series in brackets; it never holds a scored row):

* ``C``: Series C within the session, 30 % held out per split, the pool the other 70 % (prior: Series B);
* ``A``: Series A's grid (11,911 poses), 30 % held out, the pool 2,000 seeded rows of the other 70 % (prior: C);
* ``B->C``, ``C->B``, ``C->D``, ``D->C``: the pool all of S, T's set-up re-registered on 60 seeded rows of T
  (robot and discrepancy held), working configurations and scored rows from T's other rows (prior: S).

Per case and split one JSON file in the cache directory (resumable); the prior models are cached there too.

Run:  OMP_NUM_THREADS=1 python -m benchmarks.learning_curves --case C --seeds 20 [--cache runs/curves]
      [--json out.json] [--figure docs/learning_curves.png]   (IPA data: $PIN_KPI_OED_IPA_DATA or shared/data/ipa_ur10)
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks.common import find_ipa_data, load_ipa_series
from pin_kpi_oed import NoiseModel, TrackerModel, load_robot
from pin_kpi_oed.data.atomic import atomic_write_json
from pin_kpi_oed.discrepancy.prior import DiscrepancyPrior
from pin_kpi_oed.studies.learning_curves import METHODS, LearningCurves, poses_text, curve_split, region_beyond

#: case -> (pool series, target series or None, prior series, pool size or None)
CASES = {"C": ("C", None, "B", None), "A": ("A", None, "C", 2000), "B->C": ("B", "C", "B", None),
         "C->B": ("C", "B", "C", None), "C->D": ("C", "D", "C", None), "D->C": ("D", "C", "D", None)}
LABELS = {"kpi_gp": "discrepancy-aware KPI", "kpi_gp_region": "discrepancy-aware KPI, region",
          "kpi": "KPI (noise only)", "D": "D-optimal", "random": "random"}


def ur10_model() -> TrackerModel:
    return TrackerModel(load_robot("ur10"), reflector_m=np.array([0.0, 0.0, 0.109]),
                        noise=NoiseModel(sigma_xyz_m=(1e-4,) * 3))


def prior_of_series(model: TrackerModel, series: str, S: dict, cache: Path) -> DiscrepancyPrior:
    """The discrepancy of ``identify(..., discrepancy="auto", seed=0)`` on all rows of ``series`` (cached)."""
    from pin_kpi_oed.identification.identify import identify
    from pin_kpi_oed.calibrated.model_file import load_model_file

    path = cache / f"prior_{series}.json"
    if not path.exists():
        t0 = time.perf_counter()
        print(f"fitting the prior discrepancy on Series {series} ({len(S[series])} rows) ...", flush=True)
        cm = identify(model, S[series], use_orientation=False, discrepancy="auto", seed=0,
                      raise_on_failure=False).calibrated_model()
        cm.save(path)
        print(f"  {cm.discrepancy.decision} ({time.perf_counter() - t0:.0f} s)", flush=True)
    d = load_model_file(path).discrepancy
    return DiscrepancyPrior.from_discrepancy(d, f"Series {series} (all {d.n_rows} rows, marginal likelihood)")


def run_case(case: str, n_seeds: int, cache: Path, model: TrackerModel, folder: Path,
             region_sizes: tuple[int, ...] = (), region_rows: int = 100,
             methods: tuple[str, ...] = METHODS, random_sizes: tuple[int, ...] = ()) -> LearningCurves:
    src, tgt, pri, pool_size = CASES[case]
    S = {s: load_ipa_series(folder, s) for s in {src, pri} | ({tgt} if tgt else set())}
    prior = prior_of_series(model, pri, S, cache)
    print(f"[{case}] {prior.describe()}", flush=True)
    splits = []
    t0 = time.perf_counter()
    for seed in range(n_seeds):
        path = cache / f"{case.replace('->', '_to_')}_seed{seed}.json"
        if path.exists():
            old = json.loads(path.read_text())
            if old["methods"] == list(methods) and old.get("region_rows", 100) == region_rows:
                splits.append(old)
                continue
        r = curve_split(model, S[src], prior, S[tgt] if tgt else None, seed=seed, pool_size=pool_size,
                        methods=methods, region_rows=region_rows)
        r["region_rows"] = region_rows
        atomic_write_json(path, r)
        splits.append(r)
        e = {k: r["error_mean_m"][k] for k in r["methods"]}
        print(f"[{case}] split {seed + 1}/{n_seeds} (seed {seed}): {r['time_s']:.0f} s, {r['n_scored']} scored rows; "
              f"20 poses " + ", ".join(f"{k} {v[1] * 1e3:.3f}" for k, v in e.items())
              + f" mm; full pool {r['full']['error_mean_m'] * 1e3:.3f} mm", flush=True)
    for seed, r in enumerate(splits):  # larger sets of the region form and of random, added to the cached split
        for key, meth, want in (("region_beyond", "kpi_gp_region", region_sizes),
                                ("random_beyond", "random", random_sizes)):
            have = r.get(key) or {"sizes": [], "error_mean_m": []}
            todo = tuple(m for m in want if m not in have["sizes"] and m < r["n_pool"])
            if not todo:
                continue
            new = region_beyond(model, S[src], prior, S[tgt] if tgt else None, seed=seed, sizes=todo,
                                pool_size=pool_size, region_rows=region_rows, method=meth)
            both = sorted(zip(have["sizes"] + new["sizes"], have["error_mean_m"] + new["error_mean_m"]))
            r[key] = {"sizes": [m for m, _ in both], "error_mean_m": [e for _, e in both],
                      "time_s": have.get("time_s", 0.0) + new["time_s"]}
            atomic_write_json(cache / f"{case.replace('->', '_to_')}_seed{seed}.json", r)
            print(f"[{case}] split {seed + 1}/{n_seeds}: {meth} with " + ", ".join(
                f"{m} poses {e * 1e3:.3f}" for m, e in zip(new["sizes"], new["error_mean_m"]))
                + f" mm ({new['time_s']:.0f} s)", flush=True)
    return LearningCurves(case=case, prior=prior.source, sizes=splits[0]["sizes"], methods=splits[0]["methods"],
                          splits=splits, success=True, status="completed", nit=len(splits),
                          message=f"{len(splits)} splits", time_s=time.perf_counter() - t0)


def _cells(res: LearningCurves, methods, j: int, full: bool = False) -> list[str]:
    """Table cells of size index ``j``: the median (mm; ``full``: mean ± spread first) and, against random, the
    median paired change, wins and the Wilcoxon p."""
    cells = []
    for k in methods:
        e = res.array("error_mean_m", k)[:, j] * 1e3
        c = (f"{e.mean():.3f} ± {e.std(ddof=1):.3f}, med. " if full else "") + f"{np.median(e):.3f}"
        if k != "random":
            p = res.paired(k)[j]
            c += f" ({100 * p['change']:+.0f} %, {p['wins']}/{p['n']}, p {p['p_wilcoxon']:.2g})"
        cells.append(c)
    return cells


def markdown(res: LearningCurves) -> str:
    """The case as markdown: per m and method the mean ± spread and the median (mm) and against random the median
    paired change, wins and the Wilcoxon p; then the poses each method needs to come within 10 % of the full pool
    (observed, predicted)."""
    meths = res.methods
    head = "| m | " + " | ".join(LABELS.get(k, k) for k in meths) + " |"
    rows = [head, "|---" * (len(meths) + 1) + "|"]
    for j, m in enumerate(res.sizes):
        rows.append(f"| {m} | " + " | ".join(_cells(res, meths, j, full=True)) + " |")
    f = res.full("error_mean_m") * 1e3
    rows.append(f"| full pool ({res.splits[0]['n_pool']}) | {f.mean():.3f} ± {f.std(ddof=1):.3f}, "
                f"med. {np.median(f):.3f} |" + " |" * (len(meths) - 1))
    need = {w: res.needed(key) for w, key in (("observed", "error_mean_m"), ("predicted, sigma at W",
                                                                              "pred_sigma_work_m"),
                                               ("predicted, RMS at the scored rows", "pred_rms_scored_m"))}
    rows += ["", "| poses to within 10 % of the full pool (median curves) | "
             + " | ".join(LABELS.get(k, k) for k in meths) + " |",
             "|---" * (len(meths) + 1) + "|"]
    for w, d in need.items():
        rows.append(f"| {w} | " + " | ".join((f"> {res.largest(k) if w == 'observed' else res.sizes[-1]}"
                                              if not np.isfinite(d[k]) else f"{d[k]:.0f}") for k in meths) + " |")
    rows += ["", "| poses to match random's median error at m = " + ", ".join(map(str, res.sizes))
             + " | observed | predicted (RMS at the scored rows) |", "|---|---|---|"]
    for k in meths:
        if k != "random":
            rows.append(f"| {LABELS.get(k, k)} | " + " | ".join(
                ", ".join(poses_text(v, res.sizes[-1], res.sizes[0]) for v in res.equivalent(k, key=key))
                for key in ("error_mean_m", "pred_rms_scored_m")) + " |")
    rows += ["", "| m | " + " | ".join(f"{LABELS.get(k, k)}: predicted RMS / observed RMS (mm)" for k in meths)
             + " |", "|---" * (len(meths) + 1) + "|"]
    for j, m in enumerate(res.sizes):
        rows.append(f"| {m} | " + " | ".join(f"{res.array('pred_rms_scored_m', k)[:, j].mean() * 1e3:.3f} / "
                                             f"{res.array('error_rms_m', k)[:, j].mean() * 1e3:.3f}" for k in meths)
                    + " |")
    if "->" in res.case and all("pred_rms_scored_exact_m" in sp for sp in res.splits):  # across sessions
        rows += ["", "| m | " + " | ".join(f"{LABELS.get(k, k)}: predicted RMS, criterion's / exact re-registered "
                                           f"form, and observed (median, mm)" for k in meths) + " |",
                 "|---" * (len(meths) + 1) + "|"]
        for j, m in enumerate(res.sizes):
            rows.append(f"| {m} | " + " | ".join(" / ".join(
                f"{np.median(res.array(key, k)[:, j]) * 1e3:.3f}"
                for key in ("pred_rms_scored_m", "pred_rms_scored_exact_m", "error_rms_m")) for k in meths) + " |")
    others = [k for k in meths if k != "random"]
    if others and "random" in meths:
        rows += ["", "| m | " + " | ".join(f"{LABELS.get(k, k)}: change of the RMS against random, predicted / observed"
                                           for k in others) + " |", "|---" * (len(others) + 1) + "|"]
        chg = {k: [res.paired(k, key=key) for key in ("pred_rms_scored_m", "error_rms_m")] for k in others}
        for j, m in enumerate(res.sizes):
            rows.append(f"| {m} | " + " | ".join(f"{100 * chg[k][0][j]['change']:+.0f} % / "
                                                 f"{100 * chg[k][1][j]['change']:+.0f} %" for k in others) + " |")
    for meth in ("random", "kpi_gp_region"):
        big = res.beyond(meth)
        if big is not None:
            rows += ["", f"{LABELS[meth]}, larger sets (median over the splits): " + ", ".join(
                f"{m} poses {v * 1e3:.3f} mm" for m, v in zip(big[0], np.median(big[1], 0)))]
    return "\n".join(rows)


def compact_markdown(results: list[LearningCurves], methods: tuple[str, ...] = ("kpi_gp", "kpi", "D", "random")
                     ) -> str:
    """Several cases in one markdown table: per case and m the median (mm) of each method, against random the
    median paired change, wins and Wilcoxon p; then the poses each needs to come within 10 % of the full pool."""
    methods = tuple(k for k in methods if all(k in res.methods for res in results))  # the ones every case ran
    rows = ["| case | m | " + " | ".join(LABELS[k] for k in methods) + " |", "|---" * (len(methods) + 2) + "|"]
    for res in results:
        for j, m in enumerate(res.sizes):
            rows.append(f"| {res.case if j == 0 else ''} | {m} | " + " | ".join(_cells(res, methods, j)) + " |")
    rows += ["", "| case | full pool (poses, median mm) | " + " | ".join(LABELS[k] for k in methods)
             + " |", "|---" * (len(methods) + 2) + "|"]
    for res in results:
        need = res.needed()
        rows.append(f"| {res.case} | {res.splits[0]['n_pool']}, {np.median(res.full('error_mean_m')) * 1e3:.3f} | "
                    + " | ".join(poses_text(need[k], res.largest(k), res.sizes[0]) for k in methods) + " |")
    return "\n".join(rows)


def figure(results: list[LearningCurves], path: str) -> None:
    """Observed RMS 3-D error of the scored rows (solid: median over the splits, band: quartiles) and the predicted
    RMS (dashed, median: universal kriging under the prior discrepancy plus its white level) per method against the
    number of poses; the full pool's observed RMS in grey with its +10 % band."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    from pin_kpi_oed.viz.style import design_colours, hex_colour

    col = {k: hex_colour(v) for k, v in design_colours(list(METHODS)).items()}
    ncol = min(len(results), 3)
    nrow = -(-len(results) // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.4 * ncol, 3.8 * nrow), squeeze=False)
    for ax in axes.ravel()[len(results):]:
        ax.set_visible(False)
    for ax, res in zip(axes.ravel(), results):
        m = np.array(res.sizes)
        for meth in res.methods:
            e = res.array("error_rms_m", meth) * 1e3
            q = np.percentile(e, [25, 50, 75], axis=0)
            ax.plot(m, q[1], "-o", color=col[meth], ms=4)
            ax.fill_between(m, q[0], q[2], color=col[meth], alpha=0.15)
            ax.plot(m, np.median(res.array("pred_rms_scored_m", meth), 0) * 1e3, "--", color=col[meth], lw=1)
        f = float(np.median(res.full("error_rms_m"))) * 1e3
        ax.axhline(f, color="0.4", lw=1)
        ax.axhspan(f, 1.1 * f, color="0.85")
        ax.set_xscale("log")
        ax.set_xticks(m, [str(v) for v in m])
        ax.set_xticks([], minor=True)
        ax.set_xlabel("calibration poses m")
        ax.set_title(f"{res.case}: {len(res.splits)} splits, full pool {res.splits[0]['n_pool']} poses", fontsize=9)
        ax.grid(alpha=0.3)
    for row in axes:
        row[0].set_ylabel("RMS 3-D error near the work (mm)")
    handles = [Line2D([], [], color=col[k], marker="o", ms=4, label=LABELS.get(k, k)) for k in results[0].methods]
    handles += [Line2D([], [], color="k", ls="-", label="observed"), Line2D([], [], color="k", ls="--", lw=1,
                                                                           label="predicted"),
                Line2D([], [], color="0.4", lw=1, label="full pool (band: +10 %)")]
    axes[0][0].legend(handles=handles, fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    print(f"figure written to {path}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", default="C", help=f"comma-separated cases of {', '.join(CASES)} (default C)")
    ap.add_argument("--seeds", type=int, default=20, help="splits, seeds 0 ... N-1 (default 20)")
    ap.add_argument("--cache", default="runs/learning_curves", help="cache directory (one JSON per case and split)")
    ap.add_argument("--json", default=None, help="write the summaries here")
    ap.add_argument("--markdown", action="store_true", help="also print the tables as markdown")
    ap.add_argument("--figure", default=None, help="draw observed vs predicted curves of the cases here (PNG)")
    ap.add_argument("--region-rows", dest="region_rows", type=int, default=100,
                    help="most pool rows of the working region in kpi_gp_region's criterion (default 100; a larger "
                         "number takes every pool row within the radius; give another --cache)")
    ap.add_argument("--methods", default=",".join(METHODS), help=f"comma-separated of {', '.join(METHODS)}")
    ap.add_argument("--region-beyond", dest="region_beyond", default="",
                    help="larger sizes of the region form (kpi_gp_region), comma-separated, e.g. 240,480: where it "
                         "comes within 10 %% of the full pool (added to the cached splits)")
    ap.add_argument("--random-beyond", dest="random_beyond", default="",
                    help="larger sizes of the random sets beyond 240,480,960, comma-separated, e.g. 1360 "
                         "(added to the cached splits)")
    a = ap.parse_args(argv)
    folder = find_ipa_data()
    if folder is None or not (folder / "Series_C").is_dir():
        print("IPA UR10 data not found: nothing to do (set PIN_KPI_OED_IPA_DATA)")
        return 0
    cases = [c.strip() for c in a.case.split(",") if c.strip()]
    for c in cases:
        if c not in CASES:
            ap.error(f"unknown case '{c}' (known: {', '.join(CASES)})")
    cache = Path(a.cache)
    cache.mkdir(parents=True, exist_ok=True)
    model = ur10_model()
    results = []
    for c in cases:
        res = run_case(c, a.seeds, cache, model, folder,
                       tuple(int(x) for x in a.region_beyond.split(",") if x.strip()), a.region_rows,
                       tuple(x.strip() for x in a.methods.split(",") if x.strip()),
                       tuple(int(x) for x in a.random_beyond.split(",") if x.strip()))
        results.append(res)
        print(res.summary(), flush=True)
        if a.markdown:
            print(markdown(res), flush=True)
    if a.markdown and len(results) > 1:
        print(compact_markdown(results), flush=True)
    if a.json:
        atomic_write_json(a.json, {"cases": [r.to_dict() for r in results], "seeds": a.seeds})
    if a.figure:
        figure(results, a.figure)
    return 0


if __name__ == "__main__":
    sys.exit(main())
