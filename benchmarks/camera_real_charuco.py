"""Real images: the hand-eye calibration of a static camera seeing a ChArUco board on a robot's tool, on the test data
industrial_calibration ships (github.com/ros-industrial/industrial_calibration, Apache-2.0,
``examples/data/test_set_charuco``: 16 images 1600 x 1200 px, the tool poses in the robot base, a 7 x 5 ChArUco board
of 36.195 mm squares, DICT_6X6_250, the camera's calibrated intrinsics without distortion).

The data give the tool poses, not joint values: the robot is held as the data state it, and the fit is the camera
model's reprojection error over the set-up alone (camera_T_base and tool_T_board, 12 parameters), with the package's
projection (:func:`pin_kpi_oed.model.camera.project`, OpenCV's model) and corners (:func:`detect_corners`). Compared:

* intrinsics: the data's (theirs) against ``cv2.calibrateCamera`` on our detected corners (with distortion);
* hand-eye: ``cv2.calibrateHandEye`` (Tsai, Park, Daniilidis; eye-to-hand: the base-to-tool poses in, camera-to-base
  out; the board on the tool from the per-image PnP poses, averaged) against the reprojection fit started from the
  best of them; every solution scored by the same reprojection RMS over every detected corner (px).

industrial_calibration's own test asserts a final RMS below 1.5 px on these images (``examples/extrinsic_hand_eye.cpp``,
``ChArUcoGridTarget``: ``sqrt(final_cost_per_obs) < 1.5``).

Run: ``python -m benchmarks.camera_real_charuco PATH/test_set_charuco [--json out.json]`` (the images are read from
the given folder; they are not part of this repository).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pinocchio as pin

METHODS = ("TSAI", "PARK", "DANIILIDIS")


def load(folder: Path):
    """(images' grey arrays, base_T_tool per image, the data's intrinsics (9,), the board and its ChArUco fields)."""
    import cv2
    import yaml

    from pin_kpi_oed.model.camera import Board

    cfg = yaml.safe_load((folder / "cal_data.yaml").read_text())
    tf = cfg["target_finder"]
    names = {10: "DICT_6X6_250"}
    board = Board(int(tf["rows"]) - 1, int(tf["cols"]) - 1, float(tf["chessboard_dim"]))
    images, poses = [], []
    for item in cfg["data"]:
        images.append(cv2.imread(str(folder / item["image"]), cv2.IMREAD_GRAYSCALE))
        p = yaml.safe_load((folder / item["pose"]).read_text())
        q = pin.Quaternion(p["qw"], p["qx"], p["qy"], p["qz"]).normalized()
        poses.append(pin.SE3(q.matrix(), np.array([p["x"], p["y"], p["z"]])))
    k = cfg["intrinsics"]
    intr = np.array([k["fx"], k["fy"], k["cx"], k["cy"], 0.0, 0.0, 0.0, 0.0, 0.0])
    return images, poses, intr, board, float(tf["aruco_marker_dim"]), names[int(tf["dictionary"])]


def corners(images, board, marker, dictionary):
    """Per image (ids, uv) of the detected ChArUco corners."""
    from pin_kpi_oed.model.board_detection import detect_corners

    return [detect_corners(img, board, "charuco", marker, dictionary) for img in images]


def calibrate_intrinsics(det, board, size):
    """cv2.calibrateCamera on the images with at least 6 corners: (intrinsics (9,), its RMS px)."""
    import cv2

    obj = [board.corners()[i].astype(np.float32) for i, _ in det if len(i) >= 6]
    img = [uv.astype(np.float32) for i, uv in det if len(i) >= 6]
    rms, K, dist, _, _ = cv2.calibrateCamera(obj, img, size, None, None)
    return np.r_[K[0, 0], K[1, 1], K[0, 2], K[1, 2], dist.ravel()[:5]], float(rms)


def reprojection(C: pin.SE3, B: pin.SE3, poses, det, board, k) -> np.ndarray:
    """Residuals (px) of every detected corner: camera_T_base C, tool_T_board B, base_T_tool per image."""
    from pin_kpi_oed.model.camera import project

    out = []
    for T, (ids, uv) in zip(poses, det):
        if len(ids) == 0:
            continue
        M = C * T * B
        X = board.corners()[ids] @ M.rotation.T + M.translation
        out.append((project(X, k)[0] - uv).ravel())
    return np.concatenate(out)


def handeye_cv2(poses, det, board, k, method: str) -> tuple[pin.SE3, pin.SE3]:
    """(camera_T_base, tool_T_board) of cv2.calibrateHandEye (eye-to-hand) and the averaged board on the tool."""
    import cv2

    K = np.array([[k[0], 0, k[2]], [0, k[1], k[3]], [0, 0, 1.0]])
    Rb, tb, Rt, tt, used = [], [], [], [], []
    for i, (T, (ids, uv)) in enumerate(zip(poses, det)):
        if len(ids) < 6:
            continue
        ok, rv, tv = cv2.solvePnP(board.corners()[ids], uv, K, k[4:])
        if not ok:
            continue
        Ti = T.inverse()
        Rb.append(Ti.rotation)
        tb.append(Ti.translation)
        Rt.append(cv2.Rodrigues(rv)[0])
        tt.append(tv.ravel())
        used.append(i)
    R, t = cv2.calibrateHandEye(Rb, tb, Rt, tt, method=getattr(cv2, f"CALIB_HAND_EYE_{method}"))
    base_T_cam = pin.SE3(R, t.ravel())
    tool_T_board = [poses[i].inverse() * base_T_cam * pin.SE3(Rt[j], tt[j]) for j, i in enumerate(used)]
    U, _, Vt = np.linalg.svd(sum(M.rotation for M in tool_T_board))
    Rm = U @ np.diag([1, 1, np.linalg.det(U @ Vt)]) @ Vt
    B = pin.SE3(Rm, np.mean([M.translation for M in tool_T_board], axis=0))
    return base_T_cam.inverse(), B


def handeye_fit(C0: pin.SE3, B0: pin.SE3, poses, det, board, k) -> tuple[pin.SE3, pin.SE3]:
    """The reprojection fit over camera_T_base and tool_T_board (right perturbations exp6), from (C0, B0)."""
    from scipy.optimize import least_squares

    def fun(x):
        return reprojection(C0 * pin.exp6(x[:6]), B0 * pin.exp6(x[6:]), poses, det, board, k)

    sol = least_squares(fun, np.zeros(12), method="lm", x_scale=np.r_[[0.01] * 3, [0.01] * 3, [0.01] * 3,
                                                                        [0.01] * 3])
    return C0 * pin.exp6(sol.x[:6]), B0 * pin.exp6(sol.x[6:])


def rms(r: np.ndarray) -> float:
    """RMS over the corners of the 2-D error (px): sqrt(mean(du² + dv²))."""
    return float(np.sqrt(np.mean(r.reshape(-1, 2) ** 2) * 2))


def their_metric(r: np.ndarray) -> float:
    """industrial_calibration's sqrt(final_cost_per_obs): Ceres' cost ½Σr² over the number of residuals (u and v
    each), i.e. the RMS per coordinate / sqrt(2) (px)."""
    return float(np.sqrt(0.5 * np.mean(r ** 2)))


def homography_filter(det, board, threshold_px: float = 2.0):
    """industrial_calibration's input check: an image whose corners a homography of the board plane reproduces with
    a mean error above ``threshold_px`` (their ``homography_threshold``) is left out (empty ids)."""
    import cv2

    out = []
    for ids, uv in det:
        if len(ids) >= 4:
            H, _ = cv2.findHomography(board.corners()[ids, :2], uv, 0)
            p = np.c_[board.corners()[ids, :2], np.ones(len(ids))] @ H.T
            if np.mean(np.linalg.norm(p[:, :2] / p[:, 2:] - uv, axis=1)) <= threshold_px:
                out.append((ids, uv))
                continue
        out.append((np.zeros(0, int), np.zeros((0, 2))))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", help="industrial_calibration's examples/data/test_set_charuco folder")
    ap.add_argument("--json", default=None, help="write the figures here")
    args = ap.parse_args(argv)
    images, poses, k_data, board, marker, dictionary = load(Path(args.folder))
    det = homography_filter(corners(images, board, marker, dictionary), board)
    n_corners = sum(len(i) for i, _ in det)
    k_ours, rms_intr = calibrate_intrinsics(det, board, images[0].shape[::-1])
    print(f"{len(images)} images, {sum(len(i) > 0 for i, _ in det)} with the board, {n_corners} corners")
    print(f"intrinsics by cv2.calibrateCamera on our corners: fx {k_ours[0]:.1f}, fy {k_ours[1]:.1f}, cx "
          f"{k_ours[2]:.1f}, cy {k_ours[3]:.1f} px, k1 {k_ours[4]:.3f}, k2 {k_ours[5]:.3f}; RMS {rms_intr:.3f} px "
          f"(in-sample; the data's: fx {k_data[0]:.1f}, fy {k_data[1]:.1f}, cx {k_data[2]:.1f}, cy {k_data[3]:.1f}, "
          "no distortion)")
    out: dict = {"n_images": len(images), "n_corners": n_corners, "intrinsics_ours": k_ours.tolist(),
                 "calibrate_camera_rms_px": rms_intr, "hand_eye": {}}
    for label, k in (("the data's intrinsics", k_data), ("our intrinsics", k_ours)):
        rows = {}
        for m in METHODS:
            C, B = handeye_cv2(poses, det, board, k, m)
            rows[m] = (rms(reprojection(C, B, poses, det, board, k)), C, B)
        best = min(rows, key=lambda m: rows[m][0])
        C, B = handeye_fit(rows[best][1], rows[best][2], poses, det, board, k)
        rows["reprojection fit"] = (rms(reprojection(C, B, poses, det, board, k)), C, B)
        theirs = their_metric(reprojection(C, B, poses, det, board, k))
        print(f"hand-eye with {label}: reprojection RMS 2-D (px) "
              + ", ".join(f"{m} {v[0]:.3f}" for m, v in rows.items())
              + f"; the fit's in industrial_calibration's measure sqrt(final_cost_per_obs) {theirs:.3f} px"
              + f"; camera in the base moved {np.linalg.norm((rows[best][1].inverse() * C).translation) * 1e3:.1f} mm "
                f"from {best}'s by the fit")
        out["hand_eye"][label] = {**{m: v[0] for m, v in rows.items()}, "fit_sqrt_cost_per_obs": theirs}
    print("industrial_calibration's own test on these images: final RMS < 1.5 px (examples/extrinsic_hand_eye.cpp)")
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
