"""A camera cell through ``design`` -> ``simulate --design`` -> ``identify`` -> ``predict --at tcp`` (and ``export``,
``view``) on the shipped example camera cell, at the smallest sizes: 8 poses from 100 candidates, 5 IPOPT
iterations. The true robot is not the package's model (every joint placement, the hand-eye transform and the board
off nominal)."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from pin_kpi_oed.cell.camera_check import check_camera_poses
from pin_kpi_oed.cell.camera_view import cell_camera_view, cell_view_limits
from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.data.corner_measurements import read_corners
from pin_kpi_oed.simulation.camera_sim import true_tcp
from tests.cli_run import run_cli

CELL = Path(__file__).resolve().parents[1] / "examples" / "ur5_camera_cell.yaml"


#: the tests sharing the module fixture ``pipeline``: on one worker under ``--dist loadgroup``, computed once
GROUP = "test_camera_design_cli_pipeline"


@pytest.fixture(scope="module")
def pipeline(tmp_path_factory):
    """design -> simulate --design -> identify -> predict --at tcp, each step's (exit code, stdout, stderr)."""
    d = tmp_path_factory.mktemp("camera_design_cli")
    steps = {"design": run_cli("design", "--cell", CELL, "--n", 8, "--pool-size", 100, "--max-iter", 5, "--seed", 0,
                               "--json", d / "design.json")}
    steps["simulate"] = run_cli("simulate", "--design", d / "design.json", "--out", d / "corners.csv",
                                "--truth-json", d / "truth.json", "--seed", 4)
    steps["identify"] = run_cli("identify", "--data", d / "corners.csv", "--cell", CELL, "--model-out", d / "m.json")
    cell = load_cell(str(CELL))
    Q = cell.measurement_model().views(10, seed=21, around=cell.q_work)
    (d / "joints.csv").write_text(",".join(cell.robot.joint_names) + "\n"
                                  + "".join(",".join(repr(float(v)) for v in q) + "\n" for q in Q))
    steps["predict"] = run_cli("predict", "--model", d / "m.json", "--data", d / "joints.csv", "--at", "tcp",
                               "--out", d / "pred.csv")
    return d, cell, Q, steps


@pytest.mark.xdist_group(GROUP)
def test_every_step_exits_0(pipeline):
    _, _, _, steps = pipeline
    for name, (rc, _, err) in steps.items():
        assert rc == 0, (name, err)


@pytest.mark.xdist_group(GROUP)
def test_design_prints_the_table_and_writes_poses_that_see_the_board(pipeline):
    d, cell, _, steps = pipeline
    out = steps["design"][1]
    assert "kpi (" in out and "selection" in out and "certificate: every 8-pose design" in out
    assert "held at nominal" in out and "8 of 8 poses see the board" in out
    # IPOPT at its iteration limit (5) is said to be not converged; an efficiency is stated only when it is one
    assert "note: IPOPT not converged: stopped at its iteration limit (5)" in out
    doc = json.loads((d / "design.json").read_text())
    assert doc["device"] == "camera" and doc["cell"]["camera"]["view"]["max_angle_rad"] == pytest.approx(1.0472)
    e = doc["designs"][0]
    Q = np.array(e["q_meas"])
    assert Q.shape == (8, 6)
    t = len(cell.q_work)
    # the file's C_s is the design's (eq. 19 by the evaluation path), its σ holds the held part
    assert np.trace(np.array(e["cov_s_m2"])) == pytest.approx(e["trace_cs_m2"], rel=1e-8)
    assert e["held_trace_m2"] > 0
    assert e["tcp_sigma_m"] == pytest.approx(math.sqrt((e["trace_cs_m2"] + e["held_trace_m2"]) / t))
    assert 0 < doc["lower_bound_trace_cs_m2"] <= e["selection_trace_cs_m2"]
    assert (e["efficiency"] is None and "off pool" in out) or e["efficiency"] <= 1 + 1e-9
    # checked again here, independently of the design run: OpenCV projection and Coal rays with the file's limits
    from pin_kpi_oed.cell.collision import CollisionModel

    view = cell_camera_view(cell, CollisionModel(cell, collision=True, incidence=False))
    assert check_camera_poses(view, Q).ok.all()


