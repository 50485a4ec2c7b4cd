"""From a design to a measurement program: move times, safe transitions, ordering, robot-program export.

User-facing names (imported on first use): :func:`plan_program`, :class:`ProgramOptions`,
:class:`Program`; :func:`write_program`, :class:`ProgramInfo`, :func:`parse_program`, :data:`FORMATS`.
"""
from pin_kpi_oed._lazy import lazy_exports

_EXPORTS = {**dict.fromkeys(("plan_program", "ProgramOptions", "Program"), "pin_kpi_oed.program.ordering"),
            **dict.fromkeys(("write_program", "ProgramInfo", "parse_program", "FORMATS"), "pin_kpi_oed.program.export")}
__getattr__, __dir__ = lazy_exports(globals(), _EXPORTS)
__all__ = list(_EXPORTS)
