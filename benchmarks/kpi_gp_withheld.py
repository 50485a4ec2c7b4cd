"""Withheld effect: the discrepancy-aware KPI design against the plain KPI design on the TRUE TCP error.

The shipped UR10 cell; per seeded repetition a simulated UR10 with random geometric errors (0.5 mm / 1 mrad) and a
gear harmonic the model never names (orders 2 and 3 of the shoulder lift, the elbow and wrist 1, amplitude a per
component, random phases; a ∈ {0, 0.1, 0.3, 1} mrad, the same robot and noise for every a), tracker σ = 10 µm. A
fixed pool of feasible candidate poses of the cell (seeded), a separate pilot set of random feasible poses (the
discrepancy's hyper-parameters of ``kpi_gp`` are fitted on it, ``identify(..., discrepancy="on")``), and the
working configurations: the cell's two plus seeded perturbations of ±0.3 rad of each. m ∈ {20, 60} poses are
chosen by ``kpi_gp`` (pilot prior), ``kpi_gp`` with the default discrepancy, the plain ``kpi`` and at random;
every set is calibrated the same way (geometry + the discrepancy conditioned on the chosen poses with the pilot's
hyper-parameters) and scored by the true TCP error at the working configurations
(:mod:`pin_kpi_oed.studies.kpi_withheld`). Paired Wilcoxon tests per (a, m).

Run: ``OMP_NUM_THREADS=1 python -m benchmarks.kpi_gp_withheld [--reps 20] [--pool 1000] [--pilot 200]
[--json out.json]`` (progress per case on stderr; about 16 min on 2 cores, ``--reps 3`` for a quick look).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

AMPLITUDES_MRAD = (0.0, 0.1, 0.3, 1.0)
SIZES = (20, 60)


def main(argv: list[str] | None = None) -> dict:
    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.design.optimize import DesignProblem
    from pin_kpi_oed.studies.kpi_withheld import DESIGNS, paired_summary, withheld_case, working_region

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=20, help="simulated robots (seeds 0 .. reps-1)")
    ap.add_argument("--pool", type=int, default=1000, help="feasible candidate poses (fixed, seed 0)")
    ap.add_argument("--pilot", type=int, default=200, help="pilot poses for the discrepancy's hyper-parameters")
    ap.add_argument("--amplitudes", default=",".join(f"{a:g}" for a in AMPLITUDES_MRAD), help="mrad, comma-separated")
    ap.add_argument("--per-point", dest="per_point", type=int, default=3,
                    help="perturbed working configurations per cell working configuration")
    ap.add_argument("--pilot-discrepancy", dest="pilot_discrepancy", choices=["auto", "on"], default="auto",
                    help="the pilot's identify --discrepancy: auto (a user's default: white when the process does not "
                         "pay on the pilot) or on (always fitted)")
    ap.add_argument("--tcp-at-reflector", dest="tcp_at_reflector", action="store_true",
                    help="score the TCP at the reflector instead of the cell's TCP: what the discrepancy, learnt at "
                         "the reflector, can see (the flange's rotation error times the TCP-reflector offset it "
                         "cannot)")
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    amps = [float(x) for x in a.amplitudes.split(",")]
    t0 = time.perf_counter()
    cell = load_cell("ur10")
    problem = DesignProblem(cell)
    model = problem.model
    if a.tcp_at_reflector:
        import dataclasses

        model = dataclasses.replace(model, tcp_m=np.asarray(model.reflector_m, float).copy())
    Q_pool, _ = problem.random_design(a.pool, seed=np.random.SeedSequence([0, 1]))
    Q_pilot, _ = problem.random_design(a.pilot, seed=np.random.SeedSequence([0, 2]))
    W = working_region(cell.q_work, a.per_point, 0.3, seed=3)
    print(f"UR10 cell: pool {len(Q_pool)}, pilot {len(Q_pilot)}, {len(W)} working configurations "
          f"({time.perf_counter() - t0:.0f} s)", file=sys.stderr)
    fixed: dict = {}
    runs = []
    for rep in range(a.reps):
        for amp in amps:
            r = withheld_case(model, Q_pool, Q_pilot, W, amp * 1e-3, seed=rep, sizes=SIZES, fixed=fixed,
                              pilot_discrepancy=a.pilot_discrepancy)
            runs.append(r)
            e = r["error_m"]
            print(f"rep {rep} a {amp:g} mrad ({r['time_s']:.1f} s): " + "; ".join(
                f"m={m}: " + " ".join(f"{d} {e[d][i] * 1e3:.3f}" for d in DESIGNS) for i, m in enumerate(SIZES))
                + " mm", file=sys.stderr, flush=True)
    out = {"reps": a.reps, "pool": len(Q_pool), "pilot": len(Q_pilot), "pilot_discrepancy": a.pilot_discrepancy,
           "tcp_m": np.asarray(model.tcp_m, float).tolist(),
           "t_work": len(W), "sizes": list(SIZES),
           "amplitudes_mrad": amps, "runs": runs, "summary": []}
    head = (f"{'a mrad':>7}{'m':>4}{'kpi_gp mm':>11}{'kpi mm':>9}{'median chg':>11}{'wins':>7}{'sign p':>9}"
            f"{'gp(default) mm':>16}{'random mm':>11}{'kpi_gp pred. sigma mm':>23}{'GP pilots':>11}")
    print(f"true TCP error at {len(W)} working configurations (RMS 3-D, mean over {a.reps} robots; TCP "
          f"{', '.join(f'{v:g}' for v in model.tcp_m)} m in the tool frame, reflector "
          f"{', '.join(f'{v:g}' for v in model.reflector_m)} m); "
          "kpi_gp (pilot prior) vs plain kpi: paired median change, sign test")
    print(head)
    print("-" * len(head))
    for amp in amps:
        rs = [r for r in runs if r["amplitude_rad"] == amp * 1e-3]
        for i, m in enumerate(SIZES):
            col = {d: [r["error_m"][d][i] for r in rs] for d in DESIGNS}
            s = paired_summary(col["kpi_gp"], col["kpi"])
            s.update({"amplitude_mrad": amp, "m": m, "mean_kpi_gp_default_m": float(np.mean(col["kpi_gp_default"])),
                      "mean_random_m": float(np.mean(col["random"])),
                      "default_vs_kpi": paired_summary(col["kpi_gp_default"], col["kpi"]),
                      "mean_pred_sigma_kpi_gp_m": float(np.nanmean([r["predicted_sigma_m"]["kpi_gp"][i] for r in rs])),
                      "gp_pilots": int(sum(r["pilot"]["kind"] != "white" for r in rs))})
            out["summary"].append(s)
            print(f"{amp:>7g}{m:>4}{s['mean_a_m'] * 1e3:>11.4f}{s['mean_b_m'] * 1e3:>9.4f}"
                  f"{100 * s['change_median']:>+10.1f}%"
                  f"{s['wins_a']:>4}/{s['n']:<2}{s['p_sign']:>9.2g}{s['mean_kpi_gp_default_m'] * 1e3:>16.4f}"
                  f"{s['mean_random_m'] * 1e3:>11.4f}{s['mean_pred_sigma_kpi_gp_m'] * 1e3:>23.4f}"
                  f"{s['gp_pilots']:>8}/{len(rs)}")
    out["time_s"] = time.perf_counter() - t0
    print(f"{len(runs)} cases in {out['time_s']:.0f} s")
    if a.json:
        from pin_kpi_oed.data.atomic import atomic_write_json

        atomic_write_json(a.json, out)
    return out


if __name__ == "__main__":
    main(sys.argv[1:])
