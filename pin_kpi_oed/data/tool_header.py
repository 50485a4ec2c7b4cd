"""The tool a measurement was taken with: robot, tool frame, reflector, TCP, working configurations.

One source of truth travels with the data: the cell file states the tool frame, the reflector and the
TCP (both in the tool frame, m); the design file, every measurement CSV the package writes and the model
file carry them on. A measurement CSV holds them as comment lines before its column header, one field
per line, the value in JSON::

    # pin_kpi_oed.tool/1
    # robot: "panda"
    # tool_frame: "panda_link8"
    # reflector_m: [0.05, 0.0, 0.1]
    # tcp_m: [0.0, 0.0, 0.1034]
    # q_work: [[0.0, -0.3, 0.0, -2.2, 0.0, 1.9, 0.785]]
    # nests_m: [[0.05, 0.0, 0.1], [0.05, 0.08, 0.1]]

``q_work`` are the working configurations of the cell (rad / m per joint), from which compensation takes
its branch. ``nests_m`` are the tool's reflector nests (k, 3) m in the tool frame, nest 0 the reflector, when the
rows were measured at several (the file's ``nest`` column picks one per row): a file with them identifies without
the cell that declared them. Every field is optional; other comment lines are ignored. A reader keeps the fields
(:attr:`~pin_kpi_oed.data.measurement_set.MeasurementSet.tool`) and the writer writes them back.

:func:`resolve_tool` joins what several sources say (a command's options, a cell file, the headers of
the data files): the first source that gives a field sets it; another source that gives a different
value is a contradiction, refused in one line naming both sources.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from pin_kpi_oed.errors import InputError

__all__ = ["TOOL_HEADER_MAGIC", "TOOL_FIELDS", "ToolSpec", "parse_tool_header", "split_tool_header",
           "resolve_tool", "with_tool"]

#: First comment line of the header (format name and version).
TOOL_HEADER_MAGIC = "pin_kpi_oed.tool/1"
#: The header's fields, in the order they are written.
TOOL_FIELDS = ("robot", "tool_frame", "reflector_m", "tcp_m", "q_work", "nests_m")
#: Two lengths (m) or angles (rad) closer than this are the same value.
SAME_TOL = 1e-9


@dataclass
class ToolSpec:
    """What a source says about the tool (every field optional; SI units).

    Attributes:
        robot: robot name or URDF path.
        tool_frame: name of the tool frame in the URDF.
        reflector_m: reflector in the tool frame, (3,) m.
        tcp_m: TCP (the point whose accuracy matters) in the tool frame, (3,) m.
        q_work: working configurations, (k, n) rad / m.
        nests_m: the reflector nests in the tool frame, (k, 3) m, nest 0 the reflector (several nests only).
        source: where the fields come from (for messages), e.g. ``"train.csv"`` or ``"--cell cell.yaml"``.
    """

    robot: str | None = None
    tool_frame: str | None = None
    reflector_m: np.ndarray | None = None
    tcp_m: np.ndarray | None = None
    q_work: np.ndarray | None = None
    nests_m: np.ndarray | None = None
    source: str = ""

    def __post_init__(self) -> None:
        where = self.source or "tool"
        for k in ("robot", "tool_frame"):
            v = getattr(self, k)
            if v is not None and (not isinstance(v, str) or not v.strip()):
                raise InputError(f"{where}: field '{k}' must be a non-empty name, got {v!r}")
        for k in ("reflector_m", "tcp_m"):
            v = getattr(self, k)
            if v is not None:
                a = _floats(v, f"{where}: field '{k}'")
                if a.shape != (3,):
                    raise InputError(f"{where}: field '{k}' must be 3 numbers x, y, z (m), got {v!r}")
                setattr(self, k, a)
        if self.q_work is not None:
            Q = _floats(self.q_work, f"{where}: field 'q_work'")
            Q = np.atleast_2d(Q)
            if Q.ndim != 2 or Q.size == 0:
                raise InputError(f"{where}: field 'q_work' must be a list of joint vectors, got shape {Q.shape}")
            self.q_work = Q
        if self.nests_m is not None:
            N = _floats(self.nests_m, f"{where}: field 'nests_m'")
            if N.ndim != 2 or N.shape[1] != 3 or len(N) < 1:
                raise InputError(f"{where}: field 'nests_m' must be a list of [x, y, z] positions (m), got shape "
                                 f"{N.shape}")
            if self.reflector_m is not None and np.linalg.norm(N[0] - self.reflector_m) > SAME_TOL:
                raise InputError(f"{where}: field 'nests_m': nest 0 {N[0].tolist()} is not the reflector_m "
                                 f"{self.reflector_m.tolist()}")
            self.nests_m = N

    @property
    def empty(self) -> bool:
        """Whether no field is set."""
        return all(getattr(self, k) is None for k in TOOL_FIELDS)

    def to_dict(self) -> dict:
        """The set fields as plain numbers."""
        out = {}
        for k in TOOL_FIELDS:
            v = getattr(self, k)
            if v is not None:
                out[k] = v.tolist() if isinstance(v, np.ndarray) else v
        return out

    def header_lines(self) -> list[str]:
        """The comment lines of a measurement CSV (none when no field is set)."""
        d = self.to_dict()
        if not d:
            return []
        return [f"# {TOOL_HEADER_MAGIC}"] + [f"# {k}: {json.dumps(v)}" for k, v in d.items()]

    def describe(self) -> str:
        """One short phrase: ``tool frame panda_link8, reflector [..] mm, TCP [..] mm``."""
        parts = []
        if self.tool_frame:
            parts.append(f"tool frame {self.tool_frame}")
        for k, lab in (("reflector_m", "reflector"), ("tcp_m", "TCP")):
            v = getattr(self, k)
            if v is not None:
                parts.append(f"{lab} {np.round(v * 1e3, 2).tolist()} mm")
        return ", ".join(parts)


def _floats(v: object, where: str) -> np.ndarray:
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{where} must hold numbers, got {v!r}") from None
    if not np.all(np.isfinite(a)):
        raise InputError(f"{where} must hold finite numbers, got {v!r}")
    return a


def split_tool_header(text: str) -> tuple[list[tuple[int, str]], str, int]:
    """The leading comment lines of a CSV text, and the rest.

    Returns:
        ``([(line number from 1, comment text without '#'), ...], rest of the text, number of lines
        before the rest)``: add that number to a line number counted in the rest.
    """
    lines = text.split("\n")
    comments: list[tuple[int, str]] = []
    start = 0
    for i, line in enumerate(lines):
        s = line.strip()
        if s and not s.startswith("#"):
            break
        if s:
            comments.append((i + 1, s[1:].strip()))
        start = i + 1
    if not comments:
        return [], text, 0
    return comments, "\n".join(lines[start:]), start


def parse_tool_header(comments: Iterable[tuple[int, str]], src: str) -> ToolSpec | None:
    """The :class:`ToolSpec` of a CSV's leading comment lines (None when it has none of its fields).

    Raises:
        InputError: a field given twice or with a malformed value (file, line and field named).
    """
    found: dict[str, Any] = {}
    for line, text in comments:
        key, sep, value = text.partition(":")
        key = key.strip()
        if not sep or key not in TOOL_FIELDS:
            continue
        if key in found:
            raise InputError(f"{src}: line {line}: header field '{key}' appears twice")
        value = value.strip()
        try:
            found[key] = json.loads(value)
        except json.JSONDecodeError:
            if key in ("robot", "tool_frame"):
                found[key] = value
            else:
                raise InputError(f"{src}: line {line}: header field '{key}' is not a JSON value: {value!r}") from None
    if not found:
        return None
    return ToolSpec(**found, source=src)


def _same(a: object, b: object) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        A, B = np.asarray(a, float), np.asarray(b, float)
        return A.shape == B.shape and bool(np.all(np.abs(A - B) <= SAME_TOL))
    return a == b


def _show(v: object) -> str:
    if isinstance(v, np.ndarray):
        return f"{np.round(v, 6).tolist()}" + (" m" if v.ndim == 1 else "")
    return repr(v)


_LABEL = {"robot": "robot", "tool_frame": "tool frame", "reflector_m": "reflector", "tcp_m": "TCP",
          "q_work": "working configurations", "nests_m": "reflector nests (relative to nest 0)"}


def resolve_tool(specs: Sequence[ToolSpec | None], skip: Sequence[str] = ()) -> ToolSpec:
    """Join what several sources say about the tool; the first source that gives a field sets it.

    Args:
        specs: the sources in order of precedence (None entries are skipped), each naming its ``source``.
        skip: fields not compared (e.g. ``reflector_m`` when every station has its own reflector). The nests are
            compared relative to nest 0 (a station's own reflector moves them all).

    Returns:
        A :class:`ToolSpec` with every field some source gives; ``source`` names, per field, where it came from
        (``"tool_frame from train.csv, tcp_m from --cell c.yaml"``).

    Raises:
        InputError: two sources give different values of a field (both named, with their values).
    """
    out: dict[str, Any] = {}
    origin: dict[str, str] = {}
    for spec in specs:
        if spec is None:
            continue
        for k in TOOL_FIELDS:
            v = getattr(spec, k)
            if v is None:
                continue
            if k not in out:
                out[k], origin[k] = v, spec.source
            elif k not in skip and not _same(*((out[k] - out[k][0], v - v[0]) if k == "nests_m" else (out[k], v))):
                raise InputError(f"{spec.source}: {_LABEL[k]} {_show(v)} contradicts {_show(out[k])} from "
                                 f"{origin[k]}; the tool must be the one the data were measured with: drop or "
                                 "correct one of them")
    res = ToolSpec(**out)
    res.source = ", ".join(f"{k} from {s}" for k, s in origin.items())
    return res


def with_tool(spec: ToolSpec | None, **fields: Any) -> ToolSpec:
    """A copy of ``spec`` (or a new spec) with ``fields`` set."""
    return dataclasses.replace(spec or ToolSpec(), **fields)
