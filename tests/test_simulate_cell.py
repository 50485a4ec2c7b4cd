"""simulate: held-out poses feasible in the cell, given poses (--poses), one simulated robot reused (--truth)."""

from __future__ import annotations

import json

import numpy as np

from pin_kpi_oed.data.measurements import read_measurement_tool, read_measurements

from tests.cli_run import run_cli

CELL = "ur10"  # a shipped cell: a table, a pedestal, working configurations




def test_held_out_poses_are_feasible_in_the_cell_and_the_tool_is_the_cells(tmp_path):
    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.cell.feasibility import FeasibilityChecker

    tr, te = tmp_path / "tr.csv", tmp_path / "te.csv"
    rc, out, err = run_cli("simulate", "--cell", CELL, "--n", 12, "--n-test", 30, "--seed", 2, "--out", tr,
                         "--test-out", te)
    assert rc == 0, err
    assert "30 held-out (feasible in the cell)" in out
    cell = load_cell(CELL)
    for f in (tr, te):
        Q = read_measurements(f, joint_names=cell.robot.joint_names).q
        rep = FeasibilityChecker(cell).check(Q)
        assert rep.all_feasible, rep.violations()  # random joint values in the ur10 cell: most hit the table
    tool = read_measurement_tool(te)
    assert tool.tool_frame == cell.robot.tool_frame and np.allclose(tool.reflector_m, cell.reflector_m)
    assert np.allclose(tool.tcp_m, cell.tcp_m) and np.allclose(tool.q_work, cell.q_work)
    rc, _, err = run_cli("simulate", "--cell", CELL, "--reflector", "0,0,0.2", "--out", tmp_path / "x.csv")
    assert rc == 2 and "reflector" in err and "contradicts" in err and not (tmp_path / "x.csv").exists()


def test_truth_file_reuses_the_simulated_robot_at_given_poses(tmp_path):
    tr, te, truth = tmp_path / "tr.csv", tmp_path / "te.csv", tmp_path / "truth.json"
    rc, out, err = run_cli("simulate", "--robot", "kr15", "--n", 20, "--n-test", 8, "--seed", 5, "--effects",
                         "gear_harmonic=5e-5", "--out", tr, "--test-out", te, "--truth", truth)
    assert rc == 0 and "true robot saved to" in out, err
    doc = json.loads(truth.read_text())
    assert doc["format"] == "pin_kpi_oed.truth/1" and doc["effects"][0]["name"] == "gear_harmonic"
    # the same robot measured again at the held-out poses with the same noise seed: the same readings
    again = tmp_path / "again.csv"
    rc, out, err = run_cli("simulate", "--truth", truth, "--poses", te, "--seed", 5, "--out", again)
    assert rc == 0 and "true robot of" in out, err
    a, b = read_measurements(te), read_measurements(again)
    assert np.array_equal(a.q, b.q)
    noise = np.asarray(json.loads(truth.read_text())["noise"]["sigma_xyz_m"], float)
    assert np.all(np.abs(a.position_m - b.position_m) < 10 * noise)  # same robot, other noise draws
    c = tmp_path / "c.csv"
    assert run_cli("simulate", "--truth", truth, "--poses", te, "--seed", 6, "--out", c)[0] == 0
    assert not np.array_equal(read_measurements(c).position_m, b.position_m)
    other = tmp_path / "other.csv"  # a new robot (no --truth): readings differ by the geometric errors
    assert run_cli("simulate", "--robot", "kr15", "--poses", te, "--seed", 7, "--out", other)[0] == 0
    assert np.abs(read_measurements(other).position_m - a.position_m).max() > 1e-4
    assert json.loads(truth.read_text()) == doc  # reused, not rewritten
    rc, _, err = run_cli("simulate", "--truth", truth, "--poses", te, "--effects", "backlash=1e-4", "--out", c)
    assert rc == 2 and "--effects: the true robot comes from --truth" in err
    rc, _, err = run_cli("simulate", "--truth", truth, "--poses", te, "--out", truth)
    assert rc == 2 and json.loads(truth.read_text()) == doc
