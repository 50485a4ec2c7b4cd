"""UR kinematics files (ur_description layout) in and out, and export-model's formats."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import yaml

from pin_kpi_oed.cli.app import main
from pin_kpi_oed.errors import InputError, RobotLoadError
from pin_kpi_oed.calibrated.model_file import CalibratedModel, Setup, load_model_file
from pin_kpi_oed.calibrated.formats.base import calibrated_placements
from pin_kpi_oed.calibrated.formats.registry import MODEL_FORMATS, export_model
from pin_kpi_oed.model.robot import load_robot
from pin_kpi_oed.model.ur_kinematics import (UR_KEYS, UR_SEGMENTS, UR_KINEMATICS_DIR, URKinematics,
                                             default_ur_kinematics, read_ur_kinematics, ur_values_of)

REPO = Path(__file__).resolve().parents[1]
_Q = np.random.default_rng(7).uniform(-np.pi, np.pi, size=(300, 6))


def _tool0(robot, Q=_Q) -> np.ndarray:
    return np.array([robot.oMtool(q).translation for q in Q])


def _calibrated_tool0(cm, Q=_Q) -> np.ndarray:
    rb = cm.robot
    ref = rb.model.copy()
    for j, M in zip(rb.joint_ids, calibrated_placements(cm)):
        ref.jointPlacements[j] = M
    d = ref.createData()
    out = []
    for q in Q:
        pin.framesForwardKinematics(ref, d, q)
        out.append(d.oMf[rb.tool_frame_id].translation.copy())
    return np.array(out)


def _model(robot, seed=0, scale=1.0, effects=()) -> CalibratedModel:
    """A calibrated model with random joint-placement errors (0.5 mm, 1 mrad) on every parameter."""
    rng = np.random.default_rng(seed)
    p = np.concatenate([np.r_[rng.normal(0, 5e-4, 3), rng.normal(0, 1e-3, 3)] for _ in range(robot.nq)]) * scale
    st = Setup(np.eye(4), np.array([0.02, 0.0, 0.07]), n_rows=10)
    return CalibratedModel(robot, p, setups={"s": st}, default_station="s")


@pytest.mark.parametrize("name", ["ur3", "ur5", "ur10"])
def test_shipped_nominal_written_as_yaml_and_read_back_has_the_urdf_forward_kinematics(name, tmp_path):
    robot = load_robot(name)
    ref = default_ur_kinematics(name)
    kin = URKinematics.from_values(ur_values_of(robot.model, robot.joint_ids, robot.tool_frame_id, reference=ref))
    path = tmp_path / "k.yaml"
    path.write_text(kin.text())
    back = load_robot(name, kinematics=path)
    assert back.joint_names == robot.joint_names and back.tool_frame == "tool0"
    gap = np.linalg.norm(_tool0(back) - _tool0(robot), axis=1).max()
    assert gap < 1e-9
    # following the reference's link frames, the values are ur_description's own (to its 1e-9 rad rounding of pi/2)
    for P, R in zip(kin.placements(), ref.placements()):
        assert np.linalg.norm(P.translation - R.translation) < 1e-9
        assert np.linalg.norm(pin.log3(P.rotation.T @ R.rotation)) < 1e-8


@pytest.mark.parametrize("name", ["ur3", "ur5", "ur10"])
def test_ur_description_defaults_match_the_shipped_urdfs(name):
    gap = np.linalg.norm(_tool0(load_robot(name, kinematics=UR_KINEMATICS_DIR / f"{name}.yaml"))
                         - _tool0(load_robot(name)), axis=1).max()
    assert gap < 1e-9  # the default files round pi/2 to 1.570796327: 3e-10 m at most


def test_file_keeps_ur_description_keys_and_order(tmp_path):
    cm = _model(load_robot("ur10"))
    out = tmp_path / "calib.yaml"
    export_model(cm, out, "ur-yaml")
    text = out.read_text()
    doc = yaml.safe_load(text)
    assert list(doc) == ["kinematics"]
    assert list(doc["kinematics"]) == list(UR_SEGMENTS) + ["hash"]
    for seg in UR_SEGMENTS:
        assert list(doc["kinematics"][seg]) == list(UR_KEYS)
    assert doc["kinematics"]["hash"].startswith("calib_") and doc["kinematics"]["hash"][6:].isdigit()
    # the same lines as ur_description's default file, values aside
    shape = [ln.split(":")[0] for ln in text.splitlines() if not ln.startswith("#")]
    ref = [ln.split(":")[0] for ln in (UR_KINEMATICS_DIR / "ur10.yaml").read_text().splitlines()
           if not ln.startswith("#")]
    assert shape == ref


@pytest.mark.parametrize("name", ["ur10", "ur5e"])
def test_identified_model_round_trips_through_the_yaml(name, tmp_path):
    cm = _model(load_robot(name), seed=3)
    out = tmp_path / "calib.yaml"
    rep = export_model(cm, out, "ur-yaml")
    assert rep.check_m < 1e-9
    back = load_robot(name, kinematics=out)
    gap = np.linalg.norm(_tool0(back) - _calibrated_tool0(cm), axis=1).max()
    assert gap < 1e-9
    assert np.linalg.norm(_tool0(back) - _tool0(cm.robot), axis=1).max() > 1e-4  # the calibration is in it
    # TCP (reflector) positions predicted by the round-tripped robot equal the model's
    cm2 = CalibratedModel(back, np.zeros(36), setups=cm.setups, default_station="s")
    assert np.abs(cm2.predict(_Q[:50]) - cm.predict(_Q[:50])).max() < 1e-9


def test_rotation_about_a_joint_axis_is_carried_as_that_joints_offset(tmp_path):
    robot = load_robot("ur10")
    p = np.zeros(36)
    p[6 * 2 + 4] = 2e-3  # elbow: the ERD joint turns about its own y axis: a 2 mrad joint zero offset
    cm = CalibratedModel(robot, p, setups={"s": Setup(np.eye(4), np.zeros(3))}, default_station="s")
    out = tmp_path / "k.yaml"
    export_model(cm, out, "ur-yaml")
    back = load_robot("ur10", kinematics=out)
    assert np.linalg.norm(_tool0(back) - _calibrated_tool0(cm), axis=1).max() < 1e-9
    # the same as turning the elbow by 2 mrad on the nominal robot
    Q2 = _Q.copy()
    Q2[:, 2] += 2e-3
    assert np.linalg.norm(_tool0(back) - _tool0(robot, Q2), axis=1).max() < 1e-9
    # and it sits in the forearm's placement only: the others are the nominal ones
    nom = URKinematics.from_values(ur_values_of(robot.model, robot.joint_ids, robot.tool_frame_id,
                                                reference=default_ur_kinematics("ur10")))
    V = read_ur_kinematics(out).values
    changed = np.flatnonzero(np.abs(V - nom.values).max(axis=1) > 1e-12)
    assert list(changed) == [2]


def test_what_the_yaml_cannot_carry_is_said_and_measured(tmp_path):
    from pin_kpi_oed.effects.library import make_effect

    robot = load_robot("ur10")
    eff = make_effect("joint_scale", robot)
    theta = np.full(len(eff.param_names()), 1e-3)
    cm = _model(robot)
    cm = CalibratedModel(robot, cm.joint_p, [eff], [theta], cm.setups, default_station="s")
    out = tmp_path / "k.yaml"
    rep = export_model(cm, out, "ur-yaml")
    assert any("joint_scale" in x for x in rep.lost) and any("set-ups" in x for x in rep.lost)
    assert "joint_scale" in out.read_text().splitlines()[2]  # said in the file's header too
    # the file reproduces the geometry, not the effect: the effect's share is lost (here 1e-3 of each angle)
    back = CalibratedModel(load_robot("ur10", kinematics=out), np.zeros(36), setups=cm.setups, default_station="s")
    lost = np.linalg.norm(back.predict(_Q[:50]) - cm.predict(_Q[:50]), axis=1)
    geometric = CalibratedModel(robot, cm.joint_p, setups=cm.setups, default_station="s")
    assert np.abs(back.predict(_Q[:50]) - geometric.predict(_Q[:50])).max() < 1e-9
    assert lost.max() > 1e-4


def test_model_file_of_a_yaml_robot_holds_its_kinematics(tmp_path):
    kin = tmp_path / "calib.yaml"
    export_model(_model(load_robot("ur10"), seed=5), kin, "ur-yaml")
    robot = load_robot("ur10", kinematics=kin)
    cm = _model(robot, seed=6)
    cm.save(tmp_path / "m.json")
    back = load_model_file(tmp_path / "m.json")
    assert back.robot.kinematics == robot.kinematics
    assert np.abs(back.predict(_Q[:20]) - cm.predict(_Q[:20])).max() < 1e-12
    urdf = tmp_path / "c.urdf"
    rep = export_model(back, urdf, "urdf")  # the shipped UR10's URDF (meshes, link frames) with these origins
    assert rep.check_m < 1e-9 and "meshes/ur10" in urdf.read_text()
    rep = export_model(_model(load_robot("ur5e")), urdf, "urdf")  # an e-series arm: ur_description's chain
    assert rep.check_m < 1e-9 and "base_link_inertia" in urdf.read_text()


def test_e_series_and_cells_take_kinematics(tmp_path):
    r = load_robot("ur5e")
    assert r.kinematics.hash == "calib_12788084448423163542" and abs(r.reach() - 1.04) < 0.01
    with pytest.raises(RobotLoadError, match="ur10e: no default kinematics"):
        load_robot("ur10e")
    from pin_kpi_oed.cell.cell import load_cell

    (tmp_path / "k.yaml").write_text((UR_KINEMATICS_DIR / "ur5.yaml").read_text())
    cell_text = (REPO / "examples" / "ur5_cell.yaml").read_text().replace("tool_frame: tool0", "kinematics: k.yaml")
    (tmp_path / "cell.yaml").write_text(cell_text)
    cell = load_cell(tmp_path / "cell.yaml")
    assert cell.robot.kinematics is not None and cell.robot.kinematics.hash == "calib_209549117540498681"
    assert len(cell.robot_capsules) > 3  # the shipped UR5's collision meshes still hang on its links
    plain = load_cell(REPO / "examples" / "ur5_cell.yaml")
    assert np.linalg.norm(_tool0(cell.robot) - _tool0(plain.robot), axis=1).max() < 1e-9


def test_bad_kinematics_files_are_refused_in_one_line(tmp_path):
    other = UR_KINEMATICS_DIR / "ur5.yaml"
    with pytest.raises(RobotLoadError, match="not a ur10's kinematics .*closest: ur5"):
        load_robot("ur10", kinematics=other)
    with pytest.raises(RobotLoadError, match="not of 'kr15'"):
        load_robot("kr15", kinematics=other)
    bad = tmp_path / "b.yaml"
    bad.write_text((UR_KINEMATICS_DIR / "ur10.yaml").read_text().replace("z: 0.1273", "z: 127.3"))
    with pytest.raises(InputError, match="kinematics.shoulder.z = 127.3 is beyond 5 m: looks like mm"):
        load_robot("ur10", kinematics=bad)
    bad.write_text("kinematics:\n  shoulder: {x: 0}\n")
    with pytest.raises(InputError, match="kinematics.shoulder.y must be a finite number"):
        read_ur_kinematics(bad)
    with pytest.raises(InputError, match="not a Universal Robots arm.*write model_format='urdf'"):
        export_model(_model(load_robot("kr15")), tmp_path / "x.yaml", "ur-yaml")
    assert not (tmp_path / "x.yaml").exists()


def test_export_model_cli(tmp_path, capsys):
    cm = _model(load_robot("ur10"), seed=2)
    cm.save(tmp_path / "m.json")
    assert set(MODEL_FORMATS) == {"urdf", "ur-yaml"}
    assert main(["export-model", "--model", str(tmp_path / "m.json"), "--format", "ur-yaml",
                 "--out", str(tmp_path / "c.yaml")]) == 0
    out = capsys.readouterr().out
    assert "reproduces the calibrated tool frame" in out and "not in this file" in out
    assert main(["export-model", "--model", str(tmp_path / "m.json"), "--format", "urdf",
                 "--out", str(tmp_path / "c.urdf"), "--tcp", "0,0,0.1"]) == 0
    urdf = (tmp_path / "c.urdf").read_text()
    assert 'name="tcp"' in urdf and 'name="tracker_s"' in urdf  # the set-up frames, for TF
    assert "package://example-robot-data/robots/ur_description/meshes/ur10" in urdf  # ROS mesh URIs kept
    back = load_robot("ur10", kinematics=tmp_path / "c.yaml")
    assert np.linalg.norm(_tool0(back) - _calibrated_tool0(cm), axis=1).max() < 1e-9
    # bad input: one line, exit 2, nothing written
    kr = _model(load_robot("kr15"))
    kr.save(tmp_path / "kr.json")
    assert main(["export-model", "--model", str(tmp_path / "kr.json"), "--format", "ur-yaml",
                 "--out", str(tmp_path / "kr.yaml")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not a Universal Robots arm" in err and not (tmp_path / "kr.yaml").exists()
    assert "write --format urdf" in err  # the library's model_format='urdf', in the command line's words
    assert main(["info", "ur10", "--kinematics", str(UR_KINEMATICS_DIR / "ur5.yaml")]) == 2
    assert "not a ur10's kinematics" in capsys.readouterr().err
    assert main(["info", "ur10", "--kinematics", str(tmp_path / "c.yaml"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["robot"]["name"] == "ur10"


def test_an_e_series_arm_goes_through_the_command_line(tmp_path, capsys):
    """simulate -> identify -> predict -> export-model on a UR5e (ur_description's default kinematics): the data's
    tool header names the robot 'ur5e' and every command agrees it is the model's robot."""
    d = tmp_path
    assert main(["simulate", "--robot", "ur5e", "--n", "120", "--n-test", "40", "--reflector", "0.03,0.02,0.08",
                 "--out", str(d / "m.csv"), "--test-out", str(d / "h.csv")]) == 0
    assert main(["identify", "--robot", "ur5e", "--data", str(d / "m.csv"), "--validate", str(d / "h.csv"),
                 "--reflector", "0.03,0.02,0.08", "--sigma", "1e-5", "--model-out", str(d / "model.json"),
                 "--quiet"]) == 0
    assert main(["predict", "--model", str(d / "model.json"), "--data", str(d / "h.csv"), "--out",
                 str(d / "p.csv")]) == 0
    assert main(["export-model", "--model", str(d / "model.json"), "--format", "ur-yaml", "--out",
                 str(d / "k.yaml")]) == 0
    capsys.readouterr()
    cm = load_model_file(d / "model.json")
    assert cm.robot.kinematics.hash == "calib_12788084448423163542"  # the nominal it started from
    back = load_robot("ur5e", kinematics=d / "k.yaml")
    assert np.linalg.norm(_tool0(back) - _calibrated_tool0(cm), axis=1).max() < 1e-9
