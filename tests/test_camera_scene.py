"""The meshcat drawing of a camera design: the frustum's far corners re-project onto the image's corners (OpenCV),
its apex is the camera centre, and every pose's frustum and rays are drawn (the first shown, the others hidden)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from pin_kpi_oed.cell.camera_view import CameraView
from pin_kpi_oed.viz.camera_scene import camera_pose_in_base, draw_camera_design, frustum_corners
from pin_kpi_oed.viz.recorder import SceneRecorder, import_meshcat
from tests.camera_setup import Q0, ur5_camera


@pytest.mark.parametrize("mode", ["eye_in_hand", "eye_to_hand"])
def test_frustum_reprojects_onto_the_image_corners(mode):
    view = CameraView(ur5_camera(mode))
    Q = Q0 + np.random.default_rng(0).uniform(-0.2, 0.2, (3, 6))
    F = frustum_corners(view, Q, 0.7)
    R, t, _ = camera_pose_in_base(view, Q)
    intr = view.camera.intrinsics
    want = np.array([[0.0, 0.0], [intr.width, 0.0], [intr.width, intr.height], [0.0, intr.height]])
    for k in range(len(Q)):
        assert np.allclose(F[k, 0], t[k])
        X = (F[k, 1:] - t[k]) @ R[k]  # camera frame
        assert np.allclose(X[:, 2], 0.7)
        uv = cv2.projectPoints(X, np.zeros(3), np.zeros(3), intr.matrix(), intr.dist)[0][:, 0]
        assert np.abs(uv - want).max() < 0.05  # px (undistortPoints iterates)
    # the board seen by the model sits inside that frustum: its pixels inside the image
    uv = view.camera.predict(np.zeros(view.camera.n_params), Q0[None]).reshape(-1, 2)
    assert np.all((uv >= 0) & (uv <= [intr.width, intr.height]))


def test_draw_camera_design_records_every_pose():
    import_meshcat()
    import meshcat

    view = CameraView(ur5_camera("eye_in_hand"))
    Q = Q0 + np.random.default_rng(1).uniform(-0.2, 0.2, (3, 6))
    rec = SceneRecorder()
    draw_camera_design(meshcat.Visualizer(window=rec), view, Q, robot=False)
    paths = rec.object_paths()
    assert "/meshcat/camera/board" in paths
    for k in range(3):
        assert f"/meshcat/camera/pose_{k}/frustum" in paths and f"/meshcat/camera/pose_{k}/rays" in paths
        assert rec.properties(f"/meshcat/camera/pose_{k}")["visible"] == (k == 0)
