"""The calibrated model: what an identification delivers and every later use reads.

The model and its file (:class:`CalibratedModel`, :func:`load_model_file`: ``.save(path)`` writes one,
``.predict(Q)`` predicts with its σ), the σ of its predictions (:func:`predictive_sigma`), the joint-space
coverage of its training data, and the formats it is written in for robots and their software
(:func:`export_model`, :data:`MODEL_FORMATS`, :func:`write_model_urdf`, :func:`write_calibrated_urdf`).
"""
from pin_kpi_oed._lazy import lazy_exports

_EXPORTS = {"CalibratedModel": "pin_kpi_oed.calibrated.model_file",
            "load_model_file": "pin_kpi_oed.calibrated.model_file",
            "predictive_sigma": "pin_kpi_oed.calibrated.prediction_sigma",
            "write_model_urdf": "pin_kpi_oed.calibrated.urdf_export",
            "write_calibrated_urdf": "pin_kpi_oed.calibrated.urdf_export",
            "export_model": "pin_kpi_oed.calibrated.formats.registry",
            "MODEL_FORMATS": "pin_kpi_oed.calibrated.formats.registry"}
__getattr__, __dir__ = lazy_exports(globals(), _EXPORTS)
__all__ = list(_EXPORTS)
