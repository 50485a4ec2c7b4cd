"""Run the command line in-process and capture what it prints (shared by the CLI tests)."""

from __future__ import annotations

import contextlib
import io
import subprocess
import traceback
import warnings


def run_cli(*argv) -> tuple[int, str, str]:
    """(exit code, stdout, stderr) of ``pin-kpi-oed argv...`` run in this process."""
    from pin_kpi_oed.cli.app import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = main([str(a) for a in argv])
        except SystemExit as exc:
            rc = int(exc.code)
    return rc, out.getvalue(), err.getvalue()


def run_cli_as_process(*argv) -> subprocess.CompletedProcess:
    """``pin-kpi-oed argv...`` in this process as a process would end, for the tests of a command's output and exit
    code rather than of its process (tests/test_cli_startup.py runs the real one; a fresh interpreter costs about
    1.5 s CPU a call): stdout, stderr and the exit code; an escaped exception is its traceback on stderr and exit
    code 1, and each warning is printed on stderr (not collected by pytest), as the interpreter would do."""
    from pin_kpi_oed.cli.app import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), warnings.catch_warnings():
        warnings.simplefilter("default")
        warnings.showwarning = lambda message, category, filename, lineno, file=None, line=None: err.write(
            warnings.formatwarning(message, category, filename, lineno, line))
        try:
            code = main([str(a) for a in argv])
        except SystemExit as stop:
            code = stop.code if isinstance(stop.code, int) else (0 if stop.code is None else 1)
        except Exception:  # noqa: BLE001 - a traceback is what the tests must never see
            err.write(traceback.format_exc())
            code = 1
    return subprocess.CompletedProcess(["pin-kpi-oed", *map(str, argv)], code, out.getvalue(), err.getvalue())


def without_times(doc):
    """A JSON document a command wrote without its wall and CPU times (they differ between any two runs), to compare
    the command line's file with the API's."""
    if isinstance(doc, dict):
        return {k: without_times(v) for k, v in doc.items() if not k.endswith(("time_s", "_cpu_s"))}
    if isinstance(doc, list):
        return [without_times(v) for v in doc]
    return doc
