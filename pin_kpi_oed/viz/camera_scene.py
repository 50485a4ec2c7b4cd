"""Meshcat drawing of a camera design: the robot, the board, and at every pose the camera's viewing frustum and the
rays to the board that the design keeps clear (:mod:`pin_kpi_oed.cell.camera_view`).

The frustum is the pyramid of the image: its apex the camera centre, its edges the rays through the image's four
corners, undistorted by OpenCV (``cv2.undistortPoints``) and drawn to ``depth_m`` (default the view's far limit,
capped at twice the board's distance). Units: m; base frame of the robot.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pinocchio as pin

from pin_kpi_oed.cell.camera_view import CameraView
from pin_kpi_oed.model.kinematics import Chain

__all__ = ["frustum_corners", "camera_pose_in_base", "draw_camera_design", "camera_design_scene"]

FRUSTUM_COLOUR = 0x2277CC
RAY_COLOUR = 0xDD8800
BOARD_COLOUR = 0xEEEEEE


def camera_pose_in_base(view: CameraView, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(base_R_camera (m, 3, 3), camera centre (m, 3) m, board corners (m, N, 3) m) at the nominal parameters."""
    cam = view.camera
    Q = np.atleast_2d(np.asarray(Q, float))
    kin = Chain.from_robot(cam.robot).tool_point(Q, np.zeros(3))
    p0 = np.zeros(cam.n_params)
    C, B = cam.pose_of("camera", p0), cam.pose_of("board", p0)
    b = cam.board.corners()
    m = Q.shape[0]
    if cam.eye_in_hand:
        R = kin.R_tool @ C.rotation
        t = kin.p + kin.R_tool @ C.translation
        corners = np.broadcast_to((b - B.translation) @ B.rotation, (m, b.shape[0], 3))
    else:
        R = np.broadcast_to(C.rotation.T, (m, 3, 3))
        t = np.broadcast_to(-C.rotation.T @ C.translation, (m, 3))
        corners = np.einsum("mab,nb->mna", kin.R_tool, b @ B.rotation.T + B.translation) + kin.p[:, None]
    return np.array(R), np.array(t), np.array(corners)


def frustum_corners(view: CameraView, Q: np.ndarray, depth_m: float) -> np.ndarray:
    """The frustum of each pose: the camera centre and the image's corners (0, 0), (W, 0), (W, H), (0, H) seen at
    depth ``depth_m`` (m, along the optical axis), base frame, (m, 5, 3) m."""
    import cv2

    intr = view.camera.intrinsics
    px = np.array([[0.0, 0.0], [intr.width, 0.0], [intr.width, intr.height], [0.0, intr.height]])
    xy = cv2.undistortPoints(px.reshape(-1, 1, 2), intr.matrix(), intr.dist)[:, 0]  # normalised x/z, y/z
    local = np.column_stack([xy * depth_m, np.full(4, depth_m)])  # camera frame
    R, t, _ = camera_pose_in_base(view, Q)
    far = np.einsum("mab,kb->mka", R, local) + t[:, None]
    return np.concatenate([t[:, None], far], axis=1)


