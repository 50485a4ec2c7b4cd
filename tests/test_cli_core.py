"""CLI of the core: info, evaluate, and one-line errors on bad input (no traceback)."""

from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest

from pin_kpi_oed.model.robot import load_robot

from .cli_run import run_cli_as_process as run


def assert_clean_error(res: subprocess.CompletedProcess, *needles: str) -> None:
    assert res.returncode != 0
    assert "Traceback" not in res.stderr
    lines = [ln for ln in res.stderr.strip().splitlines() if ln.strip()]
    assert len(lines) == 1, res.stderr
    for n in needles:
        assert n in lines[0], lines[0]


def test_info_prints_rank_and_explains_on_axis_reflector():
    res = run("info", "ur10", "--reflector", "0.05,0.02,0.05")
    assert res.returncode == 0, res.stderr
    assert "identifiable (rank): 27" in res.stdout
    res = run("info", "ur10", "--reflector", "0,0,0.1")
    assert "identifiable (rank): 25" in res.stdout
    assert "rank drops by 2" in res.stdout


BRANCHED = """<robot name="branched">
  <link name="base"/><link name="a"/><link name="b"/><link name="c"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="a"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="base"/><child link="b"/><axis xyz="0 1 0"/>
    <origin xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="j3" type="revolute"><parent link="a"/><child link="c"/><axis xyz="0 1 0"/>
    <origin xyz="1 0 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
</robot>
"""


@pytest.mark.parametrize("content,tool,needle", [
    (None, None, "no such URDF file"),
    ("<robot name='x'><link name='a'>", None, "malformed URDF"),
    ("hello world", None, "malformed URDF"),
    ("<sdf version='1.6'/>", None, "not a URDF"),
])
def test_bad_urdf_gives_one_line(tmp_path, content, tool, needle):
    path = tmp_path / "robot.urdf"
    if content is not None:
        path.write_text(content)
    args = ["info", str(path)] + (["--tool", tool] if tool else [])
    assert_clean_error(run(*args), needle, str(path))


def test_branch_off_the_chain_is_locked_at_neutral_and_said(tmp_path):
    """j2 branches off the chain base -> j1 -> j3 -> c: the arm is j1, j3; j2 is locked at neutral, in the note."""
    path = tmp_path / "robot.urdf"
    path.write_text(BRANCHED)
    res = run("info", str(path), "--tool", "c")
    assert res.returncode == 0, res.stderr
    assert "locked joints: j2" in res.stdout
    assert ("note: joint(s) j2 branch off the chain to 'c': locked at neutral, clipped into their limits (their links "
            "stay in the model and its collision geometry at that posture)") in res.stdout.splitlines()
    assert load_robot(str(path), tool_frame="c").joint_names == ["j1", "j3"]


def test_unknown_tool_frame():
    assert_clean_error(run("info", "kr15", "--tool", "flange9"), "unknown tool frame 'flange9'")


def _design_json(tmp_path, q_meas, q_work=None):
    rb = load_robot("kr15")
    d = {"robot": "kr15", "tracker_T_base": np.eye(4).tolist(), "reflector_m": [0.05, 0.02, 0.05],
         "noise": {"sigma_xyz_m": [1e-6] * 3}, "q_meas": q_meas,
         "q_work": q_work if q_work is not None else [rb.neutral().tolist()]}
    d["tracker_T_base"][0][3] = 3.0
    path = tmp_path / "design.json"
    path.write_text(json.dumps(d))
    return path


def test_evaluate_scores_every_criterion(tmp_path):
    rb = load_robot("kr15")
    Q = rb.random_q(np.random.default_rng(0), 40).tolist()
    out = tmp_path / "scores.json"
    res = run("evaluate", str(_design_json(tmp_path, Q)), "--json", str(out))
    assert res.returncode == 0, res.stderr
    d = json.loads(out.read_text())
    assert set(d["criteria"]) >= {"kpi", "param", "D", "E", "cond", "O1", "O2", "O3", "O4", "O5"}
    assert d["criteria"]["kpi"] == pytest.approx(d["trace_cs_m2"])
    assert d["rank"] == 27
    assert res.stdout.splitlines()[0] == (f"scored q_meas of {tmp_path / 'design.json'}: 40 measurement "
                                          "configurations, KPI at 1 working configuration(s)")
    assert d["design"] == {"file": str(tmp_path / "design.json"), "criterion": None, "n_meas": 40, "n_work": 1}
    # a criterion this file cannot be scored under is named with its reason, never silently left out
    assert "kpi_path" not in d["criteria"] and "working_paths" in d["not_scored"]["kpi_path"]
    assert any(line.startswith("kpi_path") and "not scored: " in line for line in res.stdout.splitlines())
    doc = json.loads((tmp_path / "design.json").read_text())
    (tmp_path / "design.json").write_text(json.dumps({**doc, "q_meas_criterion": "kpi"}))
    res = run("evaluate", str(tmp_path / "design.json"))
    assert res.stdout.splitlines()[0].startswith(f"scored design 'kpi' (its q_meas) of {tmp_path / 'design.json'}")


def test_evaluate_rejects_out_of_limits_and_nan(tmp_path):
    rb = load_robot("kr15")
    Q = rb.random_q(np.random.default_rng(0), 40)
    Q[3, 1] = 2.5
    assert_clean_error(run("evaluate", str(_design_json(tmp_path, Q.tolist()))), "joint_a2", "outside its limits")
    Q[3, 1] = 0.0
    Qs = Q.tolist()
    Qs[5][2] = float("nan")
    assert_clean_error(run("evaluate", str(_design_json(tmp_path, Qs))), "joint_a3", "not finite")


