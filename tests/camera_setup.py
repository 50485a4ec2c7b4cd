"""The UR5 camera set-ups the camera-design tests share: an 8 x 6 board of 25 mm squares on the table seen by a
camera beside the flange (eye-in-hand), or on the tool seen by a camera above the table (eye-to-hand)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from pin_kpi_oed.model.camera import Board, CameraModel, Intrinsics
from pin_kpi_oed.model.robot import load_robot

Q0 = np.array([0.0, -1.57, 1.57, -1.57, -1.57, 0.0])  # the UR5's tool looking down at the table
#: the UR5's capsules fitted to its meshes that overlap by construction (as in the shipped UR10 cell), and the table
UR5_SKIP = [("base_link", "upper_arm_link"), ("forearm_link", "wrist_2_link"), ("wrist_1_link", "wrist_3_link"),
            ("base_link", "table"), ("shoulder_link", "table")]


def ur5_camera(mode: str) -> CameraModel:
    """A UR5 and an 8 x 6 board of 25 mm squares: on the table seen by a camera beside the flange (eye-in-hand),
    or on the tool seen by a camera 1.2 m above the table (eye-to-hand)."""
    intr = Intrinsics(1200.0, 1210.0, 640.0, 512.0, np.array([-0.1, 0.05, 1e-3, -5e-4, 0.01]))
    if mode == "eye_in_hand":
        cam = pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, 0.3), np.array([0.05, 0.0, 0.03]))
        brd = pin.SE3(np.eye(3), np.array([0.4125, 0.0375, 0.0])).inverse()
    else:
        cam = pin.SE3(pin.rpy.rpyToMatrix(np.pi, 0, 0), np.array([0.5, 0.1, 1.2])).inverse()
        brd = pin.SE3(pin.rpy.rpyToMatrix(np.pi, 0, 0), np.array([-0.0875, -0.0625, 0.02]))
    return CameraModel(load_robot("ur5"), intr, Board(6, 8, 0.025), mode=mode, camera_pose=cam, board_pose=brd,
                       tcp_m=np.array([0.0, 0.0, 0.15]))
