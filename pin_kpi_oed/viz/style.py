"""Colours of the pictures: one per design criterion, shared by the meshcat scene and the report figures."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

#: Colours (0xRRGGBB) of the usual design criteria; the robot itself is orange, so none of these is.
DESIGN_COLOURS: dict[str, int] = {
    "random": 0x1F77B4,     # heuristic: blue
    "heuristic": 0x1F77B4,
    "param": 0x9467BD,      # A on C_p: purple
    "kpi": 0x2CA02C,        # A on C_s (the paper's KPI design): green
}
#: Colours handed out, in order, to any other criterion.
EXTRA_COLOURS: tuple[int, ...] = (0x17BECF, 0xE377C2, 0x7F7F7F, 0xBCBD22, 0x8C564B, 0x393B79, 0x637939)
#: The robot (drawn from primitives), RGBA 0…1.
ROBOT_RGBA = np.array([0.96, 0.47, 0.13, 1.0])
#: The robot's collision capsules, RGBA 0…1.
CAPSULE_RGBA = np.array([0.1, 0.75, 0.95, 0.35])
#: The laser beam.
BEAM_COLOUR = 0xE41A1C


def design_colours(criteria: Sequence[str], given: Mapping[str, int] | None = None) -> dict[str, int]:
    """A colour (0xRRGGBB) per criterion: ``given``, else :data:`DESIGN_COLOURS`, else the next of
    :data:`EXTRA_COLOURS` (in order, cycling)."""
    out: dict[str, int] = {}
    k = 0
    for c in criteria:
        colour = (given or {}).get(c, DESIGN_COLOURS.get(c))
        if colour is None:
            colour = EXTRA_COLOURS[k % len(EXTRA_COLOURS)]
            k += 1
        out[c] = int(colour)
    return out


def hex_colour(colour: int) -> str:
    """0xRRGGBB -> ``"#rrggbb"``."""
    return f"#{int(colour):06x}"


def rgb(colour: int) -> np.ndarray:
    """0xRRGGBB -> (r, g, b) in 0…1."""
    return np.array([(colour >> 16) & 255, (colour >> 8) & 255, colour & 255]) / 255.0
