"""Parameter identification by weighted least squares (eq. 5), simulation, model files, compensation.

User-facing names (imported on first use): :class:`IdentifyOptions`, :class:`IdentificationResult`,
:func:`validate` (held-out errors), :func:`error_stats`; :func:`random_truth`, :class:`Tolerances`
(simulated robots); :class:`CalibratedModel`, :func:`load_model_file` (model files: ``.save(path)``
writes one, ``.predict(Q)`` predicts); :func:`register_setup`, :func:`predict_table`;
:class:`CompensationOptions`, :func:`compensate_program`; :func:`write_model_urdf`,
:func:`write_calibrated_urdf`. The functions ``identify``, ``simulate`` and ``compensate`` are
``pin_kpi_oed.identify`` / ``.simulate`` / ``.compensate`` (here they are also module names).
"""
from pin_kpi_oed._lazy import lazy_exports

_EXPORTS = {"IdentifyOptions": "pin_kpi_oed.identification.identify_options",
            "IdentificationResult": "pin_kpi_oed.identification.identify_result",
            "validate": "pin_kpi_oed.identification.heldout", "error_stats": "pin_kpi_oed.identification.heldout",
            "random_truth": "pin_kpi_oed.identification.simulate", "Tolerances": "pin_kpi_oed.model.tolerances",
            "CalibratedModel": "pin_kpi_oed.identification.model_file",
            "load_model_file": "pin_kpi_oed.identification.model_file",
            "register_setup": "pin_kpi_oed.identification.transfer",
            "registration_gates": "pin_kpi_oed.identification.registration_check",
            "predict_table": "pin_kpi_oed.identification.transfer",
            "CompensationOptions": "pin_kpi_oed.identification.compensate",
            "compensate_program": "pin_kpi_oed.identification.compensate",
            "write_model_urdf": "pin_kpi_oed.identification.urdf_export",
            "write_calibrated_urdf": "pin_kpi_oed.identification.urdf_export"}
__getattr__, __dir__ = lazy_exports(globals(), _EXPORTS)
__all__ = list(_EXPORTS)
