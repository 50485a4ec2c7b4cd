"""The work cell: robot and obstacle capsules, tracker, constraints (collision, incidence), feasibility check.

User-facing names (imported on first use): :func:`load_cell` (a shipped cell name or a YAML file),
:class:`Cell`, :class:`CapsuleSpec`, :class:`HalfSpace`, :func:`cell_from_dict`,
:func:`capsules_from_urdf`, :class:`FeasibilityChecker` (the independent Coal check of poses).
"""
from pin_kpi_oed._lazy import lazy_exports

_EXPORTS = {**dict.fromkeys(("Cell", "CapsuleSpec", "HalfSpace", "load_cell", "cell_from_dict", "capsules_from_urdf",
                             "SHIPPED_CELLS"), "pin_kpi_oed.cell.cell"),
            "FeasibilityChecker": "pin_kpi_oed.cell.feasibility", "FeasibilityReport": "pin_kpi_oed.cell.feasibility"}
__getattr__, __dir__ = lazy_exports(globals(), _EXPORTS)
__all__ = list(_EXPORTS)
