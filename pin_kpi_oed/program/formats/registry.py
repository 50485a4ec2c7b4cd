"""The program formats ``export --format`` knows: one line per format."""

from __future__ import annotations

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.program.formats.base import ProgramFormat
from pin_kpi_oed.program.formats.csv import CsvFormat
from pin_kpi_oed.program.formats.krl import KrlFormat
from pin_kpi_oed.program.formats.rapid import RapidFormat
from pin_kpi_oed.program.formats.urscript import URScriptFormat

__all__ = ["PROGRAM_FORMATS", "register_format", "get_format"]

#: name -> format (one line per format).
PROGRAM_FORMATS: dict[str, ProgramFormat] = {f.name: f for f in (
    CsvFormat(),
    URScriptFormat(),
    KrlFormat(),
    RapidFormat(),
)}


def register_format(fmt: ProgramFormat) -> ProgramFormat:
    """Add a format from outside the package (``export``, ``--format`` and the parsers find it).

    Raises:
        InputError: not a :class:`ProgramFormat`, no name, or a name already taken by another format.
    """
    if not isinstance(fmt, ProgramFormat) or not fmt.name:
        raise InputError(f"program format {fmt!r}: must be a named ProgramFormat")
    if PROGRAM_FORMATS.get(fmt.name, fmt) is not fmt:
        raise InputError(f"program format '{fmt.name}': already registered")
    PROGRAM_FORMATS[fmt.name] = fmt
    return fmt


def get_format(name: str, option: str = "program_format: ") -> ProgramFormat:
    """The registered format ``name``.

    Raises:
        InputError: an unknown format, naming the known ones.
    """
    if name not in PROGRAM_FORMATS:
        raise InputError(f"{option}unknown format '{name}' (known: {', '.join(PROGRAM_FORMATS)})")
    return PROGRAM_FORMATS[name]
