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
