"""The tool travels: cell -> measurement CSV header -> identify -> model file -> compensate, and a contradiction is
refused in one line (robot, tool frame, reflector, TCP)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pin_kpi_oed.data.measurements import (MeasurementSet, concat_measurements, read_measurement_tool,
                                           read_measurements, write_measurements)
from pin_kpi_oed.data.tool_header import ToolSpec, resolve_tool
from pin_kpi_oed.errors import InputError

from tests.cli_run import run_cli


def _set(tool: ToolSpec | None, m: int = 4, seed: int = 0) -> MeasurementSet:
    rng = np.random.default_rng(seed)
    return MeasurementSet(["a", "b"], rng.uniform(-1, 1, (m, 2)), rng.uniform(0, 2, (m, 3)), tool=tool)




def test_header_round_trip_keeps_every_field_and_the_line_numbers(tmp_path):
    tool = ToolSpec(robot="panda", tool_frame="panda_link8", reflector_m=[0.0, 0.06, 0.07], tcp_m=[0, 0, 0.1034],
                    q_work=[[0.1, -0.2]])
    f = tmp_path / "m.csv"
    write_measurements(_set(tool), f)
    text = f.read_text()
    assert text.startswith("# pin_kpi_oed.tool/1\n# robot: \"panda\"\n# tool_frame: \"panda_link8\"\n")
    back = read_measurements(f)
    assert back.tool.tool_frame == "panda_link8" and back.tool.robot == "panda"
    assert np.array_equal(back.tool.tcp_m, [0, 0, 0.1034]) and np.array_equal(back.tool.q_work, [[0.1, -0.2]])
    assert read_measurement_tool(f).reflector_m.tolist() == [0.0, 0.06, 0.07]
    write_measurements(back, tmp_path / "again.csv")  # the reader keeps it, the writer writes it back
    assert (tmp_path / "again.csv").read_text() == text
    assert back.subset([0, 2]).tool is back.tool
    bad = text.replace("0.7", "x", 1) if "0.7" in text else text
    lines = text.splitlines()
    lines[7] = lines[7].split(",")[0] + ",oops," + ",".join(lines[7].split(",")[2:])
    f.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=r"row 1 \(line 8\)"):  # data lines counted in the file, header included
        read_measurements(f)
    assert bad


def test_malformed_or_repeated_header_fields_are_refused_with_the_line(tmp_path):
    f = tmp_path / "m.csv"
    f.write_text("# a free comment\n# reflector_m: [0.1, 0.2\na,x,y,z\n0.1,1,2,3\n")
    with pytest.raises(InputError, match=r"m.csv: line 2: header field 'reflector_m' is not a JSON value"):
        read_measurements(f)
    f.write_text("# tool_frame: tool0\n# tool_frame: flange\na,x,y,z\n0.1,1,2,3\n")
    with pytest.raises(InputError, match="line 2: header field 'tool_frame' appears twice"):
        read_measurements(f)
    f.write_text("# tcp_m: [0, 0]\na,x,y,z\n0.1,1,2,3\n")
    with pytest.raises(InputError, match="'tcp_m' must be 3 numbers"):
        read_measurements(f)
    f.write_text("# just a note\na,x,y,z\n0.1,1,2,3\n")  # other comments: no tool, rows read
    ms = read_measurements(f)
    assert ms.tool is None and len(ms) == 1


def test_resolve_names_both_sources_of_a_contradiction():
    a = ToolSpec(tool_frame="panda_link8", tcp_m=[0, 0, 0.1], source="--cell c.yaml")
    b = ToolSpec(tool_frame="panda_hand_tcp", source="train.csv")
    with pytest.raises(InputError) as exc:
        resolve_tool([a, b])
    msg = str(exc.value)
    assert "train.csv: tool frame 'panda_hand_tcp' contradicts 'panda_link8' from --cell c.yaml" in msg
    assert "\n" not in msg
    ok = resolve_tool([a, ToolSpec(tool_frame="panda_link8", reflector_m=[0, 0.06, 0.07], source="t.csv")])
    assert ok.tool_frame == "panda_link8" and ok.reflector_m.tolist() == [0, 0.06, 0.07]
    assert "tool_frame from --cell c.yaml" in ok.source and "reflector_m from t.csv" in ok.source
    with pytest.raises(InputError, match="TCP"):
        resolve_tool([a, ToolSpec(tcp_m=[0, 0, 0.2], source="x")])


def test_concat_joins_stations_of_one_tool_and_refuses_two_tool_frames():
    t1 = ToolSpec(tool_frame="tool0", reflector_m=[0, 0, 0.1], source="B.csv")
    t2 = ToolSpec(tool_frame="tool0", reflector_m=[0, 0, 0.2], source="C.csv")  # another reflector: another station
    both = concat_measurements([_set(t1), _set(t2, seed=1)], labels=["B", "C"])
    assert both.tool.tool_frame == "tool0"
    with pytest.raises(InputError, match="C.csv: tool frame 'flange' contradicts 'tool0' from B.csv"):
        concat_measurements([_set(t1), _set(ToolSpec(tool_frame="flange", source="C.csv"), seed=1)],
                            labels=["B", "C"])


def test_identify_api_refuses_data_of_another_tool_frame():
    from pin_kpi_oed.identification.identify import identify
    from pin_kpi_oed.model.robot import load_robot
    from pin_kpi_oed.model.tracker import TrackerModel

    robot = load_robot("kr15")
    Q = robot.random_q(np.random.default_rng(0), 30)
    data = MeasurementSet(list(robot.joint_names), Q, np.ones((30, 3)) + Q[:, :3] * 0.1,
                          tool=ToolSpec(tool_frame="flange", source="meas.csv"))
    with pytest.raises(InputError, match=r"meas.csv: measured in tool frame 'flange' \(its header\), the model uses "
                                         r"'tool0': load the robot with tool frame 'flange'"):
        identify(TrackerModel(robot, reflector_m=np.zeros(3)), data)


def test_every_tool_help_states_the_panda_default(capsys):
    from pin_kpi_oed.cli.app import build_parser

    parser = build_parser()
    for cmd in ("identify", "diagnose", "simulate", "info"):
        with pytest.raises(SystemExit):
            parser.parse_args([cmd, "--help"])
        text = " ".join(capsys.readouterr().out.split())
        assert "panda_hand_tcp for panda" in text and "tool0 for the other robots" in text, cmd


def test_simulate_identify_carry_the_tool_and_refuse_a_contradiction(tmp_path):
    tr, te, model = tmp_path / "tr.csv", tmp_path / "te.csv", tmp_path / "m.json"
    rc, out, err = run_cli("simulate", "--robot", "kr15", "--tool", "link_6", "--reflector", "0.03,0.02,0.08", "--n",
                         "40", "--n-test", "5", "--out", tr, "--test-out", te)
    assert rc == 0, err
    assert read_measurement_tool(tr).tool_frame == "link_6" and read_measurement_tool(te).tool_frame == "link_6"
    rc, out, err = run_cli("identify", "--data", tr, "--model-out", model, "--accept-poor-fit")  # no --robot: header
    assert rc == 0, err
    assert "tool: tool frame link_6, reflector [30.0, 20.0, 80.0] mm" in out
    d = json.loads(model.read_text())
    assert d["robot"]["tool_frame"] == "link_6" and d["robot"]["spec"] == "kr15"
    rc, out, err = run_cli("identify", "--robot", "kr15", "--data", tr, "--tool", "tool0")
    assert rc == 2 and err.strip().count("\n") == 0
    assert f"{tr}: tool frame 'link_6' contradicts 'tool0' from --tool tool0" in err
    rc, out, err = run_cli("identify", "--robot", "kr15", "--data", tr, "--reflector", "0.03,0.02,0.09")
    assert rc == 2 and "reflector" in err and "contradicts" in err
    rc, out, err = run_cli("identify", "--robot", "ur5", "--data", tr)
    assert rc == 2 and "robot" in err and "contradicts" in err
    rc, out, err = run_cli("design", "--cell", "kr15", "--model", model, "--criteria", "kpi", "--json",
                         tmp_path / "d.json")  # the cell's tool0 against the model's link_6
    assert rc == 2 and "--cell kr15: tool frame 'tool0' contradicts 'link_6' from --model" in err
    assert not (tmp_path / "d.json").exists()
    rc, out, err = run_cli("predict", "--model", model, "--data", te, "--out", tmp_path / "p.csv")
    assert rc == 0 and "(the station's reflector in tool frame link_6)" in out, err
    rc, out, err = run_cli("register", "--model", model, "--data", te, "--model-out", tmp_path / "r.json")
    assert "contradicts" not in err
    te2 = tmp_path / "te2.csv"
    ms = read_measurements(te)
    ms.tool = ToolSpec(tool_frame="tool0", source=str(te2))
    write_measurements(ms, te2)
    rc, out, err = run_cli("register", "--model", model, "--data", te2, "--model-out", tmp_path / "r2.json")
    assert rc == 2 and "tool frame 'tool0' contradicts 'link_6'" in err
    assert not (tmp_path / "r2.json").exists()


def test_model_file_keeps_working_configurations_and_the_tcp_source(tmp_path):
    from pin_kpi_oed.compensation.compensator import PoseModel
    from pin_kpi_oed.calibrated.model_file import CalibratedModel, Setup, load_model_file
    from pin_kpi_oed.model.robot import load_robot

    robot = load_robot("kr15")
    setup = Setup(tracker_T_base=np.eye(4), reflector_m=np.array([0.03, 0.02, 0.08]))
    cm = CalibratedModel(robot, np.zeros(6 * robot.nq), setups={"A": setup}, tcp_m=np.array([0.0, 0.0, 0.2]),
                         q_work=robot.neutral()[None], tool_source="--cell c.yaml")
    cm.save(tmp_path / "m.json")
    back = load_model_file(tmp_path / "m.json")
    assert back.tool_source == "--cell c.yaml" and np.array_equal(back.q_work, robot.neutral()[None])
    assert np.array_equal(PoseModel(back, "base").tcp, [0, 0, 0.2])  # the stated TCP is compensate's default
    plain = CalibratedModel(robot, np.zeros(6 * robot.nq), setups={"A": setup}, tcp_m=np.array([0.0, 0.0, 0.2]))
    assert np.array_equal(PoseModel(plain, "base").tcp, [0.03, 0.02, 0.08])  # not stated: the reflector, as before
    d = json.loads((tmp_path / "m.json").read_text())
    d["q_work"] = [[0.1, 0.2]]
    (tmp_path / "bad.json").write_text(json.dumps(d))
    with pytest.raises(InputError, match="q_work"):
        load_model_file(tmp_path / "bad.json")


def test_header_carries_the_nests_and_refuses_bad_or_contradicting_ones(tmp_path):
    """The reflector nests (k, 3) m travel in the header and back; nest 0 must be the reflector; a header whose
    nests differ from the cell's relative to nest 0 is a contradiction, one that only moves them all is not."""
    nests = [[0.0, 0.06, 0.07], [0.05, 0.0, 0.07]]
    tool = ToolSpec(robot="panda", reflector_m=nests[0], nests_m=nests)
    f = tmp_path / "m.csv"
    write_measurements(_set(tool), f)
    assert '# nests_m: [[0.0, 0.06, 0.07], [0.05, 0.0, 0.07]]' in f.read_text()
    back = read_measurements(f)
    assert np.array_equal(back.tool.nests_m, nests) and np.array_equal(read_measurement_tool(f).nests_m, nests)
    with pytest.raises(InputError, match="field 'nests_m': nest 0"):
        ToolSpec(reflector_m=nests[1], nests_m=nests, source="h.csv")
    with pytest.raises(InputError, match="field 'nests_m' must be a list of"):
        ToolSpec(nests_m=[0.0, 0.06, 0.07], source="h.csv")
    moved = ToolSpec(nests_m=np.array(nests) + 0.01, source="b.csv")  # another station's reflector: not compared
    assert np.array_equal(resolve_tool([tool, moved]).nests_m, nests)
    other = ToolSpec(nests_m=[nests[0], [0.09, 0.0, 0.07]], source="c.csv")
    with pytest.raises(InputError, match="c.csv: reflector nests"):
        resolve_tool([tool, other])
