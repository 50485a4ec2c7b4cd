"""Run the command line in-process and capture what it prints (shared by the CLI tests)."""

from __future__ import annotations

import contextlib
import io


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


def without_times(doc):
    """A JSON document a command wrote without its wall and CPU times (they differ between any two runs), to compare
    the command line's file with the API's."""
    if isinstance(doc, dict):
        return {k: without_times(v) for k, v in doc.items() if not k.endswith(("time_s", "_cpu_s"))}
    if isinstance(doc, list):
        return [without_times(v) for v in doc]
    return doc
