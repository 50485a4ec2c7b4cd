"""The calibrated model's route through ``check_calibration`` (``python -m tests.route_count``, docs/ARCHITECTURE.md):
the check hands the model down in one pass and asks it once more only to re-fit a change; the walk follows the model
into containers and leaves out calls that do not carry it."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests._cache_misc import PARSED_GROUP, release_after_last_reader
from tests.route_count import route

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module", autouse=True)
def _trees_dropped_after_the_last_reader(request):
    """The package's trees (tests/_cache_misc.py) dropped after this module unless a later module reads them: kept,
    every garbage collection of the tests that come after walks them."""
    yield
    release_after_last_reader(request)


@pytest.mark.xdist_group(PARSED_GROUP)  # the package's trees, parsed once with tests/test_architecture.py's
def test_the_model_flows_down_the_check_in_one_pass():
    files, climbs = route(ROOT)
    assert files[0] == files[-1] == "upkeep.check"
    assert len(set(files)) <= 6 and climbs <= 3, (files, climbs)
    # the verdict's module hands the model down twice: the rows' pass and the re-fit of a named change
    assert sum(a == "upkeep.check" for a in files[1:-1]) == 1, files


def _package(root: Path, modules: dict[str, str]) -> Path:
    for name, text in modules.items():
        path = root / "pin_kpi_oed" / f"{name.replace('.', '/')}.py"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return root


def test_the_walk_follows_the_model_into_a_container_and_counts_climbs(tmp_path):
    root = _package(tmp_path, {
        "calibrated.model_file": "class CalibratedModel:\n    robot: int\n\n    def station(self):\n        return 1\n",
        "calibrated.view": "def view(box):\n    return box\n",
        "oed.law": "def threshold(x):\n    return x\n",
        "model.joints": "def align(robot):\n    return robot\n",
        "upkeep.check": (
            "from dataclasses import dataclass\n"
            "from pin_kpi_oed.calibrated.model_file import CalibratedModel\n"
            "from pin_kpi_oed.calibrated.view import view\n"
            "from pin_kpi_oed.oed.law import threshold\n"
            "from pin_kpi_oed.model.joints import align\n\n"
            "@dataclass\nclass Box:\n    held: CalibratedModel\n    n: int\n\n"
            "def check_calibration(model):\n"
            "    box = Box(model, 3)\n"
            "    threshold(box.n)\n"            # an array of the container: not the model
            "    view(box)\n"                   # the container carries the model
            "    threshold(3)\n"
            "    align(box.held.robot)\n"       # a part of the model held by the container
            "    box.held.station()\n"),        # a method of the model
    })
    files, climbs = route(root)
    assert files == ["upkeep.check", "calibrated.view", "upkeep.check", "model.joints", "upkeep.check",
                     "calibrated.model_file", "upkeep.check"]
    assert climbs == 2
