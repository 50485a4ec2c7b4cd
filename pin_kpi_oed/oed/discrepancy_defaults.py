r"""The discrepancy a design assumes before any measurement, per robot class.

Before a robot is measured the discrepancy δ(q) (what the geometric model leaves after calibration) is not known;
``design --model`` takes a fitted one. Without it, the design assumes a stated default whose size depends on the
kind of arm: the residual of a calibrated arm grows with its reach (an angular error times a lever) and with the
flexibility of its drives. Per class c the per-axis scale is

    S = S_c · max(1, reach / reach_c),

with the class's reference arm (``reach_c``) and its S_c; the kernel is the generic one of
:data:`KERNEL_SHAPE` (k(q, q) = 1, half whole-configuration with length scales of 1 rad, half one-joint with
0.5 rad), and the white level w = (white_c / S_c)² = 1/100 for every class:
the white σ is S/10. Without a parameter prior tr C_s then only scales by S², so the class and the reach set the
size of the honest σ, not which design is optimal. The classes:

* ``collaborative`` (light arms with strain-wave drives: UR3/5/10, Panda): S_c = 0.25 mm at the UR10's reach
  (1.75 m), white 25 µm per axis. Basis: the discrepancy fitted on all 1,484 rows of the real UR10's Series B
  (δ σ 0.30 / 0.25 / 0.25 mm, white 37 / 31 / 31 µm per axis; docs/results.md). A UR5 (reach 1.24 m) gets
  the same S_c (the max(1, ·) keeps short arms at S_c).
* ``industrial`` (KUKA KR arms and alike): S_c = 0.1 mm at the KR 15's reach (2.15 m), white 10 µm: an
  assumption of the order of the residuals after geometric calibration, not a fit (no measured industrial arm
  ships with the package); the KR 300 / KR 500 get 0.15 / 0.18 mm.
* ``generic`` (a robot of unknown class): S = 0.1 mm, white 10 µm, whatever the reach — the package's
  :func:`default_discrepancy`.

The reach is :meth:`~pin_kpi_oed.model.robot.Robot.reach` (a linear track's travel included). A linear joint
(prismatic, in m) enters the kernel on the line, its length scales the same shares of its travel / 2π (m): a
6.4 m track gets 1.02 m and 0.51 m (:meth:`~pin_kpi_oed.discrepancy.kernel.JointKernel.for_joints`).

The class is taken from the robot's name (``ur*``, ``panda*``: collaborative; ``kr*``: industrial) unless given;
the design output states the class, the numbers and that they are an assumption.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pin_kpi_oed.discrepancy.kernel import JointKernel
from pin_kpi_oed.discrepancy.prior import DiscrepancyPrior
from pin_kpi_oed.errors import InputError

__all__ = ["RobotClass", "ROBOT_CLASSES", "KERNEL_SHAPE", "robot_class_of", "class_discrepancy",
           "default_discrepancy"]

#: The kernel every default assumes (a stated assumption, not a fit): the share of k(q, q) = 1 in the
#: whole-configuration part, its length scale and the one-joint parts' length scale (rad).
KERNEL_SHAPE = {"product_share": 0.5, "length_scale_rad": 1.0, "joint_length_scale_rad": 0.5}


@dataclass(frozen=True)
class RobotClass:
    """A robot class's default discrepancy.

    Attributes:
        name: class name (``collaborative``, ``industrial``, ``generic``).
        scale_m: S_c, per-axis scale at the reference reach (m).
        reach_m: reference reach (m); None: S does not grow with the reach.
        white_m: white σ per axis at S_c (m); it scales with S.
        basis: where the numbers come from (printed).
        prefixes: robot-name prefixes of the class.
    """

    name: str
    scale_m: float
    reach_m: float | None
    white_m: float
    basis: str
    prefixes: tuple[str, ...] = ()

    def scale_for(self, reach_m: float) -> float:
        """S (m) for an arm of reach ``reach_m`` (m)."""
        return self.scale_m if self.reach_m is None else self.scale_m * max(1.0, float(reach_m) / self.reach_m)


#: The classes, by name: the one place to add a class.
ROBOT_CLASSES: dict[str, RobotClass] = {c.name: c for c in (
    RobotClass("collaborative", 2.5e-4, 1.752, 2.5e-5,
               "the discrepancy fitted on the real UR10's Series B (0.25-0.30 mm, white 31-37 um per axis)",
               ("ur", "panda")),
    RobotClass("industrial", 1e-4, 2.15, 1e-5,
               "an assumption of the order of the residuals after geometric calibration (KR 15: 0.1 mm)",
               ("kr",)),
    RobotClass("generic", 1e-4, None, 1e-5, "the package's generic default for a robot of unknown class"),
)}


def robot_class_of(name: str) -> str:
    """The class of a robot from its name (``generic`` when no class's prefix matches)."""
    low = str(name).lower()
    for c in ROBOT_CLASSES.values():
        if any(low.startswith(p) for p in c.prefixes):
            return c.name
    return "generic"


def class_discrepancy(robot, robot_class: str | None = None) -> DiscrepancyPrior:
    """The default discrepancy of ``robot`` (a :class:`~pin_kpi_oed.model.robot.Robot`) for its class.

    Args:
        robot: the robot (its ``name``, ``reach()`` and ``nq`` are used).
        robot_class: a key of :data:`ROBOT_CLASSES`, or None to take it from the robot's name.

    Returns:
        The :class:`~pin_kpi_oed.discrepancy.prior.DiscrepancyPrior`; its ``source`` states the class, S, the white
        level and the basis.

    Raises:
        InputError: an unknown class.
    """
    given = robot_class is not None
    key = robot_class if given else robot_class_of(robot.name)
    if key not in ROBOT_CLASSES:
        raise InputError(f"robot class '{key}': unknown (known: {', '.join(ROBOT_CLASSES)})")
    c = ROBOT_CLASSES[key]
    reach = float(robot.reach())
    S = c.scale_for(reach)
    rev = getattr(robot, "is_revolute", None)
    base = default_discrepancy(robot.nq, None if rev is None else ~np.asarray(rev, bool),
                               None if rev is None else np.asarray(robot.q_upper, float) - np.asarray(robot.q_lower,
                                                                                                     float))
    how = "given" if given else f"from the name '{robot.name}'"
    grow = "" if c.reach_m is None else f" = {c.scale_m * 1e3:g} mm x max(1, reach {reach:.2f} m / {c.reach_m:g} m)"
    source = (f"default for the {c.name} class, {how}: S = {S * 1e3:.3g} mm{grow}; basis: {c.basis}; not a fit "
              f"(robot_class to change the class, model_file for a fitted one)")
    return DiscrepancyPrior(base.kernel, np.full(3, S), (c.white_m / c.scale_m) ** 2, source)


def default_discrepancy(n_joints: int, linear: np.ndarray | None = None,
                        span: np.ndarray | None = None) -> DiscrepancyPrior:
    """The documented default before any measurement, whatever the robot: the ``generic`` class of
    :data:`ROBOT_CLASSES` with the kernel :data:`KERNEL_SHAPE`.

    S = 0.1 mm per axis, white 10 µm per axis (w = (10 µm / 0.1 mm)² = 0.01), k(q, q) = 1 split half into the
    whole-configuration part (c² = 0.5, L_j = 1 rad) and half into one-joint parts (a_j² = 0.5/d, ℓ_j = 0.5 rad).
    A stated assumption of the order of the residuals after geometric calibration of industrial arms (the
    real UR10 data of this package leave 0.1-0.5 mm); pass ``--model`` with a fitted discrepancy for a real one.
    A ``linear`` joint (prismatic) is on the line, its length scales those shares of its travel ``span`` (m) / 2π.
    """
    share = KERNEL_SHAPE["product_share"]
    k = JointKernel.for_joints(np.sqrt(share), np.full(n_joints, KERNEL_SHAPE["length_scale_rad"]),
                               np.full(n_joints, np.sqrt((1 - share) / n_joints)),
                               np.full(n_joints, KERNEL_SHAPE["joint_length_scale_rad"]), linear, span)
    g = ROBOT_CLASSES["generic"]
    return DiscrepancyPrior(k, np.full(3, g.scale_m), (g.white_m / g.scale_m) ** 2,
                            f"default: S = {g.scale_m * 1e3:g} mm, white {g.white_m * 1e6:g} um per axis, length "
                            f"scales {KERNEL_SHAPE['length_scale_rad']:g} rad (whole configuration) and "
                            f"{KERNEL_SHAPE['joint_length_scale_rad']:g} rad (one joint)"
                            + ("; a linear joint's x its travel / 2pi in m" if k.linear is not None else "")
                            + "; an assumption, not a fit")
