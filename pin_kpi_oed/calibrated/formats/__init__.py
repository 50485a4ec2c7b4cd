"""Formats a calibrated model is written in for robots and their software (``pin-kpi-oed export-model``).

One module per format, each a :class:`~pin_kpi_oed.calibrated.formats.base.ModelFormat`; the registry
(:data:`~pin_kpi_oed.calibrated.formats.registry.MODEL_FORMATS`) holds one line per format.
"""
from pin_kpi_oed._lazy import lazy_exports

_EXPORTS = {"ModelFormat": "pin_kpi_oed.calibrated.formats.base",
            "ExportReport": "pin_kpi_oed.calibrated.formats.base",
            "MODEL_FORMATS": "pin_kpi_oed.calibrated.formats.registry",
            "export_model": "pin_kpi_oed.calibrated.formats.registry"}
__getattr__, __dir__ = lazy_exports(globals(), _EXPORTS)
__all__ = list(_EXPORTS)
