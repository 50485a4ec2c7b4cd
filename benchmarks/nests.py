"""One reflector nest or two chosen by the design: the σ at the TCP against the realised TCP errors.

Per seed (a UR5 of example-robot-data):

1. two nests on the tool: nest 0 on the last joint's axis at the flange, nest 1 0.06 m off the axis and 0.05 m out;
   the TCP 0.15 m out along the axis (0.15 m from nest 0); 35 poses chosen by the ``kpi`` criterion at nest 0 from
   400 random candidates for the TCP at 5 working configurations; the nest of each pose chosen by the TCP's tr C_s
   (:func:`pin_kpi_oed.oed.nests.assign_nests`: the assign-after design), against every pose at nest 0 (the same
   poses); and the design over pose × nest from the assign-after design (``alt``:
   :func:`pin_kpi_oed.design.nest_design.alternate_nests`, IPOPT on the poses at their nests and the nests reassigned,
   in turn, in a cell of the same robot, tracker, nests and working configurations with no obstacle and the
   incidence angle free, as the candidates were drawn);
2. a true robot with errors on EVERY joint parameter (0.5 mm, 1 mrad: also those no reflector measurement sees),
   the nests' shared offset 1 mm off nominal, and an unmodelled gear harmonic (σ 50 µrad per coefficient),
   measured at the designed poses at their nests (tracker noise 25 µm per axis);
3. ``identify`` with default options on each design's rows (the ``nest`` column);
4. at 40 held-out random configurations, the true TCP (the simulated robot's point, effects included, true tracker
   frame) − the calibrated model's TCP against the one σ at the TCP (``tcp_sigma``): standardised RMS
   sqrt(mean(eᵀ C⁻¹ e) / 3) and the share inside the 95 % ellipsoid, per seed and pooled; the σ (RMS over the
   rows of sqrt(tr C)) and the realised error (RMS |e|) of two nests against one, paired over the seeds (median of
   the ratios, sign test: :func:`pin_kpi_oed.studies.paired.paired_comparison`).

Run: ``python -m benchmarks.nests --seed 0 --seeds 10 [--alternate] [--json out.json]`` (``--alternate``: the
``alt`` arm too).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

NESTS_M = np.array([[0.0, 0.0, 0.0], [0.06, 0.0, 0.05]])
TCP_M = np.array([0.0, 0.0, 0.15])
NOISE_M = 2.5e-5
CHI2_3_95 = 7.8147


def _stats(e: np.ndarray, C: np.ndarray) -> dict:
    """Standardised RMS, share inside 95 %, σ and error (RMS, m) and the squared Mahalanobis distances."""
    d2 = np.einsum("ma,ma->m", e, np.linalg.solve(C, e[:, :, None])[:, :, 0])
    return {"z": float(np.sqrt(np.mean(d2) / 3.0)), "in95": float(np.mean(d2 <= CHI2_3_95)),
            "sigma_m": float(np.sqrt(np.mean(np.einsum("maa->m", C)))),
            "error_m": float(np.sqrt(np.mean(np.sum(e ** 2, axis=1)))), "d2": d2.tolist()}


def _cell(model, Qw: np.ndarray):
    """A cell of the benchmark's robot, tracker, nests, TCP, noise and working configurations, free of obstacles,
    robot capsules and the incidence limit (the candidates are drawn without them), for the IPOPT design."""
    import pinocchio as pin

    from pin_kpi_oed.cell.cell import cell_from_dict

    T = model.tracker_T_base.inverse()  # the tracker in the base frame (the cell frame here)
    d = {"name": "ur5_nests", "robot": "ur5", "tool_frame": "tool0",
         "tracker": {"xyz_m": T.translation.tolist(), "rpy_deg": np.degrees(pin.rpy.matrixToRpy(T.rotation)).tolist()},
         "reflector_m": NESTS_M[0].tolist(), "nests_m": NESTS_M.tolist(), "tcp_m": TCP_M.tolist(),
         "noise": {"sigma_xyz_m": [NOISE_M] * 3}, "incidence_max_deg": 180.0, "robot_capsules": [],
         "working_configurations_rad": Qw.tolist(), "measurements": 35}
    return cell_from_dict(d, "benchmarks/nests.py")


def _alternate(model, Qd: np.ndarray, Qw: np.ndarray, seed: int) -> tuple:
    """The design over pose × nest from the assign-after design's poses (module docstring): (poses, nests, result)."""
    from pin_kpi_oed.design.ipopt import ipopt_options
    from pin_kpi_oed.design.nest_design import alternate_nests
    from pin_kpi_oed.design.optimize import DesignProblem

    problem = DesignProblem(_cell(model, Qw))
    res = alternate_nests(problem, Qd, seed=seed, options=ipopt_options(max_iter=200))
    return res.q_meas, res.nest, res


