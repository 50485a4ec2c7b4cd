"""Using the calibrated model: compensated joints for Cartesian targets and robot programs.

:func:`compensate` (targets), :func:`compensate_program` (a program, its corrections kept smooth),
:class:`CompensationOptions`, :class:`CompensationResult` and :func:`write_compensation` (the CSV a controller
receives), :func:`forward` (the calibrated model's TCP at given joints).
"""
from pin_kpi_oed._lazy import lazy_exports

_EXPORTS = {"compensate": "pin_kpi_oed.compensation.compensator",
            "compensate_program": "pin_kpi_oed.compensation.compensator",
            "CompensationOptions": "pin_kpi_oed.compensation.compensator",
            "forward": "pin_kpi_oed.compensation.compensator",
            "CompensationResult": "pin_kpi_oed.compensation.result",
            "write_compensation": "pin_kpi_oed.compensation.result"}
__getattr__, __dir__ = lazy_exports(globals(), _EXPORTS)
__all__ = list(_EXPORTS)
