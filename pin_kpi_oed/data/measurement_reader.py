"""Reading measurement files (CSV): header, values, units and duplicates checked, file / row / column named.

The format: :mod:`pin_kpi_oed.data.measurements`.
"""

from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass
from pathlib import Path
from collections.abc import Callable, Sequence

import numpy as np

from pin_kpi_oed.data.measurement_set import (NEST_COLUMN, PAYLOAD_COLUMN, POSITION_COLUMNS, RESERVED_COLUMNS,
                                              ROTVEC_COLUMNS,
                                              SIGMA_AXIS_COLUMNS, SIGMA_COLUMN, STATION_COLUMN, TEMPERATURE_COLUMN,
                                              TIME_COLUMN, MeasurementSet)
from pin_kpi_oed.data.table import Units, parse_columns, parse_text_table, parse_units, read_text_file, rename_header
from pin_kpi_oed.data.tool_header import ToolSpec, parse_tool_header, split_tool_header
from pin_kpi_oed.data.corner_measurements import CORNER_COLUMNS
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.validation.units import check_position_spread_m

__all__ = ["ANGLE_LIMIT_RAD", "MAX_MEDIAN_DISTANCE_M", "MAX_MEDIAN_SIGMA_M", "read_measurements",
           "read_measurement_tool", "parse_numeric_table", "check_positive_sigma"]

#: Joint values (rad) or rotation-vector components beyond this look like degrees.
ANGLE_LIMIT_RAD = 2.0 * math.pi + 0.1
#: Median tracker-to-reflector distance (m) beyond which a file looks like mm.
MAX_MEDIAN_DISTANCE_M = 50.0
#: the smallest standard deviation a measurement file may state (m or rad): 1 nm / 1 nrad
MIN_SIGMA = 1e-9
#: Median standard deviation (m) beyond which sigma looks like mm/µm.
MAX_MEDIAN_SIGMA_M = 0.1


def _fmt_rows(rows: list[int], lines: list[int], idx: Sequence[int], first: int = 3) -> str:
    """``row r (line l)`` of the first few rows, and how many there are in all (a message stays one short line)."""
    out = ", ".join(f"row {rows[i]} (line {lines[i]})" for i in idx[:first])
    return out + (f" and {len(idx) - first} more ({len(idx)} rows)" if len(idx) > first else "")


def parse_numeric_table(rows: Sequence[Sequence[str]], lines: Sequence[int], header: Sequence[str], src: str,
                        parse: Callable[[str], float] = float, found: str = "",
                        skip: Sequence[str] = ()) -> np.ndarray:
    """Parse the cells of a table into floats, naming the file, column, row and value of any bad cell.

    The cells go into an object array and are converted at once by NumPy (``astype(float)``: Python's correctly
    rounded ``float`` of each cell, which ignores surrounding whitespace, so ``repr`` floats read back
    bit-identical); a custom ``parse`` (e.g. decimal commas) is mapped over the cells. Only when a conversion fails
    are the cells scanned, in row-major order, for the first bad one.

    Args:
        rows: the cells of each data row (strings).
        lines: the file line number of each row (for messages).
        header: column names.
        src: file name for messages.
        parse: cell parser (``float``, or one for decimal commas); raises ValueError on bad cells.
        found: description of the columns found, added to a wrong-cell-count message.
        skip: columns not parsed (left NaN), e.g. timestamps.

    Returns:
        (len(rows), len(header)) array.

    Raises:
        InputError: a row with the wrong number of cells, a cell that is not a number, NaN or inf.
    """
    ncol = len(header)
    for r, (cells, line) in enumerate(zip(rows, lines)):
        if len(cells) != ncol:
            raise InputError(f"{src}: row {r + 1} (line {line}) has {len(cells)} cells, the header has {ncol}"
                             + (f" ({found})" if found else ""))
    cols = [c for c, name in enumerate(header) if name not in set(skip)]
    data = np.full((len(rows), ncol), np.nan)
    if not rows or not cols:
        return data
    grid = np.empty((len(rows), ncol), dtype=object)
    grid[:] = rows  # rows of ncol cells (checked above); an object array keeps each cell a Python string
    text = grid[:, cols]
    try:
        if parse is float or parse is _parse_float:
            values = text.astype(float)
        else:
            values = np.array([[parse(c) for c in r] for r in text], dtype=float)
    except (ValueError, TypeError):
        values = None
    if values is None:  # find the first cell that is not a number (row-major), to name it
        for r, line in enumerate(lines):
            for c in cols:
                cell = rows[r][c]
                try:
                    parse(cell)
                except ValueError:
                    shown = repr(cell) if cell.strip() else "an empty cell"
                    raise InputError(f"{src}: column '{header[c]}', row {r + 1} (line {line}): {shown} is not a "
                                     "number") from None
        raise InputError(f"{src}: cannot convert the table to numbers")  # pragma: no cover - parse is consistent
    bad = ~np.isfinite(values)
    if bad.any():
        r, k = np.argwhere(bad)[0]
        c = cols[k]
        raise InputError(f"{src}: column '{header[c]}', row {r + 1} (line {lines[r]}): value {rows[r][c].strip()!r} "
                         "is not finite (NaN/inf)")
    data[:, cols] = values
    return data


