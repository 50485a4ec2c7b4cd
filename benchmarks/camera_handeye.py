"""A camera on the tool (eye-in-hand) seeing a chessboard: KPI-designed poses against random ones, the σ at the TCP
and the hand-eye transform against OpenCV's ``calibrateHandEye``, on robots whose truth is not the package's model.

Per robot (a UR5; the Panda with ``--robots ur5,panda``) and seed:

1. the set-up: an 8 x 6 board of 25 mm squares on the table, a camera (1200 px focal length, 1280 x 1024 px, OpenCV
   distortion known from a separate intrinsic calibration) 5 cm beside the flange looking along the tool axis, the
   TCP 0.15 m out along it; 0.2 px noise per corner coordinate;
2. a pool of 600 configurations around a looking-down configuration in which the whole board is seen (every corner
   20 px inside the image, 0.15-2 m away, viewing angle <= 60 deg: the board-in-view constraint as a pool filter);
   5 working configurations drawn from the same region (the KPI: the TCP in the board frame there);
3. 15 poses chosen by the package's ``kpi`` criterion on the camera's information matrix, against 15 random poses
   of the same pool (seeded);
4. a true robot with errors on EVERY joint parameter (0.5 mm, 1 mrad), the hand-eye transform 2 mm / 10 mrad and the
   board 5 mm / 20 mrad off their nominal values, and an unmodelled gear harmonic (joint-angle errors a sin q +
   b cos q + c sin 2q + d cos 2q, sigma 50 urad); images simulated at the chosen poses;
5. ``fit_camera`` from the nominal model; the sigma at the TCP C_s = E C_p E^T + G Sigma_N G^T (the parameters held
   at nominal with their tolerances), the realised TCP error (true TCP, gear harmonic included, minus the
   calibrated model's), the standardised RMS sqrt(mean(e^T C^-1 e) / 3) pooled over robots (honest: 0.67-1.5);
6. the hand-eye transform tool_T_camera from the fit and from ``cv2.calibrateHandEye`` (Tsai, Park, Daniilidis) on
   the same images (board poses by ``cv2.solvePnP``, flange poses by the nominal forward kinematics, which is what
   the robot reports), against two truths: the physical one (the camera on the true flange) and the one of the
   identifiable parameterisation (the physical robot re-expressed with the parameters the camera cannot see held at
   nominal: the last joint's placement across its axis moves into the hand-eye transform; found by fitting the
   geometric truth, noise- and harmonic-free, at 100 poses, residual printed).

Paired over the seeds (median of the per-robot ratios, sign test: :mod:`pin_kpi_oed.studies.paired`).

Run: ``python -m benchmarks.camera_handeye --seeds 10 [--seed 0] [--robots ur5,panda] [--json out.json]``
(``--summary out.json`` prints the summary of an earlier run again).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import pinocchio as pin

CHI2_3_95 = 7.8147
#: a configuration of each robot whose tool axis points down at the table, and the board's centre below it (m)
LOOK_DOWN = {"ur5": (np.array([0.0, -1.57, 1.57, -1.57, -1.57, 0.0]), np.array([0.5, 0.1, 0.0])),
             "panda": (np.array([0.0, 0.0, 0.0, -1.8, 0.0, 1.8, 0.785]), None)}
METHODS = ("TSAI", "PARK", "DANIILIDIS")


def set_up(name: str):
    """The nominal eye-in-hand camera model of a robot and its looking-down configuration."""
    from pin_kpi_oed.model.camera import Board, CameraModel, Intrinsics
    from pin_kpi_oed.model.kinematics import Chain
    from pin_kpi_oed.model.robot import load_robot

    rb = load_robot(name)
    q0, centre = LOOK_DOWN[name]
    if centre is None:  # below the tool at the looking-down configuration, on the table
        tool = Chain.from_robot(rb).tool_point(q0[None], np.zeros(3)).p[0]
        centre = np.array([tool[0], tool[1], tool[2] - 0.45])
    board = Board(6, 8, 0.025)
    corner0 = centre - np.array([0.5 * (board.cols - 1), 0.5 * (board.rows - 1), 0.0]) * board.square_m
    intr = Intrinsics(1200.0, 1200.0, 640.0, 512.0, np.array([-0.1, 0.05, 1e-3, -5e-4, 0.01]))
    cam = pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, 0.3), np.array([0.05, 0.0, 0.03]))
    return CameraModel(rb, intr, board, mode="eye_in_hand", camera_pose=cam,
                       board_pose=pin.SE3(np.eye(3), corner0).inverse(), tcp_m=np.array([0.0, 0.0, 0.15])), q0


def feasible(model, q0: np.ndarray, n: int, rng: np.random.Generator, spread: float = 0.7) -> np.ndarray:
    """n configurations around q0, within the joint limits, seeing the whole board (module docstring)."""
    out: list[np.ndarray] = []
    lo, hi = model.robot.q_lower, model.robot.q_upper
    while sum(len(o) for o in out) < n:
        Q = np.clip(q0 + rng.uniform(-spread, spread, (20 * n, len(q0))), lo, hi)
        out.append(Q[model.in_view(np.zeros(model.n_params), Q)])
    return np.concatenate(out)[:n]


def truth(model, rng: np.random.Generator) -> np.ndarray:
    """The true raw parameters: every joint placement, the hand-eye transform and the board off nominal."""
    from pin_kpi_oed.model.tolerances import Tolerances

    p = rng.normal(size=model.n_params) * Tolerances(5e-4, 1e-3).sigma_vector(model)
    L = model.layout
    for g, t, r in (("camera", 2e-3, 1e-2), ("board", 5e-3, 2e-2)):
        s = L.group_slice(g)
        p[s] = rng.normal(size=6) * np.array([t, t, t, r, r, r])
    return p


def opencv_hand_eye(model, Q: np.ndarray, uv: np.ndarray) -> dict[str, pin.SE3]:
    """The hand-eye transform by ``cv2.calibrateHandEye`` (each method) from the images, solvePnP per image and the
    nominal flanges: tool_T_camera (eye-in-hand), or camera_T_base (eye-to-hand: the flange poses inverted, OpenCV's
    eye-to-hand use)."""
    import cv2

    from pin_kpi_oed.model.kinematics import Chain

    kin = Chain.from_robot(model.robot).tool_point(Q, np.zeros(3))
    obj = model.board.corners()
    K, dist = model.intrinsics.matrix(), model.intrinsics.dist
    Rt, tt = [], []
    for i in range(len(Q)):
        ok, rvec, tvec = cv2.solvePnP(obj, uv[i].reshape(-1, 1, 2), K, dist, flags=cv2.SOLVEPNP_ITERATIVE)
        if not ok:
            raise RuntimeError(f"solvePnP failed on image {i}")
        Rt.append(cv2.Rodrigues(rvec)[0])
        tt.append(tvec.ravel())
    if model.eye_in_hand:
        Rg, tg = list(kin.R_tool), list(kin.p)
    else:
        Rg = [R.T for R in kin.R_tool]
        tg = [-R.T @ p for R, p in zip(kin.R_tool, kin.p)]
    out = {}
    for m in METHODS:
        R, t = cv2.calibrateHandEye(Rg, tg, Rt, tt, method=getattr(cv2, f"CALIB_HAND_EYE_{m}"))
        T = pin.SE3(R, t.ravel())
        out[m] = T if model.eye_in_hand else T.inverse()  # eye-to-hand: OpenCV returns base_T_camera
    return out


def pose_error(a: pin.SE3, b: pin.SE3) -> tuple[float, float]:
    """(translation error mm, rotation error mrad) of a against b."""
    d = a.inverse() * b
    return float(np.linalg.norm(a.translation - b.translation) * 1e3), float(np.linalg.norm(pin.log3(d.rotation)) * 1e3)


def run_design(model, base, Q, p, eff, theta, Qw, rng, held, sig_held) -> dict:
    """Images at Q, the fit, its TCP error and σ at Qw, its and OpenCV's hand-eye transform."""
    from pin_kpi_oed.identification.camera_fit import camera_tcp_covariance, fit_camera

    uv = model.predict(p, Q + eff.joint_offset(theta, Q)[0])
    uv = uv + rng.normal(scale=model.sigma_px, size=uv.shape)
    fit = fit_camera(model, Q, uv, base)
    e = model.kpi(p, Qw + eff.joint_offset(theta, Qw)[0]) - model.kpi(fit.p, Qw)
    Cs, Ch = camera_tcp_covariance(model, fit, Q, Qw, held, sig_held)
    d2 = np.einsum("ma,ma->m", e, np.linalg.solve(Cs, e[:, :, None])[:, :, 0])
    return {"tcp_error_mm": float(np.sqrt(np.mean(np.sum(e ** 2, axis=1))) * 1e3),
            "tcp_sigma_mm": float(np.sqrt(np.mean(np.trace(Cs, axis1=1, axis2=2))) * 1e3),
            "held_sigma_mm": float(np.sqrt(np.mean(np.trace(Ch, axis1=1, axis2=2))) * 1e3),
            "d2": d2.tolist(), "rms_px": fit.rms_px, "chi2": fit.chi2_reduced, "success": fit.success,
            "hand_eye": model.hand_eye(fit.p), "opencv": opencv_hand_eye(model, Q, uv)}


