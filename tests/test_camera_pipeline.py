"""The camera through the whole command line on a small eye-in-hand UR5 cell: simulate -> identify -> predict --at
tcp -> compensate -> check, on a true robot that is not the package's model (every joint placement, the hand-eye
transform and the board off nominal, an unmodelled gear harmonic)."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from pin_kpi_oed.calibrated.model_file import load_model_file
from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.data.corner_measurements import CornerSet, read_corners
from pin_kpi_oed.effects.spec import effect_from_spec
from pin_kpi_oed.identification.camera_identify import camera_model_of
from pin_kpi_oed.simulation.camera_sim import simulate_corners, true_tcp
from pin_kpi_oed.upkeep.camera_check import check_camera
from tests.camera_cell import camera_cell
from tests.cli_run import run_cli


def _rows(path):
    with open(path) as f:
        return list(csv.DictReader(f))


#: the tests sharing the module fixture ``calibrated``: on one worker under ``--dist loadgroup``, computed once
GROUP = "test_camera_pipeline_calibrated"


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    """The simulated images, the identified model file and the truth."""
    d = tmp_path_factory.mktemp("camera_pipeline")
    cell_path = camera_cell(d)
    rc, out, err = run_cli("simulate", "--cell", cell_path, "--n", 25, "--n-test", 8, "--test-out", d / "check.csv",
                           "--out", d / "train.csv", "--truth-json", d / "truth.json", "--effects",
                           "gear_harmonic=5e-5", "--seed", 3)
    assert rc == 0, err
    rc, out, err = run_cli("identify", "--data", d / "train.csv", "--cell", cell_path, "--model-out", d / "m.json",
                           "--validate", d / "check.csv")
    assert rc == 0, err
    cell = load_cell(cell_path)
    model = cell.measurement_model()
    truth = json.loads((d / "truth.json").read_text())
    p_true = np.array([truth["raw_parameters"][n] for n in model.layout.names])
    effects = [(effect_from_spec(e, model.robot), np.array(e["theta"])) for e in truth["effects"]]
    Q = model.views(12, seed=17, around=cell.q_work)
    (d / "joints.csv").write_text(",".join(model.robot.joint_names) + "\n"
                                  + "".join(",".join(repr(float(v)) for v in q) + "\n" for q in Q))
    return d, cell_path, cell, model, p_true, effects, Q, out


@pytest.mark.xdist_group(GROUP)
def test_simulate_writes_the_corners_of_a_truth_that_is_not_the_model(calibrated):
    d, _, _, model, p_true, effects, _, _ = calibrated
    cs = read_corners(d / "train.csv")
    labels, Q, uv = cs.arrays(model.board.n)
    assert len(labels) == 25 and cs.joint_names == list(model.robot.joint_names)
    n = model.robot.nq
    assert np.all(p_true[:6 * n] != 0)  # every joint parameter off nominal
    assert effects and effects[0][0].name == "gear_harmonic"
    # the pixels are the truth's plus 0.2 px noise, far from the nominal model's
    r_true = (simulate_corners(model, Q, p_true, effects, seed=99) - uv)[np.isfinite(uv)]
    r_nom = (model.predict(np.zeros(model.n_params), Q) - uv)[np.isfinite(uv)]
    assert 0.2 < np.sqrt(np.mean(r_true ** 2)) < 0.35  # two independent 0.2 px draws: 0.28 px
    assert np.sqrt(np.mean(r_nom ** 2)) > 20


@pytest.mark.xdist_group(GROUP)
def test_identify_prints_the_fit_and_writes_a_model_file_that_loads_back(calibrated):
    d, _, _, model, _, _, _, out = calibrated
    assert "camera fit: 25 images" in out and "held-out" in out
    rms = float(out.split("reprojection RMS ")[1].split(" px")[0])
    assert 0.17 < rms < 0.23
    cm = load_model_file(d / "m.json")
    again, p = camera_model_of(cm)
    assert again.mode == "eye_in_hand" and again.board.n == model.board.n
    cm.save(d / "m2.json")
    cm2 = load_model_file(d / "m2.json")
    assert cm2.fit["device"] == cm.fit["device"] and cm2.parameters["names"] == cm.parameters["names"]
    Q = calibrated[6][:4]
    a, b = cm.predict_tcp(Q), cm2.predict_tcp(Q)
    assert np.allclose(a.position_m, b.position_m, atol=1e-12) and np.allclose(a.sigma_m, b.sigma_m, rtol=1e-9)


@pytest.mark.xdist_group(GROUP)
def test_predicted_tcp_error_is_within_3_sigma_of_the_truth(calibrated):
    d, _, _, model, p_true, effects, Q, _ = calibrated
    rc, out, err = run_cli("predict", "--model", d / "m.json", "--data", d / "joints.csv", "--at", "tcp",
                           "--out", d / "pred.csv")
    assert rc == 0, err
    rows = _rows(d / "pred.csv")
    y = np.array([[float(r[k]) for k in ("x_pred", "y_pred", "z_pred")] for r in rows])
    sigma = np.array([float(r["sigma_tcp"]) for r in rows])
    e = np.linalg.norm(true_tcp(model, Q, p_true, effects) - y, axis=1)  # the TCP in the board frame
    e_nominal = np.linalg.norm(true_tcp(model, Q, p_true, effects) - model.kpi(np.zeros(model.n_params), Q), axis=1)
    assert np.all(e < 3 * sigma), (e, sigma)
    assert np.median(e / sigma) > 0.2  # the sigma is not vacuous
    assert np.median(e) < 0.5 * np.median(e_nominal)  # the calibration moved the TCP towards the truth


@pytest.mark.xdist_group(GROUP)
def test_compensated_joints_put_the_true_tcp_within_3_sigma_of_the_target(calibrated):
    """Targets in the board frame (the frame a camera calibration knows the TCP in; the base frame adds joint 1's
    placement, which the board's pose absorbs), with the program's joints as hints."""
    d, _, _, model, p_true, effects, Q, _ = calibrated
    p0 = np.zeros(model.n_params)
    target = model.kpi(p0, Q)  # the nominal robot's TCP in the board frame at Q
    names = list(model.robot.joint_names)
    (d / "targets.csv").write_text("name,x,y,z," + ",".join(names) + "\n" + "".join(
        f"t{i}," + ",".join(repr(float(v)) for v in np.r_[target[i], Q[i]]) + "\n" for i in range(len(Q))))
    rc, out, err = run_cli("compensate", "--model", d / "m.json", "--targets", d / "targets.csv", "--frame",
                           "tracker", "--out", d / "comp.csv")
    assert rc == 0, err
    # the messages speak of the camera's set-up: the board's frame (eye-in-hand), no reflector, tracker or lever arm
    assert "the board's frame" in out and "the measured camera" in out, out
    assert "reflector" not in out and "tracker" not in out and "lever arm" not in out, out
    rows = _rows(d / "comp.csv")
    # sendable, and said to rest on a TCP no image measured: the flange's axial offset held at its tolerance
    # dominates the σ (0.5 mm of about 0.51 mm)
    assert all(r["status"] == "tcp_unmeasured" for r in rows), [r["status"] for r in rows]
    Qc = np.array([[float(r[n]) for n in names] for r in rows])
    sigma = np.array([float(r["sigma_m"]) for r in rows])
    e = np.linalg.norm(true_tcp(model, Qc, p_true, effects) - target, axis=1)
    e_uncompensated = np.linalg.norm(true_tcp(model, Q, p_true, effects) - target, axis=1)
    assert np.all(e < 3 * sigma), (e, sigma)
    assert np.median(e) < 0.5 * np.median(e_uncompensated)


@pytest.mark.xdist_group(GROUP)
def test_check_holds_on_new_images_and_names_a_moved_board_and_a_changed_robot(calibrated):
    d, _, cell, model, p_true, effects, _, _ = calibrated
    rc, out, err = run_cli("check", "--model", d / "m.json", "--data", d / "check.csv")
    assert rc == 0 and "verdict: holds" in out, out + err
    cm = load_model_file(d / "m.json")
    Q = model.views(10, seed=23, around=cell.q_work)
    L = model.layout
    verdicts = {}
    for what, group, k, delta in (("board moved", "board", 0, 3e-3), ("robot changed", "elbow_joint", 3, 2e-3)):
        p = p_true.copy()
        p[L.group_slice(group).start + k if group == "board" else L.names.index(f"{group}.rx")] += delta
        uv = simulate_corners(model, Q, p, effects, seed=5)
        cs = CornerSet.from_arrays([f"q{i}" for i in range(len(Q))], Q, uv, list(model.robot.joint_names))
        verdicts[what] = check_camera(cm, cs).verdict
    assert verdicts == {"board moved": "setup_moved", "robot changed": "recalibrate"}


@pytest.mark.xdist_group(GROUP)
def test_tracker_only_pieces_are_refused_in_one_line(calibrated):
    d, cell_path, *_ = calibrated
    for argv, says in (
            (("predict", "--model", d / "m.json", "--data", d / "joints.csv", "--out", d / "x.csv"),
             "a camera's model predicts the TCP (--at tcp)"),
            (("identify", "--data", d / "train.csv", "--model-out", d / "y.json"), "need --cell with the camera"),
            (("identify", "--data", d / "train.csv", "--cell", cell_path, "--reflector", "0,0,0.1"),
             "identify --reflector: not for camera measurements"),
            (("simulate", "--cell", cell_path, "--out", d / "z.csv", "--noise", "1e-5"),
             "simulate --noise: a laser tracker's option"),
            (("check", "design", "--model", d / "m.json", "--out", d / "c.csv"), "not for a camera's model yet"),
            (("register", "--model", d / "m.json", "--data", d / "check.csv", "--model-out", d / "r.json"),
             "a camera's measurement file (one row per board corner"),
            (("report", "--model", d / "m.json", "--train", d / "train.csv", "--validate", d / "check.csv", "--html",
              d / "r.html", "--register-rows", 3), "report --register-rows: not for camera measurements")):
        rc, out, err = run_cli(*argv)
        assert rc == 2 and says in err and len(err.strip().splitlines()) == 1, (argv, err)


def test_eye_to_hand_camera_through_simulate_and_identify(tmp_path):
    """A camera fixed above the robot, the board on the tool: the TCP (camera frame) within 3 sigma of the truth."""
    import yaml

    from tests.camera_cell import CAMERA_CELL

    cam = {**CAMERA_CELL["camera"], "mount": "eye_to_hand",
           "pose": {"xyz_m": [0.49, 0.11, 1.2], "rpy_rad": [np.pi, 0.0, 0.0]}}
    board = {**CAMERA_CELL["board"], "pose": {"xyz_m": [-0.1, -0.075, 0.05], "rpy_rad": [np.pi, 0.0, 0.0]}}
    cell_path = camera_cell(tmp_path, camera=cam, board=board,
                            working_configurations_rad=[[0.0, -1.57, 1.57, -1.57, -1.57, 0.0]])
    assert yaml.safe_load(cell_path.read_text())["camera"]["mount"] == "eye_to_hand"
    rc, out, err = run_cli("simulate", "--cell", cell_path, "--n", 20, "--out", tmp_path / "t.csv", "--truth-json",
                           tmp_path / "truth.json", "--seed", 4)
    assert rc == 0, err
    rc, out, err = run_cli("identify", "--data", tmp_path / "t.csv", "--cell", cell_path, "--model-out",
                           tmp_path / "m.json")
    assert rc == 0, err
    assert "(in the camera frame)" in out and "the fitted board pose on the tool absorbs it" in out
    model = load_cell(cell_path).measurement_model()
    truth = json.loads((tmp_path / "truth.json").read_text())
    p_true = np.array([truth["raw_parameters"][n] for n in model.layout.names])
    Q = model.views(8, seed=9, around=load_cell(cell_path).q_work)
    ts = load_model_file(tmp_path / "m.json").predict_tcp(Q)
    e = np.linalg.norm(true_tcp(model, Q, p_true) - ts.position_m, axis=1)
    assert np.all(e < 3 * ts.sigma_m), (e, ts.sigma_m)
