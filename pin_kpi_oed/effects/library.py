"""Unmodelled (non-geometric) effects: parametric extensions of the geometric model.

Each effect follows the *Effect interface* of ``docs/ARCHITECTURE.md``: it adds
joint-angle errors ``dQ`` and/or task-space offsets ``dY`` that depend linearly
on its parameters θ, with analytic derivatives, so that identification predicts::

    Y = model.predict(p, Q + Σ dQ) + Σ dY,     ∂Y/∂θ = Ydq(Q + dQ) · ∂dQ/∂θ + ∂dY/∂θ

Library (names are the ``--effects`` / report names):

===================== ================================================ ===================== ==========
name                  model                                            parameters            unit of θ
===================== ================================================ ===================== ==========
``joint_compliance``  Δq_j = c_j · τ_g,j(q)  (gravity torque of the    one per loaded joint  rad/(N·m)
                      URDF inertias + ``payload`` kg at the tool frame)
``gear_harmonic``     Δq_j = a_j sin q_j + b_j cos q_j                 four per joint        rad
                      + c_j sin 2q_j + d_j cos 2q_j
``backlash``          Δq_j = β_j · sign(τ_g,j(q))                      one per loaded joint  rad
``thermal_expansion`` every link length (joint placements and the      one (α)               1/K
                      tool-frame offset) scales by 1 + α (T − T_ref)
``joint_scale``       Δq_j = s_j · q_j  (transmission-ratio error)     one per joint         1 (rad/rad)
===================== ================================================ ===================== ==========

Opt-in effects (:data:`OPT_IN_EFFECTS`, by name through :func:`make_effect` and
:func:`parse_effects_spec`, not default candidates): ``transmission_error``
(:mod:`pin_kpi_oed.effects.periodic`, :class:`GearHarmonic` with orders 1 … 40 or chosen
(joint, order) pairs), ``link_bending`` (:mod:`pin_kpi_oed.effects.coupled`, cos/sin of the
arm-plane links' angles q2, q2+q3, q2+q3+q4 on those joints) and ``drift``
(:mod:`pin_kpi_oed.effects.drift`, a tracker-frame offset linear or quadratic in time per
station; ``setup_specific``: re-fitted at every registration, never transferred). Which
transmission and bending terms a data set needs is chosen by held-out error in
:mod:`pin_kpi_oed.diagnosis.selection`. Every effect answers :meth:`Effect.groups` (parameters
selected together, e.g. a cos/sin pair), :meth:`Effect.restrict` and :meth:`Effect.describe`
(plain words with units).

Each effect also has a ``plausible_max`` (largest plausible |θ|): the diagnosis holds at 0 the
parameters the data cannot determine better than that, and names them. An exploratory,
opt-in :class:`JointAngleTable` (``joint_angle_table``: a piecewise-linear joint-angle error
table, any order) is provided for real data whose transmission errors have many cycles per
revolution; it subsumes ``gear_harmonic`` and ``joint_scale`` and is not a default candidate.

Gravity torque τ_g(q) is Pinocchio's generalized gravity
(``pin.computeGeneralizedGravity``, the torque that holds the arm against
gravity) from the URDF inertias, plus — when the measurements carry a
``payload`` column (kg) — the torque of a point mass m at the tool-frame origin,
τ = −J_toolᵀ · m · g  (J_tool: linear rows of the LOCAL_WORLD_ALIGNED frame
Jacobian, g = ``model.gravity``, i.e. (0, 0, −9.81) m/s²). "Loaded joints" are
those whose gravity torque reaches 1 % of the largest over random
configurations (with the URDF masses and a 1 kg test payload); the joint about
the vertical base axis carries none and is left out.

Thermal expansion is a tool-offset effect, first order in α ΔT: scaling joint
placement j's translation t_j (parent frame) by (1+ε) is the right perturbation
δ_j = ε R_jᵀ t_j of :mod:`pin_kpi_oed.model.parameters`, so::

    ΔY = α (T − T_ref) · [ Σ_j ∂y/∂δ_j,trans · R_jᵀ t_j  +  ∂y/∂r · R_toolᵀ t_tool ]

using the translation columns of :meth:`TrackerModel.jacobian` (and its
reflector columns for the tool-frame offset). It needs a ``temperature``
column (°C); without one it is skipped with a note. Only the *variation* of the
temperature is informative: a constant scale is absorbed by the geometric
link-length parameters.

What cannot be seen
-------------------
A **range-scale error of the tracker** (all measured distances ×(1+s)) is the
same as a uniform scaling of the whole robot (every link length and the
tracker-to-base distance ×(1+s)); the geometric parameters absorb it exactly,
so no measurement of this kind can reveal it (see :data:`UNOBSERVABLE_NOTES`).
The diagnosis report says so instead of pretending to diagnose it; it can only
be checked against an independent length standard (a calibrated scale bar).

Modules: the interface (:mod:`~pin_kpi_oed.effects.base`), gravity-driven effects
(:mod:`~pin_kpi_oed.effects.gravity`), joint-angle effects (:mod:`~pin_kpi_oed.effects.joint_angle`),
thermal expansion (:mod:`~pin_kpi_oed.effects.thermal`), composition with a model
(:mod:`~pin_kpi_oed.effects.compose`); this module holds the registry and re-exports them all.
"""

