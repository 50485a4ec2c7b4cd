"""The camera device: a pinhole camera with OpenCV's distortion seeing a chessboard, eye-in-hand and eye-to-hand.

Projection against OpenCV's ``projectPoints``, the parameter and joint derivatives against finite differences,
what the identifiability analysis says a camera sees (the scale from the board's size) and cannot see (the first
joint's placement aliased with the fixed frame, the last joint's with the hand-eye transform), and the fit on
the reprojection error with its covariance against Monte-Carlo.
"""

from __future__ import annotations

import cv2
import numpy as np
import pinocchio as pin
import pytest

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.identification.camera_fit import camera_tcp_covariance, fit_camera
from pin_kpi_oed.model.camera import Board, CameraModel, Intrinsics
from pin_kpi_oed.model.robot import load_robot
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.oed.identifiability import analyse, check_kpi

Q0 = np.array([0.0, -1.57, 1.57, -1.57, -1.57, 0.0])  # the UR5's tool looking down at the table


def _camera(mode: str = "eye_in_hand", **kw) -> CameraModel:
    """A UR5 with an 8 x 6 board of 25 mm squares on the table (eye-in-hand: a camera 5 cm beside the flange
    looking along the tool axis) or on the tool (eye-to-hand: a camera 1.2 m above the table looking down)."""
    intr = Intrinsics(1200.0, 1210.0, 640.0, 512.0, np.array([-0.1, 0.05, 1e-3, -5e-4, 0.01]))
    if mode == "eye_in_hand":
        cam = pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, 0.3), np.array([0.05, 0.0, 0.03]))
        brd = pin.SE3(np.eye(3), np.array([0.4125, 0.0375, 0.0])).inverse()
    else:
        cam = pin.SE3(pin.rpy.rpyToMatrix(np.pi, 0, 0), np.array([0.5, 0.1, 1.2])).inverse()
        brd = pin.SE3(pin.rpy.rpyToMatrix(np.pi, 0, 0), np.array([-0.0875, -0.0625, 0.02]))
    return CameraModel(load_robot("ur5"), intr, Board(6, 8, 0.025), mode=mode, camera_pose=cam, board_pose=brd,
                       tcp_m=np.array([0.0, 0.0, 0.15]), **kw)


def _poses(model: CameraModel, n: int, seed: int, spread: float = 0.6) -> np.ndarray:
    """n configurations around Q0 that see the whole board."""
    Q = Q0 + np.random.default_rng(seed).uniform(-spread, spread, (40 * n, 6))
    Q = Q[model.in_view(np.zeros(model.n_params), Q)]
    assert len(Q) >= n
    return Q[:n]


@pytest.mark.parametrize("mode", ["eye_in_hand", "eye_to_hand"])
def test_projection_matches_opencv(mode):
    cam = _camera(mode, estimate_intrinsics=True)
    rng = np.random.default_rng(1)
    p = rng.normal(scale=1e-3, size=cam.n_params)
    Q = _poses(cam, 4, 2)
    X = cam.camera_points(p, Q)
    k = cam.intrinsic_vector(p)
    K = np.array([[k[0], 0, k[2]], [0, k[1], k[3]], [0, 0, 1]])
    uv = cam.predict(p, Q).reshape(len(Q), -1, 2)
    for i in range(len(Q)):
        ref = cv2.projectPoints(X[i], np.zeros(3), np.zeros(3), K, k[4:])[0][:, 0]
        assert np.abs(uv[i] - ref).max() < 1e-9
    # and the camera-frame points are the board seen through the hand-eye chain, by Pinocchio's forward kinematics
    rb = cam.robot
    data = rb.model.createData()
    pin.framesForwardKinematics(rb.model, data, Q[0])
    T_bt = data.oMf[rb.tool_frame_id]
    p0 = np.zeros(cam.n_params)
    C, B = cam.pose_of("camera", p0), cam.pose_of("board", p0)
    T = (T_bt * C).inverse() * B.inverse() if mode == "eye_in_hand" else C * T_bt * B
    b = cam.board.corners()
    assert np.abs(cam.camera_points(p0, Q[:1])[0] - (b @ T.rotation.T + T.translation)).max() < 1e-12


