"""Safety margins of a design: the optimiser designs in a tightened cell, the check reports the true one.

``pin-kpi-oed design --clearance-margin 0.02 --incidence-margin 1`` designs in
:func:`with_margins` (required clearance raised by the margin, incidence limit lowered by its
margin: eqs. 20–23 and 24b with tighter bounds), so a pose a few millimetres or a fraction of a
degree off its designed value (model error, tracker set-up) stays clear and visible. The
independent check (:class:`~pin_kpi_oed.cell.feasibility.FeasibilityChecker` of the *untightened*
cell) then reports every pose's true clearance and incidence.
"""

from __future__ import annotations

import dataclasses
import math

from pin_kpi_oed.cell.cell import Cell
from pin_kpi_oed.errors import InputError

#: default clearance margin of ``pin-kpi-oed design`` (m): 20 mm, the order of the capsules' own
#: approximation error and of a small model / set-up error at 1 m reach.
DEFAULT_CLEARANCE_MARGIN_M = 0.02
#: default incidence margin of ``pin-kpi-oed design`` (deg).
DEFAULT_INCIDENCE_MARGIN_DEG = 1.0


def with_margins(cell: Cell, clearance_margin_m: float = 0.0, incidence_margin_deg: float = 0.0) -> Cell:
    """The cell the optimiser designs in: clearance + margin, incidence limit − margin.

    Args:
        cell: the true cell.
        clearance_margin_m: added to ``cell.clearance_m`` (m), >= 0.
        incidence_margin_deg: subtracted from ``cell.incidence_max_deg`` (deg), in [0, limit).

    Returns:
        A copy of the cell with the tightened limits (the same cell when both margins are 0).

    Raises:
        InputError: a negative margin, or an incidence margin that leaves no admissible angle.
    """
    cm, im = float(clearance_margin_m), float(incidence_margin_deg)
    if not (cm >= 0.0 and cm < 1.0):
        raise InputError(f"parameter 'clearance_margin_m' must be in [0, 1) m, got {clearance_margin_m}")
    lim = cell.incidence_max_deg
    if not im >= 0.0:
        raise InputError(f"incidence_margin_deg: must be >= 0 deg, got {incidence_margin_deg}")
    if not im < lim:
        raise InputError(f"incidence_margin_deg: {incidence_margin_deg} deg leaves no angle under the cell's "
                         f"incidence_max_deg {lim:g} deg, which it is subtracted from: give a smaller margin (0: none)"
                         + (f", or the cell's limit in degrees ({lim:g} rad = {math.degrees(lim):.3g} deg)"
                            if lim <= math.pi / 2 else ""))
    if cm == 0.0 and im == 0.0:
        return cell
    return dataclasses.replace(cell, clearance_m=cell.clearance_m + cm, incidence_max_deg=cell.incidence_max_deg - im,
                               clearance_margin_m=cell.clearance_margin_m + cm)
