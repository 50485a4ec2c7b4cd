"""KPI optimum experimental design solved by IPOPT (eq. 24), design files, user pools, sequential design.

User-facing names (imported on first use): :func:`run_designs` (heuristic + optimum designs of a cell),
:class:`DesignOptions`, :class:`DesignProblem`, :class:`DesignResult`, :func:`design_random`,
:func:`design_ipopt`; :func:`load_design`, :class:`DesignFile`, :class:`DesignEntry`, :func:`write_design`,
:func:`design_document` (design files: what ``view`` and ``export`` read);
:func:`design_run`, :class:`DesignSettings`, :class:`DesignRun` (a run as a declaration; :func:`design_problem`, the
problem its settings declare); :class:`ProblemOptions` (what a :class:`DesignProblem` is declared with: measured
poses and their prior :class:`ParameterPrior`, extended model, discrepancy, working region, re-registration);
:func:`read_poses` (a user pool), :func:`poses_until` (how many more poses on top of measured ones); :func:`certify`
(the optimality certificate of a design problem).
"""
from pin_kpi_oed._lazy import lazy_exports

_EXPORTS = {**dict.fromkeys(("run_designs", "DesignOptions", "DesignProblem", "DesignResult", "design_random",
                             "design_ipopt"), "pin_kpi_oed.design.optimize"),
            **dict.fromkeys(("load_design", "DesignFile", "DesignEntry", "write_design", "design_document"),
                           "pin_kpi_oed.design.design_file"),
            **dict.fromkeys(("design_run", "DesignRun", "DesignSettings"), "pin_kpi_oed.design.runner"),
            "design_problem": "pin_kpi_oed.design.declare",
            "read_poses": "pin_kpi_oed.design.user_pool",
            **dict.fromkeys(("ProblemOptions", "ParameterPrior"), "pin_kpi_oed.design.problem_options"),
            "poses_until": "pin_kpi_oed.design.sequential",
            "certify": "pin_kpi_oed.design.optimality"}
__getattr__, __dir__ = lazy_exports(globals(), _EXPORTS)
__all__ = list(_EXPORTS)
