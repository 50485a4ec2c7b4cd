"""Simulated robots and measurements: a random "real" robot within the tolerances (:func:`random_truth`,
:class:`Tolerances`), its tracker readings with noise and effects (:func:`simulate`), truth files
(:func:`load_truth`) and the default tracker pose of a cell (:func:`default_tracker_pose`).
"""
from pin_kpi_oed._lazy import lazy_exports

_EXPORTS = {"simulate": "pin_kpi_oed.simulation.simulator",
            "random_truth": "pin_kpi_oed.simulation.simulator",
            "load_truth": "pin_kpi_oed.simulation.simulator",
            "default_tracker_pose": "pin_kpi_oed.simulation.simulator",
            "Tolerances": "pin_kpi_oed.model.tolerances"}
__getattr__, __dir__ = lazy_exports(globals(), _EXPORTS)
__all__ = list(_EXPORTS)
