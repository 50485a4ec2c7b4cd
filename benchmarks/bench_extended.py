"""Designs over the extended model: simulation with withheld effects, and the design time (issue 14).

**Simulation.** A UR10 measured by a laser tracker (σ = 10 µm per axis). Truth: random geometric
errors (:class:`~pin_kpi_oed.identification.simulate.Tolerances`, 0.5 mm / 1 mrad) plus transmission
errors of four joints (orders of the real UR10's selected terms: shoulder_lift 20, elbow 18,
shoulder_pan 12, wrist_1 10), each coefficient ~ N(0, a²), a growing. A fixed pool of 400 random
configurations, 5 working configurations, 60 poses per design:

* ``geo/geo``: KPI design on the geometric model, calibrated with the geometric model (status quo);
* ``geo/ext``: the same design, calibrated with the extended model (geometry + the four terms, MAP,
  prior σ 200 µrad per coefficient);
* ``ext/ext``: KPI design on the extended model (same prior, :func:`pin_kpi_oed.oed.extended.select_pool`),
  calibrated with the extended model.

Score: true TCP error at the working configurations (mean 3-D norm), per repetition (new truth,
new noise), ≥ 100 repetitions per size; paired Wilcoxon test ext/ext vs geo/ext and geo/geo.

**Time.** Pool selection of 60 of 2,000 KR 15 cell candidates, KPI on the geometric vs the extended
model (geometry + a transmission-error pair on A2 and A3), and the IPOPT KPI design of the KR 15 cell
(60 poses, pool start) on the geometric vs the extended model (gear harmonics of A2, A3, exact gradients).

Run: ``python -m benchmarks.bench_extended [--reps 100] [--json out.json]`` (about 3–6 min on 2 cores).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

PAIRS = [("shoulder_lift_joint", 20), ("elbow_joint", 18), ("shoulder_pan_joint", 12), ("wrist_1_joint", 10)]
SIZES_RAD = (0.0, 1e-4, 3e-4)
PRIOR_RAD = 2e-4
NOISE_M = 1e-5


def simulation(reps: int = 100, seed: int = 0, sizes: tuple[float, ...] = SIZES_RAD) -> dict:
    """Monte-Carlo of the three design/calibration pairs over effect sizes; returns plain numbers (m)."""
    from scipy import stats

    from pin_kpi_oed.effects.periodic import TransmissionError
    from pin_kpi_oed.identification.simulate import Tolerances, default_tracker_pose, random_truth, simulate
    from pin_kpi_oed.model.noise import NoiseModel
    from pin_kpi_oed.model.robot import load_robot
    from pin_kpi_oed.model.tracker import TrackerModel
    from pin_kpi_oed.oed.criteria import get_criterion
    from pin_kpi_oed.oed.extended import ExtendedModel, select_pool
    from pin_kpi_oed.oed.identifiability import analyse
    from pin_kpi_oed.oed.pool import select
    from pin_kpi_oed.studies.validation import _fit_extended

    rb = load_robot("ur10")
    model = TrackerModel(rb, tracker_T_base=default_tracker_pose(rb), reflector_m=np.array([0.05, 0.02, 0.10]),
                         noise=NoiseModel((NOISE_M,) * 3))
    base = analyse(model).base
    eff = TransmissionError(rb, pairs=PAIRS)
    rng = np.random.default_rng(seed)
    Qp = rb.random_q(rng, 400)
    Qw = rb.random_q(rng, 5)
    p0 = np.zeros(model.n_params)
    ext = ExtendedModel(model, p0, base, [eff])
    ext.prior_info = np.diag(np.r_[np.zeros(ext.nb), np.full(ext.k, PRIOR_RAD ** -2)])
    Fp = ext.jacobian(Qp)
    E = ext.kpi_jacobian(Qw)
    kpi = get_criterion("kpi")
    t0 = time.perf_counter()
    d_geo = np.sort(select(Fp[:, :, :ext.nb], 60, kpi.pool_form(E[:, :ext.nb], ext.nb), seed=seed).indices)
    d_ext = np.sort(select_pool(Fp, 60, kpi.pool_form(E, ext.nx), ext.prior_info, seed=seed).indices)
    t_design = time.perf_counter() - t0
    out = {"sizes_rad": list(sizes), "reps": reps, "prior_rad": PRIOR_RAD, "design_time_s": t_design, "cases": []}
    for a in sizes:
        errs = {"geo/geo": [], "geo/ext": [], "ext/ext": []}
        seeds = np.random.SeedSequence([seed, int(a * 1e7)]).spawn(reps)
        for r in range(reps):
            s1, s2, s3 = (int(x) for x in seeds[r].generate_state(3))
            p_true = random_truth(model, Tolerances(), seed=s1, only=base)
            th = a * np.random.default_rng(s2).standard_normal(eff.n_params)
            s_true = model.kpi(p_true, Qw + eff.joint_offset(th, Qw)[0])
            for key, design in (("geo/geo", d_geo), ("geo/ext", d_geo), ("ext/ext", d_ext)):
                data = simulate(model, Qp[design], p_true, effects=[(eff, th)], seed=s3, record_sigma=False)
                effects = [eff] if key.endswith("ext") else []
                x = _fit_extended(model, data, base, effects, p0, PRIOR_RAD)
                P = p0.copy()
                P[base] = x[:base.size]
                dQ = eff.joint_offset(x[base.size:], Qw)[0] if effects else 0.0
                errs[key].append(float(np.linalg.norm(model.kpi(P, Qw + dQ) - s_true, axis=1).mean()))
        e = {k: np.array(v) for k, v in errs.items()}
        case = {"size_rad": a, **{k: {"mean_m": float(v.mean()), "std_m": float(v.std(ddof=1))} for k, v in e.items()}}
        for ref in ("geo/ext", "geo/geo"):
            case[f"ext/ext vs {ref}"] = {"reduction": float(1 - e["ext/ext"].mean() / e[ref].mean()),
                                         "wins": int(np.sum(e["ext/ext"] < e[ref])),
                                         "p_wilcoxon": float(stats.wilcoxon(e["ext/ext"], e[ref]).pvalue)}
        out["cases"].append(case)
        print(f"a = {a * 1e6:5.0f} urad: " + "  ".join(f"{k} {v.mean() * 1e6:7.2f} um" for k, v in e.items())
              + "  | ext/ext vs geo/ext {:+.1%} (wins {}/{}, p {:.2g}); vs geo/geo {:+.1%} (p {:.2g})".format(
                  -case["ext/ext vs geo/ext"]["reduction"], case["ext/ext vs geo/ext"]["wins"], reps,
                  case["ext/ext vs geo/ext"]["p_wilcoxon"], -case["ext/ext vs geo/geo"]["reduction"],
                  case["ext/ext vs geo/geo"]["p_wilcoxon"]), flush=True)
    return out


def design_time(seed: int = 0) -> dict:
    """Pool selection time (s) on the KR 15 cell: KPI on the geometric vs the extended model."""
    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.effects.periodic import TransmissionError
    from pin_kpi_oed.oed.criteria import get_criterion
    from pin_kpi_oed.oed.extended import ExtendedModel, select_pool
    from pin_kpi_oed.oed.identifiability import analyse
    from pin_kpi_oed.oed.pool import select

    cell = load_cell("kr15")
    model = cell.tracker_model()
    rb = model.robot
    base = analyse(model).base
    j = rb.joint_names
    ext = ExtendedModel(model, np.zeros(model.n_params), base, [TransmissionError(rb, pairs=[(j[1], 1), (j[2], 1)])])
    ext.prior_info = np.diag(np.r_[np.zeros(ext.nb), np.full(ext.k, PRIOR_RAD ** -2)])
    Q = rb.random_q(np.random.default_rng(seed), 2000)
    kpi = get_criterion("kpi")
    t0 = time.perf_counter()
    Fg = model.weighted_jacobian(np.zeros(model.n_params), Q)[:, :, base]
    Eg = model.kpi_jacobian(np.zeros(model.n_params), cell.q_work)[:, base]
    select(Fg, 60, kpi.pool_form(Eg, base.size), seed=seed)
    t_geo = time.perf_counter() - t0
    t0 = time.perf_counter()
    select_pool(ext.jacobian(Q), 60, kpi.pool_form(ext.kpi_jacobian(cell.q_work), ext.nx), ext.prior_info, seed=seed)
    t_ext = time.perf_counter() - t0
    print(f"KR 15 cell, 60 of 2000 candidates: geometric KPI {t_geo:.2f} s, extended KPI {t_ext:.2f} s "
          f"(ratio {t_ext / t_geo:.2f}, target <= 2)", flush=True)
    return {"geometric_s": t_geo, "extended_s": t_ext, "ratio": t_ext / t_geo}


def ipopt_time(seed: int = 0) -> dict:
    """IPOPT KPI design of the KR 15 cell (60 poses, pool start, one start): geometric vs extended model.

    Extended: geometry + gear harmonics (orders 1, 2) of A2 and A3 with exact gradients
    (:class:`~pin_kpi_oed.oed.extended.ExtendedDesignCriterion`), prior σ 200 µrad per coefficient.
    """
    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.design.optimize import DesignOptions, DesignProblem, run_designs
    from pin_kpi_oed.effects.library import GearHarmonic
    from pin_kpi_oed.oed.extended import ExtendedDesignCriterion, ExtendedModel

    cell = load_cell("kr15")
    out = {}
    for kind in ("geometric", "extended"):
        problem = DesignProblem(cell)
        if kind == "extended":
            rb = problem.model.robot
            ext = ExtendedModel(problem.model, problem.p0, problem.base, [GearHarmonic(rb, joints=rb.joint_names[1:3])])
            ext.prior_info = np.diag(np.r_[np.zeros(ext.nb), np.full(ext.k, PRIOR_RAD ** -2)])
            problem.extended = ext
        t0 = time.perf_counter()
        res = run_designs(cell, ["kpi"], 60, seed, DesignOptions(n_starts=1), problem)[-1]
        out[kind] = {"time_s": time.perf_counter() - t0, "ipopt_time_s": res.time_s, "iterations": res.nit,
                     "feasible": res.feasible}
        if kind == "extended":
            crit = ExtendedDesignCriterion(problem.extended, "kpi", cell.q_work)
            out[kind]["extended_tr_cs_m2"] = crit.value(res.q_meas)
    out["ratio"] = out["extended"]["time_s"] / out["geometric"]["time_s"]
    print(f"KR 15 cell IPOPT KPI design (60 poses, pool start): geometric {out['geometric']['time_s']:.1f} s "
          f"({out['geometric']['iterations']} it), extended {out['extended']['time_s']:.1f} s "
          f"({out['extended']['iterations']} it); ratio {out['ratio']:.2f} (target <= 2)", flush=True)
    return out


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", default=None)
    ap.add_argument("--only", choices=["time", "ipopt", "simulation"], default=None)
    a = ap.parse_args(argv if argv is not None else [])
    out = {}
    if a.only in (None, "time"):
        out["design_time"] = design_time(a.seed)
    if a.only in (None, "ipopt"):
        out["ipopt_time"] = ipopt_time(a.seed)
    if a.only in (None, "simulation"):
        out["simulation"] = simulation(a.reps, a.seed)
    if a.json:
        from pin_kpi_oed.data.atomic import atomic_write_json

        atomic_write_json(a.json, out)
    return out


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
