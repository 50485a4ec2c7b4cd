"""Continuous URDF joints read as the revolute joints the calibration takes.

Pinocchio models a continuous joint (a revolute joint without stops, as the Kinova Gen2/Gen3 joints that turn without
end) by (cos q, sin q): two configuration values for one velocity. The package takes one value per joint (rad or m),
so a continuous joint is read as a revolute joint with the limits ±2π rad (one turn either way): its type is rewritten
in the URDF's XML before Pinocchio builds the model. Every origin, axis, effort and velocity stays as written (the
numbers exact), the links and their geometry are untouched, so the collision and visual geometry of the file load on
the model unchanged. The robot's loader says which joints were taken so (:attr:`Robot.notes`), never silently.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin

#: The range a continuous joint is given either way (rad): one turn.
TURN_RAD = 2.0 * math.pi


def continuous_as_revolute(root: ET.Element) -> list[str]:
    """Rewrite (in place) every ``type="continuous"`` joint of a URDF's XML as ``type="revolute"`` with the limits
    ±2π rad; its ``<limit>`` element's effort and velocity are kept (one with both 0 is added where it has none).

    Args:
        root: the ``<robot>`` element of a parsed URDF.

    Returns:
        The names of the joints rewritten, in the file's order (empty when the URDF has none).
    """
    names: list[str] = []
    for el in root.findall("joint"):
        if el.get("type") != "continuous":
            continue
        el.set("type", "revolute")
        lim = el.find("limit")
        if lim is None:
            lim = ET.SubElement(el, "limit", {"effort": "0", "velocity": "0"})
        lim.set("lower", repr(-TURN_RAD))
        lim.set("upper", repr(TURN_RAD))
        names.append(str(el.get("name")))
    return names


def revolute_urdf_text(text: str) -> tuple[str, list[str]]:
    """A URDF text with its continuous joints written as revolute joints of ±2π rad (:func:`continuous_as_revolute`).

    Args:
        text: the URDF text.

    Returns:
        (the text — the same string when the URDF has no continuous joint —, the names of the joints rewritten).

    Raises:
        xml.etree.ElementTree.ParseError: the text is not XML.
    """
    root = ET.fromstring(text)
    names = continuous_as_revolute(root)
    return (ET.tostring(root, encoding="unicode") if names else text), names


def model_from_urdf_text(text: str) -> tuple[pin.Model, list[str]]:
    """The full Pinocchio model of a URDF text, its continuous joints revolute of ±2π rad (one value per joint).

    Args:
        text: the URDF text.

    Returns:
        (the model, the names of the joints taken from continuous to revolute).

    Raises:
        xml.etree.ElementTree.ParseError: the text is not XML.
        ValueError, RuntimeError: Pinocchio cannot build the model (as :func:`pinocchio.buildModelFromXML`).
    """
    fixed, names = revolute_urdf_text(text)
    return pin.buildModelFromXML(fixed), names


def locked_posture(model: pin.Model) -> np.ndarray:
    """The configuration at which the joints off the chain are locked: Pinocchio's neutral, each 1-DoF joint's value
    clipped into its finite limits (a B1's calf has 0 rad outside [−2.6, −0.6] rad: locked at −0.6 rad, a posture the
    robot can take).

    Args:
        model: the full model, before the reduction.

    Returns:
        (model.nq,) configuration (rad / m; (cos, sin) pairs of unbounded joints as neutral).
    """
    q = pin.neutral(model).copy()
    for j in range(1, model.njoints):
        jm = model.joints[j]
        if jm.nq != 1:
            continue
        i = jm.idx_q
        lo, hi = model.lowerPositionLimit[i], model.upperPositionLimit[i]
        if np.isfinite(lo) and np.isfinite(hi) and lo <= hi:
            q[i] = min(max(q[i], lo), hi)
    return q
