"""Camera KPI designs that keep the board in view, against random feasible poses, on simulated robots whose truth
is not the package's model: the UR5 and the Panda, eye-in-hand and eye-to-hand.

Per set-up and seed (one simulated robot):

1. the set-up: an 8 x 6 board of 25 mm squares, a camera (1200 px focal length, 1280 x 1024 px, OpenCV distortion
   known from a separate intrinsic calibration), the TCP 0.15 m out along the tool axis, 0.2 px noise per corner
   coordinate. Eye-in-hand: the camera 5 cm beside the flange looking along the tool axis, the board on the table
   below the tool's looking-down configuration; eye-to-hand: the board 2 cm in front of the flange facing along the
   tool axis, the camera on the table 0.38 m below it looking up. The cell: the robot's capsules fitted to its
   URDF meshes (pairs overlapping at the looking-down configuration skipped: adjacent by construction), the table
   as a half-space; the view limits: every corner 20 px inside the image, depth 0.15-2 m, viewing angle <= 60 deg,
   the five rays camera -> board (4 outer corners, centre) clear of every link but the carrying one;
2. 5 working configurations (the KPI: the TCP in the device frame there) and a pool of feasible candidates
   sampled around them (``CameraDesignProblem.pool``: every constraint above satisfied);
3. 15 poses designed by the package (``design_camera``: the KPI pool selection with its certificate, then IPOPT with
   the camera's constraints), against 15 random candidates of the same pool (seeded);
4. a true robot with errors on EVERY joint parameter (0.5 mm, 1 mrad), the hand-eye transform 2 mm / 10 mrad and
   the board 5 mm / 20 mrad off nominal, and an unmodelled gear harmonic (sigma 50 urad per coefficient): the
   truth of ``benchmarks.camera_handeye``; images simulated at both designs' poses with the same noise seed;
5. ``fit_camera`` from the nominal model; the sigma at the TCP C_s = E C_p E^T + G Sigma_N G^T (the parameters no
   camera sees held at nominal with their tolerances: the held term, the same for every design up to its small
   dependence on the poses), the realised TCP error, the standardised RMS sqrt(mean(e^T C_s^-1 e) / 3) pooled
   over robots (honest: 0.67-1.5);
6. the hand-eye transform from the fit and from ``cv2.calibrateHandEye`` (Tsai, Park, Daniilidis) on the same
   images (board poses by ``cv2.solvePnP``, flange poses by the nominal forward kinematics), against the truth of
   the identifiable parameterisation (the geometric truth re-fitted noise- and harmonic-free at 100 poses with the
   held parameters nominal).

Paired over the seeds per set-up (median of the per-robot ratios designed/random, sign test:
:func:`pin_kpi_oed.studies.paired.paired_comparison`).

Measured (``--seeds 10 --pool 150 --max-iter 20``, 10 robots per set-up, ~30 s each; designed/random, paired
medians, sign test): the design's part of the TCP sigma -65 % (UR5 eye-in-hand), -56 % (UR5 eye-to-hand), -61 %
(Panda eye-in-hand), -59 % (Panda eye-to-hand), 10/10 wins each (p = 0.002); the total TCP sigma only -1.4 % to -5.7 %
(10/10 wins each), because 0.500 mm (UR5) / 0.508 mm (Panda) of it is the held term no camera sees (the TCP's
axial offset along the last joint); the realised TCP error -15 %, -8 %, -9 %, -12 % (8/10, 7/10, 9/10, 9/10 wins;
p 0.11, 0.34, 0.021, 0.021). Standardised RMS of the sigma 1.22 / 1.19 / 1.36 / 1.29 (designed) and 1.02 / 0.85 /
0.95 / 1.15 (random): inside 0.67-1.5, the designed poses' sigma somewhat optimistic (80-92 % of the TCP points
inside the 95 % ellipsoid). The hand-eye transform against the identifiable truth: 0.05-0.10 mm and 0.09-0.27 mrad
against OpenCV's best 0.83-1.68 mm and 1.8-3.5 mrad (10/10 wins each; OpenCV takes the nominal flange poses, so
the robot's own errors enter it). Every designed pose (600) passed the independent check.

Run: ``nice -n 10 python -m benchmarks.camera_design --seeds 10 [--setups ur5:eye_in_hand,...] [--json out.json]``
(``--summary out.json`` prints the summary of an earlier run).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import pinocchio as pin

from benchmarks.camera_handeye import CHI2_3_95, LOOK_DOWN, METHODS, opencv_hand_eye, pose_error, truth

SETUPS = ("ur5:eye_in_hand", "ur5:eye_to_hand", "panda:eye_in_hand", "panda:eye_to_hand")
M = 15


def set_up(name: str, mode: str):
    """(camera model, looking-down configuration, cell, view limits) of a robot and mounting (module docstring)."""
    from pin_kpi_oed.cell.camera_view import ViewLimits, camera_cell
    from pin_kpi_oed.cell.cell import capsules_from_urdf
    from pin_kpi_oed.cell.cell_model import HalfSpace
    from pin_kpi_oed.cell.collision import CollisionModel
    from pin_kpi_oed.model.camera import Board, CameraModel, Intrinsics
    from pin_kpi_oed.model.kinematics import Chain
    from pin_kpi_oed.model.robot import load_robot

    rb = load_robot(name)
    q0 = LOOK_DOWN[name][0]
    kin = Chain.from_robot(rb).tool_point(q0[None], np.zeros(3))
    tool, z_tool = kin.p[0], kin.R_tool[0][:, 2]
    board = Board(6, 8, 0.025)
    half = 0.5 * np.array([(board.cols - 1) * board.square_m, (board.rows - 1) * board.square_m, 0.0])
    intr = Intrinsics(1200.0, 1200.0, 640.0, 512.0, np.array([-0.1, 0.05, 1e-3, -5e-4, 0.01]))
    if mode == "eye_in_hand":
        centre = LOOK_DOWN[name][1] if LOOK_DOWN[name][1] is not None else tool - np.array([0.0, 0.0, 0.43])
        cam = pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, 0.3), np.array([0.05, 0.0, 0.03]))
        brd = pin.SE3(np.eye(3), centre - half).inverse()
        table = min(centre[2], 0.0) - 0.01
    else:  # the board faces along the tool axis; the camera 0.38 m in front of it, looking back at it
        brd = pin.SE3(np.eye(3), np.array([-half[0], -half[1], 0.02]))
        centre = tool + 0.02 * z_tool
        eye = centre + 0.38 * z_tool
        R = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), -z_tool).matrix()  # camera z to the board
        cam = pin.SE3(R, eye).inverse()
        table = min(eye[2] - 0.02, 0.0)
    model = CameraModel(rb, intr, board, mode=mode, camera_pose=cam, board_pose=brd, tcp_m=np.array([0.0, 0.0, 0.15]))
    tab = HalfSpace("table", np.array([0.0, 0.0, 1.0]), float(table))
    caps = capsules_from_urdf(rb)
    fixed = [(c.name, "table") for c in caps if rb.model.frames[rb.model.getFrameId(c.link)].parentJoint == 0]
    cell = camera_cell(rb, half_spaces=[tab], skip_pairs=fixed, capsules=caps)
    coll = CollisionModel(cell, collision=True, incidence=False, prune=False)
    g = coll.evaluate(q0[None], with_grad=False)[0]
    skip = [tuple(coll.names[i].split(":", 1)[1].split("|")) for i in np.flatnonzero(g < 0)
            if coll.names[i].startswith("robot:")]
    skip += [(n.split("@")[0], "table") for i, n in enumerate(coll.names) if "@table" in n and g[i] < 0]
    cell = camera_cell(rb, half_spaces=[tab], skip_pairs=fixed + skip, capsules=caps)
    return model, q0, cell, ViewLimits(margin_px=20.0, max_angle_deg=60.0, near_m=0.15, far_m=2.0)


def score(model, base, Q, p, eff, theta, Qw, seed, held, sig_held, he_truth) -> dict:
    """Images at Q (gear harmonic and 0.2 px noise), the fit, its TCP error and σ at Qw, the hand-eye errors."""
    from pin_kpi_oed.identification.camera_fit import camera_tcp_covariance, fit_camera

    rng = np.random.default_rng(seed)
    uv = model.predict(p, Q + eff.joint_offset(theta, Q)[0])
    uv = uv + rng.normal(scale=model.sigma_px, size=uv.shape)
    fit = fit_camera(model, Q, uv, base)
    e = model.kpi(p, Qw + eff.joint_offset(theta, Qw)[0]) - model.kpi(fit.p, Qw)
    Cs, Ch = camera_tcp_covariance(model, fit, Q, Qw, held, sig_held)
    d2 = np.einsum("ma,ma->m", e, np.linalg.solve(Cs, e[:, :, None])[:, :, 0])
    out = {"tcp_error_mm": float(np.sqrt(np.mean(np.sum(e ** 2, axis=1))) * 1e3),
           "tcp_sigma_mm": float(np.sqrt(np.mean(np.trace(Cs, axis1=1, axis2=2))) * 1e3),
           "held_sigma_mm": float(np.sqrt(np.mean(np.trace(Ch, axis1=1, axis2=2))) * 1e3),
           "d2": d2.tolist(), "rms_px": fit.rms_px, "chi2": fit.chi2_reduced,
           "he": pose_error(model.hand_eye(fit.p), he_truth)}
    for m, T in opencv_hand_eye(model, Q, uv).items():
        out[f"cv_{m}"] = pose_error(T, he_truth)
    return out


def run_one(setup: str, seed: int, pool_size: int, max_iter: int) -> dict:
    """One set-up and seed (module docstring)."""
    from pin_kpi_oed.design.camera_design import CameraDesignProblem, design_camera
    from pin_kpi_oed.design.ipopt import ipopt_options
    from pin_kpi_oed.effects.joint_angle import GearHarmonic
    from pin_kpi_oed.identification.camera_fit import fit_camera
    from pin_kpi_oed.model.tolerances import Tolerances, held_columns

    t0 = time.perf_counter()
    name, mode = setup.split(":")
    model, q0, cell, limits = set_up(name, mode)
    rng = np.random.default_rng(seed)
    seeing = CameraDesignProblem(cell, model, limits, q0[None])  # the working configurations: around q0
    Qw = seeing.pool(5, seed=seed + 1000, spread=0.5)[0]
    problem = CameraDesignProblem(cell, model, limits, Qw)
    d = design_camera(problem, M, seed=seed, pool_size=pool_size, ipopt_options=ipopt_options(max_iter=max_iter))
    Q_pool = d.certificate.Q_pool
    Q_rnd = Q_pool[rng.choice(len(Q_pool), M, replace=False)]
    base = problem.base
    p = truth(model, rng)
    eff = GearHarmonic(model.robot)
    theta = rng.normal(size=len(eff.param_names(model.robot))) * 5e-5
    held = held_columns(model, base)
    sig_held = Tolerances(5e-4, 1e-3).sigma_vector(model)[held]
    Qbig = problem.pool(100, seed=seed + 2000)[0]
    conv = fit_camera(model, Qbig, model.predict(p, Qbig), base, max_nfev=200)
    he_truth = model.hand_eye(conv.p)
    out = {"setup": setup, "seed": seed, "conv_rms_px": conv.rms_px, "n_base": int(base.size),
           "design": {"source": d.source, "efficiency": d.efficiency, "trace_cs_m2": d.trace_cs_m2,
                      "selection_trace_cs_m2": d.selection_trace_cs_m2,
                      "bound_trace_cs_m2": d.certificate.lower_bound_trace_cs_m2, "check_ok": int(d.check.ok.sum()),
                      "ipopt": d.ipopt.solver_status if d.ipopt else "", "time_s": d.time_s},
           "random_trace_cs_m2": problem.trace_cs(Q_rnd)}
    for key, Q in (("kpi", d.Q), ("random", Q_rnd)):
        out[key] = score(model, base, Q, p, eff, theta, Qw, seed + 1, held, sig_held, he_truth)
    out["time_s"] = time.perf_counter() - t0
    return out


def summarise(rows: list[dict]) -> None:
    """The paired comparisons, the honesty of the σ and the hand-eye errors of one set-up."""
    from pin_kpi_oed.studies.paired import paired_comparison, paired_text

    def col(design, key, i=None):
        return np.array([r[design][key] if i is None else r[design][key][i] for r in rows])

    def identified(design):  # the part the design controls: E C_p E^T (tr C_s = its trace + the held term's)
        return np.sqrt(np.maximum(col(design, "tcp_sigma_mm") ** 2 - col(design, "held_sigma_mm") ** 2, 0.0))

    for key, a, b in (("total TCP sigma", col("kpi", "tcp_sigma_mm"), col("random", "tcp_sigma_mm")),
                      ("design's part", identified("kpi"), identified("random")),
                      ("TCP error", col("kpi", "tcp_error_mm"), col("random", "tcp_error_mm"))):
        c = paired_comparison(a, b)
        print(f"  {key:16s} kpi {c['median_a']:.4f} mm vs random {c['median_b']:.4f} mm (medians); kpi/random: "
              f"{paired_text(c)}")
    print(f"  held term (no camera sees it): median {np.median(col('kpi', 'held_sigma_mm')):.4f} mm of the total "
          f"{np.median(col('kpi', 'tcp_sigma_mm')):.4f} mm (kpi)")
    for design in ("kpi", "random"):
        d2 = np.concatenate([r[design]["d2"] for r in rows])
        print(f"  honesty ({design:6s}): standardised RMS {np.sqrt(np.mean(d2) / 3):.2f}, inside 95 % "
              f"{np.mean(d2 <= CHI2_3_95):.0%} ({len(d2)} TCP points)")
    for i, what in ((0, "mm"), (1, "mrad")):
        ours = col("kpi", "he", i)
        cvs = {m: col("kpi", f"cv_{m}", i) for m in METHODS}
        best = min(cvs, key=lambda m: np.median(cvs[m]))
        c = paired_comparison(ours, cvs[best])
        print(f"  hand-eye ({what:4s}, kpi poses): ours {np.median(ours):.4f}, OpenCV "
              + ", ".join(f"{m} {np.median(v):.4f}" for m, v in cvs.items()) + f" (medians); ours/{best}: "
              + paired_text(c))
    eff = [r["design"]["efficiency"] for r in rows]
    src = [r["design"]["source"] for r in rows]
    print(f"  design: median efficiency {np.median(eff):.1%} of the pool's bound (IPOPT leaves the pool), "
          f"{src.count('ipopt')} of {len(rows)} from IPOPT; independent check "
          f"{sum(r['design']['check_ok'] for r in rows)} of {M * len(rows)} poses see the board")


def summarise_file(path: str) -> None:
    """The summary of a ``--json`` file written before."""
    rows = json.loads(Path(path).read_text())
    for s in dict.fromkeys(r["setup"] for r in rows):
        print(f"--- {s}")
        summarise([r for r in rows if r["setup"] == s])


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark; one line per set-up and seed, then the paired summary per set-up."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=0, help="first seed")
    ap.add_argument("--seeds", type=int, default=10, help="seeds (simulated robots) per set-up")
    ap.add_argument("--setups", default=",".join(SETUPS), help="robot:mounting, comma-separated")
    ap.add_argument("--pool", type=int, default=300, help="feasible candidates of the pool")
    ap.add_argument("--max-iter", type=int, default=60, help="IPOPT iterations")
    ap.add_argument("--json", default=None, help="write the figures here (after every robot)")
    ap.add_argument("--summary", default=None, help="only summarise this --json file of an earlier run")
    args = ap.parse_args(argv)
    if args.summary:
        summarise_file(args.summary)
        return 0
    from pin_kpi_oed.threads import limited_threads

    rows: list[dict] = []
    print("set-up              seed | TCP sigma / error mm: kpi | random | tr C_s kpi/random | efficiency, source | "
          "hand-eye mm: ours, Tsai")
    with limited_threads():
        for setup in args.setups.split(","):
            for s in range(args.seed, args.seed + args.seeds):
                r = run_one(setup, s, args.pool, args.max_iter)
                rows.append(r)
                k, q, d = r["kpi"], r["random"], r["design"]
                print(f"{setup:19s} {s:4d} | {k['tcp_sigma_mm']:.4f} / {k['tcp_error_mm']:.4f} | "
                      f"{q['tcp_sigma_mm']:.4f} / {q['tcp_error_mm']:.4f} | "
                      f"{d['trace_cs_m2'] / r['random_trace_cs_m2']:.3f} | {d['efficiency']:.0%}, {d['source']} | "
                      f"{k['he'][0]:.3f}, {k['cv_TSAI'][0]:.3f}  ({r['time_s']:.0f} s)", flush=True)
                if args.json:
                    Path(args.json).write_text(json.dumps(rows, indent=1))
    for s in dict.fromkeys(r["setup"] for r in rows):
        print(f"--- {s}")
        summarise([r for r in rows if r["setup"] == s])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
