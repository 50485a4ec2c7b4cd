"""The example eye-in-hand UR5 camera cell (``examples/ur5_camera_cell.yaml``), shared by the camera tests."""

from __future__ import annotations

import copy
from pathlib import Path

import yaml

#: the shipped example: the camera 5 cm beside the flange looking along the tool axis, an 8 x 6 inner-corner board
#: of 25 mm squares on the table below the looking-down configuration, the TCP 0.15 m out along the tool axis
EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "ur5_camera_cell.yaml"
CAMERA_CELL = yaml.safe_load(EXAMPLE.read_text())


def camera_cell(folder: Path, name: str = "cam.yaml", **changes) -> Path:
    """Write the camera cell (top-level fields replaced by ``changes``) into ``folder``; returns its path."""
    d = copy.deepcopy(CAMERA_CELL)
    d.update(changes)
    path = Path(folder) / name
    path.write_text(yaml.safe_dump(d))
    return path


#: the eye-to-hand UR5 (the geometry of ``benchmarks.camera_design``): the board 2 cm in front of the flange facing
#: along the tool axis, the camera on the table 0.38 m below it at the looking-down configuration, looking up
EYE_TO_HAND = {
    "camera": {**CAMERA_CELL["camera"], "mount": "eye_to_hand",
               "pose": {"xyz_m": [0.487, 0.11, 0.03], "rpy_rad": [0.0, 0.0, 0.0]}},
    "board": {**CAMERA_CELL["board"], "pose": {"xyz_m": [-0.0875, -0.0625, 0.02], "rpy_rad": [0.0, 0.0, 0.0]}},
    "obstacles": {"half_spaces": [{"name": "table", "normal": [0.0, 0.0, 1.0], "offset_m": 0.0}]},
    "skip_pairs": [["base_link", "upper_arm_link"], ["base_link", "table"], ["shoulder_link", "table"],
                   ["upper_arm_link", "table"]],
    "working_configurations_rad": [[0.0, -1.57, 1.57, -1.57, -1.57, 0.0]],
}
