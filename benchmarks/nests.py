"""One reflector nest or two chosen by the design: the σ at the TCP against the realised TCP errors.

Per seed (a UR5 of example-robot-data):

1. two nests on the tool: nest 0 on the last joint's axis at the flange, nest 1 0.06 m off the axis and 0.05 m out;
   the TCP 0.15 m out along the axis (0.15 m from nest 0); 35 poses chosen by the ``kpi`` criterion at nest 0 from
   400 random candidates for the TCP at 5 working configurations; the nest of each pose chosen by the TCP's tr C_s
   (:func:`pin_kpi_oed.oed.nests.assign_nests`), against every pose at nest 0 (the same poses);
2. a true robot with errors on EVERY joint parameter (0.5 mm, 1 mrad: also those no reflector measurement sees),
   the nests' shared offset 1 mm off nominal, and an unmodelled gear harmonic (σ 50 µrad per coefficient),
   measured at the designed poses at their nests (tracker noise 25 µm per axis);
3. ``identify`` with default options on each design's rows (the ``nest`` column);
4. at 40 held-out random configurations, the true TCP (the simulated robot's point, effects included, true tracker
   frame) − the calibrated model's TCP against the one σ at the TCP (``tcp_sigma``): standardised RMS
   sqrt(mean(eᵀ C⁻¹ e) / 3) and the share inside the 95 % ellipsoid, per seed and pooled; the σ (RMS over the
   rows of sqrt(tr C)) and the realised error (RMS |e|) of two nests against one, paired over the seeds (median of
   the ratios, sign test: :func:`pin_kpi_oed.studies.paired.paired_comparison`).

Run: ``python -m benchmarks.nests --seed 0 --seeds 10 [--json out.json]``.
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


def run_one(seed: int) -> dict:
    """One seed (module docstring): the figures with one nest and with the design's nests."""
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
    for arm, nest in (("one", np.zeros(len(Qd), int)), ("two", chosen.nest)):
        train = simulate(model, Qd, p, [(eff, theta)], seed=seed + 1, nest=nest)
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
    ap.add_argument("--json", default=None, help="write the figures here")
    args = ap.parse_args(argv)
    rows = []
    print("seed  nest-1 poses | one nest: sigma, error (mm), z, in95 | design's nests: sigma, error (mm), z, in95")
    for s in range(args.seed, args.seed + args.seeds):
        r = run_one(s)
        rows.append(r)
        f = "{:6.3f} {:6.3f} {:5.2f} {:4.0%}".format
        one, two = r["one"], r["two"]
        print(f"{s:4d}  {r['n_nest1']:3d}/35 | {f(one['sigma_m'] * 1e3, one['error_m'] * 1e3, one['z'], one['in95'])}"
              f" | {f(two['sigma_m'] * 1e3, two['error_m'] * 1e3, two['z'], two['in95'])}   ({r['time_s']:.0f} s)",
              flush=True)
    print(rows[0]["design_line"])
    for arm in ("one", "two"):
        d2 = np.concatenate([r[arm]["d2"] for r in rows])
        print(f"pooled {arm}: standardised RMS {np.sqrt(np.mean(d2) / 3):.2f}, inside 95 % "
              f"{np.mean(d2 <= CHI2_3_95):.0%} ({len(d2)} rows)")
    for what in ("sigma_m", "error_m"):
        c = paired_comparison([r["two"][what] for r in rows], [r["one"][what] for r in rows])
        print(f"two nests vs one, {what}: {paired_text(c)}")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
