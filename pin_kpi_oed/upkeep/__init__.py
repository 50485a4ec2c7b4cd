"""Keeping the calibrated model: registration in a new set-up and transfer, the quick check and its design,
monitoring in production with the set-up filter.

:func:`register_setup`, :func:`registration_gates`, :func:`predict_table`, :func:`validate_transfer`;
:func:`check_calibration` (has the robot changed?), :func:`design_check` (the poses of a check);
:func:`monitor`, :class:`Monitor` (a running check), :class:`SetupFilter`.
"""
from pin_kpi_oed._lazy import lazy_exports

_EXPORTS = {"register_setup": "pin_kpi_oed.upkeep.transfer",
            "predict_table": "pin_kpi_oed.upkeep.transfer",
            "validate_transfer": "pin_kpi_oed.upkeep.transfer",
            "RegistrationResult": "pin_kpi_oed.upkeep.transfer",
            "registration_gates": "pin_kpi_oed.upkeep.registration_check",
            "check_calibration": "pin_kpi_oed.upkeep.check",
            "CheckResult": "pin_kpi_oed.upkeep.check",
            "design_check": "pin_kpi_oed.upkeep.check_design",
            "CheckDesign": "pin_kpi_oed.upkeep.check_design",
            "monitor": "pin_kpi_oed.upkeep.monitoring",
            "Monitor": "pin_kpi_oed.upkeep.monitoring",
            "MonitorLog": "pin_kpi_oed.upkeep.monitoring",
            "SetupFilter": "pin_kpi_oed.upkeep.setup_filter"}
__getattr__, __dir__ = lazy_exports(globals(), _EXPORTS)
__all__ = list(_EXPORTS)