def test_evaluate_too_few_measurements(tmp_path):
    rb = load_robot("kr15")
    Q = rb.random_q(np.random.default_rng(0), 5).tolist()
    assert_clean_error(run("evaluate", str(_design_json(tmp_path, Q))), "measure at least 9")


def test_simulate_needs_robot_or_design_not_both(tmp_path):
    """``simulate``: random poses of --robot or the poses of --design, one clear line otherwise, nothing written."""
    out = tmp_path / "m.csv"
    assert_clean_error(run("simulate", "--out", str(out)), "--robot", "--design")
    design = tmp_path / "d.json"
    design.write_text(json.dumps({"robot": "kr15", "designs": [{"criterion": "kpi", "q_meas": [[0.0] * 6] * 3}]}))
    assert_clean_error(run("simulate", "--robot", "kr15", "--design", str(design), "--out", str(out)), "not both")
    assert_clean_error(run("simulate", "--robot", "kr15", "--criterion", "kpi", "--out", str(out)), "--criterion")
    assert not out.exists()


def test_simulate_design_measures_the_design_poses(tmp_path):
    rng = np.random.default_rng(0)
    Q = load_robot("kr15").random_q(rng, 14)
    design = tmp_path / "d.json"
    design.write_text(json.dumps({"robot": "kr15", "reflector_m": [0.05, 0.0, 0.1],
                                  "designs": [{"criterion": "random", "q_meas": Q[:10].tolist()},
                                              {"criterion": "kpi", "q_meas": Q.tolist()}]}))
    res = run("simulate", "--design", str(design), "--out", str(tmp_path / "m.csv"))
    assert res.returncode == 0, res.stderr
    assert "design 'kpi'" in res.stdout
    text = (tmp_path / "m.csv").read_text()
    assert '# tool_frame: "tool0"' in text and "# reflector_m: [0.05, 0.0, 0.1]" in text  # the design's tool
    lines = [ln for ln in text.splitlines() if not ln.startswith("#")]
    head = lines[0].split(",")
    joints = np.array([[float(v) for v in ln.split(",")[:6]] for ln in lines[1:]])
    assert head[:6] == list(load_robot("kr15").joint_names) and np.allclose(joints, Q, atol=1e-9)
    res = run("simulate", "--design", str(design), "--criterion", "random", "--out", str(tmp_path / "r.csv"))
    rows = [ln for ln in (tmp_path / "r.csv").read_text().splitlines() if not ln.startswith("#")]
    assert res.returncode == 0 and len(rows) == 1 + 10


@pytest.mark.parametrize("argv, expect", [
    (["design", "--robot-class", "heavy"], "argument --robot-class: invalid choice: 'heavy'"),
    (["design", "--measurements", "x"], "argument --measurements: invalid int value: 'x'"),
    (["nosuch"], "argument command: invalid choice: 'nosuch'"),
    ([], "the following arguments are required: command"),
])
def test_usage_errors_are_one_line_and_exit_2(argv, expect, capsys):
    """A usage error (unknown choice, wrong type, missing command) is one line naming the option, exit 2."""
    from pin_kpi_oed.cli.app import main

    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and expect in err[0] and err[0].endswith("--help")


def test_library_errors_name_parameters_and_the_command_line_its_options():
    """The design library names the parameter (``clearance_margin_m``), the command line the option that sets it."""
    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.cli.flags import PARAMETER_FLAGS, in_flags
    from pin_kpi_oed.design.margins import with_margins
    from pin_kpi_oed.errors import InputError

    with pytest.raises(InputError, match=r"^parameter 'clearance_margin_m' must be in \[0, 1\) m") as err:
        with_margins(load_cell("kr15"), -0.01, 0.0)
    assert in_flags(str(err.value)).startswith("--clearance-margin must be in [0, 1) m")
    # a field of a file the command line reads stays the field: the cell file's reflector_m is no --reflector
    assert in_flags("cell.yaml: reflector_m: 134.2 m from the tool frame") == \
        "cell.yaml: reflector_m: 134.2 m from the tool frame"
    assert in_flags("give reflector_m=0.1 or parameter 'tool_frame'") == "give --reflector 0.1 or --tool"
    assert in_flags("cell c: Q_given: 3 poses; target_sigma_m: 0") == "cell c: --given: 3 poses; --target-sigma: 0"
    assert in_flags("clearance_m of the cell file") == "clearance_m of the cell file"  # a word, not a parameter
    assert all(f.startswith("--") for f in PARAMETER_FLAGS.values())
    # a one-word parameter is rewritten only where marked, never as a word of the sentence
    assert in_flags("diagnose: parameter 'kfold' must be >= 2") == "diagnose: --kfold must be >= 2"
    assert in_flags("declare the units (units='mm,deg')") == "declare the units (--units mm,deg)"
    assert in_flags("the units of sigma: m") == "the units of sigma: m"
    assert in_flags("parameter 'speed' and speed='1'") == "parameter 'speed' and speed='1'"  # not in the table
    from pin_kpi_oed.cli.flags import in_flags_all

    quality = {"advice": ["loss='soft_l1' (robust), sigma columns or parameter 'sigma_xyz_m'"], "dof": 3,
               "verdict": "suspect"}
    assert in_flags_all(quality) == {"advice": ["--loss soft_l1 (robust), sigma columns or --sigma"], "dof": 3,
                                     "verdict": "suspect"}
