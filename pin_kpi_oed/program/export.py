"""Robot programs from an ordered measurement program — the public functions over the format registry.

Every format (:class:`~pin_kpi_oed.program.formats.base.ProgramFormat`, one module each in
``program/formats/``: CSV, URScript, KUKA KRL, ABB RAPID) writes ``{suffix: text}`` (KRL: ``.src`` +
``.dat``; the others one file) with a header naming the cell, the design, the robot, the units and the
date, and every measurement instruction point marked (``MEASURE k (design pose i)`` plus a wait of
``dwell_s`` for the tracker to settle and measure). Joint values are the URDF's (rad / m in the model):

* CSV: one row per target, each joint in degrees and radians (metres for prismatic joints);
* URScript: ``movej([...], a, v)`` in rad, 6 revolute joints;
* KRL: ``PTP XPk`` in the ``.src``, ``DECL E6AXIS XPk={A1 .., E1 ..}`` in the ``.dat``: the 6
  revolute joints as A1–A6 in degrees, prismatic joints (a linear track) as E1… in millimetres;
* RAPID: ``CONST jointtarget`` + ``MoveAbsJ``: robax in degrees, prismatic joints in eax_a… (mm).

The parsers (:func:`parse_program`) read the same texts back to configurations in SI units: the
tests round-trip every format to 1e-6 rad. The controller's own sign and zero conventions of each
axis are not known to the package: check them against the robot's manual before running (the
header says so). :data:`FORMATS` is the registry itself (a format registered with
:func:`~pin_kpi_oed.program.formats.registry.register_format` is known to every function here and to
``pin-kpi-oed export --format``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pin_kpi_oed.program.formats.base import ProgramInfo
from pin_kpi_oed.program.formats.krl import KrlFormat
from pin_kpi_oed.program.formats.rapid import RapidFormat
from pin_kpi_oed.program.formats.registry import PROGRAM_FORMATS, get_format
from pin_kpi_oed.program.formats.urscript import URScriptFormat

__all__ = ["FORMATS", "ProgramInfo", "program_files", "write_program", "parse_program", "write_csv",
           "write_urscript", "write_krl", "write_rapid"]

#: the known formats by name (the live registry: iterate it for the names).
FORMATS = PROGRAM_FORMATS


def program_files(fmt: str, out: str) -> dict[str, Path]:
    """Files a format writes, by suffix: the ``--out`` path (KRL: the ``.src``, ``.src`` added when missing,
    and the ``.dat`` beside it).

    Raises:
        InputError: unknown format.
    """
    return get_format(fmt).files(out)


def write_program(fmt: str, Q: np.ndarray, kinds: list[str], poses: list[int], info: ProgramInfo) -> dict[str, str]:
    """The program texts of a format.

    Args:
        fmt: one of :data:`FORMATS`.
        Q: targets in execution order (k, n), rad / m.
        kinds: ``home`` / ``measure`` / ``via`` per target.
        poses: design index per target (-1 when not a measurement point).
        info: header fields.

    Returns:
        ``{suffix: text}``.

    Raises:
        InputError: unknown format, or a robot the format cannot hold.
    """
    return get_format(fmt).write(np.atleast_2d(np.asarray(Q, float)), list(kinds), [int(p) for p in poses], info)


def parse_program(fmt: str, texts: dict[str, str], revolute: np.ndarray) -> tuple[np.ndarray, list[int]]:
    """Read a written program back.

    Args:
        fmt: the format.
        texts: ``{suffix: text}`` as :func:`write_program` returns (or as read from the files).
        revolute: revolute mask of the robot's joints (model order).

    Returns:
        (targets (k, n) in rad / m in model order, design pose index of each MEASURE point in order).

    Raises:
        InputError: an unknown format, one without a parser, or text that is not a program of the format.
    """
    return get_format(fmt, option="").parse(texts, np.asarray(revolute, bool))


def write_csv(Q: np.ndarray, kinds: list[str], poses: list[int], info: ProgramInfo) -> dict[str, str]:
    """CSV: step, kind, pose, every joint in deg (m) and in rad (m)."""
    return write_program("csv", Q, kinds, poses, info)


def write_urscript(Q: np.ndarray, kinds: list[str], poses: list[int], info: ProgramInfo, a: float = 1.4,
                   v: float = 1.05) -> dict[str, str]:
    """URScript: ``movej`` through every target (rad; acceleration ``a`` rad/s², speed ``v`` rad/s when the
    program carries no joint speeds), ``textmsg`` + ``sleep`` at measurement points."""
    return URScriptFormat(a=a, v=v).write(np.atleast_2d(np.asarray(Q, float)), list(kinds), [int(p) for p in poses],
                                          info)


def write_krl(Q: np.ndarray, kinds: list[str], poses: list[int], info: ProgramInfo) -> dict[str, str]:
    """KUKA KRL: ``.src`` (PTP to every E6AXIS point, MEASURE comments, WAIT) and ``.dat`` (the points)."""
    return KrlFormat().write(np.atleast_2d(np.asarray(Q, float)), list(kinds), [int(p) for p in poses], info)


def write_rapid(Q: np.ndarray, kinds: list[str], poses: list[int], info: ProgramInfo, speed: str = "v1000",
                tool: str = "tool0") -> dict[str, str]:
    """ABB RAPID: a module with a ``CONST jointtarget`` per target and ``MoveAbsJ`` through them."""
    return RapidFormat(speed=speed, tool=tool).write(np.atleast_2d(np.asarray(Q, float)), list(kinds),
                                                     [int(p) for p in poses], info)
