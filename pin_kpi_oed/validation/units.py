"""Unit-plausibility guards shared by every command (SI units: m, rad, s, °C).

One place decides what a plausible tracker noise, reflector offset or joint-bound value is, so
that ``simulate``, ``identify``, ``diagnose`` and the cell reader refuse the same values with the
same message (``identify --sigma 10`` and ``diagnose --sigma 15`` alike).
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np

from pin_kpi_oed.errors import InputError

__all__ = ["MAX_TOOL_OFFSET_M", "SIGMA_MAX_M", "SIGMA_ROT_MAX_RAD", "check_sigma_m", "check_sigma_rad",
           "check_offset_m",
           "check_angle_rad", "POSITION_SPREAD_FACTOR", "check_position_spread_m", "EFFECT_SIZE_MAX",
           "check_effect_sizes"]

#: largest plausible measurement noise sigma (m): 1 cm; more means the value was given in mm
SIGMA_MAX_M = 0.01
#: largest plausible reflector / TCP offset from the tool frame (m); more means mm
MAX_TOOL_OFFSET_M = 3.0
#: largest plausible orientation noise sigma (rad): about 5.7°
SIGMA_ROT_MAX_RAD = 0.1


def _text(v: object) -> str:
    """A value for a message: numbers as plain numbers (never ``np.float64(...)``), text quoted, short."""
    try:
        a = np.atleast_1d(np.asarray(v, dtype=float)).ravel()
        return ", ".join(f"{x:g}" for x in a[:6]) + (" ..." if a.size > 6 else "")
    except (TypeError, ValueError):
        return f"{v!r:.60}"


def _values(v: float | Iterable[float], what: str) -> np.ndarray:
    try:
        a = np.atleast_1d(np.asarray(v, dtype=float)).ravel()
    except (TypeError, ValueError):
        raise InputError(f"{what}: expected numbers, got {_text(v)}") from None
    if a.size == 0 or not np.all(np.isfinite(a)):
        raise InputError(f"{what}: expected finite numbers, got {_text(v)}")
    return a


def check_sigma_m(v: float | Iterable[float], what: str) -> np.ndarray:
    """A position noise sigma in m: positive, finite and at most :data:`SIGMA_MAX_M`.

    Args:
        v: value(s) (m).
        what: option or field name for the message.

    Returns:
        The values as a float array (m).

    Raises:
        InputError: naming ``what``, the value and the unit.
    """
    a = _values(v, what)
    if np.any(a <= 0):
        raise InputError(f"{what}: noise sigma must be positive (m), got {', '.join(f'{x:g}' for x in a)}")
    if np.any(a > SIGMA_MAX_M):
        raise InputError(f"{what}: noise sigma {', '.join(f'{x:g}' for x in a)} m is more than {SIGMA_MAX_M * 1e3:g} "
                         f"mm: give it in m (e.g. 1e-5 for 10 µm)")
    return a


def check_sigma_rad(v: float | Iterable[float], what: str) -> np.ndarray:
    """An orientation noise sigma in rad: positive, finite, at most :data:`SIGMA_ROT_MAX_RAD`.

    Raises:
        InputError: naming ``what``, the value and the unit.
    """
    a = _values(v, what)
    if np.any(a <= 0):
        raise InputError(f"{what}: orientation noise sigma must be positive (rad), got {_text(v)}")
    if np.any(a > SIGMA_ROT_MAX_RAD):
        raise InputError(f"{what}: orientation noise sigma {_text(v)} rad is more than {SIGMA_ROT_MAX_RAD:g} rad "
                         f"({math.degrees(SIGMA_ROT_MAX_RAD):.1f}°): give it in rad (e.g. 1e-4)")
    return a


def check_offset_m(v: Iterable[float], reach_m: float, what: str) -> np.ndarray:
    """A tool-frame offset (reflector, TCP) in m: finite and shorter than the robot's reach.

    Raises:
        InputError: naming ``what``, its length in m and the reach.
    """
    a = _values(v, what)
    n = float(np.linalg.norm(a))
    if n > reach_m:
        raise InputError(f"{what}: {n:.4g} m from the tool frame, more than the robot's reach ({reach_m:.3g} m): "
                         "give it in m (a reflector or TCP offset beyond a few metres is mm)")
    return a


def check_angle_rad(v: float | Iterable[float], what: str, limit: float = 4 * math.pi) -> np.ndarray:
    """Joint angles in rad: finite and within ±``limit`` (default ±4π; larger values are degrees).

    Raises:
        InputError: naming ``what`` and the value in rad and °.
    """
    a = _values(v, what)
    bad = np.abs(a) > limit
    if np.any(bad):
        x = float(a[np.flatnonzero(bad)[0]])
        raise InputError(f"{what}: {x:g} rad ({math.degrees(x):.0f}°) is beyond ±{limit:.3g} rad: the values look "
                         "like degrees; give them in rad")
    return a


#: The measured points of one tracker placement lie a median of at most this many times the robot's reach from
#: their median point (a robot cannot spread them further); beyond it they are in mm (or cm, inches), not m.
POSITION_SPREAD_FACTOR = 3.0


def check_position_spread_m(points: np.ndarray, reach_m: float, what: str,
                            advice: str = "convert x, y, z to m") -> float:
    """The one "looks like mm" guard of measured positions: their spread against the robot's reach.

    The median distance of the points from their median point does not depend on where the tracker
    stands; a robot of reach R cannot make it larger than R (2R between two poses). More than
    :data:`POSITION_SPREAD_FACTOR` × R means another length unit.

    Args:
        points: measured positions of one tracker placement (station), (m, 3) in m.
        reach_m: the robot's reach (m), plus the tool offset where it is known.
        what: file / station / columns for the message.
        advice: what to do, appended to the message.

    Returns:
        The median spread (m).

    Raises:
        InputError: the spread exceeds the factor × the reach, naming ``what``, the spread and the reach.
    """
    P = np.asarray(points, float).reshape(-1, 3)
    spread = float(np.median(np.linalg.norm(P - np.median(P, axis=0), axis=1))) if len(P) else 0.0
    if spread > POSITION_SPREAD_FACTOR * float(reach_m):
        raise InputError(f"{what}: the measured points lie a median {spread:.6g} m from their median point, more than "
                         f"{POSITION_SPREAD_FACTOR:g} x reach ({float(reach_m):.3g} m): looks like mm; {advice}")
    return spread


#: the largest plausible size of a simulated effect's parameters, per unit (SI): beyond, another unit was meant
#: (a gear harmonic of 5 is degrees or µrad, not rad)
EFFECT_SIZE_MAX = {"rad": 0.05, "rad/(N*m)": 1e-4, "1": 0.05, "1/K": 1e-3, "m/s": 1e-3}


def check_effect_sizes(effects: Iterable, what: str = "parameter 'effects'",
                       given: dict[str, str] | None = None) -> None:
    """Refuse simulated effect parameters beyond :data:`EFFECT_SIZE_MAX` of their unit.

    Args:
        effects: (effect, theta) pairs; an effect has ``name`` and ``unit``.
        what: the parameter (or option) the message names.
        given: the values as the user wrote them, by effect name (``{"joint_compliance": "3"}``): checked instead
            of the parameters drawn from them (a size draws parameters of 0.5 to 1 times it), and named.

    Raises:
        InputError: naming the effect, the value, its unit and the bound.
    """
    for eff, theta in effects:
        big = EFFECT_SIZE_MAX.get(getattr(eff, "unit", ""))
        text = (given or {}).get(eff.name)
        try:
            a = np.abs(np.array([float(v) for v in text.split(":")])) if text else np.abs(np.asarray(theta, float))
        except ValueError:
            a = np.abs(np.asarray(theta, float))
        if big is not None and a.size and float(a.max()) > big:
            value = f"{eff.name}={text}" if text else f"{eff.name} of size {float(a.max()):g}"
            raise InputError(f"{what}: {value} {eff.unit} is more than {big:g} "
                             f"{eff.unit}: give it in SI units ({eff.unit}), e.g. gear_harmonic=5e-5 (rad), "
                             "joint_compliance=2e-6 (rad/(N*m))")
