"""A measurement file followed while it grows (rows measured during work, appended by the tracker software).

Each :meth:`FollowedFile.poll` reads the file's complete lines (a last line without its newline is being written:
left for the next poll) with :func:`~pin_kpi_oed.data.measurements.read_measurements` and returns the rows not
returned before. A file that shrank or whose earlier rows changed (truncated, rewritten, rotated) is not an error:
the rows returned before stay returned (the caller keeps them), a one-line warning says how many of them are gone
from the file, and the rows after the common beginning are returned as new. A file that cannot be read for the
moment (fewer than :data:`MIN_ROWS` complete rows, which a header check may need) gives a one-line warning — once
per distinct message — and no rows; the next poll tries again. From :data:`MIN_ROWS` complete rows on, a file the
reader refuses (a malformed row, a value out of range) is refused as without following it: the reader's one line,
naming the file (not the copy of its complete lines the reader was given) and the row. Rows are the same when their
joint values, positions and times are.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pin_kpi_oed.data.measurement_set import MeasurementSet
from pin_kpi_oed.errors import InputError

__all__ = ["FollowedFile", "MIN_ROWS"]

#: Complete rows from which a file the reader refuses is refused, not waited for.
MIN_ROWS = 3


@dataclass
class FollowedFile:
    """A measurement CSV read again and again as it grows.

    Attributes:
        path: the file; read_options: keyword arguments of ``read_measurements`` (joint names, reach, units, ...).
        q, position_m: the rows the file held at the last poll (the common beginning with the rows returned).
        returned: rows returned so far (over every poll, rows gone from the file included).
    """

    path: str | os.PathLike
    read_options: dict = field(default_factory=dict)
    q: np.ndarray | None = None
    position_m: np.ndarray | None = None
    time_s: np.ndarray | None = None
    returned: int = 0
    _last_warning: str = field(default="", repr=False)

    def poll(self) -> tuple[MeasurementSet | None, str]:
        """(the new rows or None, a warning line or "").

        Raises:
            InputError: the reader refuses a file of at least :data:`MIN_ROWS` complete rows (the file named).
        """
        from pin_kpi_oed.data.measurements import read_measurements

        try:
            raw = Path(self.path).read_bytes()
        except OSError as exc:
            return None, self._warn(f"{self.path}: cannot be read for the moment ({exc.strerror}); waiting")
        text = raw[: raw.rfind(b"\n") + 1]
        if text.count(b"\n") < 2:
            return None, ""
        with tempfile.TemporaryDirectory() as tmp:
            part = Path(tmp) / Path(self.path).name
            part.write_bytes(text)
            try:
                ms = read_measurements(part, **self.read_options)
            except InputError as exc:
                line = str(exc).replace(str(part), str(self.path))
                if _data_rows(text) >= MIN_ROWS:
                    raise InputError(line) from None
                return None, self._warn(f"{line} (while following the file; waiting for it to change)")
        self._last_warning = ""
        return self._new_rows(ms)

    def _new_rows(self, ms: MeasurementSet) -> tuple[MeasurementSet | None, str]:
        """The rows after the common beginning with the rows seen at the last poll."""
        warning = ""
        times = None if ms.time_s is None else np.asarray(ms.time_s, float)
        start = 0 if self.q is None else _common_prefix(self.q, self.position_m, ms.q, ms.position_m)
        if self.q is not None and (self.time_s is None) != (times is None):
            start = 0
        elif self.time_s is not None and times is not None:
            start = min(start, _common_prefix(self.time_s[:, None], self.time_s[:, None], times[:, None],
                                              times[:, None]))
        if self.q is not None and start < len(self.q):
            gone = len(self.q) - start
            warning = (f"{self.path}: the file was truncated or rewritten while read: {gone} row(s) used before are no "
                       f"longer in it (kept in the log); continuing with the {len(ms) - start} row(s) after its first "
                       f"{start}")
        self.q, self.position_m = ms.q.copy(), ms.position_m.copy()
        self.time_s = None if times is None else times.copy()
        if start >= len(ms):
            return None, warning
        self.returned += len(ms) - start
        return ms.subset(np.arange(start, len(ms))), warning

    def _warn(self, line: str) -> str:
        if line == self._last_warning:
            return ""
        self._last_warning = line
        return line


def _common_prefix(qa: np.ndarray, pa: Any, qb: np.ndarray, pb: Any) -> int:
    """Number of leading rows equal in both (joint values and positions)."""
    n = min(len(qa), len(qb))
    same = np.all(qa[:n] == qb[:n], axis=1) & np.all(np.asarray(pa)[:n] == np.asarray(pb)[:n], axis=1)
    bad = np.flatnonzero(~same)
    return int(bad[0]) if bad.size else n


def _data_rows(text: bytes) -> int:
    """Lines of a CSV's complete text that are neither comments, blank, nor its column header."""
    lines = [ln for ln in text.decode("utf-8", errors="replace").splitlines() if ln.strip() and not ln.startswith("#")]
    return max(len(lines) - 1, 0)