def run_one(name: str, seed: int) -> dict:
    """One robot and seed (module docstring)."""
    from pin_kpi_oed.effects.joint_angle import GearHarmonic
    from pin_kpi_oed.identification.camera_fit import fit_camera
    from pin_kpi_oed.model.tolerances import Tolerances, held_columns
    from pin_kpi_oed.oed.identifiability import analyse
    from pin_kpi_oed.oed.objective import DesignCriterion

    t0 = time.perf_counter()
    model, q0 = set_up(name)
    rng = np.random.default_rng(seed)
    pool = feasible(model, q0, 600, rng)
    Qw = feasible(model, q0, 5, rng)
    ident = analyse(model, Q=pool[:40])
    base = ident.base
    E = model.kpi_jacobian(np.zeros(model.n_params), Qw)[:, base]
    Q_kpi = pool[DesignCriterion(model, base, "kpi", E).select(pool, 15, seed=seed).indices]
    Q_rnd = pool[rng.choice(len(pool), 15, replace=False)]
    p = truth(model, rng)
    eff = GearHarmonic(model.robot)
    theta = rng.normal(size=len(eff.param_names(model.robot))) * 5e-5
    held = held_columns(model, base)
    sig_held = Tolerances(5e-4, 1e-3).sigma_vector(model)[held]
    # the truth of the identifiable parameterisation: the geometric truth re-expressed with the held ones nominal
    Qbig = pool[-100:]
    conv = fit_camera(model, Qbig, model.predict(p, Qbig), base, max_nfev=200)
    out = {"robot": name, "seed": seed, "conv_rms_px": conv.rms_px}
    truths = {"physical": model.hand_eye(p), "identifiable": model.hand_eye(conv.p)}
    for design, Q in (("kpi", Q_kpi), ("random", Q_rnd)):
        r = run_design(model, base, Q, p, eff, theta, Qw, np.random.default_rng(seed + 1), held, sig_held)
        for tname, T in truths.items():
            r[f"he_{tname}"] = pose_error(r["hand_eye"], T)
            for m, Tm in r["opencv"].items():
                r[f"cv_{m}_{tname}"] = pose_error(Tm, T)
        del r["hand_eye"], r["opencv"]
        out[design] = r
    out["time_s"] = time.perf_counter() - t0
    return out


