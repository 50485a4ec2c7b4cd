"""The Python surface: every exported name resolves, none hides a module, ``import pin_kpi_oed`` stays cheap."""

from __future__ import annotations

import importlib
import pkgutil
import subprocess
import sys

import pytest

import pin_kpi_oed

SUBPACKAGES = ["calibrated", "calibrated.formats", "cell", "compensation", "data", "design", "diagnosis", "effects",
               "identification", "model", "oed", "program", "simulation", "upkeep", "viz"]


@pytest.mark.parametrize("name", ["", *SUBPACKAGES])
def test_exports_resolve_and_hide_no_module(name: str) -> None:
    pkg = importlib.import_module("pin_kpi_oed" + (f".{name}" if name else ""))
    assert pkg.__all__, f"{pkg.__name__} exports nothing"
    modules = {m.name for m in pkgutil.iter_modules(pkg.__path__)}
    # a re-exported function named like a module of the package would be replaced by that module on its import
    assert not set(pkg.__all__) & modules, f"{pkg.__name__}: exports named like its modules"
    for export in pkg.__all__:
        value = getattr(pkg, export)
        assert value is not None and not isinstance(value, type(pkg)), f"{pkg.__name__}.{export}"
        assert export in dir(pkg)


def test_pipeline_names_are_the_defining_objects() -> None:
    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.identification.heldout import validate
    from pin_kpi_oed.identification.identify import identify
    from pin_kpi_oed.simulation.simulator import simulate

    assert pin_kpi_oed.load_cell is load_cell and pin_kpi_oed.identify is identify
    assert pin_kpi_oed.simulate is simulate and pin_kpi_oed.validate is validate
    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        pin_kpi_oed.no_such_name  # noqa: B018


def test_import_stays_cheap() -> None:
    """``import pin_kpi_oed`` loads the robot model only: no SciPy optimiser, IPOPT, Coal checks or pandas."""
    code = ("import sys, pin_kpi_oed; heavy = [m for m in ('scipy.optimize', 'cyipopt', 'pandas', "
            "'pin_kpi_oed.identification.identify', 'pin_kpi_oed.design.optimize') if m in sys.modules]; print(heavy)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "[]", f"import pin_kpi_oed loads {out}"


def test_design_file_written_from_python_is_read_back(tmp_path) -> None:
    """``write_design`` writes what ``load_design`` (and so ``view`` / ``export``) reads: same poses, same C_s."""
    import numpy as np

    cell = pin_kpi_oed.load_cell("kr15")
    problem = pin_kpi_oed.DesignProblem(cell)
    designs = pin_kpi_oed.run_designs(cell, ["random"], m=12, problem=problem)
    run = pin_kpi_oed.DesignRun(cell=cell, problem=problem, results=designs, m=12, seed=0)
    path = pin_kpi_oed.write_design(tmp_path / "d.json", run)
    df = pin_kpi_oed.load_design(path)
    entry = df.design("random")
    np.testing.assert_allclose(entry.q_meas, designs[0].q_meas, atol=1e-12)
    assert entry.trace_cs_m2 == pytest.approx(designs[0].trace_cs_m2, rel=1e-9)
    assert df.robot.name == cell.robot.name and not df.notes
