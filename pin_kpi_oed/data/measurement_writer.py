"""Writing measurement files (CSV, SI units, shortest round-trip floats, atomic)."""

from __future__ import annotations

import csv
import io as _stdio
import os

import numpy as np

from pin_kpi_oed.data.atomic import atomic_write_text
from pin_kpi_oed.data.measurement_set import (PAYLOAD_COLUMN, POSITION_COLUMNS, RESERVED_COLUMNS, ROTVEC_COLUMNS,
                                              SIGMA_AXIS_COLUMNS, STATION_COLUMN, TEMPERATURE_COLUMN, TIME_COLUMN,
                                              MeasurementSet)
from pin_kpi_oed.errors import InputError

__all__ = ["write_measurements"]


def _format_float(v: float) -> str:
    """Shortest string that reads back as the same float (``repr``)."""
    return repr(float(v))


def _check_column_names(ms: MeasurementSet, path: str) -> None:
    names = list(ms.joint_names) + list(ms.extra)
    for n in names:
        if not n or n != n.strip():
            raise InputError(f"cannot write '{path}': column name {n!r} is empty or has leading/trailing spaces")
    clash = [n for n in names if n in RESERVED_COLUMNS]
    if clash:
        raise InputError(f"cannot write '{path}': joint/extra column name(s) {clash} clash with reserved columns")
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise InputError(f"cannot write '{path}': column name(s) {dup} used both as joint and extra column")


def write_measurements(ms: MeasurementSet, path: str | os.PathLike[str]) -> None:
    """Write a measurement set as CSV (format: see the module docstring), atomically.

    Columns: joints, ``x,y,z``, then if present ``rx,ry,rz``,
    ``sigma_x,sigma_y,sigma_z``, ``temperature``, ``payload``, ``time``,
    ``station`` (text), then the extra columns. Floats use ``repr`` so a read-back is bit-identical.
    A set with a :attr:`~MeasurementSet.tool` begins with its header (comment lines,
    :mod:`pin_kpi_oed.data.tool_header`).

    Args:
        ms: The measurements (SI units).
        path: Target CSV file; replaced atomically if it exists.

    Raises:
        InputError: If a joint/extra name is empty, padded with spaces, reserved
            or used twice, the set has no positions, or the target directory does not exist.
    """
    target = str(path)
    _check_column_names(ms, target)
    header: list[str] = list(ms.joint_names) + list(POSITION_COLUMNS)
    blocks: list[np.ndarray] = [ms.q, ms.position_m]
    if ms.rotvec_rad is not None:
        header += list(ROTVEC_COLUMNS)
        blocks.append(ms.rotvec_rad)
    if ms.sigma_m is not None:
        header += list(SIGMA_AXIS_COLUMNS)
        blocks.append(ms.sigma_m)
    for name, arr in ((TEMPERATURE_COLUMN, ms.temperature_c), (PAYLOAD_COLUMN, ms.payload_kg),
                      (TIME_COLUMN, ms.time_s)):
        if arr is not None:
            header.append(name)
            blocks.append(arr[:, None])
    n_before_station = len(header)
    if ms.station is not None:
        header.append(STATION_COLUMN)
    extra_blocks = [np.asarray(arr, dtype=float)[:, None] for arr in ms.extra.values()]
    header += list(ms.extra)
    table = np.hstack(blocks + extra_blocks) if len(ms) else np.empty((0, len(header)))
    if not ms.has_position:
        raise InputError(f"cannot write '{target}': the set has no measured positions (x, y, z)")

    buf = _stdio.StringIO()
    if ms.tool is not None:  # the tool the rows were measured with, as comment lines the reader keeps
        buf.write("".join(line + "\n" for line in ms.tool.header_lines()))
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(header)
    for i, row in enumerate(table):
        cells = [_format_float(v) for v in row]
        if ms.station is not None:
            cells.insert(n_before_station, str(ms.station[i]))
        writer.writerow(cells)
    atomic_write_text(path, buf.getvalue())
