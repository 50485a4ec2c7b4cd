"""Every script in examples/ runs to completion (so they never rot): with ``--quick`` where the script has it (the
same steps on smaller sizes; its documented Run line is the full run).

The scripts run in the test's process (``runpy``, as ``python script.py`` runs them: ``__main__``, the script's
folder first on the path, its arguments in ``sys.argv``, the test's folder as the working folder): a fresh
interpreter per script cost about 1.5 s CPU of start-up and imports each, and these tests are about the scripts,
not about the process (tests/test_cli_startup.py covers the command line's start-up). One script, the one of the
fewest imports (:data:`AS_PROCESS`), runs as a user runs it instead: ``python examples/<script>`` in a fresh
interpreter, so that what runpy in a warm process could hide (an import the test process happened to have made, an
exit code the interpreter sets) is still tested once."""

from __future__ import annotations

import os
import runpy
import subprocess
import sys

import pytest

from .conftest import REPO

EXAMPLES = sorted((REPO / "examples").glob("*.py"))
#: The example run in a fresh interpreter (the others in the test's process).
AS_PROCESS = REPO / "examples" / "kpi_covariance.py"


def test_an_example_runs_as_its_own_process(tmp_path):
    """``python examples/kpi_covariance.py`` as a user types it: a new interpreter, exit code 0, a printed result,
    nothing on stderr that looks like a failure."""
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""),
           "MPLBACKEND": "Agg"}
    env.pop("PIN_KPI_OED_QUICK", None)
    res = subprocess.run([sys.executable, str(AS_PROCESS)], capture_output=True, text=True, cwd=tmp_path, env=env,
                         timeout=300)
    assert res.returncode == 0, \
        f"{AS_PROCESS.name} failed ({res.returncode}):\n{res.stdout[-2000:]}\n{res.stderr[-3000:]}"
    assert res.stdout.strip(), f"{AS_PROCESS.name} printed nothing"
    assert "Traceback" not in res.stderr, res.stderr[-3000:]


@pytest.mark.parametrize("script", [p for p in EXAMPLES if p != AS_PROCESS],
                         ids=[p.name for p in EXAMPLES if p != AS_PROCESS])
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
