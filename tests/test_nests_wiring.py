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
    csv = tmp_path / "train.csv"
    rc, _, err = run_cli("simulate", "--design", out, "--out", csv, "--n-test", "0", "--seed", "1")
    assert rc == 0, err
    from pin_kpi_oed.data.measurements import read_measurements

    ms = read_measurements(str(csv), joint_names=cell.robot.joint_names)
    assert ms.extra["nest"].astype(int).tolist() == d["nest"]