def check_positive_sigma(sigma: np.ndarray, names: Sequence[str], lines: Sequence[int], src: str,
                         unit: str = "m") -> None:
    """Raise if a standard deviation is not > 0, naming the file, column, row and value.

    Raises:
        InputError: the first offending cell.
    """
    bad = np.argwhere(sigma <= 0)
    if bad.size:
        r, a = bad[0]
        raise InputError(f"{src}: column '{names[a]}', row {r + 1} (line {lines[r]}): "
                         f"standard deviation {float(sigma[r, a])!r} {unit} must be > 0")
    tiny = np.argwhere(sigma < MIN_SIGMA)
    if tiny.size:
        r, a = tiny[0]
        raise InputError(f"{src}: column '{names[a]}', row {r + 1} (line {lines[r]}): standard deviation "
                         f"{float(sigma[r, a]):g} {unit} is below {MIN_SIGMA:g} {unit}, finer than any tracker "
                         f"measures (its weight would swamp the fit); give sigma in {unit}")



def _parse_float(cell: str) -> float:
    return float(cell.strip())


def read_measurement_tool(path: str | os.PathLike[str]) -> ToolSpec | None:
    """The tool header of a measurement CSV (:mod:`pin_kpi_oed.data.tool_header`), read before the robot is
    loaded (the header may name its tool frame); None when the file has none.

    Raises:
        InputError: a missing or unreadable file, a malformed header field.
    """
    src = str(path)
    comments, _, _ = split_tool_header(read_text_file(path, src, "measurement file"))
    return parse_tool_header(comments, src)


def _read_table(p: Path, src: str) -> tuple[list[str], int, list[list[str]], list[int], ToolSpec | None]:
    """Step 1: the tool header, the column header and the data rows (cells as text) with their file line
    numbers (:func:`~pin_kpi_oed.data.table.parse_text_table`)."""
    comments, text, skipped = split_tool_header(read_text_file(p, src, "measurement file"))
    tool = parse_tool_header(comments, src)
    header, header_line, rows, row_lines = parse_text_table(text, src, "measurement file")
    header_line, row_lines = header_line + skipped, [r + skipped for r in row_lines]
    if not header:
        raise InputError(f"{src}: empty file, expected a header row (joint names, x, y, z, ...)")
    if len(header) == 1 and ";" in header[0]:
        raise InputError(
            f"{src}: header '{header[0][:60]}' looks ';'-separated; this reader expects ',' "
            "(use pin_kpi_oed.data.ipa.import_ipa for IPA files, or convert the file)"
        )
    if not rows:
        raise InputError(f"{src}: no measurement rows after the header")
    return header, header_line, rows, row_lines, tool


@dataclass
class _Columns:
    """Step 2: which header column holds what (names checked, groups complete)."""

    seen: dict[str, int]
    joints: list[str]
    extra: list[str]
    position: bool
    rotvec: bool
    sigma_names: tuple[str, ...]
    found: str


