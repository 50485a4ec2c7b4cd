"""Tables as they come: CSV reading, declared units and column mappings.

Every reader of the package that takes a user's table (measurements, Cartesian targets,
joint-space programs, tracker exports) goes through these helpers:

* :func:`read_text_table` reads a delimited text file with the standard library's :mod:`csv` (UTF-8, a
  byte-order mark accepted, double-quoted cells; a whitespace separator splits each line's stripped text, without
  quoting) as text cells, and returns the header,
  the data rows and the file line number of every row, so that errors can name them. Blank
  rows (all cells empty) are skipped; a row with more or fewer cells than the header is kept
  with its true cell count so the caller can refuse it with one line.
* :func:`parse_units` reads a declaration such as ``"mm,deg"``: the length and angle unit of the
  file's numbers. :class:`Units` converts them to SI (m, rad).
* :func:`parse_columns` reads a mapping such as ``"joint_a1=A1,joint_a2=A2,x=X"``: the
  package's column name on the left, the file's on the right. :func:`rename_header` applies it.

The numbers themselves are converted by :func:`parse_numeric_table` in
:mod:`pin_kpi_oed.data.measurements` (file, column, row and value named on error).
"""

from __future__ import annotations

import csv
import io
import os
import re
from dataclasses import dataclass
from pathlib import Path
from collections.abc import Iterator, Mapping

from pin_kpi_oed.errors import InputError

__all__ = ["LENGTH_UNITS", "ANGLE_UNITS", "Units", "SI_UNITS", "parse_units", "parse_columns", "rename_header",
           "read_text_table", "read_text_file", "parse_text_table"]

#: Length units accepted in a declaration and their factor to metres.
LENGTH_UNITS: dict[str, float] = {"m": 1.0, "cm": 1e-2, "mm": 1e-3, "um": 1e-6, "µm": 1e-6, "in": 0.0254}
#: Angle units accepted in a declaration and their factor to radians.
ANGLE_UNITS: dict[str, float] = {"rad": 1.0, "deg": 0.017453292519943295, "mrad": 1e-3}


@dataclass(frozen=True)
class Units:
    """Units of a file's numbers: lengths (positions, sigma, prismatic joints) and angles.

    Attributes:
        length: length unit name (``m``, ``mm``, ...).
        angle: angle unit name (``rad``, ``deg``, ...).
        declared: whether the user declared them (a declared file is not unit-sniffed).
    """

    length: str = "m"
    angle: str = "rad"
    declared: bool = False

    @property
    def length_m(self) -> float:
        """Factor from the file's length unit to metres."""
        return LENGTH_UNITS[self.length]

    @property
    def angle_rad(self) -> float:
        """Factor from the file's angle unit to radians."""
        return ANGLE_UNITS[self.angle]

    @property
    def is_si(self) -> bool:
        """Whether the file is in m and rad already."""
        return self.length == "m" and self.angle == "rad"

    def __str__(self) -> str:
        return f"{self.length},{self.angle}"


SI_UNITS = Units()


def parse_units(text: str | Units | None, what: str = "parameter 'units'") -> Units:
    """Parse a unit declaration: one length and/or one angle unit, comma-separated (``mm,deg``).

    Args:
        text: e.g. ``"mm,deg"``, ``"mm"`` (angles stay rad), ``"deg"`` (lengths stay m); None: SI,
            not declared (the reader sniffs for mm/degrees and refuses them).
        what: the option or field named in errors.

    Returns:
        The :class:`Units` (``declared`` True unless ``text`` is None).

    Raises:
        InputError: an unknown unit, two length or two angle units.
    """
    if text is None:
        return SI_UNITS
    if isinstance(text, Units):
        return text
    length = angle = None
    for tok in (t.strip() for t in str(text).split(",")):
        if not tok:
            continue
        key = tok.lower() if tok != "µm" else tok
        if key in LENGTH_UNITS:
            if length is not None:
                raise InputError(f"{what}: two length units ({length}, {tok}) in '{text}'")
            length = key
        elif key in ANGLE_UNITS:
            if angle is not None:
                raise InputError(f"{what}: two angle units ({angle}, {tok}) in '{text}'")
            angle = key
        else:
            raise InputError(f"{what}: unknown unit '{tok}' in '{text}' (lengths: {', '.join(LENGTH_UNITS)}; "
                             f"angles: {', '.join(ANGLE_UNITS)})")
    if length is None and angle is None:
        raise InputError(f"{what}: no unit in '{text}' (e.g. mm,deg)")
    return Units(length or "m", angle or "rad", declared=True)