def _segments(pairs: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """Line-segment vertices for meshcat, (3, 2k) float32."""
    return np.array([x for a, b in pairs for x in (a, b)], np.float32).T


def draw_camera_design(vis: Any, view: CameraView, Q: np.ndarray, depth_m: float | None = None,
                       robot: bool = True) -> Any:
    """Draw a camera design into a meshcat visualiser (module docstring): ``camera/board``, and per pose k
    ``camera/pose_k/frustum`` and ``camera/pose_k/rays`` (every pose but the first hidden); the robot at the first
    pose under ``robot`` (its URDF visuals through Pinocchio's meshcat visualiser).

    Args:
        vis: a ``meshcat.Visualizer`` (or one on :class:`~pin_kpi_oed.viz.recorder.SceneRecorder`).
        view: the camera's constraints (camera, limits).
        Q: the design (m, n) rad.
        depth_m: length of the frustum along the optical axis (m); default the far limit, at most twice the
            distance to the board.
        robot: draw the robot.

    Returns:
        The visualiser.
    """
    import meshcat.geometry as mg

    Q = np.atleast_2d(np.asarray(Q, float))
    R, t, corners = camera_pose_in_base(view, Q)
    if depth_m is None:
        dist = float(np.max(np.einsum("mka,ma->mk", corners - t[:, None], R[:, :, 2])))
        depth_m = min(view.limits.far_m, 2.0 * dist)
    cam = view.camera
    b = cam.board
    size = [(b.cols + 1) * b.square_m, (b.rows + 1) * b.square_m, 0.002]
    vis["camera/board"].set_object(mg.Box(size), mg.MeshLambertMaterial(color=BOARD_COLOUR, opacity=0.9))
    F = frustum_corners(view, Q, depth_m)
    for k in range(Q.shape[0]):
        node = vis[f"camera/pose_{k}"]
        apex, far = F[k, 0], F[k, 1:]
        edges = [(apex, f) for f in far] + [(far[i], far[(i + 1) % 4]) for i in range(4)]
        node["frustum"].set_object(mg.LineSegments(mg.PointsGeometry(_segments(edges)),
                                                   mg.LineBasicMaterial(color=FRUSTUM_COLOUR)))
        ends = list(corners[k][view.outer]) + [corners[k].mean(axis=0)]
        node["rays"].set_object(mg.LineSegments(mg.PointsGeometry(_segments([(t[k], e) for e in ends])),
                                                mg.LineBasicMaterial(color=RAY_COLOUR)))
        node.set_property("visible", k == 0)
    # the board's frame at the first pose (fixed eye-in-hand; on the tool eye-to-hand)
    x0 = corners[0]
    ex = (x0[b.cols - 1] - x0[0]) / np.linalg.norm(x0[b.cols - 1] - x0[0])
    ey = (x0[-1] - x0[b.cols - 1]) / np.linalg.norm(x0[-1] - x0[b.cols - 1])
    box = pin.SE3(np.column_stack([ex, ey, np.cross(ex, ey)]), x0.mean(axis=0))
    vis["camera/board"].set_transform(box.homogeneous)
    if robot:
        from pinocchio.visualize import MeshcatVisualizer

        from pin_kpi_oed.viz.robot_geometry import visual_model

        model, visual, _ = visual_model(cam.robot)
        if visual is not None:
            viz = MeshcatVisualizer(model, None, visual)
            viz.initViewer(viewer=vis)
            viz.loadViewerModel(rootNodeName="robot")
            viz.display(Q[0])
    return vis


def camera_design_scene(path: str, criterion: str | None = None, robot: bool = True) -> tuple[Any, Any]:
    """The scene of a camera's design file (``design --cell CAMERA_CELL --json``), recorded without a server:
    :func:`draw_camera_design` with the camera and view limits of the file's cell
    (:func:`~pin_kpi_oed.design.camera_design_file.load_camera_design`,
    :func:`~pin_kpi_oed.cell.camera_view.cell_camera_view`).

    Args:
        path: the design file; criterion: its design (default the file's ``q_meas`` design); robot: draw the robot.

    Returns:
        (the :class:`~pin_kpi_oed.viz.recorder.SceneRecorder` holding the scene, the
        :class:`~pin_kpi_oed.design.camera_design_file.CameraDesignFile`).

    Raises:
        InputError: not a camera's design file, or a damaged field (named).
    """
    from pin_kpi_oed.cell.camera_view import cell_camera_view
    from pin_kpi_oed.design.camera_design_file import load_camera_design
    from pin_kpi_oed.viz.recorder import SceneRecorder, import_meshcat

    meshcat = import_meshcat()
    cd = load_camera_design(path, criterion)
    rec = SceneRecorder()
    draw_camera_design(meshcat.Visualizer(window=rec), cell_camera_view(cd.cell), cd.Q, robot=robot)
    return rec, cd
