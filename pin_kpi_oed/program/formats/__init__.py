"""Formats a measurement program is written in for robot controllers (``pin-kpi-oed export --format``).

One module per format, each a :class:`~pin_kpi_oed.program.formats.base.ProgramFormat`; the registry
(:data:`~pin_kpi_oed.program.formats.registry.PROGRAM_FORMATS`) holds one line per format.
"""
from pin_kpi_oed._lazy import lazy_exports

_EXPORTS = {**dict.fromkeys(("ProgramFormat", "ProgramInfo"), "pin_kpi_oed.program.formats.base"),
            **dict.fromkeys(("PROGRAM_FORMATS", "register_format", "get_format"),
                            "pin_kpi_oed.program.formats.registry")}
__getattr__, __dir__ = lazy_exports(globals(), _EXPORTS)
__all__ = list(_EXPORTS)