def _check_header(header: list[str], header_line: int, src: str, joint_names: list[str] | None,
                  require_position: bool) -> _Columns:
    """Step 2: unique non-empty names; x, y, z (unless optional); complete rx/ry/rz and sigma groups; joints."""
    seen: dict[str, int] = {}
    for i, name in enumerate(header):
        if not name:
            raise InputError(f"{src}: header (line {header_line}) column {i + 1} has an empty name")
        if name in seen:
            raise InputError(
                f"{src}: column '{name}' appears twice in the header (columns {seen[name] + 1} and {i + 1})"
            )
        seen[name] = i
    found = ", ".join(header)
    missing_xyz = [c for c in POSITION_COLUMNS if c not in seen]
    if missing_xyz and require_position and all(c in seen for c in CORNER_COLUMNS):
        raise InputError(f"{src}: a camera's measurement file (one row per board corner: pose, corner, u_px, v_px); "
                         "this reads a tracker's positions (x, y, z): camera files go to identify --cell and check")
    if missing_xyz and (require_position or len(missing_xyz) != 3):
        raise InputError(
            f"{src}: missing position column(s) {', '.join(missing_xyz)} (m, tracker frame); "
            f"columns found: {found}; map other names with columns='x=X,...'"
        )
    rot_present = [c for c in ROTVEC_COLUMNS if c in seen]
    if rot_present and len(rot_present) != 3:
        raise InputError(
            f"{src}: orientation needs all of rx, ry, rz (rotation vector, rad); "
            f"found only {', '.join(rot_present)}"
        )
    sig_axes = [c for c in SIGMA_AXIS_COLUMNS if c in seen]
    if sig_axes and len(sig_axes) != 3:
        raise InputError(
            f"{src}: per-axis sigma needs all of sigma_x, sigma_y, sigma_z (m); found only {', '.join(sig_axes)}"
        )
    if sig_axes and SIGMA_COLUMN in seen:
        raise InputError(f"{src}: give either 'sigma' or 'sigma_x, sigma_y, sigma_z', not both")
    sigma_names: tuple[str, ...] = SIGMA_AXIS_COLUMNS if sig_axes else (
        (SIGMA_COLUMN,) * 3 if SIGMA_COLUMN in seen else ())

    if joint_names is None:
        joints = [c for c in header if c not in RESERVED_COLUMNS and c != NEST_COLUMN]
        if not joints:
            raise InputError(f"{src}: no joint columns found; columns found: {found}")
        extra_names: list[str] = [NEST_COLUMN] if NEST_COLUMN in seen else []
    else:
        joints = [str(j) for j in joint_names]
        if len(set(joints)) != len(joints):
            raise InputError(f"{src}: joint_names contains duplicates: {joints}")
        clash = [j for j in joints if j in RESERVED_COLUMNS]
        if clash:
            raise InputError(f"{src}: joint name(s) {clash} clash with reserved column names")
        missing = [j for j in joints if j not in seen]
        if missing:
            raise InputError(
                f"{src}: missing joint column(s) {', '.join(missing)} (rad); columns found: {found}; map other "
                f"names with columns='{missing[0]}=NAME,...'"
            )
        extra_names = [c for c in header if c not in RESERVED_COLUMNS and c not in set(joints)]
    return _Columns(seen, joints, extra_names, not missing_xyz, bool(rot_present), sigma_names, found)


def _build_set(data: np.ndarray, rows: list[list[str]], cols: _Columns, src: str) -> MeasurementSet:
    """Step 3: the parsed table as a :class:`MeasurementSet` (station labels taken as text)."""
    seen = cols.seen

    def col(name: str) -> np.ndarray | None:
        return data[:, seen[name]].copy() if name in seen else None

    def block(names: Sequence[str]) -> np.ndarray:
        return data[:, [seen[n] for n in names]].copy()

    m = data.shape[0]
    station = None
    if STATION_COLUMN in seen:
        station = np.array([r[seen[STATION_COLUMN]].strip() for r in rows], dtype=object)
        empty = np.flatnonzero(station == "")
        if empty.size:
            raise InputError(f"{src}: column 'station', row {int(empty[0]) + 1}: empty station label "
                             "(give every row a label, e.g. B or 1)")
        odd = [k for k, lab in enumerate(station) if not str(lab).isprintable()]
        if odd:
            raise InputError(f"{src}: column 'station', row {odd[0] + 1}: station label {station[odd[0]]!r} holds a "
                             "line break or control character (give every row a one-line label, e.g. B or 1)")
    return MeasurementSet(
        joint_names=cols.joints,
        q=block(cols.joints),
        position_m=block(POSITION_COLUMNS) if cols.position else np.full((m, 3), np.nan),
        rotvec_rad=block(ROTVEC_COLUMNS) if cols.rotvec else None,
        sigma_m=block(cols.sigma_names) if cols.sigma_names else None,
        temperature_c=col(TEMPERATURE_COLUMN),
        payload_kg=col(PAYLOAD_COLUMN),
        time_s=col(TIME_COLUMN),
        source=src,
        extra={n: col(n) for n in cols.extra},
        station=station,
    )


def _check_values(ms: MeasurementSet, cols: _Columns, row_lines: list[int], src: str) -> None:
    """Step 4: standard deviations > 0, payloads >= 0."""
    if ms.sigma_m is not None:
        check_positive_sigma(ms.sigma_m, cols.sigma_names, row_lines, src)
    if ms.payload_kg is not None and np.any(ms.payload_kg < 0):
        r = int(np.flatnonzero(ms.payload_kg < 0)[0])
        raise InputError(
            f"{src}: column 'payload', row {r + 1} (line {row_lines[r]}): payload {float(ms.payload_kg[r])!r} kg "
            "must be >= 0"
        )


