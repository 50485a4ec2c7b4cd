"""A design file's stored cell is read by the cell file's reader (``cell_from_dict``): the same cell as
``load_cell``, and the same refusals."""

from __future__ import annotations

import argparse
import copy
import json
import re

import numpy as np
import pytest

from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.design.design_cell import stored_cell
from pin_kpi_oed.design.design_file import load_design
from pin_kpi_oed.errors import InputError


@pytest.fixture(scope="module")
def design_json(tmp_path_factory) -> dict:
    from pin_kpi_oed.cli import design as cli_design

    out = tmp_path_factory.mktemp("designed") / "design.json"
    ns = argparse.Namespace(cell="kr15", criteria="random", measurements=12, seed=0, json=str(out),
                            no_collision=False, starts=1, max_iter=5, quiet=True)
    assert cli_design.run(ns) == 0
    return json.loads(out.read_text())


def test_stored_cell_is_the_cell_files(design_json):
    assert stored_cell(design_json) is not None
    cell, df = load_cell("kr15"), load_design(design_json)
    got = df.cell
    assert [c.to_dict() for c in got.robot_capsules] == [c.to_dict() for c in cell.robot_capsules]
    assert [c.to_dict() for c in got.obstacles] == [c.to_dict() for c in cell.obstacles]
    assert [h.to_dict() for h in got.half_spaces] == [h.to_dict() for h in cell.half_spaces]
    assert sorted(got.skip_pairs) == sorted(cell.skip_pairs) and got.beam_skip == cell.beam_skip
    assert (got.beam_radius_m, got.incidence_max_deg, got.clearance_m) == \
        (cell.beam_radius_m, cell.incidence_max_deg, cell.clearance_m)
    np.testing.assert_array_equal(got.q_work, cell.q_work)
    np.testing.assert_array_equal(got.q_lower, cell.q_lower)
    np.testing.assert_allclose(got.W_T_tracker.homogeneous, cell.W_T_tracker.homogeneous, atol=1e-12)
    assert got.orientation_length_m == cell.orientation_length_m and got.measurements == cell.measurements


@pytest.mark.parametrize("edit, message", [
    (lambda c: c["skip_pairs"].append(["link_2", "lnk_5"]), "unknown link or obstacle name 'lnk_5'"),
    (lambda c: c["beam"].update(radius_m=-0.01), "beam.radius_m: -0.01 is less than the minimum of 0"),
    (lambda c: c.update(incidence_max_deg=200.0), "incidence_max_deg: 200.0 is greater than the maximum of 180"),
    (lambda c: c.update(clearance_m=-1.0), "clearance_m: -1.0 is less than the minimum of 0"),
    (lambda c: c.update(q_lower_rad=c["q_upper_rad"]), "bounds"),
])
def test_a_damaged_stored_cell_is_refused_as_a_cell_file_would_be(design_json, edit, message):
    """What the cell file's reader refuses in a cell file, the design file's reader refuses in its stored cell
    (the tolerant reader took these as given)."""
    d = copy.deepcopy(design_json)
    edit(d["cell"])
    with pytest.raises(InputError, match=re.escape(message)) as exc:
        load_design(d)
    assert "cell" in str(exc.value) and "\n" not in str(exc.value)
