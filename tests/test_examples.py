"""Every script in examples/ runs to completion (so they never rot): with ``--quick`` where the script has it (the
same steps on smaller sizes; its documented Run line is the full run).

The scripts run in the test's process (``runpy``, as ``python script.py`` runs them: ``__main__``, the script's
folder first on the path, its arguments in ``sys.argv``, the test's folder as the working folder): a fresh
interpreter per script cost about 1.5 s CPU of start-up and imports each, and these tests are about the scripts,
not about the process (tests/test_cli_startup.py covers the command line's start-up)."""

from __future__ import annotations

import runpy
import sys

import pytest

from .conftest import REPO

EXAMPLES = sorted((REPO / "examples").glob("*.py"))


@pytest.mark.parametrize("script", EXAMPLES, ids=[p.name for p in EXAMPLES])
def test_example_runs(script, tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("PIN_KPI_OED_QUICK", raising=False)     # the flag alone makes a run quick
    monkeypatch.setenv("MPLBACKEND", "Agg")
    quick = ["--quick"] if '"--quick"' in script.read_text() else []
    monkeypatch.setattr(sys, "argv", [str(script), *quick])
    monkeypatch.syspath_prepend(str(script.parent))
    monkeypatch.chdir(tmp_path)
    code: object = 0
    try:
        runpy.run_path(str(script), run_name="__main__")
    except SystemExit as stop:                                  # sys.exit(main()): its code is the exit status
        code = 0 if stop.code is None else stop.code
    finally:
        if "matplotlib.pyplot" in sys.modules:
            sys.modules["matplotlib.pyplot"].close("all")
    out, err = capsys.readouterr()
    assert code == 0, f"{script.name} failed ({code}):\n{out[-2000:]}\n{err[-3000:]}"
    assert out.strip(), f"{script.name} printed nothing"
