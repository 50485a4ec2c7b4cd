"""The robot and what a measurement device sees of it: URDF loading, KUKA arms, parameter layout, the batched
kinematics core, measurement models (the device interface, the laser tracker, the camera seeing a board), noise.

User-facing names (imported on first use): :func:`load_robot`, :class:`Robot`, :class:`TrackerModel`,
:class:`MeasurementModel`, :class:`CameraModel` (with :class:`Intrinsics`, :class:`Board`), :class:`NoiseModel`,
:class:`ParameterLayout`, :class:`Tolerances`.
"""
from pin_kpi_oed._lazy import lazy_exports

_EXPORTS = {"load_robot": "pin_kpi_oed.model.robot", "Robot": "pin_kpi_oed.model.robot",
            "TrackerModel": "pin_kpi_oed.model.tracker", "MeasurementModel": "pin_kpi_oed.model.device",
            "NoiseModel": "pin_kpi_oed.model.noise", "ParameterLayout": "pin_kpi_oed.model.parameters",
            "Tolerances": "pin_kpi_oed.model.tolerances", "CameraModel": "pin_kpi_oed.model.camera",
            "Intrinsics": "pin_kpi_oed.model.camera", "Board": "pin_kpi_oed.model.camera"}
__getattr__, __dir__ = lazy_exports(globals(), _EXPORTS)
__all__ = list(_EXPORTS)
