"""Designs over the extended model: simulation with withheld effects, and the design time.

**Simulation.** A UR10 measured by a laser tracker (σ = 10 µm and 100 µm per axis). Truth: random
geometric errors (:class:`~pin_kpi_oed.simulation.simulator.Tolerances`, 0.5 mm / 1 mrad) plus
transmission errors of four joints (orders of the real UR10's selected terms: shoulder_lift 20, elbow 18,
shoulder_pan 12, wrist_1 10), each coefficient ~ N(0, a²), a growing (0, 100, 300, 1000 µrad). A fixed
pool of 400 random configurations, 5 working configurations, 60 poses per design. KPI designs on the
geometric model and on the extended model (with the tolerance prior σ₀ = 100 µrad per coefficient, and
without a prior); each calibrated with the extended model as a MAP with that prior (shrinkage bias ∝ θ)
and unregularised (least squares). Score: true TCP error at the working configurations (mean 3-D norm),
per repetition (new truth, new noise); paired Wilcoxon test per size; regression of the paired gap on a.
Why: in a linear model the estimator covariance does not depend on the true effect, so under an
unbiased calibration the gap between two designs cannot grow with the effect; it grows only through
bias, here the MAP's shrinkage, E C Σ₀⁻¹ θ, which is smaller for the design that informs θ.

**Time.** Pool selection of 60 of 2,000 KR 15 cell candidates, KPI on the geometric vs the extended
model (geometry + a transmission-error pair on A2 and A3), and the IPOPT KPI design of the KR 15 cell
(60 poses, pool start) on the geometric vs the extended model (gear harmonics of A2, A3, exact gradients).

Run: ``python -m benchmarks.bench_extended [--reps 100] [--noise 1e-5,1e-4] [--json out.json]`` (about 3–6 min on
2 cores).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

PAIRS = [("shoulder_lift_joint", 20), ("elbow_joint", 18), ("shoulder_pan_joint", 12), ("wrist_1_joint", 10)]
SIZES_RAD = (0.0, 1e-4, 3e-4, 1e-3)
PRIOR_RAD = 1e-4  # tolerance prior of the simulation's transmission-error coefficients
TIME_PRIOR_RAD = 2e-4  # prior of the timing benchmarks
NOISE_M = 1e-5


def simulation(reps: int = 100, seed: int = 0, sizes: tuple[float, ...] = SIZES_RAD, prior_rad: float = PRIOR_RAD,
               noise_m: float = NOISE_M, quiet: bool = False) -> dict:
    """Monte-Carlo: extended-model vs geometric KPI design, each calibrated two ways, over effect sizes (m).

    Truth per repetition: geometric errors ~ tolerances (on the identifiable parameters) and transmission
    errors θ ~ N(0, a² I) (four joints, :data:`PAIRS`); σ = ``noise_m`` per axis (default 10 µm). Designs (60 of a
    fixed pool of 400 random configurations, 5 working configurations), made once:

    * ``geo``: KPI on the geometric model (:func:`pin_kpi_oed.oed.pool.select`);
    * ``ext_map``: KPI on the extended model with the tolerance prior σ₀ = ``prior_rad`` per coefficient
      (:func:`pin_kpi_oed.oed.extended.select_pool`);
    * ``ext_ls``: KPI on the extended model without a prior.

    Calibrations: ``map`` (geometry + θ, prior σ₀ on θ: shrinkage bias ∝ θ) and ``ls`` (unregularised).
    Compared pairs: geo vs ext_map under ``map``, geo vs ext_ls under ``ls``. Score: true TCP error at
    the working configurations (mean 3-D norm). Paired Wilcoxon signed-rank test per size; the growth
    of the paired gap (geo − ext) with a is tested by a linear regression of the per-repetition gaps
    on a (two-sided p of the slope). The linear-model prediction of the RMS TCP error,
    sqrt(tr(E C (FᵀF + a² Σ₀⁻²) C Eᵀ)/t) with C = (FᵀF + Σ₀⁻¹)⁻¹ (MAP; a-independent for LS),
    is printed beside it.

    Args:
        reps: repetitions per size (new truth and noise each); seed: seed of pool, truths, noise.
        sizes: effect sizes a (rad); prior_rad: σ₀ of the tolerance prior (rad); noise_m: tracker σ (m).
        quiet: no printing.

    Returns:
        Plain numbers (m): per size and calibration the mean/std errors, paired tests, predictions;
        the regression of the gaps on a.
    """
    from scipy import stats

    from pin_kpi_oed.effects.periodic import TransmissionError
    from pin_kpi_oed.simulation.simulator import Tolerances, default_tracker_pose, random_truth, simulate
    from pin_kpi_oed.model.noise import NoiseModel
    from pin_kpi_oed.model.robot import load_robot
    from pin_kpi_oed.model.tracker import TrackerModel
    from pin_kpi_oed.oed.criteria import get_criterion
    from pin_kpi_oed.oed.extended import ExtendedModel, select_pool
    from pin_kpi_oed.oed.identifiability import analyse
    from pin_kpi_oed.oed.pool import select
    from pin_kpi_oed.studies.design_trials import fit_extended

    rb = load_robot("ur10")
    model = TrackerModel(rb, tracker_T_base=default_tracker_pose(rb), reflector_m=np.array([0.05, 0.02, 0.10]),
                         noise=NoiseModel((noise_m,) * 3))
    base = analyse(model).base
    eff = TransmissionError(rb, pairs=PAIRS)
    rng = np.random.default_rng(seed)
    Qp = rb.random_q(rng, 400)
    Qw = rb.random_q(rng, 5)
    p0 = np.zeros(model.n_params)
    ext = ExtendedModel(model, p0, base, [eff])
    P0 = np.diag(np.r_[np.zeros(ext.nb), np.full(ext.k, prior_rad ** -2)])
    Fp = ext.jacobian(Qp)
    E = ext.kpi_jacobian(Qw)
    kpi = get_criterion("kpi")
    t0 = time.perf_counter()
    designs = {"geo": np.sort(select(Fp[:, :, :ext.nb], 60, kpi.pool_form(E[:, :ext.nb], ext.nb), seed=seed).indices),
               "ext_map": np.sort(select_pool(Fp, 60, kpi.pool_form(E, ext.nx), P0, seed=seed).indices),
               "ext_ls": np.sort(select_pool(Fp, 60, kpi.pool_form(E, ext.nx), None, seed=seed).indices)}
    t_design = time.perf_counter() - t0
    calib = {"map": (prior_rad, "ext_map"), "ls": (np.inf, "ext_ls")}

    def predicted_rms(d: str, cal: str, a: float) -> float:
        F = Fp[designs[d]].reshape(-1, ext.nx)
        M = F.T @ F + (P0 if cal == "map" else 0.0)
        C = np.linalg.inv(M)
        Mid = F.T @ F + (a ** 2 * P0 @ P0 if cal == "map" else 0.0)
        return float(np.sqrt(np.trace(E @ C @ Mid @ C @ E.T) / Qw.shape[0]))

    out = {"sizes_rad": list(sizes), "reps": reps, "prior_rad": prior_rad, "noise_m": noise_m, "n_pool": 400,
           "n_work": 5, "n_meas": 60, "design_time_s": t_design, "cases": [], "growth": {}}
    gaps: dict[str, list] = {c: [] for c in calib}
    for a in sizes:
        errs: dict[str, list[float]] = {f"{d}/{c}": [] for c, (_, de) in calib.items() for d in ("geo", de)}
        seeds = np.random.SeedSequence([seed, int(round(a * 1e7))]).spawn(reps)
        for r in range(reps):
            s1, s2, s3 = (int(x) for x in seeds[r].generate_state(3))
            p_true = random_truth(model, Tolerances(), seed=s1, only=base)
            th = a * np.random.default_rng(s2).standard_normal(eff.n_params)
            s_true = model.kpi(p_true, Qw + eff.joint_offset(th, Qw)[0])
            for key in errs:
                d, c = key.split("/")
                data = simulate(model, Qp[designs[d]], p_true, effects=[(eff, th)], seed=s3, record_sigma=False)
                x = fit_extended(model, data, base, [eff], p0, calib[c][0])
                P = p0.copy()
                P[base] = x[:base.size]
                s_hat = model.kpi(P, Qw + eff.joint_offset(x[base.size:], Qw)[0])
                errs[key].append(float(np.linalg.norm(s_hat - s_true, axis=1).mean()))
        e = {k: np.array(v) for k, v in errs.items()}
        case = {"size_rad": a}
        for c, (_, de) in calib.items():
            g, x_ = e[f"geo/{c}"], e[f"{de}/{c}"]
            gaps[c].append(g - x_)
            case[c] = {"geo": {"mean_m": float(g.mean()), "std_m": float(g.std(ddof=1)),
                               "predicted_rms_m": predicted_rms("geo", c, a)},
                       de: {"mean_m": float(x_.mean()), "std_m": float(x_.std(ddof=1)),
                            "predicted_rms_m": predicted_rms(de, c, a)},
                       "gap_mean_m": float((g - x_).mean()),
                       "gap_sem_m": float((g - x_).std(ddof=1) / np.sqrt(reps)),
                       "reduction": float(1.0 - x_.mean() / g.mean()), "wins": int(np.sum(x_ < g)),
                       "p_wilcoxon": float(stats.wilcoxon(x_, g).pvalue) if np.any(x_ != g) else 1.0}
            if not quiet:
                cc = case[c]
                print(f"a = {a * 1e6:5.0f} urad, {c:>3} calibration: geo design {g.mean() * 1e6:8.2f} um "
                      f"(pred. RMS {cc['geo']['predicted_rms_m'] * 1e6:7.2f}), {de} design {x_.mean() * 1e6:8.2f} um "
                      f"(pred. {cc[de]['predicted_rms_m'] * 1e6:7.2f}); gap {cc['gap_mean_m'] * 1e6:+.2f} "
                      f"+- {cc['gap_sem_m'] * 1e6:.2f} um, {-100 * cc['reduction']:+.1f} %, wins {cc['wins']}/{reps}, "
                      f"Wilcoxon p {cc['p_wilcoxon']:.2g}", flush=True)
        out["cases"].append(case)
    for c in calib:
        a_all = np.repeat(np.asarray(sizes, float), reps)
        lr = stats.linregress(a_all, np.concatenate(gaps[c]))
        out["growth"][c] = {"slope_m_per_rad": float(lr.slope), "slope_stderr": float(lr.stderr),
                            "p_slope": float(lr.pvalue)}
        if not quiet:
            print(f"{c} calibration: the paired gap geo - ext grows by {lr.slope:.4f} um per urad "
                  f"(+- {lr.stderr:.4f}), p {lr.pvalue:.2g} (linear regression over "
                  f"{a_all.size} repetitions)", flush=True)
    return out


def design_time(seed: int = 0, rounds: int = 5) -> dict:
    """Pool selection time (s) on the KR 15 cell: KPI on the geometric vs the extended model.

    Args:
        seed: seed of the 2,000 random candidates and of the selections.
        rounds: interleaved timing rounds (geometric, extended); the medians are reported.

    Returns:
        {"geometric_s", "extended_s" (medians, s), "ratio", "rounds", per-round times}.
    """
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
    ext.prior_info = np.diag(np.r_[np.zeros(ext.nb), np.full(ext.k, TIME_PRIOR_RAD ** -2)])
    Q = rb.random_q(np.random.default_rng(seed), 2000)
    kpi = get_criterion("kpi")
    tg, te = [], []
    for _ in range(rounds):  # interleaved rounds, medians: robust to a shared, loaded machine
        t0 = time.perf_counter()
        Fg = model.weighted_jacobian(np.zeros(model.n_params), Q)[:, :, base]
        Eg = model.kpi_jacobian(np.zeros(model.n_params), cell.q_work)[:, base]
        select(Fg, 60, kpi.pool_form(Eg, base.size), seed=seed)
        tg.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        select_pool(ext.jacobian(Q), 60, kpi.pool_form(ext.kpi_jacobian(cell.q_work), ext.nx), ext.prior_info,
                    seed=seed)
        te.append(time.perf_counter() - t0)
    t_geo, t_ext = float(np.median(tg)), float(np.median(te))
    print(f"KR 15 cell, 60 of 2000 candidates (median of {rounds} interleaved rounds): geometric KPI {t_geo:.2f} s, "
          f"extended KPI {t_ext:.2f} s (ratio {t_ext / t_geo:.2f}, target <= 2)", flush=True)
    return {"geometric_s": t_geo, "extended_s": t_ext, "ratio": t_ext / t_geo, "rounds": rounds,
            "geometric_all_s": tg, "extended_all_s": te}


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
            ext.prior_info = np.diag(np.r_[np.zeros(ext.nb), np.full(ext.k, TIME_PRIOR_RAD ** -2)])
            problem = problem.replaced(extended=ext)
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
    ap.add_argument("--noise", default="1e-5,1e-4", help="tracker sigma(s) of the simulation, m, comma-separated")
    a = ap.parse_args(argv if argv is not None else [])
    out = {}
    if a.only in (None, "time"):
        out["design_time"] = design_time(a.seed)
    if a.only in (None, "ipopt"):
        out["ipopt_time"] = ipopt_time(a.seed)
    if a.only in (None, "simulation"):
        out["simulation"] = {}
        for nz in (float(v) for v in a.noise.split(",") if v.strip()):
            print(f"simulation, tracker sigma {nz * 1e6:g} um, prior {PRIOR_RAD * 1e6:g} urad, {a.reps} repetitions "
                  "per size:", flush=True)
            out["simulation"][f"{nz:g}"] = simulation(a.reps, a.seed, noise_m=nz)
    if a.json:
        from pin_kpi_oed.data.atomic import atomic_write_json

        atomic_write_json(a.json, out)
    return out


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