@pytest.mark.parametrize("mode", ["eye_in_hand", "eye_to_hand"])
def test_derivatives_match_finite_differences(mode):
    cam = _camera(mode, estimate_intrinsics=True)
    rng = np.random.default_rng(3)
    p = rng.normal(scale=1e-3, size=cam.n_params)  # away from nominal: the right Jacobians count
    Q = _poses(cam, 3, 4)
    J = cam.jacobian(p, Q)
    h = 1e-6
    Jf = np.zeros_like(J)
    for i in range(cam.n_params):
        d = np.zeros(cam.n_params)
        d[i] = h
        Jf[:, :, i] = (cam.predict(p + d, Q) - cam.predict(p - d, Q)) / (2 * h)
    assert np.abs(J - Jf).max() < 1e-7 * np.abs(J).max()
    Yd = cam.prediction_dq(p, Q)
    for k in range(cam.robot.nq):
        dq = np.zeros(cam.robot.nq)
        dq[k] = h
        fd = (cam.predict(p, Q + dq) - cam.predict(p, Q - dq)) / (2 * h)
        assert np.abs(Yd[..., k] - fd).max() < 1e-7 * np.abs(Yd).max()
    # the TCP in the device frame and its sensitivity
    E = cam.kpi_jacobian(p, Q)
    Ef = np.stack([(cam.kpi(p + d, Q) - cam.kpi(p - d, Q)).ravel() / (2 * h)
                   for d in np.eye(cam.n_params) * h], axis=1)
    assert np.abs(E - Ef).max() < 1e-7 * np.abs(E).max()


def _scale_direction(cam: CameraModel) -> np.ndarray:
    """p of a uniform scaling of every length but the board's squares (joint translations, hand-eye, board pose)."""
    L, rb = cam.layout, cam.robot
    d = np.zeros(cam.n_params)
    for k, jid in enumerate(rb.joint_ids):
        M = rb.model.jointPlacements[jid]
        d[6 * k:6 * k + 3] = M.rotation.T @ M.translation
    for g, T0 in (("camera", cam.camera_pose), ("board", cam.board_pose)):
        d[L.group_slice(g).start:L.group_slice(g).start + 3] = T0.rotation.T @ T0.translation
    return d


@pytest.mark.parametrize("mode,fixed,on_tool", [("eye_in_hand", "board", "camera"), ("eye_to_hand", "camera", "board")])
def test_what_a_camera_sees_and_cannot_see(mode, fixed, on_tool):
    cam = _camera(mode)
    Q = _poses(cam, 25, 5)
    ident = analyse(cam, Q=Q)
    # a board of known size fixes the scale: the camera identifies as much as a 6-DoF probe on a laser tracker
    probe = TrackerModel(cam.robot, pose6d=True, reflector_m=np.array([0.05, 0.0, 0.03]))
    assert ident.rank == analyse(probe, Q=Q).rank == 30
    F = cam.weighted_jacobian(np.zeros(cam.n_params), Q).reshape(-1, cam.n_params)
    s = _scale_direction(cam)
    assert np.linalg.norm(F @ s) > 1e-3 * np.linalg.norm(F, 2) * np.linalg.norm(s)
    assert np.linalg.norm(ident.null_space.T @ s) < 0.5 * np.linalg.norm(s)
    assert any("scale comes from the board's square size" in n for n in ident.notes)
    # the last joint's placement across its axis is aliased with what rides on the tool: its column lies in the
    # span of the hand-eye (eye-in-hand) / board-on-tool (eye-to-hand) columns, and it is the one held nominal
    L = cam.layout
    dropped = {d["name"]: d for d in ident.dropped}
    alias = dropped["wrist_3_joint.ty"]
    assert alias["convention"] and all(c.startswith(on_tool + ".") for c in alias["confounded_with"])
    c = F[:, L.index("wrist_3_joint.ty")]
    A = F[:, L.group_slice(on_tool)]
    assert np.linalg.norm(c - A @ np.linalg.lstsq(A, c, rcond=None)[0]) < 1e-9 * np.linalg.norm(c)
    # the first joint's placement is aliased with the fixed frame's pose
    assert all(f"shoulder_pan_joint.{s}" in dropped for s in ("tx", "ty", "tz", "rx", "ry", "rz"))
    assert any(c.startswith(fixed + ".") for c in dropped["shoulder_pan_joint.tz"]["confounded_with"])
    # the TCP is estimable in the fixed frame
    check_kpi(ident, cam, cam.kpi_jacobian(np.zeros(cam.n_params), Q[:2]))