def summarise(rows: list[dict]) -> None:
    """The paired comparisons and the pooled standardised RMS."""
    from pin_kpi_oed.studies.paired import paired_comparison, paired_text

    def col(design, key, i=None):
        return np.array([r[design][key] if i is None else r[design][key][i] for r in rows])

    def identified(design):  # the design's part of the TCP sigma, E C_p E^T (tr C_s = tr of it + tr of the held)
        return np.sqrt(col(design, "tcp_sigma_mm") ** 2 - col(design, "held_sigma_mm") ** 2)

    for key, a, b in (("tcp_sigma_mm", col("kpi", "tcp_sigma_mm"), col("random", "tcp_sigma_mm")),
                      ("identified part", identified("kpi"), identified("random")),
                      ("tcp_error_mm", col("kpi", "tcp_error_mm"), col("random", "tcp_error_mm"))):
        c = paired_comparison(a, b)
        print(f"{key:15s} kpi {c['median_a']:.4f} vs random {c['median_b']:.4f} (medians); kpi/random: "
              f"{paired_text(c)}")
    for design in ("kpi", "random"):
        d2 = np.concatenate([r[design]["d2"] for r in rows])
        print(f"TCP sigma honesty ({design}): standardised RMS {np.sqrt(np.mean(d2) / 3):.2f}, inside 95 % "
              f"{np.mean(d2 <= CHI2_3_95):.0%} ({len(d2)} TCP points); median held part "
              f"{np.median(col(design, 'held_sigma_mm')):.4f} mm of {np.median(col(design, 'tcp_sigma_mm')):.4f} mm")
    for truth_name in ("identifiable", "physical"):
        for design in ("kpi", "random"):
            for i, what in ((0, "translation mm"), (1, "rotation mrad")):
                ours = col(design, f"he_{truth_name}", i)
                cvs = {m: col(design, f"cv_{m}_{truth_name}", i) for m in METHODS}
                best = min(cvs, key=lambda m: np.median(cvs[m]))
                c = paired_comparison(ours, cvs[best])
                print(f"hand-eye vs {truth_name:12s} truth, {design:6s} poses, {what:14s}: ours "
                      f"{np.median(ours):.4f}, OpenCV " + ", ".join(f"{m} {np.median(v):.4f}" for m, v in cvs.items())
                      + f" (medians); ours/{best}: {paired_text(c)}")


