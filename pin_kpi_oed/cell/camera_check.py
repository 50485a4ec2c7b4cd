"""The independent check of a camera design: what the camera sees at each pose, by code paths other than the
optimiser's (:mod:`pin_kpi_oed.cell.camera_view`).

Per configuration: the board's pose in the camera frame from Pinocchio's forward kinematics (``pin.forwardKinematics``
+ the tool frame), the corners re-projected by OpenCV's ``cv2.projectPoints`` and counted inside the image with the
margin, the outer corners' depths, the viewing angle in degrees, and the Coal distances (``coal.distance`` of
capsules) from the five rays camera → outer corners and centre to every robot and obstacle capsule the rays are
checked against.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from pin_kpi_oed.cell.camera_view import CameraView
from pin_kpi_oed.cell.feasibility import coal_capsule

__all__ = ["CameraCheck", "check_camera_poses"]


@dataclass
class CameraCheck:
    """What the camera sees at each configuration (SI units; pixels and degrees for display).

    Attributes:
        corners_inside: corners inside the image with the margin, (m,) of ``n_corners``.
        n_corners: corners of the board.
        depth_m: the outer corners' depths, (m, 4) m.
        angle_deg: the viewing angle, (m,) deg.
        ray_clearance_m: the smallest Coal distance of a ray's capsule to a checked capsule, (m,) m (inf: none).
        ok: every corner inside, depths within the depth of field, angle within the limit, rays clear, (m,) bool.
    """

    corners_inside: np.ndarray
    n_corners: int
    depth_m: np.ndarray
    angle_deg: np.ndarray
    ray_clearance_m: np.ndarray
    ok: np.ndarray


def _tool_poses(robot, Q: np.ndarray) -> list[pin.SE3]:
    data = robot.model.createData()
    out = []
    for q in Q:
        pin.framesForwardKinematics(robot.model, data, np.asarray(q, float))
        out.append(data.oMf[robot.tool_frame_id].copy())
    return out


def check_camera_poses(view: CameraView, Q: np.ndarray) -> CameraCheck:
    """Check every configuration of a design independently (module docstring).

    Args:
        view: the camera's constraints (camera, limits and the cell's capsules; only its set-up is read).
        Q: configurations (m, n) rad.

    Returns:
        The :class:`CameraCheck`.
    """
    import coal
    import cv2

    cam, lim = view.camera, view.limits
    Q = np.atleast_2d(np.asarray(Q, float))
    p0 = np.zeros(cam.n_params)
    C, B = cam.pose_of("camera", p0), cam.pose_of("board", p0)
    K, dist = cam.intrinsics.matrix(), cam.intrinsics.dist
    corners = cam.board.corners()
    outer = [0, cam.board.cols - 1, cam.board.n - cam.board.cols, cam.board.n - 1]
    coll = view.coll
    m = Q.shape[0]
    inside, depth = np.zeros(m, int), np.zeros((m, 4))
    angle, clear = np.zeros(m), np.full(m, np.inf)
    data = coll.robot.model.createData() if coll is not None else None
    for i, T_bt in enumerate(_tool_poses(cam.robot, Q)):
        base_T_cam = T_bt * C if cam.eye_in_hand else C.inverse()
        base_T_board = B.inverse() if cam.eye_in_hand else T_bt * B
        cam_T_board = base_T_cam.inverse() * base_T_board
        X = corners @ cam_T_board.rotation.T + cam_T_board.translation
        uv = cv2.projectPoints(corners, cv2.Rodrigues(cam_T_board.rotation)[0], cam_T_board.translation, K,
                               dist)[0][:, 0]
        W, H, mu = cam.intrinsics.width, cam.intrinsics.height, lim.margin_px
        inside[i] = int(np.sum((X[:, 2] > 0) & (uv[:, 0] >= mu) & (uv[:, 0] <= W - mu) & (uv[:, 1] >= mu)
                               & (uv[:, 1] <= H - mu)))
        depth[i] = X[outer, 2]
        nrm = base_T_board.rotation[:, 2] * (1.0 if lim.front_z else -1.0)
        r = base_T_cam.translation - base_T_board.act(corners.mean(axis=0))
        angle[i] = np.degrees(np.arccos(np.clip(nrm @ r / np.linalg.norm(r), -1.0, 1.0)))
        if coll is None or view.blockers.size == 0:
            continue
        assert data is not None
        pin.framesForwardKinematics(coll.robot.model, data, Q[i])
        req, best = coal.DistanceRequest(), np.inf
        for end in list(corners[outer]) + [corners.mean(axis=0)]:
            ray, Tr = coal_capsule(base_T_cam.translation, base_T_board.act(end), lim.ray_radius_m)
            for a in view.blockers:
                A, Bp = _segment_in_base(coll, a, data)
                shape, Ts = coal_capsule(A, Bp, coll.radius[a])
                res = coal.DistanceResult()
                best = min(best, coal.distance(ray, Tr, shape, Ts, req, res))
        clear[i] = best
    ok = ((inside == cam.board.n) & np.all((depth >= lim.near_m) & (depth <= lim.far_m), axis=1)
          & (angle <= lim.max_angle_deg) & (clear >= lim.clearance_m))
    return CameraCheck(inside, cam.board.n, depth, angle, clear, ok)


def _segment_in_base(coll, a: int, data) -> tuple[np.ndarray, np.ndarray]:
    """End points of collision segment ``a`` in the base frame from Pinocchio's frame placements (m)."""
    if coll.seg_joint[a] < 0:  # an obstacle: stored in the base frame
        return coll.A_loc[a], coll.B_loc[a]
    rm = coll.robot.model
    link = coll.seg_link[a]
    fid = rm.getFrameId(link, pin.FrameType.BODY)
    oMj = data.oMi[int(rm.frames[fid].parentJoint)]
    return oMj.act(coll.A_loc[a]), oMj.act(coll.B_loc[a])