def test_fit_recovers_the_geometry_and_its_tcp_sigma_agrees_with_monte_carlo():
    """40 noise draws of 12 images (the draws make the statistic; 12 images of 96 pixel coordinates identify the
    geometry, as in the robust-loss test, and each fit costs 12/20 of one on 20 images). The first draw's fit starts
    at the nominal model and recovers the truth from there; the others start at that estimate (a warm start: fewer
    iterations to the same least-squares minimum, whose spread over the draws is the statistic)."""
    cam = _camera()
    Q = _poses(cam, 12, 6)
    ident = analyse(cam, Q=Q)
    base = ident.base
    rng = np.random.default_rng(7)
    p_true = np.zeros(cam.n_params)
    p_true[base] = rng.normal(scale=5e-4, size=base.size)  # the identifiable truth: no model error
    clean = cam.predict(p_true, Q)
    Qw = _poses(cam, 2, 8)
    s_true = cam.kpi(p_true, Qw)
    est, chi2, start = [], [], None
    for r in range(40):
        uv = clean + np.random.default_rng(100 + r).normal(scale=cam.sigma_px, size=clean.shape)
        fit = fit_camera(cam, Q, uv, base, p_ref=start)
        assert fit.success
        if start is None:  # from nominal: the truth within 5 of its σ in every identifiable parameter
            z = (fit.p[base] - p_true[base]) / np.sqrt(np.diag(fit.covariance))
            assert np.abs(z).max() < 5, z
            start = fit.p
        est.append((cam.kpi(fit.p, Qw) - s_true).ravel())
        chi2.append(fit.chi2_reduced)
    Cs = camera_tcp_covariance(cam, fit, Q, Qw)[0]
    e = np.array(est)
    # the spread of the TCP over 40 noise draws against the stated σ (standard error of a σ from 40 draws: 11 %)
    ratio = e.std(axis=0) / np.sqrt(np.concatenate([np.diag(C) for C in Cs]))
    assert np.all((ratio > 0.65) & (ratio < 1.4)), ratio
    assert np.abs(e.mean(axis=0)).max() < 4 * e.std(axis=0).max() / np.sqrt(len(e))
    assert 0.9 < np.mean(chi2) < 1.1
    assert fit.rms_px == pytest.approx(cam.sigma_px, rel=0.1)


def test_robust_loss_resists_a_misdetected_corner():
    cam = _camera()
    Q = _poses(cam, 12, 9)
    base = analyse(cam, Q=Q).base
    p_true = np.zeros(cam.n_params)
    p_true[base] = np.random.default_rng(10).normal(scale=5e-4, size=base.size)
    uv = cam.predict(p_true, Q) + np.random.default_rng(11).normal(scale=cam.sigma_px, size=(len(Q), cam.nh))
    uv[3, 10:14] += 40.0  # two corners 40 px off
    uv[5, 20:22] = np.nan  # a corner not detected
    Qw = _poses(cam, 3, 12)
    err = {loss: np.abs(cam.kpi(fit_camera(cam, Q, uv, base, loss=loss).p, Qw) - cam.kpi(p_true, Qw)).max()
           for loss in ("linear", "soft_l1")}
    assert err["soft_l1"] < 0.2 * err["linear"]


def test_bad_input_is_named():
    cam = _camera()
    Q = _poses(cam, 3, 13)
    with pytest.raises(InputError, match=r"pixels must be \(3, 96\)"):
        fit_camera(cam, Q, np.zeros((3, 10)), np.arange(5))
    with pytest.raises(InputError, match="loss 'l1'"):
        fit_camera(cam, Q, np.zeros((3, 96)), np.arange(5), loss="l1")
    with pytest.raises(InputError, match="camera mode 'eye_on_hand'"):
        _camera("eye_on_hand")
    with pytest.raises(InputError, match="board"):
        Board(1, 8, 0.025)


@pytest.mark.parametrize("mode", ["eye_in_hand", "eye_to_hand"])
def test_the_batched_tcp_of_many_drawn_robots_is_the_tcp_of_each(mode):
    """``sensor_points`` (the TCP in the device frame at many parameter vectors in one batched pass, what the camera
    certificate's Monte-Carlo draws through) equals ``kpi`` at each vector (the per-draw path it replaced) to 1e-12 m:
    joint placements, hand-eye and board drawn at 1 mrad / 1 mm; on a robot with a linear track too (the chain's
    prismatic joint), against ``sensor_point`` of the tracker."""
    cam = _camera(mode)
    Q = _poses(cam, 4, 3)
    P = np.random.default_rng(5).normal(scale=1e-3, size=(40, cam.n_params))
    Y = cam.sensor_points(P, Q, cam.tcp_m)
    assert Y.shape == (40, 4, 3)
    ref = np.array([cam.kpi(p, Q) for p in P])
    assert np.abs(Y - ref).max() < 1e-12 and np.abs(ref - ref[0]).max() > 1e-4  # the draws move the TCP
    tm = TrackerModel(load_robot("kr15_track"))
    Qt = tm.robot.random_q(np.random.default_rng(6), 5)
    Pt = np.random.default_rng(7).normal(scale=1e-3, size=(10, tm.n_params))
    x = np.array([0.01, 0.02, 0.1])
    assert np.abs(tm.sensor_points(Pt, Qt, x) - [tm.sensor_point(p, Qt, x).Y for p in Pt]).max() < 1e-12
    with pytest.raises(InputError, match="parameter vectors must have"):
        cam.sensor_points(P[:, :5], Q, cam.tcp_m)