def parse_columns(text: str | Mapping[str, str] | None, what: str = "parameter 'columns'") -> dict[str, str]:
    """Parse a column mapping ``ours=theirs,...`` (e.g. ``joint_a1=A1,x=X``).

    Args:
        text: the mapping text, or a dict {package name: file name}; None: no mapping.
        what: the option named in errors.

    Returns:
        {file column name: package column name}.

    Raises:
        InputError: an entry without ``=``, an empty name, a file column mapped twice or a
            package name given twice.
    """
    if text is None:
        return {}
    pairs = list(text.items()) if isinstance(text, Mapping) else []
    if not isinstance(text, Mapping):
        for tok in (t.strip() for t in str(text).split(",")):
            if not tok:
                continue
            if tok.count("=") != 1:
                raise InputError(f"{what}: entry '{tok}' must be ours=theirs (e.g. joint_a1=A1, x=X)")
            ours, theirs = (s.strip() for s in tok.split("="))
            pairs.append((ours, theirs))
    out: dict[str, str] = {}
    seen_ours: set[str] = set()
    for ours, theirs in pairs:
        ours, theirs = str(ours).strip(), str(theirs).strip()
        if not ours or not theirs:
            raise InputError(f"{what}: empty column name in '{ours}={theirs}'")
        if theirs in out:
            raise InputError(f"{what}: file column '{theirs}' is mapped twice")
        if ours in seen_ours:
            raise InputError(f"{what}: column '{ours}' is given twice")
        out[theirs] = ours
        seen_ours.add(ours)
    return out


def rename_header(header: list[str], mapping: Mapping[str, str], src: str, what: str = "parameter 'columns'",
                  strict: bool = True) -> list[str]:
    """Rename the file's columns by ``mapping`` ({file name: package name}).

    ``strict=False`` ignores mapped names the file does not have (one mapping for several files).

    Raises:
        InputError: a mapped file column that is not in the header (the columns found are listed),
            or a rename that collides with another column of the file.
    """
    if not mapping:
        return list(header)
    missing = [c for c in mapping if c not in header]
    if missing and strict:
        raise InputError(f"{src}: {what} maps column(s) {', '.join(missing)} that the file does not have; "
                         f"columns found: {', '.join(header)}")
    out = [mapping.get(c, c) for c in header]
    dup = sorted({c for c in out if out.count(c) > 1})
    if dup:
        raise InputError(f"{src}: after {what}, column(s) {', '.join(dup)} appear twice (map or rename the other)")
    return out


def read_text_table(path: str | os.PathLike, src: str, kind: str = "file", sep: str = ","
                    ) -> tuple[list[str], int, list[list[str]], list[int]]:
    """Header and data rows of a delimited text file, as text cells with their file line numbers.

    Args:
        path: the file.
        src: its name in messages.
        kind: what the file should be (for messages).
        sep: the delimiter.

    Returns:
        ``(header, header_line, rows, row_lines)``: header names stripped of spaces; rows keep
        their true cell count (more or fewer than the header); lines count from 1.

    Raises:
        InputError: a missing file, a directory, unreadable or not UTF-8 text, an empty file.
    """
    return parse_text_table(read_text_file(path, src, kind), src, kind, sep)


def read_text_file(path: str | os.PathLike, src: str, kind: str = "file") -> str:
    """The text of a UTF-8 file (a byte-order mark dropped).

    Raises:
        InputError: a missing file, a directory, unreadable or not UTF-8 text.
    """
    p = Path(path)
    if not p.exists():
        raise InputError(f"{kind} '{src}' does not exist")
    if p.is_dir():
        raise InputError(f"{kind} '{src}' is a directory, expected a text file")
    try:
        return p.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(f"{src}: not a UTF-8 text file ({exc})") from None
    except OSError as exc:
        raise InputError(f"{src}: cannot read file ({exc.strerror})") from None


def parse_text_table(text: str, src: str, kind: str = "file", sep: str = ","
                     ) -> tuple[list[str], int, list[list[str]], list[int]]:
    """:func:`read_text_table` on text already read (same returns; lines count in ``text``).

    Raises:
        InputError: text the CSV reader cannot parse (a NUL character).
    """
    if not text.strip():
        return [], 0, [], []
    try:
        records = list(_records(text, sep))
    except csv.Error as exc:
        raise InputError(f"{src}: cannot parse as {kind} ({str(exc).splitlines()[0]})") from None
    header: list[str] | None = None
    header_line = 0
    rows: list[list[str]] = []
    lines: list[int] = []
    for i, cells in enumerate(records):
        if not cells or all(not str(c).strip() for c in cells):
            continue
        if header is None:
            header = [str(c).strip() for c in cells]
            header_line = i + 1
            continue
        rows.append([str(c) for c in cells])
        lines.append(i + 1)
    if header is None:
        return [], 0, [], []
    return header, header_line, rows, lines


def _records(text: str, sep: str) -> Iterator[list[str]]:
    """The records of ``text``, each a list of its cells as text (a blank line: an empty or blank record, counted).
    A one-character ``sep``: the :mod:`csv` reader (double quotes, a doubled quote inside them); a longer one is a
    regular expression that splits each line's stripped text, without quoting (``\\s+``: whitespace-separated
    exports)."""
    if len(sep) == 1:
        yield from csv.reader(io.StringIO(text), delimiter=sep, quotechar='"')
        return
    pattern = re.compile(sep)
    for line in io.StringIO(text):
        yield pattern.split(line.strip())
