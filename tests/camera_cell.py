"""A small eye-in-hand UR5 camera cell shared by the camera pipeline's tests (written to a test's folder)."""

from __future__ import annotations

import copy
from pathlib import Path

import yaml

#: the camera 5 cm beside the flange looking along the tool axis, an 8 x 6 inner-corner board of 25 mm squares on the
#: table below the looking-down configuration, the TCP 0.15 m out along the tool axis
CAMERA_CELL = {
    "name": "ur5_camera", "robot": "ur5", "base": {"xyz_m": [0.0, 0.0, 0.0]}, "tcp_m": [0.0, 0.0, 0.15],
    "camera": {"mount": "eye_in_hand", "pose": {"xyz_m": [0.05, 0.0, 0.03], "rpy_rad": [0.0, 0.0, 0.3]},
               "intrinsics": {"fx": 1200.0, "fy": 1200.0, "cx": 640.0, "cy": 512.0,
                              "distortion": [-0.1, 0.05, 0.001, -0.0005, 0.01], "image_size_px": [1280, 1024]},
               "sigma_px": 0.2},
    "board": {"type": "chessboard", "rows": 7, "columns": 9, "square_m": 0.025,
              "pose": {"xyz_m": [0.4125, 0.0375, 0.0]}},
    "working_configurations_rad": [[0.0, -1.57, 1.57, -1.57, -1.57, 0.0], [0.3, -1.4, 1.5, -1.7, -1.57, 0.2]],
}


def camera_cell(folder: Path, name: str = "cam.yaml", **changes) -> Path:
    """Write the camera cell (top-level fields replaced by ``changes``) into ``folder``; returns its path."""
    d = copy.deepcopy(CAMERA_CELL)
    d.update(changes)
    path = Path(folder) / name
    path.write_text(yaml.safe_dump(d))
    return path
