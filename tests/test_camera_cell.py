"""The cell file's camera and board: the nominal frames, the validation (one line, exit 2), ``info CELL``."""

from __future__ import annotations

import copy

import numpy as np
import pinocchio as pin
import pytest

from pin_kpi_oed.cell.cell import cell_from_dict, load_cell
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.camera import CameraModel
from tests.camera_cell import CAMERA_CELL, camera_cell
from tests.cli_run import run_cli


def test_camera_cell_builds_the_camera_model_in_the_cell_frames(tmp_path):
    base = {"xyz_m": [0.1, -0.2, 0.05], "rpy_deg": [0, 0, 30]}
    cell = load_cell(camera_cell(tmp_path, base=base))
    model = cell.measurement_model()
    assert isinstance(model, CameraModel) and model.eye_in_hand and model.board.n == 48
    # the board's corner 0 is at the board pose in the cell frame: seen from the base through board_T_base
    W_T_base = cell.W_T_base
    corner0_in_base = model.board_pose.inverse().translation
    assert np.allclose(W_T_base.act(corner0_in_base), [0.4125, 0.0375, 0.0], atol=1e-12)
    assert np.allclose(model.camera_pose.translation, [0.05, 0.0, 0.03])
    assert np.allclose(model.intrinsics.dist, [-0.1, 0.05, 0.001, -0.0005, 0.01])
    assert (model.intrinsics.width, model.intrinsics.height) == (1280, 1024)
    assert model.sigma_px == 0.2 and np.allclose(model.tcp_m, [0, 0, 0.15])
    # a camera cell's tracker stand-in is the device frame, its reflector stand-in the camera's origin on the tool
    assert np.allclose(cell.W_T_tracker.translation, [0.4125, 0.0375, 0.0])
    assert np.allclose(cell.reflector_m, [0.05, 0.0, 0.03])
    # the nominal looking-down configuration sees the whole board
    assert model.in_view(np.zeros(model.n_params), cell.q_work[:1]).all()
    # the file's fields survive the cell's plain-number form
    again = cell_from_dict({**copy.deepcopy(CAMERA_CELL), "base": base, **cell.camera.to_dict()})
    assert np.allclose(again.measurement_model().predict(np.zeros(model.n_params), cell.q_work),
                       model.predict(np.zeros(model.n_params), cell.q_work), atol=1e-9)


def test_eye_to_hand_camera_is_the_device_frame(tmp_path):
    W_T_cam = pin.SE3(pin.rpy.rpyToMatrix(np.pi, 0.0, 0.0), np.array([0.5, 0.1, 1.2]))
    cam = {**CAMERA_CELL["camera"], "mount": "eye_to_hand",
           "pose": {"xyz_m": W_T_cam.translation.tolist(), "rpy_rad": [np.pi, 0.0, 0.0]}}
    board = {**CAMERA_CELL["board"], "pose": {"xyz_m": [-0.1, -0.075, 0.05]}}
    model = load_cell(camera_cell(tmp_path, camera=cam, board=board)).measurement_model()
    assert model.mode == "eye_to_hand" and model.frame_group == "camera"
    assert np.allclose(model.camera_pose.homogeneous, W_T_cam.inverse().homogeneous, atol=1e-12)
    assert np.allclose(model.board_pose.translation, [-0.1, -0.075, 0.05])


@pytest.mark.parametrize("field, value, says", [
    ("camera", {"mount": "on_the_wall"}, "camera.mount"),
    ("camera", {**CAMERA_CELL["camera"], "sigma_px": -1}, "camera.sigma_px"),
    ("camera", {**CAMERA_CELL["camera"], "intrinsics": {"fx": 1200, "fy": 1200, "cx": 640, "cy": 512}},
     "camera.intrinsics.image_size_px"),
    ("camera", {**CAMERA_CELL["camera"], "intrinsics": {**CAMERA_CELL["camera"]["intrinsics"], "cx": 2000}},
     "principal point"),
    ("camera", {**CAMERA_CELL["camera"], "intrinsics": {**CAMERA_CELL["camera"]["intrinsics"],
                                                        "distortion": [0.1, 0.2]}}, "camera.intrinsics.distortion"),
    ("board", {**CAMERA_CELL["board"], "square_m": 25}, "board.square_m"),
    ("camera", {**CAMERA_CELL["camera"], "intrinsics": {**CAMERA_CELL["camera"]["intrinsics"], "fx": 8.0}},
     "camera.intrinsics.fx: 8 px is less than 50 px"),   # the lens's focal length in mm
    ("camera", {**CAMERA_CELL["camera"], "sigma_px": 200}, "a corner's detection noise is a fraction of a pixel"),
    ("board", {**CAMERA_CELL["board"], "type": "circles"}, "board.type"),
    ("board", {**CAMERA_CELL["board"], "rows": 2}, "board.rows"),
    ("board", {**CAMERA_CELL["board"], "type": "charuco", "marker_m": 0.018, "dictionary": "DICT_NOPE"},
     "board.dictionary"),
    ("board", {**CAMERA_CELL["board"], "type": "charuco", "marker_m": 0.03, "dictionary": "DICT_5X5_100"},
     "board.marker_m"),
    ("tracker", {"xyz_m": [2, 0, 0]}, "a camera cell has no tracker"),
])
def test_bad_camera_fields_are_one_line_naming_the_file_and_field(tmp_path, field, value, says):
    path = camera_cell(tmp_path, **{field: value})
    with pytest.raises(InputError, match=says.replace(".", r"\.").replace("(", r"\(")):
        load_cell(path)
    rc, out, err = run_cli("info", path)
    assert rc == 2 and len(err.strip().splitlines()) == 1 and str(path) in err and "Traceback" not in err


def test_board_without_camera_is_named(tmp_path):
    d = copy.deepcopy(CAMERA_CELL)
    del d["camera"]
    with pytest.raises(InputError, match="camera: missing field"):
        cell_from_dict(d, "x.yaml")


def test_info_cell_says_what_the_camera_cannot_see(tmp_path):
    rc, out, err = run_cli("info", camera_cell(tmp_path))
    assert rc == 0, err
    assert "device: CameraModel" in out
    assert "the scale comes from the board's square size (25 mm)" in out
    assert "the TCP is estimable in the board frame only" in out
    # the flange's own offsets across the last axis are carried by the hand-eye transform
    absorbed = next(line for line in out.splitlines() if "what the tool-mounted part (camera) absorbs" in line)
    assert "wrist_3_joint.ty" in absorbed and "wrist_3_joint.ry" in absorbed
    assert "identifiable (rank): 30" in out
