"""Parameter identification by weighted least squares (eq. 5): the fit.

The problem (stations, the residual and its Jacobian), its solution, the fit-quality verdict and the held-out
validation. User-facing names (imported on first use): :class:`IdentifyOptions`, :class:`IdentificationResult`
(``.calibrated_model()`` is the :class:`~pin_kpi_oed.calibrated.CalibratedModel` it delivers), :func:`validate`
(held-out errors), :func:`error_stats`, :func:`fit_camera` and :func:`camera_tcp_covariance` (a camera's fit on the
reprojection error and its TCP covariance). The function ``identify`` is ``pin_kpi_oed.identify`` (here it is also a
module name). What uses the fit lives downstream: :mod:`pin_kpi_oed.compensation`, :mod:`pin_kpi_oed.upkeep`.
"""
from pin_kpi_oed._lazy import lazy_exports

_EXPORTS = {"IdentifyOptions": "pin_kpi_oed.identification.identify_options",
            "IdentificationResult": "pin_kpi_oed.identification.identify_result",
            "validate": "pin_kpi_oed.identification.heldout", "error_stats": "pin_kpi_oed.identification.heldout",
            "CalibratedModel": "pin_kpi_oed.calibrated.model_file",
            "load_model_file": "pin_kpi_oed.calibrated.model_file",
            "fit_camera": "pin_kpi_oed.identification.camera_fit",
            "camera_tcp_covariance": "pin_kpi_oed.identification.camera_fit"}
__getattr__, __dir__ = lazy_exports(globals(), _EXPORTS)
__all__ = list(_EXPORTS)
