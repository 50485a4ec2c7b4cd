"""Several reflector nests through the files: a cell listing nests makes ``design`` choose and store each pose's
nest (and ``simulate --design`` measure it), and a calibrated model file keeps the nests and predicts each row at
its nest."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from tests.cli_run import run_cli

CELLS = Path(__file__).resolve().parents[1] / "pin_kpi_oed" / "cell" / "cells"
NESTS = [[0.06, 0.0, 0.12], [0.0, 0.0, 0.12]]  # the kr15 cell's reflector (off the flange axis), one on the axis


def _cell_with_nests(tmp_path: Path, nests=NESTS) -> Path:
    """The kr15 cell with two nests and its TCP 0.15 m off the flange axis: the last joint's rotation about its
    axis moves the TCP, and only a second nest determines it (one nest's offset absorbs it)."""
    d = yaml.safe_load((CELLS / "kr15.yaml").read_text())
    d["nests_m"], d["tcp_m"] = nests, [0.15, 0.0, 0.2]
    path = tmp_path / "kr15_nests.yaml"
    path.write_text(yaml.safe_dump(d))
    return path


def test_cell_reads_and_writes_its_nests(tmp_path):
    from pin_kpi_oed.cell.cell import load_cell

    cell = load_cell(str(_cell_with_nests(tmp_path)))
    assert np.allclose(cell.nests_m, NESTS)
    assert cell.tracker_model().n_nests == 2 and np.allclose(cell.tracker_model().nests_m, NESTS)
    assert np.allclose(cell.to_dict()["nests_m"], NESTS)
    assert load_cell("kr15").nests_m is None and "nests_m" not in load_cell("kr15").to_dict()


@pytest.mark.parametrize("nests, message", [([[0.0, 0.0, 0.12], [0.06, 0.0, 0.12]], "nest 0"),
                                            ([[60.0, 0.0, 120.0]], "look like mm")])
def test_bad_cell_nests_are_refused_in_one_line(tmp_path, nests, message):
    rc, out, err = run_cli("design", "--cell", _cell_with_nests(tmp_path, nests), "--criteria", "random",
                           "--measurements", "8")
    assert rc == 2 and "nests_m" in err and message in err and "Traceback" not in err


def test_design_chooses_stores_and_simulate_measures_the_nests(tmp_path):
    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.oed.nests import assign_nests

    cell_file, out = _cell_with_nests(tmp_path), tmp_path / "design.json"
    rc, printed, err = run_cli("design", "--cell", cell_file, "--criteria", "random", "--measurements", "12",
                               "--seed", "0", "--json", out)
    assert rc == 0, err
    line = next(x for x in printed.splitlines() if x.startswith("nests of random:"))
    assert "with nest 0 alone tr(C_s) =" in line
    doc = json.loads(out.read_text())
    d = doc["designs"][0]
    assert len(d["nest"]) == 12 and set(d["nest"]) == {0, 1} and "% less" in line
    assert d["nests"]["chosen"]["held_m2"] + d["nests"]["chosen"]["identified_m2"] < 0.95 * (
        d["nests"]["one"]["held_m2"] + d["nests"]["one"]["identified_m2"])
    assert set(d["nests"]["chosen"]["held_names"]) < set(d["nests"]["one"]["held_names"])  # the second nest
    # determines a parameter of the last joint nest 0 leaves held
    assert {n.split(".")[0] for n in set(d["nests"]["one"]["held_names"]) - set(d["nests"]["chosen"]["held_names"])} \
        == {"joint_a6"}
    cell = load_cell(str(cell_file))  # the stored nests are the ones the KPI chooses for the stored poses
    again = assign_nests(cell.tracker_model(), np.asarray(d["q_meas"]), cell.q_work, seed=0)
    assert again.nest.tolist() == d["nest"] and again.line() == d["nests"]["line"] == line.split(": ", 1)[1]
    assert np.allclose(doc["cell"]["nests_m"], NESTS) and np.allclose(doc["nests_m"], NESTS)
    from pin_kpi_oed.design.design_file import load_design

    df = load_design(out)  # the stored cell read back (as simulate, view and export read it)
    assert np.allclose(df.cell.nests_m, NESTS) and np.allclose(df.model.nests_m, NESTS)
    assert df.designs[0].info["nest"] == d["nest"]
    csv = tmp_path / "train.csv"
    rc, _, err = run_cli("simulate", "--design", out, "--out", csv, "--n-test", "0", "--seed", "1")
    assert rc == 0, err
    from pin_kpi_oed.data.measurements import read_measurements

    ms = read_measurements(str(csv), joint_names=cell.robot.joint_names)
    assert ms.extra["nest"].astype(int).tolist() == d["nest"]


def test_model_file_keeps_the_nests_and_predicts_each_row_at_its_nest(tmp_path):
    """A fit on rows at two nests (a truth with joint errors, 1 µm noise): the model file written and read back holds
    the fitted nests, and predicts held-out rows at their nests to the noise level; the same rows read as nest 0
    are off by the nests' distance. A registration of a moved tracker on rows at both nests keeps them too."""
    from pin_kpi_oed.calibrated.model_file import load_model_file
    from pin_kpi_oed.identification.identify import identify
    from pin_kpi_oed.model.noise import NoiseModel
    from pin_kpi_oed.model.robot import load_robot
    from pin_kpi_oed.model.tracker import TrackerModel
    from pin_kpi_oed.simulation.simulator import default_tracker_pose, random_truth, simulate

    rb, nests = load_robot("ur5"), [[0.0, 0.0, 0.0], [0.06, 0.0, 0.05]]
    model = TrackerModel(rb, tracker_T_base=default_tracker_pose(rb), reflector_m=nests[0], nests_m=nests,
                         tcp_m=np.array([0.0, 0.0, 0.15]), noise=NoiseModel(sigma_xyz_m=(1e-6,) * 3))
    truth, rng = random_truth(model, seed=2), np.random.default_rng(1)
    Q, Qt = rb.random_q(rng, 36), rb.random_q(rng, 10)
    train = simulate(model, Q, truth, nest=np.arange(36) % 2, seed=3)
    test = simulate(model, Qt, truth, nest=np.arange(10) % 2, seed=4)
    cm = identify(model, train, discrepancy="none").calibrated_model()
    cm.save(tmp_path / "model.json")
    back = load_model_file(tmp_path / "model.json")
    st = next(iter(back.setups.values()))
    assert st.nests_m is not None and st.nests_m.shape == (2, 3)
    assert np.allclose(st.nests_m, next(iter(cm.setups.values())).nests_m, atol=0)
    assert np.allclose(st.nests_m[1] - st.nests_m[0], np.subtract(nests[1], nests[0]), atol=1e-12)
    err = np.linalg.norm(back.predict(test.q, aux=test) - test.position_m, axis=1)
    assert err.max() < 2e-5
    from pin_kpi_oed.identification.heldout import validate

    assert np.abs(validate(back, test)["residuals_m"]).max() < 2e-5  # the held-out validation, row at its nest
    from pin_kpi_oed.upkeep.transfer import register_setup

    moved = simulate(model, Qt, truth, nest=np.arange(10) % 2, seed=5)  # another session: the tracker moved
    moved.position_m = moved.position_m @ np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]).T + 0.5
    reg = register_setup(back, moved, station="B", check=False).model
    assert np.allclose(reg.setups["B"].nests_m[1] - reg.setups["B"].nests_m[0], np.subtract(nests[1], nests[0]))
    assert np.linalg.norm(reg.predict(Qt, aux=moved, station="B") - moved.position_m, axis=1).max() < 2e-5
    test.extra.pop("nest")
    err0 = np.linalg.norm(back.predict(test.q, aux=test) - test.position_m, axis=1)
    assert np.all(err0[1::2] > 0.05) and err0[0::2].max() < 2e-5


