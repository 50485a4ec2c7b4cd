"""The abstract base of a program format: what an ordered measurement program becomes in a controller's language.

A program is the targets Q (k, n) in execution order (rad for revolute joints, m for prismatic ones, model
order), the kind of each target (``home`` / ``measure`` / ``via``) and the design pose index of each
measurement point (-1 otherwise). A format writes it as ``{suffix: text}`` (one file, or several beside each
other: KRL's ``.src`` + ``.dat``) with a header naming the cell, the design, the robot, the units and the date
(:class:`ProgramInfo`), every measurement point marked ``MEASURE k (design pose i)`` and followed by a wait of
``dwell_s`` for the tracker. Where a format has a parser it reads the texts back to (Q in SI units, the design
pose of each MEASURE point in order). Add a format: subclass :class:`ProgramFormat` in a module of this
package and add one line to :data:`~pin_kpi_oed.program.formats.registry.PROGRAM_FORMATS` (or call
:func:`~pin_kpi_oed.program.formats.registry.register_format` from outside the package).
"""

from __future__ import annotations

import datetime as _dt
import os
import re
from abc import ABC, abstractmethod
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pin_kpi_oed.errors import InputError

__all__ = ["ProgramFormat", "ProgramInfo", "program_name", "split_joints", "step_marks", "measure_marks", "NUM"]

#: a decimal number in a program text.
NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


@dataclass
class ProgramInfo:
    """What the header says.

    Attributes:
        cell: cell name.
        design: design file and criterion.
        robot: robot name.
        joint_names: joint names in model order.
        revolute: revolute mask of the joints.
        cycle_time_s: predicted motion time (s).
        date: ISO date-time (UTC) of the export (now if empty).
        dwell_s: wait at each measurement point (s).
        name: program name (KRL / RAPID module name).
        speeds: joint speeds the predicted motion time assumes (URDF limits × override; rad/s, m/s);
            URScript then moves each ``movej`` at the leading-joint speed that gives that time.
    """

    cell: str
    design: str
    robot: str
    joint_names: list[str]
    revolute: np.ndarray
    cycle_time_s: float = float("nan")
    date: str = ""
    dwell_s: float = 0.5
    name: str = "pko_program"
    speeds: np.ndarray | None = None

    def header_lines(self, units: str) -> list[str]:
        """Header lines (no comment prefix)."""
        date = self.date or _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
        return ["pin-kpi-oed measurement program", f"cell: {self.cell}", f"design: {self.design}",
                f"robot: {self.robot}; joints: {', '.join(self.joint_names)}", f"units: {units}",
                f"date: {date}", f"predicted motion time: {self.cycle_time_s:.2f} s (max_j |dq_j|/v_j per move, "
                "URDF speed limits, no ramps)",
                f"measurement points: marked MEASURE k (design pose i), wait {self.dwell_s:g} s each",
                "joint values are the URDF's: check the controller's axis signs and zeros before running"]


def program_name(info: ProgramInfo) -> str:
    """The program / module name a controller accepts (letters, digits, ``_``; at most 24 characters)."""
    return re.sub(r"[^A-Za-z0-9_]", "_", info.name)[:24] or "pko_program"


def split_joints(info: ProgramInfo, fmt: str, allow_prismatic: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Indices of the revolute (robot) and prismatic (external) joints.

    Raises:
        InputError: not 6 revolute joints, prismatic joints where the format has no external axes, or more
            than 6 of them.
    """
    rev = np.flatnonzero(np.asarray(info.revolute, bool))
    ext = np.flatnonzero(~np.asarray(info.revolute, bool))
    if rev.size != 6 or (not allow_prismatic and ext.size) or ext.size > 6:
        raise InputError(f"program_format {fmt}: needs 6 revolute joints"
                         f"{'' if allow_prismatic else ' and no prismatic'} (up to 6 prismatic as external axes), "
                         f"robot {info.robot} has {rev.size} revolute and {ext.size} prismatic")
    return rev, ext


def step_marks(kinds: list[str], poses: list[int]) -> list[str]:
    """Comment text of each target (``MEASURE k (design pose i)``, ``home``, ``via``)."""
    out, k = [], 0
    for kind, p in zip(kinds, poses):
        if kind == "measure":
            k += 1
            out.append(f"MEASURE {k} (design pose {p})")
        else:
            out.append(kind)
    return out


def measure_marks(text: str, pattern: str) -> list[int]:
    """The design pose index (group 1 of ``pattern``) of every MEASURE mark in a program text, in order."""
    return [int(m.group(1)) for m in re.finditer(pattern, text)]


class ProgramFormat(ABC):
    """A robot-program format.

    Attributes:
        name: the ``--format`` name.
        suffix: the suffix of the (main) file.
        description: one line for the help.
    """

    name: str = ""
    suffix: str = ""
    description: str = ""

    def files(self, out: str | os.PathLike) -> dict[str, Path]:
        """Files the format writes for the ``--out`` path, by suffix (default: the path itself)."""
        return {self.suffix: Path(out)}

    @abstractmethod
    def write(self, Q: np.ndarray, kinds: list[str], poses: list[int], info: ProgramInfo) -> dict[str, str]:
        """The program texts.

        Args:
            Q: targets in execution order (k, n), rad / m, model order.
            kinds: ``home`` / ``measure`` / ``via`` per target.
            poses: design index per target (-1 when not a measurement point).
            info: header fields.

        Returns:
            ``{suffix: text}``, one entry per file of :meth:`files`.

        Raises:
            InputError: a robot the format cannot hold (named).
        """

    @property
    def can_read(self) -> bool:
        """Whether the format has a parser (overrides :meth:`parse`)."""
        return type(self).parse is not ProgramFormat.parse

    def parse(self, texts: dict[str, str], revolute: np.ndarray) -> tuple[np.ndarray, list[int]]:
        """Read written texts back.

        Args:
            texts: ``{suffix: text}`` as :meth:`write` returns them.
            revolute: revolute mask of the robot's joints (model order).

        Returns:
            (targets (k, n) in rad / m in model order, design pose index of each MEASURE point in order).

        Raises:
            InputError: text that is not a program of the format, or a format without a parser.
        """
        raise InputError(f"program_format {self.name}: no parser for this format (it can be written, not read back)")

    def read(self, path: str | os.PathLike, revolute: np.ndarray) -> tuple[np.ndarray, list[int]]:
        """Read the program files written for ``path`` (see :meth:`files`) back, as :meth:`parse`.

        Raises:
            InputError: a missing or unreadable file (named), or text that is not a program of the format.
        """
        texts = {}
        for suffix, f in self.files(path).items():
            try:
                texts[suffix] = f.read_text()
            except OSError as e:
                raise InputError(f"{f}: cannot read the {self.name} program ({e.strerror or e})") from None
        return self.parse(texts, revolute)