from __future__ import annotations

import re
from typing import Any
from collections.abc import Sequence

import numpy as np

from pin_kpi_oed.effects.base import Effect, SubsetEffect, joint_label
from pin_kpi_oed.effects.compose import (effect_jacobian, position_dq, predict_with_effects, size_effect,
                                         sum_joint_offsets, sum_tool_offsets, visible_rms)
from pin_kpi_oed.effects.gravity import LOADED_REL_TOL, Backlash, JointCompliance, gravity_torque, loaded_joints
from pin_kpi_oed.effects.joint_angle import GearHarmonic, JointAngleTable, JointScale
from pin_kpi_oed.effects.thermal import ThermalExpansion
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.robot import Robot

__all__ = [
    "Effect", "SubsetEffect", "JointAngleTable", "JointCompliance", "GearHarmonic", "Backlash", "ThermalExpansion",
    "JointScale", "EFFECTS", "EFFECT_NAMES", "OPT_IN_EFFECTS", "ALL_EFFECT_NAMES", "effect_class", "joint_label",
    "UNOBSERVABLE_NOTES", "range_scale_parameters", "make_effect",
    "candidate_effects", "parse_effects_spec", "gravity_torque", "loaded_joints", "position_dq", "sum_joint_offsets",
    "sum_tool_offsets", "predict_with_effects", "effect_jacobian", "visible_rms", "size_effect", "LOADED_REL_TOL",
]

#: Things the data cannot reveal; copied verbatim into every diagnosis report.
UNOBSERVABLE_NOTES: tuple[str, ...] = (
    "tracker range scale: a range-scale error of the laser tracker (all distances x(1+s)) equals a uniform "
    "scaling of the whole robot (every link length and the tracker-to-base distance x(1+s)); the geometric "
    "link-length parameters absorb it exactly, so these data cannot reveal it - check the tracker against an "
    "independent length standard (scale bar) instead",
)

#: Effect classes by name (the order is the order of the report's candidate list).
EFFECTS: dict[str, type[Effect]] = {
    "joint_compliance": JointCompliance,
    "gear_harmonic": GearHarmonic,
    "backlash": Backlash,
    "thermal_expansion": ThermalExpansion,
    "joint_scale": JointScale,
}
#: The default candidates of a diagnosis.
EFFECT_NAMES: tuple[str, ...] = tuple(EFFECTS)

#: Opt-in effects, by name -> ``module:Class`` (imported on first use): not default candidates of a
#: diagnosis because they have many parameters whose terms are chosen from the data
#: (:mod:`pin_kpi_oed.diagnosis.selection`) or belong to one set-up (``drift``).
OPT_IN_EFFECTS: dict[str, str] = {
    "transmission_error": "pin_kpi_oed.effects.periodic:TransmissionError",
    "link_bending": "pin_kpi_oed.effects.coupled:LinkBending",
    "drift": "pin_kpi_oed.effects.drift:Drift",
}
#: Every effect name :func:`make_effect` knows.
ALL_EFFECT_NAMES: tuple[str, ...] = EFFECT_NAMES + tuple(OPT_IN_EFFECTS)


def effect_class(name: str) -> type[Effect]:
    """The effect class registered under ``name`` (default or opt-in).

    Raises:
        InputError: unknown name (the message lists the known ones).
    """
    key = str(name).strip()
    if key in EFFECTS:
        return EFFECTS[key]
    if key in OPT_IN_EFFECTS:
        import importlib

        mod, cls = OPT_IN_EFFECTS[key].split(":")
        return getattr(importlib.import_module(mod), cls)
    raise InputError(f"unknown effect '{name}' (known: {', '.join(ALL_EFFECT_NAMES)}; a tracker range-scale error "
                     "is not among them because it cannot be observed)")


def make_effect(name: str, robot: Robot, **options: Any) -> Effect:
    """Build an effect by name (:data:`ALL_EFFECT_NAMES`: ``joint_compliance``, ``gear_harmonic``, ``backlash``,
    ``thermal_expansion``, ``joint_scale``, and the opt-in ``transmission_error``, ``link_bending``, ``drift``).

    Raises:
        InputError: unknown name (the message lists the known ones).
    """
    return effect_class(name)(robot, **options)


