"""Every script in examples/ runs to completion (so they never rot): with ``--quick`` where the script has it (the
same steps on smaller sizes; its documented Run line is the full run)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from .conftest import REPO

EXAMPLES = sorted((REPO / "examples").glob("*.py"))


@pytest.mark.parametrize("script", EXAMPLES, ids=[p.name for p in EXAMPLES])
def test_example_runs(script, tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "PIN_KPI_OED_QUICK"}   # the flag alone makes a run quick
    env["MPLBACKEND"] = "Agg"
    quick = ["--quick"] if '"--quick"' in script.read_text() else []
    res = subprocess.run([sys.executable, str(script), *quick], cwd=tmp_path, capture_output=True, text=True, env=env,
                         timeout=240)
    assert res.returncode == 0, f"{script.name} failed:\n{res.stdout[-2000:]}\n{res.stderr[-3000:]}"
    assert res.stdout.strip(), f"{script.name} printed nothing"
