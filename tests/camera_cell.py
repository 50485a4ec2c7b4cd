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
