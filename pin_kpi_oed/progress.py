"""Progress bars for long runs (design multi-start, studies, Monte-Carlo): tqdm on a terminal, silent otherwise.

Usage::

    from pin_kpi_oed.progress import progress

    for start in progress(range(n_starts), desc="multi-start"):
        ...
    with progress(total=n, desc="Monte-Carlo", unit="run") as bar:
        ...
        bar.update()

The bar goes to stderr and only when stderr is a terminal, so pipes, log files,
CI and tests stay quiet (stdout, where results are printed, is never touched).
``disable=True`` turns it off (e.g. ``disable=not show_progress``); ``disable=False``
or None leaves the terminal rule in place. ``PIN_KPI_OED_PROGRESS=1`` forces the
bar on, ``=0`` off (unless ``disable=True``).
"""

from __future__ import annotations

import os
import sys
from typing import Any, TypeVar
from collections.abc import Iterable

T = TypeVar("T")

ENV = "PIN_KPI_OED_PROGRESS"


def enabled(stream: Any = None) -> bool:
    """Whether a bar would be shown on ``stream`` (default stderr)."""
    env = os.environ.get(ENV, "").strip().lower()
    if env in ("1", "true", "yes", "on"):
        return True
    if env in ("0", "false", "no", "off"):
        return False
    stream = sys.stderr if stream is None else stream
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):  # closed or replaced stream
        return False


def progress(iterable: Iterable[T] | None = None, total: int | None = None, desc: str | None = None,
             disable: bool | None = None, **kwargs: Any):
    """A :class:`tqdm.tqdm` bar on stderr when it is a terminal; a silent one (same interface) otherwise.

    Args:
        iterable: what to iterate over (or None and use ``update``).
        total: number of steps (default ``len(iterable)`` when it has one).
        desc: short label in front of the bar.
        disable: True: no bar; False / None: a bar only on a terminal (or as ``PIN_KPI_OED_PROGRESS`` says).
        **kwargs: passed to tqdm (``unit``, ``leave``, ``position`` ...).
    """
    from tqdm.auto import tqdm

    file = kwargs.pop("file", sys.stderr)
    disable = bool(disable) or not enabled(file)
    kwargs.setdefault("dynamic_ncols", True)
    kwargs.setdefault("leave", False)
    return tqdm(iterable, total=total, desc=desc, disable=disable, file=file, **kwargs)
