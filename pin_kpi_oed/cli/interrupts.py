"""Interrupts (SIGINT, Ctrl-C) while the command line runs.

While :func:`~pin_kpi_oed.cli.app.main` runs, SIGINT is recorded (:data:`SIGNALLED`) before Python's own
KeyboardInterrupt is raised. The record decides what an interrupt was when the KeyboardInterrupt does not reach the
command line: a compiled module interrupted while it initialises reports another error instead, and a library may
swallow it (seen inside NumPy's lazy imports). A command that ends on Ctrl-C by design (following a file, serving a
viewer) takes the interrupt as its normal end with :func:`consume`.
"""

from __future__ import annotations

import signal
from typing import Any

#: One entry per SIGINT received while the command line runs (cleared when it starts and by :func:`consume`).
SIGNALLED: list[bool] = []


def on_interrupt(signum: int, frame: Any) -> None:
    """SIGINT: recorded, then Python's own KeyboardInterrupt."""
    SIGNALLED.append(True)
    raise KeyboardInterrupt


def watch() -> Any:
    """Record interrupts (:data:`SIGNALLED`, cleared first) when SIGINT has Python's default handler and this is the
    main thread.

    Returns:
        The handler to restore afterwards (None: nothing installed).
    """
    SIGNALLED.clear()
    try:
        if signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
            return None
        return signal.signal(signal.SIGINT, on_interrupt)
    except ValueError:  # not the main thread
        return None


def consume() -> None:
    """The interrupts received so far were handled by the command (its normal end on Ctrl-C): forget them."""
    SIGNALLED.clear()