@pytest.mark.xdist_group(GROUP)
def test_simulate_design_writes_the_corners_at_the_design_poses(pipeline):
    d, cell, _, steps = pipeline
    Q = np.array(json.loads((d / "design.json").read_text())["q_meas"])
    cs = read_corners(d / "corners.csv")
    labels, Qs, uv = cs.arrays(cell.measurement_model().board.n)
    assert len(labels) == 8 and np.allclose(Qs, Q, atol=1e-12)
    assert np.isfinite(uv).all()  # every corner of every designed pose detected
    assert "at the 8 poses of design kpi" in steps["simulate"][1]


@pytest.mark.xdist_group(GROUP)
def test_identified_tcp_is_within_3_sigma_of_the_truth(pipeline):
    d, cell, Q, _ = pipeline
    model = cell.measurement_model()
    truth = json.loads((d / "truth.json").read_text())
    p_true = np.array([truth["raw_parameters"][n] for n in model.layout.names])
    with open(d / "pred.csv") as f:
        rows = list(csv.DictReader(f))
    y = np.array([[float(r[k]) for k in ("x_pred", "y_pred", "z_pred")] for r in rows])
    sigma = np.array([float(r["sigma_tcp"]) for r in rows])
    e = np.linalg.norm(true_tcp(model, Q, p_true) - y, axis=1)  # the TCP in the board frame
    assert np.all(e < 3 * sigma), (e, sigma)
    assert np.median(e / sigma) > 0.05  # the sigma is not vacuous


@pytest.mark.xdist_group(GROUP)
def test_export_writes_the_program_of_the_camera_design(pipeline):
    d, cell, _, _ = pipeline
    rc, out, err = run_cli("export", d / "design.json", "--format", "csv", "--out", d / "prog.csv")
    assert rc == 0, err
    assert "0 colliding pose(s) (a camera design" in out and "incidence" not in out  # no stand-in tracker's angles
    Q = np.array(json.loads((d / "design.json").read_text())["q_meas"])
    with open(d / "prog.csv") as f:
        rows = [r for r in csv.reader(line for line in f if not line.startswith("#"))]
    head, body = rows[0], rows[1:]
    cols = [head.index(f"{n}_rad") for n in cell.robot.joint_names]
    P = np.array([[float(r[c]) for c in cols] for r in body if r[head.index("kind")] == "measure"])
    assert len(P) == len(Q)
    # every designed pose is a measurement point of the program (up to whole turns)
    for q in Q:
        dq = np.abs((P - q + np.pi) % (2 * np.pi) - np.pi)
        assert np.min(dq.max(axis=1)) < 1e-6


@pytest.mark.xdist_group(GROUP)
def test_view_scene_draws_every_pose(pipeline):
    from pin_kpi_oed.viz.camera_scene import camera_design_scene

    d, _, _, _ = pipeline
    rec, cd = camera_design_scene(str(d / "design.json"), robot=False)
    paths = rec.object_paths()
    assert len(cd.Q) == 8 and any(p.endswith("camera/board") for p in paths)
    for k in range(8):
        assert any(p.endswith(f"camera/pose_{k}/frustum") for p in paths)
        assert any(p.endswith(f"camera/pose_{k}/rays") for p in paths)


@pytest.mark.parametrize("args, named", [
    (("--criteria", "random,kpi"), "design --criteria random,kpi"),
    (("--clearance-margin", "0.02"), "design --clearance-margin"),
    (("--starts", "2"), "design --starts"),
    (("--no-collision",), "design --no-collision"),
    (("--robot-class", "industrial"), "design --robot-class"),
    (("--certificate",), "design --certificate: a camera cell (")])
def test_tracker_design_options_refused_with_a_camera_cell(tmp_path, args, named):
    rc, out, err = run_cli("design", "--cell", CELL, "--n", 8, *args, "--json", tmp_path / "x.json")
    assert rc == 2 and named in err and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "x.json").exists()