def run_one(seed: int, alternate: bool = False) -> dict:
    """One seed (module docstring): the figures with one nest, with the design's nests and (``alternate``) with
    the design over pose × nest."""
    from benchmarks.unshipped_robots import true_point
    from pin_kpi_oed.calibrated.tcp_sigma import tcp_sigma
    from pin_kpi_oed.compensation.compensator import forward
    from pin_kpi_oed.effects.joint_angle import GearHarmonic
    from pin_kpi_oed.identification.identify import identify
    from pin_kpi_oed.model.noise import NoiseModel
    from pin_kpi_oed.model.robot import load_robot
    from pin_kpi_oed.model.tolerances import Tolerances
    from pin_kpi_oed.model.tracker import TrackerModel
    from pin_kpi_oed.oed.identifiability import analyse
    from pin_kpi_oed.oed.nests import assign_nests
    from pin_kpi_oed.oed.objective import DesignCriterion
    from pin_kpi_oed.simulation.simulator import default_tracker_pose, random_truth, simulate

    t0 = time.perf_counter()
    rb = load_robot("ur5")
    noise = NoiseModel(sigma_xyz_m=(NOISE_M,) * 3)
    model = TrackerModel(rb, tracker_T_base=default_tracker_pose(rb), reflector_m=NESTS_M[0], tcp_m=TCP_M,
                         noise=noise, nests_m=NESTS_M)
    rng = np.random.default_rng(seed)
    base = analyse(model, Q=rb.random_q(rng, 60)).base
    pool, Qw = rb.random_q(rng, 400), rb.random_q(rng, 5)
    E = model.kpi_jacobian(np.zeros(model.n_params), Qw)[:, base]
    Qd = pool[DesignCriterion(model, base, "kpi", E).select(pool, 35, seed=seed).indices]
    chosen = assign_nests(model, Qd, Qw, seed=seed)
    p = random_truth(model, Tolerances(5e-4, 1e-3, reflector_m=1e-3), seed=seed)
    eff = GearHarmonic(rb)
    theta = rng.normal(size=len(eff.param_names(rb))) * 5e-5
    Qt = rb.random_q(rng, 40)
    e_true = true_point((model, p, [(eff, theta)]), TCP_M, Qt)
    nominal = TrackerModel(rb, reflector_m=NESTS_M[0], tcp_m=TCP_M, noise=noise, nests_m=NESTS_M)
    out: dict = {"seed": seed, "design_line": chosen.line(), "n_nest1": int(np.sum(chosen.nest == 1)),
                 "trace_one_mm2": chosen.one.total_m2 * 1e6, "trace_two_mm2": chosen.chosen.total_m2 * 1e6}
    arms = [("one", Qd, np.zeros(len(Qd), int)), ("two", Qd, chosen.nest)]
    if alternate:
        Qa, na, res = _alternate(model, Qd, Qw, seed)
        arms.append(("alt", Qa, na))
        from pin_kpi_oed.oed.nests import nest_trace

        ident = [nest_trace(model, Q_, n_, Qw, seed=seed).identified_m2 * 1e6 for Q_, n_ in ((Qd, chosen.nest),
                                                                                            (Qa, na))]
        out.update(trace_alt_mm2=res.trace_m2 * 1e6, trace_alt_start_mm2=res.start_trace_m2 * 1e6,
                   identified_two_mm2=ident[0], identified_alt_mm2=ident[1],
                   alt_rounds=res.nit, alt_feasible=bool(res.success), n_nest1_alt=int(np.sum(na == 1)))
    for arm, Q_arm, nest in arms:
        train = simulate(model, Q_arm, p, [(eff, theta)], seed=seed + 1, nest=nest)
        cm = identify(nominal, train, Q_work=Qt).calibrated_model()
        at = tcp_sigma(cm, Qt, TCP_M)
        out[arm] = _stats(e_true - forward(cm, Qt, frame="cell", tcp_m=TCP_M), at.covariance_m2)
    out["time_s"] = time.perf_counter() - t0
    return out


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark; print one line per seed, the pooled honesty and the paired comparison."""
    from pin_kpi_oed.studies.paired import paired_comparison, paired_text

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=0, help="first seed")
    ap.add_argument("--seeds", type=int, default=10, help="number of seeds (seed, seed+1, ...)")
    ap.add_argument("--alternate", action="store_true", help="also the design over pose x nest (the alt arm)")
    ap.add_argument("--json", default=None, help="write the figures here")
    args = ap.parse_args(argv)
    rows = []
    print("seed  nest-1 poses | one nest: sigma, error (mm), z, in95 | design's nests: sigma, error (mm), z, in95")
    for s in range(args.seed, args.seed + args.seeds):
        r = run_one(s, args.alternate)
        rows.append(r)
        f = "{:6.3f} {:6.3f} {:5.2f} {:4.0%}".format
        one, two = r["one"], r["two"]
        print(f"{s:4d}  {r['n_nest1']:3d}/35 | {f(one['sigma_m'] * 1e3, one['error_m'] * 1e3, one['z'], one['in95'])}"
              f" | {f(two['sigma_m'] * 1e3, two['error_m'] * 1e3, two['z'], two['in95'])}   ({r['time_s']:.0f} s)",
              flush=True)
        if args.alternate:
            a = r["alt"]
            print(f"      alt: tr(C_s) {r['trace_alt_start_mm2']:.6g} -> {r['trace_alt_mm2']:.6g} mm^2 (identified "
                  f"part {r['identified_two_mm2']:.4g} -> {r['identified_alt_mm2']:.4g}) in {r['alt_rounds']} rounds, "
                  f"{r['n_nest1_alt']}/35 at nest 1, feasible {r['alt_feasible']} | "
                  f"{f(a['sigma_m'] * 1e3, a['error_m'] * 1e3, a['z'], a['in95'])}", flush=True)
    print(rows[0]["design_line"])
    arms = ("one", "two", "alt") if args.alternate else ("one", "two")
    for arm in arms:
        d2 = np.concatenate([r[arm]["d2"] for r in rows])
        print(f"pooled {arm}: standardised RMS {np.sqrt(np.mean(d2) / 3):.2f}, inside 95 % "
              f"{np.mean(d2 <= CHI2_3_95):.0%} ({len(d2)} rows)")
    if args.alternate:
        c = paired_comparison([r["identified_alt_mm2"] for r in rows], [r["identified_two_mm2"] for r in rows])
        print(f"pose x nest vs assign-after, identified part of tr(C_s): {paired_text(c)}")
    for what in ("sigma_m", "error_m"):
        c = paired_comparison([r["two"][what] for r in rows], [r["one"][what] for r in rows])
        print(f"two nests vs one, {what}: {paired_text(c)}")
        if args.alternate:
            c = paired_comparison([r["alt"][what] for r in rows], [r["two"][what] for r in rows])
            print(f"pose x nest vs assign-after, {what}: {paired_text(c)}")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
