"""The robot and what a measurement device sees of it: URDF loading, KUKA arms, parameter layout, the batched
kinematics core, measurement models (the device interface and the laser tracker), noise.

User-facing names (imported on first use): :func:`load_robot`, :class:`Robot`, :class:`TrackerModel`,
:class:`MeasurementModel`, :class:`NoiseModel`, :class:`ParameterLayout`, :class:`Tolerances`.
"""
from pin_kpi_oed._lazy import lazy_exports

_EXPORTS = {"load_robot": "pin_kpi_oed.model.robot", "Robot": "pin_kpi_oed.model.robot",
            "TrackerModel": "pin_kpi_oed.model.tracker", "MeasurementModel": "pin_kpi_oed.model.device",
            "NoiseModel": "pin_kpi_oed.model.noise", "ParameterLayout": "pin_kpi_oed.model.parameters",
            "Tolerances": "pin_kpi_oed.model.tolerances"}
__getattr__, __dir__ = lazy_exports(globals(), _EXPORTS)
__all__ = list(_EXPORTS)