@pytest.mark.xdist_group(GROUP)
def test_view_refuses_the_tracker_options_of_a_camera_design(pipeline):
    d, _, _, _ = pipeline
    rc, _, err = run_cli("view", d / "design.json", "--scale", 3, "--html", d / "v.html", "--no-open")
    assert rc == 2 and "view --scale: not for a camera's design" in err and "Traceback" not in err


def _cell_with_view(tmp_path, view) -> Path:
    d = yaml.safe_load(CELL.read_text())
    d["camera"]["view"] = view
    p = tmp_path / "cell.yaml"
    p.write_text(yaml.safe_dump(d))
    return p


def test_view_limits_come_from_the_cell_file_in_si_units(tmp_path):
    cell = load_cell(str(_cell_with_view(tmp_path, {"max_angle_rad": 0.5, "near_m": 0.3})))
    lim = cell_view_limits(cell)
    assert lim.max_angle_deg == pytest.approx(math.degrees(0.5)) and lim.near_m == 0.3
    assert lim.far_m == 2.0 and lim.margin_px == 20.0  # the defaults where the file says nothing
    assert cell_view_limits(load_cell(str(CELL))).max_angle_deg == pytest.approx(60.0, abs=1e-3)


@pytest.mark.parametrize("view, named", [
    ({"max_angle_rad": 60}, "camera.view.max_angle_rad: must be in (0, 1.5708) rad, got 60 (it looks like degrees"),
    ({"near_m": 1.0, "far_m": 0.5}, "need 0 < near_m < far_m"),
    ({"far_m": 2000}, "camera.view.far_m: 2000 is more than 50 m"),
    ({"margin_px": -1}, "camera.view.margin_px: must be >= 0 px"),
    ({"margin": 5}, "camera.view: unknown field(s) margin"),
    ({"near_m": "0.2"}, "camera.view.near_m: expected a number")])
def test_bad_view_limits_refused_in_one_line(tmp_path, view, named):
    rc, _, err = run_cli("design", "--cell", _cell_with_view(tmp_path, view), "--n", 8)
    assert rc == 2 and named in err and "Traceback" not in err and len(err.strip().splitlines()) == 1, err


@pytest.mark.xdist_group(GROUP)
def test_evaluate_refuses_a_camera_design(pipeline):
    d, _, _, _ = pipeline
    rc, _, err = run_cli("evaluate", d / "design.json")
    assert rc == 2 and "a camera's design file; evaluate scores a laser tracker's poses" in err


@pytest.mark.xdist_group(GROUP)
def test_predict_at_tcp_takes_a_corners_file_and_refuses_it_without_at_tcp(pipeline):
    """The corners file identify read is a valid --data of predict --at tcp (one row per image, its joint values, the
    same TCP and sigma as the joint values alone); without --at tcp it is refused in one line naming the fix."""
    d, cell, _, _ = pipeline
    cs = read_corners(d / "corners.csv")
    labels, Qs, _ = cs.arrays(cell.measurement_model().board.n)
    (d / "img_joints.csv").write_text(",".join(cs.joint_names) + "\n"
                                      + "".join(",".join(repr(float(v)) for v in q) + "\n" for q in Qs))
    rc, out, err = run_cli("predict", "--model", d / "m.json", "--data", d / "corners.csv", "--at", "tcp",
                           "--out", d / "pred_corners.csv")
    assert rc == 0, err
    assert f"at {len(labels)} rows of" in out
    rc, _, err = run_cli("predict", "--model", d / "m.json", "--data", d / "img_joints.csv", "--at", "tcp",
                         "--out", d / "pred_joints.csv")
    assert rc == 0, err
    assert (d / "pred_corners.csv").read_text() == (d / "pred_joints.csv").read_text()
    rc, _, err = run_cli("predict", "--model", d / "m.json", "--data", d / "corners.csv", "--out", d / "no.csv")
    assert rc == 2 and "give --at tcp" in err and len(err.strip().splitlines()) == 1
    assert not (d / "no.csv").exists()