def test_measurement_header_carries_the_nests_and_identify_needs_no_cell(tmp_path):
    """simulate --design writes the cell's nests in the measurement file's tool header; identify on that file
    alone (robot, tool and nests from the header) fits each row at its nest, the same model as with the cell."""
    from pin_kpi_oed.calibrated.model_file import load_model_file
    from pin_kpi_oed.data.measurements import read_measurement_tool

    cell_file, design = _cell_with_nests(tmp_path), tmp_path / "design.json"
    assert run_cli("design", "--cell", cell_file, "--criteria", "random", "--measurements", "40", "--seed", "0",
                   "--json", design, "--quiet")[0] == 0
    csv = tmp_path / "train.csv"
    assert run_cli("simulate", "--design", design, "--out", csv, "--n-test", "0", "--seed", "1")[0] == 0
    assert np.allclose(read_measurement_tool(str(csv)).nests_m, NESTS)
    rc, _, err = run_cli("identify", "--data", csv, "--model-out", tmp_path / "alone.json", "--accept-poor-fit")
    assert rc == 0, err
    rc, _, err = run_cli("identify", "--data", csv, "--cell", cell_file, "--model-out", tmp_path / "cell.json",
                         "--accept-poor-fit")
    assert rc == 0, err
    alone, with_cell = load_model_file(tmp_path / "alone.json"), load_model_file(tmp_path / "cell.json")
    st = next(iter(alone.setups.values()))
    assert st.nests_m is not None and np.allclose(st.nests_m[1] - st.nests_m[0], np.subtract(NESTS[1], NESTS[0]))
    assert st.rms_m < 1e-4  # each row fitted at its own nest (at nest 0 they would be ~60 mm off)
    np.testing.assert_allclose(alone.joint_p, with_cell.joint_p, atol=1e-7)
