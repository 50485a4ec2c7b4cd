"""The camera's constraints of a design (the board in the image, depth of field, viewing angle, rays clear of the
robot and the obstacles): their Jacobian against finite differences, the aggregate conservative, and the rows
against the independent check (OpenCV's projection, Coal's distances)."""

from __future__ import annotations

import numpy as np
import pytest

from pin_kpi_oed.cell.camera_check import check_camera_poses
from pin_kpi_oed.cell.camera_view import CameraView, ViewLimits, camera_cell, camera_constraints
from pin_kpi_oed.cell.cell_model import CapsuleSpec, HalfSpace
from pin_kpi_oed.cell.collision import CollisionModel
from pin_kpi_oed.errors import InputError
from tests.camera_setup import Q0, UR5_SKIP, ur5_camera

def _view(mode: str, limits: ViewLimits | None = None) -> CameraView:
    cam = ur5_camera(mode)
    post = CapsuleSpec("post", np.array([0.2, -0.4, 0.0]), np.array([0.2, -0.4, 0.8]), 0.05)
    cell = camera_cell(cam.robot, obstacles=[post], half_spaces=[HalfSpace("table", np.array([0, 0, 1.0]), -0.01)],
                       skip_pairs=UR5_SKIP)
    return CameraView(cam, limits, CollisionModel(cell, collision=True, incidence=False))


def _poses(view: CameraView, n: int, seed: int, spread: float = 0.6) -> np.ndarray:
    Q = Q0 + np.random.default_rng(seed).uniform(-spread, spread, (60 * n, 6))
    Q = Q[view.camera.in_view(view.p0, Q)]
    assert len(Q) >= n
    return Q[:n]


@pytest.mark.parametrize("mode", ["eye_in_hand", "eye_to_hand"])
def test_jacobian_matches_finite_differences(mode):
    view = _view(mode)
    Q = _poses(view, 6, 1)
    g, G, names = camera_constraints(view.camera, Q, view.limits, view.coll)
    assert g.shape == G.shape[:2] and len(names) == g.shape[1]
    assert {"image", "depth", "angle", "rays"} <= {n.split(":")[0] for n in names}
    h = 1e-6
    Gfd = np.zeros_like(G)
    for j in range(6):
        d = np.zeros(6)
        d[j] = h
        Gfd[:, :, j] = (view.evaluate(Q + d, False)[0] - view.evaluate(Q - d, False)[0]) / (2 * h)
    for kind in range(4):  # px, m, cos, m: each kind against its own scale
        rows = view.kinds == kind
        scale = np.abs(Gfd[:, rows]).max()
        assert scale > 0
        assert np.abs(G[:, rows] - Gfd[:, rows]).max() < 1e-6 * scale, kind
    # the aggregated rows: conservative (at most the smallest row of their kind) with the exact gradient
    ga, Ga = view.aggregate(Q)
    for k in range(4):
        assert np.all(ga[:, k] <= g[:, view.kinds == k].min(axis=1) + 1e-12)
    Gafd = np.stack([(view.aggregate(Q + h * e, False)[0] - view.aggregate(Q - h * e, False)[0]) / (2 * h)
                     for e in np.eye(6)], axis=-1)
    assert np.abs(Ga - Gafd).max() < 1e-6 * np.abs(Gafd).max(axis=(0, 2))[None, :, None].max()


@pytest.mark.parametrize("mode", ["eye_in_hand", "eye_to_hand"])
def test_rows_agree_with_the_independent_check(mode):
    view = _view(mode, ViewLimits(margin_px=30.0, max_angle_deg=40.0, near_m=0.2, far_m=1.0))
    Q = Q0 + np.random.default_rng(2).uniform(-0.6, 0.6, (300, 6))
    g, _ = view.evaluate(Q, with_grad=False)
    chk = check_camera_poses(view, Q)
    feas = np.all(g >= 0, axis=1)
    assert 0 < feas.sum() < len(Q)  # both kinds present: the comparison means something
    assert np.array_equal(feas, chk.ok)
    # the image rows are OpenCV's corners inside the margin, the angle row OpenCV-independent geometry
    inside = (g[:, view.kinds == 0].reshape(len(Q), -1, 4) >= 0).all(axis=2).sum(axis=1)
    seen = chk.depth_m.min(axis=1) > 0
    assert np.array_equal(inside[seen], chk.corners_inside[seen])
    cos_rows = g[:, view.kinds == 2][:, 0] + np.cos(np.radians(40.0))
    assert np.allclose(np.degrees(np.arccos(np.clip(cos_rows, -1, 1))), chk.angle_deg, atol=1e-7)
    rays = g[:, view.kinds == 3].min(axis=1) + view.limits.ray_radius_m  # Coal's distance of capsules of radius
    assert np.allclose(rays - view.limits.ray_radius_m, chk.ray_clearance_m, atol=1e-6)


def test_an_obstacle_between_camera_and_board_is_refused():
    """A small obstacle halfway between the camera and the board's centre: the ray rows (and Coal) say blocked while
    the image, depth and angle rows do not."""
    from pin_kpi_oed.model.kinematics import Chain

    cam = ur5_camera("eye_in_hand")
    centre_cam = Chain.from_robot(cam.robot).tool_point(Q0[None], cam.camera_pose.translation).p[0]
    centre_board = cam.board_pose.inverse().act(cam.board.corners().mean(axis=0))
    mid = 0.5 * (centre_cam + centre_board)
    ball = CapsuleSpec("ball", mid, mid + [0.0, 0.0, 0.01], 0.02)
    cell = camera_cell(cam.robot, obstacles=[ball], half_spaces=[HalfSpace("table", np.array([0, 0, 1.0]), -0.01)],
                       skip_pairs=UR5_SKIP)
    view = CameraView(cam, None, CollisionModel(cell, collision=True, incidence=False))
    g, _ = view.evaluate(Q0[None], with_grad=False)
    assert g[0, view.kinds == 3].min() < 0 and g[0, view.kinds != 3].min() >= 0
    chk = check_camera_poses(view, Q0[None])
    assert not chk.ok[0] and chk.ray_clearance_m[0] <= 0.0
    assert chk.corners_inside[0] == cam.board.n


def test_limits_refused_with_their_field():
    with pytest.raises(InputError, match="max_angle_deg"):
        ViewLimits(max_angle_deg=95)
    with pytest.raises(InputError, match="near_m"):
        ViewLimits(near_m=1.0, far_m=0.5)
