r"""Joint-angle periodic (transmission) errors: a Fourier series in each joint's own angle, any order.

A strain-wave or planetary gear, an encoder's eccentricity and the pitch errors of a gear train
make the angle the joint really turns differ from the angle it reports by a periodic function
of that angle. Over one revolution of the output the error repeats k times for a component of
order k ("k cycles per revolution"), so::

    Δq_j(q) = Σ_{k ∈ K_j} a_jk sin(k q_j) + b_jk cos(k q_j)          (rad)
            = Σ_{k ∈ K_j} A_jk sin(k q_j + φ_jk),   A = √(a² + b²),  φ = atan2(b, a)

with θ = (a_jk, b_jk) in rad. :class:`TransmissionError` is
:class:`~pin_kpi_oed.effects.library.GearHarmonic` (orders 1 and 2 of every joint) with orders
1 … ``max_order`` (default 40), or with chosen (joint, order) pairs — the ones
:func:`pin_kpi_oed.diagnosis.selection.select_terms` picks by held-out error from the full
basis. Each (sin, cos) pair is one group: it is selected, reported and dropped as a whole,
so the phase of a component is never forced.

Why it transfers: the basis depends only on the joint's own angle and is periodic in 2π, so
it is the same function on another day, after the tracker moved, and on wrapped angles
(q and q + 2π give the same error, as a gear does). Outside the range of angles the
training data cover the series continues periodically: a physical transmission error does,
but a term fitted to absorb something else does not, so fit with a prior (ridge) in rad and
check the coverage (:func:`pin_kpi_oed.diagnosis.selection.coverage`).

What the geometry absorbs: a constant offset (order 0) is the joint's zero offset, a
geometric parameter; order 1 of the first joint about a vertical axis is partly a tilt of
the base. The selection works on what the geometric fit left and never needs them twice.

Parameter names: ``transmission_error.<joint>.sin<k>`` / ``.cos<k>`` (rad; ``k`` = cycles per
revolution); :meth:`TransmissionError.describe` prints e.g.
``shoulder_lift: 18 cycles per revolution, 120 µrad amplitude (phase 35°)``.
"""

from __future__ import annotations

from collections.abc import Sequence

from pin_kpi_oed.effects.joint_angle import GearHarmonic
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.robot import Robot

__all__ = ["TransmissionError", "DEFAULT_MAX_ORDER"]

#: Highest order of the default Fourier basis (cycles per revolution).
DEFAULT_MAX_ORDER = 40


class TransmissionError(GearHarmonic):
    """Joint-angle transmission error: a Fourier series of each joint's own angle, orders 1 … K (rad).

    Args:
        robot: the arm (revolute joints only are used).
        joints: joint names (default every revolute joint).
        max_order: highest order K (cycles per revolution) of the full basis (default 40).
        pairs: explicit (joint name or index, order) pairs instead of joints × 1 … K.

    Raises:
        InputError: unknown joint, a prismatic joint in ``pairs``, an order < 1.
    """

    name = "transmission_error"
    unit = "rad"
    plausible_max = 2e-3
    description = ("joint-angle error a sin(k q) + b cos(k q) of a joint's own angle, k cycles per revolution "
                   "(gear / encoder transmission error), amplitudes in rad")

    def __init__(self, robot: Robot, joints: Sequence[str] | None = None, max_order: int = DEFAULT_MAX_ORDER,
                 pairs: Sequence[tuple[str | int, int]] | None = None):
        if pairs is None and not (float(max_order) == int(max_order) >= 1):
            raise InputError(f"{self.name}: max_order must be an integer >= 1, got {max_order}")
        super().__init__(robot, joints=joints, orders=range(1, int(max_order) + 1), pairs=pairs)

    @classmethod
    def from_spec(cls, robot: Robot, text: str) -> TransmissionError:
        """From ``"shoulder_lift_joint:7,elbow_joint:18"`` ((joint, order) pairs) or ``"max_order=40"``.

        Raises:
            InputError: an item that is neither ``joint:order`` nor ``max_order=K``.
        """
        items = [t.strip() for t in str(text).replace(";", ",").split(",") if t.strip()]
        if len(items) == 1 and items[0].replace(" ", "").startswith("max_order="):
            try:
                return cls(robot, max_order=int(items[0].split("=", 1)[1]))
            except ValueError:
                raise InputError(f"{cls.name}[{text}]: max_order must be an integer") from None
        pairs = []
        for it in items:
            j, sep, o = it.partition(":")
            try:
                pairs.append((j.strip(), int(o)))
            except ValueError:
                raise InputError(f"{cls.name}[{text}]: '{it}' is not joint:order (e.g. elbow_joint:18)") from None
            if not sep:
                raise InputError(f"{cls.name}[{text}]: '{it}' is not joint:order (e.g. elbow_joint:18)")
        if not pairs:
            raise InputError(f"{cls.name}[]: give joint:order pairs, e.g. {cls.name}[elbow_joint:18]")
        return cls(robot, pairs=pairs)
