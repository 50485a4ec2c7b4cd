"""The nominal reflector offset estimated from the data (the default of identify/diagnose).

The nominal reflector offset does more than start the fit: the structural identifiable set is
computed at it (:func:`pin_kpi_oed.oed.identifiability.analyse`). A reflector assumed at the
flange centre (0, 0, 0), on the last joint's axis, makes the last joints' placement errors look
unidentifiable, so they are held at nominal and the fit ends far above the noise (a KR 15 with the
reflector at (30, 20, 80) mm fitted as if at 0: reduced χ² 28, held-out RMS 5x the noise floor).
:func:`estimate_reflector` fits the set-up only
(tracker pose and reflector, nominal geometry) and returns the reflector rounded to 1 mm, so a
reflector truly on the axis stays on it (components under 0.5 mm become 0) while an off-axis
one is recognised.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["estimate_reflector"]


def estimate_reflector(model: Any, data: Any, options: Any = None, *, round_m: float = 1e-3) -> np.ndarray:
    """Reflector offset in the tool frame (m) fitted with the geometry held nominal, rounded to ``round_m``.

    Args:
        model: :class:`~pin_kpi_oed.model.tracker.TrackerModel` (its reflector is the start, usually 0).
        data: the measurements (:class:`~pin_kpi_oed.data.measurements.MeasurementSet`).
        options: :class:`~pin_kpi_oed.identification.identify.IdentifyOptions` of the full fit (weights,
            orientation, stations); the set-up-only fit uses the plain loss.
        round_m: rounding step (m).

    Returns:
        (3,) reflector offset (m).

    Raises:
        PinKpiOedError: as :func:`~pin_kpi_oed.identification.identify.identify`.
    """
    from pin_kpi_oed.identification.identify import IdentifyOptions, identify

    opts = IdentifyOptions.resolve(options, {})
    res = identify(model, data, opts, setup_only=True, loss="linear", raise_on_failure=False,
                   discrepancy="none", on_poor_fit="ignore")
    r = np.asarray(res.reflector_m, float)
    return np.round(r / round_m) * round_m + 0.0