def summarise_file(path: str) -> None:
    """The summary of a ``--json`` file written before."""
    rows = json.loads(Path(path).read_text())
    for name in dict.fromkeys(r["robot"] for r in rows):
        print(f"--- {name}")
        summarise([r for r in rows if r["robot"] == name])


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark; one line per robot and seed, then the paired summary."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=0, help="first seed")
    ap.add_argument("--seeds", type=int, default=10, help="number of seeds (robots with errors) per robot type")
    ap.add_argument("--robots", default="ur5")
    ap.add_argument("--json", default=None, help="write the figures here")
    ap.add_argument("--summary", default=None, help="only summarise this --json file of an earlier run")
    args = ap.parse_args(argv)
    if args.summary:
        summarise_file(args.summary)
        return 0
    rows = []
    print("robot  seed | TCP sigma / error mm: kpi | random | hand-eye error (mm, mrad) vs identifiable truth: "
          "ours kpi, Tsai kpi | fit RMS px, chi2 | re-expression RMS px")
    for name in args.robots.split(","):
        for s in range(args.seed, args.seed + args.seeds):
            r = run_one(name, s)
            rows.append(r)
            k, q = r["kpi"], r["random"]
            print(f"{name:6s} {s:4d} | {k['tcp_sigma_mm']:.4f} / {k['tcp_error_mm']:.4f} | {q['tcp_sigma_mm']:.4f} / "
                  f"{q['tcp_error_mm']:.4f} | ({k['he_identifiable'][0]:.3f}, {k['he_identifiable'][1]:.3f}) "
                  f"({k['cv_TSAI_identifiable'][0]:.3f}, {k['cv_TSAI_identifiable'][1]:.3f}) | {k['rms_px']:.3f}, "
                  f"{k['chi2']:.2f} | {r['conv_rms_px']:.1e}  ({r['time_s']:.0f} s)", flush=True)
    for name in dict.fromkeys(r["robot"] for r in rows):
        print(f"--- {name}")
        summarise([r for r in rows if r["robot"] == name])
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
