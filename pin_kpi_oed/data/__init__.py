"""File formats and containers: measurement sets (CSV), importers, atomic writes.

User-facing names (imported on first use): :class:`MeasurementSet`, :func:`read_measurements`,
:func:`write_measurements`, :func:`concat_measurements`; :class:`TargetSet`, :func:`read_targets`
(compensation targets / programs); :func:`import_ipa` (IPA UR10 files), :func:`import_tracker_export`
(tracker point export + joint log).
"""
from pin_kpi_oed._lazy import lazy_exports

_EXPORTS = {**dict.fromkeys(("MeasurementSet", "read_measurements", "write_measurements", "concat_measurements"),
                            "pin_kpi_oed.data.measurements"),
            "TargetSet": "pin_kpi_oed.data.targets", "read_targets": "pin_kpi_oed.data.targets",
            "import_ipa": "pin_kpi_oed.data.ipa", "import_tracker_export": "pin_kpi_oed.data.tracker_export",
            "write_tracker_export": "pin_kpi_oed.data.tracker_export"}
__getattr__, __dir__ = lazy_exports(globals(), _EXPORTS)
__all__ = list(_EXPORTS)