def _check_units(ms: MeasurementSet, cols: _Columns, row_lines: list[int], src: str, reach_m: float | None,
                 joint_units: Sequence[str] | None = None, joint_guard: Sequence[float] | None = None,
                 declared: bool = False) -> None:
    """Step 5: the unit guard (mm instead of m, degrees instead of rad, sigma in mm/µm). A revolute joint's values
    are compared with its own ``joint_guard`` (rad; a joint of a few turns) when given, else with 2π + 0.1 rad;
    joint values are not sniffed when the units are ``declared`` (the robot's limits still check them)."""
    pos = ms.position_m
    if cols.position:
        dist = np.linalg.norm(pos, axis=1)
        med = float(np.median(dist))
        limit = MAX_MEDIAN_DISTANCE_M
        if med > limit:
            r = int(np.argmax(dist))
            raise InputError(
                f"{src}: columns x, y, z: median distance from the tracker {med:.6g} m exceeds {limit:g} m "
                f"(e.g. row {r + 1} (line {row_lines[r]}): {dist[r]:.6g}); looks like mm/degrees; "
                f"convert to m/rad or declare the units (units='mm,deg')"
            )
    if reach_m is not None and cols.position:
        for lab, rows in ms.station_rows().items():  # each station has its own tracker frame
            where = f"{src}: columns x, y, z" + (f", station '{lab}'" if ms.station is not None else "")
            check_position_spread_m(pos[rows], float(reach_m), where,
                                    "convert to m/rad or declare the units (units='mm,deg')")
    rev = np.array([u != "m" for u in joint_units]) if joint_units is not None else np.ones(len(cols.joints), bool)
    nj = len(cols.joints)
    guard = (np.maximum(np.asarray(joint_guard, float), ANGLE_LIMIT_RAD) if joint_guard is not None
             and np.size(joint_guard) == nj else np.full(nj, ANGLE_LIMIT_RAD))
    for arr, names, mask, lim in ((None if declared else ms.q, cols.joints, rev, guard),
                                  (ms.rotvec_rad, ROTVEC_COLUMNS, np.ones(3, bool), np.full(3, ANGLE_LIMIT_RAD))):
        if arr is None:
            continue
        big = (np.abs(arr) > lim[None, :]) & mask[None, :]  # prismatic joints (m) are not angles
        if np.any(big):
            r, c = np.argwhere(big)[0]
            what = "2π+0.1 rad" if lim[c] == ANGLE_LIMIT_RAD else f"{lim[c]:.4g} rad (the joint's own limit + 0.1)"
            raise InputError(
                f"{src}: column '{names[c]}', row {r + 1} (line {row_lines[r]}): value {float(arr[r, c])!r} "
                f"exceeds {what} in magnitude; looks like mm/degrees; "
                f"convert to m/rad or declare the units (units='mm,deg')"
            )
    if ms.sigma_m is not None:
        sigma = ms.sigma_m
        med_sigma = float(np.median(sigma))
        if med_sigma > MAX_MEDIAN_SIGMA_M:
            r = int(np.argmax(sigma.max(axis=1)))
            raise InputError(
                f"{src}: column(s) {', '.join(dict.fromkeys(cols.sigma_names))}: median standard deviation "
                f"{med_sigma:.6g} m exceeds {MAX_MEDIAN_SIGMA_M:g} m (e.g. row {r + 1} (line {row_lines[r]}): "
                f"{sigma[r].max():.6g}); looks like mm/degrees; convert to m/rad or declare the units (units='mm,deg')"
            )


def _check_duplicates(ms: MeasurementSet, row_lines: list[int], src: str) -> None:
    """Step 6: no two rows with identical joint values and identical measurement."""
    m = len(ms)
    row_nums = list(range(1, m + 1))
    key_parts = [ms.q] + ([ms.position_m] if ms.has_position else []) + \
        ([ms.rotvec_rad] if ms.rotvec_rad is not None else [])
    keys = np.hstack(key_parts) + 0.0  # +0.0 folds -0.0 into 0.0
    first: dict[bytes, int] = {}
    dups: dict[int, list[int]] = {}
    for r in range(m):
        kb = keys[r].tobytes()
        if kb in first:
            dups.setdefault(first[kb], []).append(r)
        else:
            first[kb] = r
    if dups:
        parts = []
        for orig, copies in list(dups.items())[:5]:
            verb = "is a duplicate of" if len(copies) == 1 else "are duplicates of"
            parts.append(f"{_fmt_rows(row_nums, row_lines, copies)} {verb} {_fmt_rows(row_nums, row_lines, [orig])}")
        more = f" (and {len(dups) - 5} more groups)" if len(dups) > 5 else ""
        what = "same joint values and same x, y, z" if ms.has_position else "same joint values"
        raise InputError(
            f"{src}: duplicate measurements ({what}"
            f"{', rx, ry, rz' if ms.rotvec_rad is not None else ''}): " + "; ".join(parts) + more
        )


