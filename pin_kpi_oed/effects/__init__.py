"""Non-geometric error effects (compliance, gear harmonics, thermal, ...) that extend the geometric model.

User-facing names (imported on first use): :class:`Effect` (the interface), the effects
(:class:`JointCompliance`, :class:`GearHarmonic`, :class:`Backlash`, :class:`ThermalExpansion`,
:class:`JointScale`, :class:`JointAngleTable`, :class:`TransmissionError`, :class:`LinkBending`,
:class:`Drift`), the registry :data:`EFFECTS`, :func:`make_effect`, :func:`parse_effects_spec`.
"""
from pin_kpi_oed._lazy import lazy_exports

_EXPORTS = {**dict.fromkeys(("Effect", "JointCompliance", "GearHarmonic", "Backlash", "ThermalExpansion", "JointScale",
                             "JointAngleTable", "EFFECTS", "OPT_IN_EFFECTS", "make_effect", "parse_effects_spec"),
                            "pin_kpi_oed.effects.library"),
            "TransmissionError": "pin_kpi_oed.effects.periodic", "LinkBending": "pin_kpi_oed.effects.coupled",
            "Drift": "pin_kpi_oed.effects.drift"}
__getattr__, __dir__ = lazy_exports(globals(), _EXPORTS)
__all__ = list(_EXPORTS)
