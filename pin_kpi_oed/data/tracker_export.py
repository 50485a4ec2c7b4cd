r"""Importer of tracker-software point exports (ASCII points with names and time stamps, mm) + a joint log.

Tracker software exports measured points as text; the joint values come from the robot
controller's log. This module reads both and joins them by point name into a
:class:`~pin_kpi_oed.data.measurements.MeasurementSet` (SI units).

Point export layout (modelled on the ASCII point export of SpatialAnalyzer-type tracker software:
"Collection Group Target x y z" names, optional time stamps, ``//`` comment lines)::

    // pin_kpi_oed tracker point export
    // Frame: Tracker
    // Units: mm
    Collection,Group,Target,X,Y,Z,Timestamp
    Cell1,Robot,P0001,2143.0712,-1032.5531,415.2207,2026-11-22T10:15:03.250
    Cell1,Robot,P0002,2098.6617,-1104.0093,388.9410,2026-11-22T10:15:09.875

* Comment lines start with ``//`` (or ``#``); a comment ``Units: <unit>`` (``mm``, ``m``, ``cm``,
  ``in``, ``um``; also ``Millimeters``, ``Meters``, ``Inches``) declares the length unit. Without it
  the unit is the ``units`` argument, else mm (the usual default of such exports). A ``units``
  argument that contradicts the file's comment is refused.
* Separator: comma, semicolon, tab or spaces (detected from the header line).
* Header (case-insensitive): the point name is ``Target`` (or ``Point``, ``Name``); ``Collection``
  and ``Group`` are optional and, when present, part of the full name ``Collection::Group::Target``
  only if the joint log uses such names; coordinates ``X, Y, Z``; optional time stamp ``Timestamp``
  (or ``Time Stamp``, ``Time``) as ISO-8601 date-time (``2026-11-22T10:15:03.250`` or with a space)
  or as a number of seconds; optional per-point uncertainties ``SX, SY, SZ`` (or ``Ux, Uy, Uz``,
  same unit as the coordinates, one standard deviation).
* Other names are mapped with ``columns`` (``target=Punkt,x=X_mm``; see
  :mod:`pin_kpi_oed.data.table`).

Joint log layout: a CSV with the point name (``Target``/``Point``/``Name``) and one column per
robot joint (URDF names, or mapped with ``columns``), in degrees unless ``joint_units`` says
``rad`` (prismatic joints in the export's length unit); optional ``temperature`` (°C),
``payload`` (kg).

:func:`write_tracker_export` writes the layout (used to make sample files in the tests; a real
export comes from the tracker software).
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from collections.abc import Mapping, Sequence

import numpy as np

from pin_kpi_oed.data.atomic import atomic_write_text
from pin_kpi_oed.data.measurements import MeasurementSet, check_positive_sigma, parse_numeric_table
from pin_kpi_oed.data.table import (ANGLE_UNITS, LENGTH_UNITS, parse_columns, parse_text_table, read_text_table,
                                   rename_header)
from pin_kpi_oed.errors import InputError

__all__ = ["TrackerExport", "read_point_export", "import_tracker_export", "write_tracker_export"]

_UNIT_WORDS = {"millimeters": "mm", "millimetres": "mm", "meters": "m", "metres": "m", "centimeters": "cm",
               "inches": "in", "micrometers": "um", "microns": "um"}
_NAME_COLS = ("target", "point", "name")
_TIME_COLS = ("timestamp", "time stamp", "time")
_SIGMA_COLS = (("sx", "sy", "sz"), ("ux", "uy", "uz"))


@dataclass
class TrackerExport:
    """The points of a tracker export (SI units).

    Attributes:
        names: point names (``Target``), one per row.
        position_m: (m, 3) positions in the export's frame, m.
        time_s: (m,) seconds since the first time stamp, or None.
        sigma_m: (m, 3) standard deviations, m, or None.
        units: the length unit of the file.
        frame: the frame named in a ``Frame:`` comment ("" if none).
        source: the file.
        raw_header: the file's column names (lower case), before any mapping.
        units_from: where the length unit came from (the ``Units:`` comment, the column names,
            ``--units``, or assumed).
    """

    names: list[str]
    position_m: np.ndarray
    time_s: np.ndarray | None
    sigma_m: np.ndarray | None
    units: str
    frame: str
    source: str
    raw_header: list[str]
    units_from: str = ""


def _comments_and_body(text: str) -> tuple[list[str], list[str], list[int]]:
    comments, body, lines = [], [], []
    for i, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if s.startswith("//") or s.startswith("#"):
            comments.append(s.lstrip("/#").strip())
        elif s:
            body.append(line)
            lines.append(i)
    return comments, body, lines


def _declared_unit(comments: list[str], src: str) -> str | None:
    for c in comments:
        m = re.match(r"units?\s*[:=]\s*(\S+)", c, re.IGNORECASE)
        if m:
            word = m.group(1).strip().rstrip(",;").lower()
            unit = _UNIT_WORDS.get(word, word)
            if unit not in LENGTH_UNITS:
                raise InputError(f"{src}: comment 'Units: {m.group(1)}' names an unknown length unit "
                                 f"(known: {', '.join(LENGTH_UNITS)})")
            return unit
    return None


def _frame(comments: list[str]) -> str:
    for c in comments:
        m = re.match(r"(working\s+)?frame\s*[:=]\s*(.+)", c, re.IGNORECASE)
        if m:
            return m.group(2).strip()
    return ""


def _separator(header_line: str) -> str:
    for sep in (",", ";", "\t"):
        if sep in header_line:
            return sep
    return r"\s+"


def _find(header: list[str], options: Sequence[str]) -> int | None:
    low = [h.lower() for h in header]
    for o in options:
        if o in low:
            return low.index(o)
    return None


def _parse_time(cells: list[str], lines: list[int], src: str, col: str) -> np.ndarray:
    """ISO date-times or numbers of seconds -> seconds since the first row."""
    try:
        t = np.array([float(c) for c in cells])
    except ValueError:
        t = np.empty(len(cells))
        for i, c in enumerate(cells):
            try:
                t[i] = datetime.fromisoformat(c.strip()).timestamp()
            except ValueError:
                raise InputError(f"{src}: column '{col}', line {lines[i]}: {c.strip()!r} is neither an ISO date-time "
                                 "(2026-11-22T10:15:03.250) nor a number of seconds") from None
    if not np.all(np.isfinite(t)):
        i = int(np.flatnonzero(~np.isfinite(t))[0])
        raise InputError(f"{src}: column '{col}', line {lines[i]}: time stamp is not finite")
    return t - t[0]


def read_point_export(path: str | os.PathLike, units: str | None = None,
                      columns: str | Mapping[str, str] | None = None, strict: bool = True) -> TrackerExport:
    """Read a tracker point export (layout: module docstring).

    Args:
        path: the export file.
        units: its length unit if the file does not say (``mm``, ``m``, ...); refused if it contradicts the file.
        columns: mapping of the package's names (``target``, ``x``, ``y``, ``z``, ``time``, ``sx``...) to the file's.
        strict: refuse mapped names the file does not have (False: the mapping also serves the joint log).

    Returns:
        The :class:`TrackerExport` (m, s).

    Raises:
        InputError: missing file, no header, missing Target/X/Y/Z columns, duplicate point names, a bad
            number or time stamp (file, column, line and value named), contradicting units.
    """
    p = Path(path)
    src = str(p)
    if not p.is_file():
        raise InputError(f"tracker export '{src}' does not exist" if not p.exists() else
                         f"tracker export '{src}' is not a file")
    try:
        text = p.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{src}: cannot read the tracker export as UTF-8 text ({exc})") from None
    comments, body, body_lines = _comments_and_body(text)
    if not body:
        raise InputError(f"{src}: no header line (Collection, Group, Target, X, Y, Z, ...) in the tracker export")
    declared = _declared_unit(comments, src)
    given = None
    if units is not None:
        given = _UNIT_WORDS.get(str(units).strip().lower(), str(units).strip().lower())
        if given not in LENGTH_UNITS:
            raise InputError(f"parameter 'units': unknown length unit '{units}' for a tracker export "
                             f"(known: {', '.join(LENGTH_UNITS)})")
        if declared is not None and declared != given:
            raise InputError(f"{src}: the file says 'Units: {declared}' but {given} was given; drop "
                             "parameter 'units' or fix the file")
    sep = _separator(body[0])
    # the body (comment lines removed) is read by the shared pandas reader
    header, _, rows, idx = parse_text_table("\n".join(body) + "\n", src, "tracker export", sep=sep)
    lines = [body_lines[i - 1] for i in idx]
    raw_header = [h.lower() for h in header]
    header = rename_header(raw_header,
                           {k.lower(): v for k, v in parse_columns(columns).items()}, src, strict=strict)
    if not rows:
        raise InputError(f"{src}: no points after the header")
    header, in_header = _header_units(header, raw_header, src)
    if in_header is not None:
        for what, u in (("the file says 'Units: {}'", declared), ("units='{}' was given", given)):
            if u is not None and u != in_header:
                raise InputError(f"{src}: the coordinate columns say [{in_header}] but {what.format(u)}; make them "
                                 "agree (fix the file or drop parameter 'units')")
    unit = declared or in_header or given or "mm"
    i_name = _find(header, _NAME_COLS)
    missing = [c for c in ("x", "y", "z") if c not in header] + (["target"] if i_name is None else [])
    if missing:
        raise InputError(f"{src}: missing column(s) {', '.join(missing)} in the tracker export; columns found: "
                         f"{', '.join(header)} (map other names with columns='target=NAME,x=NAME,...')")
    i_time = _find(header, _TIME_COLS)
    sig = next((s for s in _SIGMA_COLS if all(c in header for c in s)), None)
    numeric = {"x", "y", "z"} | (set(sig) if sig else set())
    data = parse_numeric_table(rows, lines, header, src, float, ", ".join(header),
                               skip=tuple(h for h in header if h not in numeric))
    f = LENGTH_UNITS[unit]
    pos = data[:, [header.index(c) for c in "xyz"]] * f
    sigma = None
    if sig:
        sigma = data[:, [header.index(c) for c in sig]] * f
        check_positive_sigma(sigma, list(sig), lines, src, unit="m")
    names = [r[i_name].strip() for r in rows]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup or any(not n for n in names):
        raise InputError(f"{src}: point names must be unique and non-empty; "
                         f"repeated: {', '.join(dup[:5]) or 'an empty name'}")
    t = _parse_time([r[i_time] for r in rows], lines, src, header[i_time]) if i_time is not None else None
    how = ("its 'Units:' comment" if declared else "its column names" if in_header else "--units" if given else
           "assumed (no 'Units:' comment, no unit in the column names, no --units)")
    return TrackerExport(names, pos, t, sigma, unit, _frame(comments), src, raw_header, how)


_HEADER_UNIT = re.compile(r"^\s*(x|y|z|sx|sy|sz|ux|uy|uz)\s*(?:[\[(]\s*([a-zµ]+)\s*[\])]|_([a-z]+))\s*$")


def _header_units(header: list[str], raw_header: list[str], src: str) -> tuple[list[str], str | None]:
    """Coordinate columns named with a unit (``X [m]``, ``x (mm)``, ``X_mm``): the bare names and that unit.

    Raises:
        InputError: coordinate columns in different units, or an unknown unit.
    """
    out, units = list(header), set()
    for k, (h, raw) in enumerate(zip(header, raw_header)):
        for name in (h, raw):
            m = _HEADER_UNIT.match(name)
            if not m:
                continue
            u = (m.group(2) or m.group(3)).replace("µ", "u")
            u = _UNIT_WORDS.get(u, u)
            if u not in LENGTH_UNITS:
                continue
            units.add(u)
            if h == name:
                out[k] = m.group(1)
            break
    if len(units) > 1:
        raise InputError(f"{src}: the coordinate columns name different units ({', '.join(sorted(units))})")
    return out, (units.pop() if units else None)


def import_tracker_export(export_path: str | os.PathLike, joints_path: str | os.PathLike,
                          joint_names: Sequence[str], *, joint_units: Sequence[str] | None = None,
                          angle_unit: str = "deg", units: str | None = None,
                          columns: str | Mapping[str, str] | None = None) -> tuple[MeasurementSet, list[str]]:
    """Join a tracker point export and the robot's joint log by point name (layouts: module docstring).

    Args:
        export_path: the tracker export.
        joints_path: the joint log (CSV: point name + one column per joint).
        joint_names: the robot's actuated joints, in model order.
        joint_units: ``rad`` / ``m`` per joint (prismatic joints are lengths); default all revolute.
        angle_unit: unit of the revolute joint values in the log (``deg`` or ``rad``).
        units: length unit of the export if it does not say (default mm).
        columns: name mapping, applied to both files.

    Returns:
        ``(measurements, names)``: the joined rows in the export's order (SI units, ``time`` from the
        time stamps, ``sigma`` from the uncertainties) and their point names.

    Raises:
        InputError: everything :func:`read_point_export` refuses; a joint log without the name or a
            joint column; a point without joint values or joint values without a point (named).
    """
    exp = read_point_export(export_path, units=units, columns=columns, strict=False)
    src = str(joints_path)
    if angle_unit not in ANGLE_UNITS:
        raise InputError(f"angle unit '{angle_unit}' unknown (known: {', '.join(ANGLE_UNITS)})")
    header, _, rows, lines = read_text_table(joints_path, src, "joint log")
    if not header or not rows:
        raise InputError(f"{src}: the joint log needs a header and at least one row")
    mapping = parse_columns(columns)
    raw_header = list(header)
    header = rename_header(header, mapping, src, strict=False)
    unused = [c for c in mapping if c not in raw_header and c.lower() not in exp.raw_header]
    if unused:
        raise InputError(f"parameter 'columns' maps column(s) {', '.join(unused)} that neither {exp.source} "
                         f"nor {src} has")
    i_name = _find(header, _NAME_COLS)
    joints = list(joint_names)
    missing = [j for j in joints if j not in header] + (["Target"] if i_name is None else [])
    if missing:
        raise InputError(f"{src}: missing column(s) {', '.join(missing)} in the joint log; columns found: "
                         f"{', '.join(header)} (map other names with parameter 'columns')")
    aux = [c for c in ("temperature", "payload") if c in header]
    data = parse_numeric_table(rows, lines, header, src, float, ", ".join(header),
                               skip=tuple(h for h in header if h not in set(joints) | set(aux)))
    ju = list(joint_units) if joint_units is not None else ["rad"] * len(joints)
    scale = np.array([ANGLE_UNITS[angle_unit] if u == "rad" else LENGTH_UNITS[exp.units] for u in ju])
    Q = data[:, [header.index(j) for j in joints]] * scale
    log_names = [r[i_name].strip() for r in rows]
    where = {n: k for k, n in enumerate(log_names)}
    if len(where) != len(log_names):
        dup = sorted({n for n in log_names if log_names.count(n) > 1})
        raise InputError(f"{src}: point name(s) {', '.join(dup[:5])} appear twice in the joint log")
    lost = [n for n in exp.names if n not in where]
    if lost:
        raise InputError(f"{exp.source}: point(s) {', '.join(lost[:5])} have no joint values in {src}")
    extra = [n for n in log_names if n not in set(exp.names)]
    if extra:
        raise InputError(f"{src}: joint values for point(s) {', '.join(extra[:5])} that {exp.source} does not have")
    order = np.array([where[n] for n in exp.names], int)
    ms = MeasurementSet(joints, Q[order], exp.position_m, sigma_m=exp.sigma_m,
                        temperature_c=data[order, header.index("temperature")] if "temperature" in aux else None,
                        payload_kg=data[order, header.index("payload")] if "payload" in aux else None,
                        time_s=exp.time_s, source=exp.source)
    return ms, list(exp.names)


def write_tracker_export(path: str | os.PathLike, names: Sequence[str], position_m: np.ndarray,
                         time_s: np.ndarray | None = None, start: str = "2026-01-01T00:00:00",
                         units: str = "mm", decimals: int = 4, collection: str = "Cell", group: str = "Robot",
                         frame: str = "Tracker") -> None:
    """Write points in the export layout (comments, header, one line per point), atomically.

    Args:
        path: target file.
        names: point names.
        position_m: (m, 3) positions, m.
        time_s: (m,) seconds after ``start`` (ISO date-time) or None (no time stamp column).
        units: length unit of the file.
        decimals: digits after the decimal point of the coordinates (the resolution of the file).
    """
    if units not in LENGTH_UNITS:
        raise InputError(f"unknown length unit '{units}' (known: {', '.join(LENGTH_UNITS)})")
    P = np.asarray(position_m, float) / LENGTH_UNITS[units]
    t0 = datetime.fromisoformat(start).timestamp()
    out = ["// pin_kpi_oed tracker point export", f"// Frame: {frame}", f"// Units: {units}",
           "Collection,Group,Target,X,Y,Z" + (",Timestamp" if time_s is not None else "")]
    for i, n in enumerate(names):
        row = [collection, group, str(n)] + [f"{v:.{decimals}f}" for v in P[i]]
        if time_s is not None:
            row.append(datetime.fromtimestamp(t0 + float(time_s[i])).isoformat(timespec="milliseconds"))
        out.append(",".join(row))
    atomic_write_text(path, "\n".join(out) + "\n")