def _apply_units(ms: MeasurementSet, u: Units, joint_units: Sequence[str] | None) -> MeasurementSet:
    """Step 3b: declared units to SI (lengths: x, y, z, sigma, prismatic joints; angles: rx, ry, rz, revolute
    joints). Temperature (°C), payload (kg), time (s) and extra columns are not converted."""
    if u.is_si:
        return ms
    n = len(ms.joint_names)
    ju = list(joint_units) if joint_units is not None else ["rad"] * n
    if len(ju) != n or any(x not in ("rad", "m") for x in ju):
        raise InputError(f"joint_units must give 'rad' or 'm' for each of the {n} joints, got {ju}")
    scale = np.array([u.angle_rad if x == "rad" else u.length_m for x in ju])
    return dataclasses.replace(
        ms, q=ms.q * scale, position_m=ms.position_m * u.length_m,
        rotvec_rad=None if ms.rotvec_rad is None else ms.rotvec_rad * u.angle_rad,
        sigma_m=None if ms.sigma_m is None else ms.sigma_m * u.length_m)


def read_measurements(
    path: str | os.PathLike[str],
    joint_names: list[str] | None = None,
    reach_m: float | None = None,
    require_position: bool = True,
    units: str | Units | None = None,
    columns: str | dict[str, str] | None = None,
    joint_units: Sequence[str] | None = None,
    joint_guard: Sequence[float] | None = None,
) -> MeasurementSet:
    """Read and validate a measurement CSV file (format: see the module docstring).

    Steps: read the table, check the header, parse every cell (file, column, row
    and value named on error), build the set, check values, units and duplicates.
    Row numbers in error messages count data rows from 1 (the header is not
    counted); the file line number is given too.

    Args:
        path: CSV file.
        joint_names: Expected joint columns (e.g. the actuated joints of the
            URDF), in model order. ``None``: every unrecognised column is a joint.
        reach_m: Robot reach (m); if given, enables the reach-based mm guard.
        require_position: False accepts a file without ``x, y, z`` (positions
            NaN, :attr:`MeasurementSet.has_position` False), e.g. for predictions.
        units: declared units of the file's numbers, e.g. ``"mm,deg"``
            (:func:`pin_kpi_oed.data.table.parse_units`); converted to SI on reading. None:
            the file is SI and the unit guard refuses mm / degrees.
        columns: column mapping ``"joint_a1=A1,x=X"`` (package name = file name), applied to the
            header before anything else.
        joint_units: ``"rad"`` or ``"m"`` per joint of ``joint_names`` (prismatic joints are
            lengths under ``units``); default all ``"rad"``.
        joint_guard: per joint of ``joint_names``, the largest magnitude its values may have in their SI unit
            (:attr:`pin_kpi_oed.model.robot.Robot.unit_guard`: a joint of a few turns keeps its range); default
            2π + 0.1 rad for every revolute joint. Not applied when ``units`` are declared.

    Returns:
        The measurements, in file order, in SI units.

    Raises:
        InputError: If the file is missing or unreadable, the header lacks joint
            or x/y/z columns, a column is duplicated, a row has the wrong number
            of cells, a cell is not a finite number (or a station label is empty),
            a standard deviation is <= 0 or a payload < 0, the values look like mm
            or degrees, or two rows are duplicates. The message names the file,
            column, row and value.
    """
    p = Path(path)
    src = str(p)
    if reach_m is not None and not (math.isfinite(float(reach_m)) and float(reach_m) > 0):
        raise InputError(f"reach_m must be a positive number of metres, got {reach_m!r}")
    u = parse_units(units)
    mapping = parse_columns(columns)
    header, header_line, rows, row_lines, tool = _read_table(p, src)
    header = rename_header(header, mapping, src)
    cols = _check_header(header, header_line, src, joint_names, require_position)
    data = parse_numeric_table(rows, row_lines, header, src, _parse_float, cols.found, skip=(STATION_COLUMN,))
    ms = _apply_units(_build_set(data, rows, cols, src), u, joint_units)
    ms.tool = tool
    _check_values(ms, cols, row_lines, src)
    _check_units(ms, cols, row_lines, src, reach_m, joint_units, joint_guard, u.declared)
    _check_duplicates(ms, row_lines, src)
    return ms
