"""Sim-to-real gap diagnosis: where the residual lies, which effect causes it, how far it shrinks.

User-facing names (imported on first use): :class:`DiagnoseOptions`, :class:`DiagnosisReport`,
:class:`EffectResult`, :func:`select_terms` (sparse selection of transferable terms). The function
``diagnose`` is ``pin_kpi_oed.diagnose`` (here ``diagnose`` is also the name of its module).
"""
from pin_kpi_oed._lazy import lazy_exports

_EXPORTS = {"DiagnoseOptions": "pin_kpi_oed.diagnosis.diagnose_options",
            "DiagnosisReport": "pin_kpi_oed.diagnosis.report", "EffectResult": "pin_kpi_oed.diagnosis.report",
            "select_terms": "pin_kpi_oed.diagnosis.selection"}
__getattr__, __dir__ = lazy_exports(globals(), _EXPORTS)
__all__ = list(_EXPORTS)
