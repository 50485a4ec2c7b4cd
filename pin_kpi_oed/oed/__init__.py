"""Optimum experimental design maths: identifiability, covariances (eq. 19), criteria, pool selection, certificates.

User-facing names (imported on first use): :func:`analyse`, :class:`Identifiability`;
:func:`score_design`, :class:`DesignScore`; :func:`kpi_covariance`, :func:`param_covariance`;
:data:`CRITERIA`, :func:`get_criterion`, :class:`Criterion`; :func:`select` (pool selection),
:func:`certify_pool` (optimality certificate of a pool); :class:`ExtendedModel` (designs over geometry + effects);
:class:`HedgedDesignCriterion`, :func:`prior_family` (``kpi_gp`` hedged over priors around an assumed discrepancy).
"""
from pin_kpi_oed._lazy import lazy_exports

_EXPORTS = {"analyse": "pin_kpi_oed.oed.identifiability", "Identifiability": "pin_kpi_oed.oed.identifiability",
            "score_design": "pin_kpi_oed.oed.evaluate", "DesignScore": "pin_kpi_oed.oed.evaluate",
            "kpi_covariance": "pin_kpi_oed.oed.covariance", "param_covariance": "pin_kpi_oed.oed.covariance",
            "CRITERIA": "pin_kpi_oed.oed.criteria", "get_criterion": "pin_kpi_oed.oed.criteria",
            "Criterion": "pin_kpi_oed.oed.criteria", "select": "pin_kpi_oed.oed.pool",
            "certify_pool": "pin_kpi_oed.oed.certificate", "ExtendedModel": "pin_kpi_oed.oed.extended",
            "HedgedDesignCriterion": "pin_kpi_oed.oed.hedged_kpi", "prior_family": "pin_kpi_oed.oed.hedged_kpi",
            "PathKpi": "pin_kpi_oed.oed.path_kpi", "PathMaxKpi": "pin_kpi_oed.oed.path_kpi_max",
            "PoseKpi": "pin_kpi_oed.oed.pose_kpi"}
__getattr__, __dir__ = lazy_exports(globals(), _EXPORTS)
__all__ = list(_EXPORTS)