def candidate_effects(robot: Robot, names: Sequence[str] | None = None, t_ref_c: float = 20.0) -> list[Effect]:
    """The candidate effects of a diagnosis (:data:`EFFECT_NAMES` by default; opt-in names may be given)."""
    out = []
    for n in (names or EFFECT_NAMES):
        out.append(make_effect(n, robot, t_ref_c=t_ref_c) if n == "thermal_expansion" else make_effect(n, robot))
    return out


_SPEC_ITEM = re.compile(r"^\s*([A-Za-z_]+)\s*(?:\[([^\]]*)\])?\s*=\s*(.+?)\s*$")
_SPEC_SPLIT = re.compile(r",(?![^\[]*\])")  # commas outside [...]


def parse_effects_spec(spec: str, robot: Robot, rng: np.random.Generator | int | None = None
                       ) -> list[tuple[Effect, np.ndarray]]:
    """Parse ``"joint_compliance=2e-6,gear_harmonic=5e-5"`` into ``[(effect, theta), ...]`` for the simulator.

    Each item is ``name=VALUE`` or ``name[OPTIONS]=VALUE``:

    * ``VALUE`` one number = the size: every parameter is drawn as
      ``±VALUE · U(0.5, 1)`` (random sign, from ``rng``); for one-parameter effects
      (``thermal_expansion``) the number is the parameter itself (α in 1/K);
    * ``VALUE`` ``v1:v2:...:vk`` = the k parameters exactly, in
      :meth:`Effect.param_names` order;
    * ``OPTIONS`` (opt-in effects) chooses the terms, read by the class's ``from_spec``:
      ``transmission_error[shoulder_lift_joint:7,elbow_joint:18]`` ((joint, order) pairs),
      ``link_bending[elbow_joint:q2+q3]`` ((joint, angle) pairs), ``drift[degree=2]``.

    Units of θ: joint_compliance rad/(N·m), gear_harmonic rad, backlash rad,
    thermal_expansion 1/K, joint_scale 1 (rad/rad), transmission_error rad, link_bending rad,
    drift m/s (and m/s²).

    Raises:
        InputError: unknown effect, an effect given twice, a value that is not a finite
            number, the wrong number of explicit values, or options an effect does not take.
    """
    rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    if spec is None or not str(spec).strip():
        return []
    out: list[tuple[Effect, np.ndarray]] = []
    seen: set[str] = set()
    for item in _SPEC_SPLIT.split(str(spec)):
        if not item.strip():
            continue
        mt = _SPEC_ITEM.match(item)
        if not mt:
            raise InputError(f"effects_spec: '{item.strip()}' is not NAME=VALUE (e.g. joint_compliance=2e-6)")
        name, opts, val = mt.group(1), mt.group(2), mt.group(3)
        if opts is None:
            eff = make_effect(name, robot)
        else:
            cls = effect_class(name)
            if not hasattr(cls, "from_spec"):
                raise InputError(f"effects_spec: {name} takes no [options]")
            eff = cls.from_spec(robot, opts)
        if name in seen:
            raise InputError(f"effects_spec: effect '{name}' given twice")
        seen.add(name)
        try:
            vals = np.array([float(v) for v in val.split(":")])
        except ValueError:
            raise InputError(f"effects_spec: {name}={val}: not a number (or v1:v2:... list)") from None
        if not np.all(np.isfinite(vals)):
            raise InputError(f"effects_spec: {name}={val}: values must be finite")
        k = eff.n_params
        if vals.size == 1 and k != 1:
            theta = vals[0] * rng.choice([-1.0, 1.0], size=k) * rng.uniform(0.5, 1.0, size=k)
        elif vals.size == k:
            theta = vals.astype(float)
        else:
            raise InputError(f"effects_spec: {name} has {k} parameters ({', '.join(eff.param_names())}); "
                             f"give one size or exactly {k} colon-separated values, got {vals.size}")
        out.append((eff, theta))
    return out


def range_scale_parameters(model: Any, s: float) -> np.ndarray:
    """Geometric parameters that reproduce a tracker range-scale error exactly: h(p_s, q) = (1+s)·h(0, q).

    Every joint-placement translation, the tool-frame offset (through the reflector
    offset), the reflector offset and the tracker translation grow by (1+s); the
    rotations stay. Proof by construction that a range-scale error is not observable
    (:data:`UNOBSERVABLE_NOTES`); ``tests/test_effects.py`` checks it to 1e-12.
    """
    L = model.layout
    rb = model.robot
    p = np.zeros(model.n_params)
    for k, jid in enumerate(rb.joint_ids):
        M = rb.model.jointPlacements[jid]
        sl = L.joint_slice(k)
        p[sl.start:sl.start + 3] = s * (M.rotation.T @ M.translation)
    Mt = rb.model.frames[rb.tool_frame_id].placement
    p[L.reflector] = s * (model.reflector_m + Mt.rotation.T @ Mt.translation)
    T0 = model.tracker_T_base
    p[L.tracker.start:L.tracker.start + 3] = s * (T0.rotation.T @ T0.translation)
    return p
