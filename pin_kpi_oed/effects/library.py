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
"""

from __future__ import annotations

import hashlib
import re
from typing import Any, Sequence

import numpy as np
import pinocchio as pin

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.robot import Robot

__all__ = [
    "Effect", "SubsetEffect", "JointAngleTable", "JointCompliance", "GearHarmonic", "Backlash", "ThermalExpansion",
    "JointScale", "EFFECTS", "EFFECT_NAMES", "OPT_IN_EFFECTS", "ALL_EFFECT_NAMES", "effect_class", "joint_label",
    "UNOBSERVABLE_NOTES", "range_scale_parameters", "make_effect",
    "candidate_effects", "parse_effects_spec", "gravity_torque", "loaded_joints", "position_dq", "sum_joint_offsets",
    "sum_tool_offsets", "predict_with_effects", "effect_jacobian", "visible_rms", "size_effect",
]

#: Things the data cannot reveal; copied verbatim into every diagnosis report.
UNOBSERVABLE_NOTES: tuple[str, ...] = (
    "tracker range scale: a range-scale error of the laser tracker (all distances x(1+s)) equals a uniform "
    "scaling of the whole robot (every link length and the tracker-to-base distance x(1+s)); the geometric "
    "link-length parameters absorb it exactly, so these data cannot reveal it - check the tracker against an "
    "independent length standard (scale bar) instead",
)

#: Relative threshold (of the largest joint torque) above which a joint counts as gravity-loaded.
LOADED_REL_TOL = 1e-2


def _n_rows(Q: np.ndarray) -> int:
    return int(np.atleast_2d(Q).shape[0])


def _check_aux_len(aux: Any, m: int, what: str) -> None:
    if aux is not None and hasattr(aux, "q") and len(aux) != m:
        raise InputError(f"{what}: the measurement set has {len(aux)} rows but {m} configurations were given")


# --------------------------------------------------------------------------- gravity
def gravity_torque(robot: Robot, Q: np.ndarray, payload_kg: np.ndarray | float | None = None) -> np.ndarray:
    """Gravity torque τ_g(q) of every configuration, (m, n) N·m (revolute) / N (prismatic).

    Pinocchio's generalized gravity from the URDF inertias, plus a point mass of
    ``payload_kg`` at the tool-frame origin: τ = −J_toolᵀ m g.

    Args:
        robot: the arm (``robot.model.gravity`` is used, default (0, 0, −9.81) m/s²).
        Q: configurations, (m, n) rad.
        payload_kg: payload per configuration (m,) or a scalar (kg); None = no payload.
    """
    Q = np.atleast_2d(np.asarray(Q, float))
    model, data = robot.model, robot.model.createData()
    m = Q.shape[0]
    tau = np.empty((m, robot.nq))
    for i in range(m):
        tau[i] = pin.computeGeneralizedGravity(model, data, Q[i])
    if payload_kg is not None:
        pl = np.broadcast_to(np.asarray(payload_kg, float), (m,))
        g = np.asarray(model.gravity.linear, float)
        fid = robot.tool_frame_id
        for i in np.flatnonzero(pl != 0):
            J = pin.computeFrameJacobian(model, data, Q[i], fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
            tau[i] -= J[:3].T @ (pl[i] * g)
    return tau


def loaded_joints(robot: Robot, rel_tol: float = LOADED_REL_TOL, n: int = 200, seed: int = 12345) -> np.ndarray:
    """Mask of joints whose gravity torque (URDF masses + 1 kg at the tool) reaches rel_tol of the largest."""
    Q = robot.random_q(np.random.default_rng(seed), n)
    t = np.abs(gravity_torque(robot, Q)).max(axis=0) + np.abs(gravity_torque(robot, Q, 1.0)).max(axis=0)
    if not np.any(t > 0):
        return np.zeros(robot.nq, bool)
    return t > rel_tol * t.max()


# --------------------------------------------------------------------------- base class
class Effect:
    """Base class of an unmodelled effect (Effect interface, ``docs/ARCHITECTURE.md``).

    Subclasses set ``name``, ``unit`` (of θ), ``description`` and override
    :meth:`param_names` and :meth:`joint_offset` and/or :meth:`tool_offset`.
    ``dQ`` and ``dY`` are linear in θ, so the derivatives are exact.

    Attributes:
        robot: the arm the effect acts on.
    """

    name: str = "effect"
    unit: str = ""
    description: str = ""
    #: MeasurementSet attributes the effect cannot work without.
    requires: tuple[str, ...] = ()
    #: Largest plausible |θ| (unit of θ): a parameter the data cannot pin down better than this is
    #: not determined by them (the diagnosis holds it at 0).
    plausible_max: float = np.inf
    #: True for effects of one measurement set-up (e.g. drift of the tracker within a session): they
    #: are re-fitted with the tracker pose at every registration and never transferred to another set-up.
    setup_specific: bool = False

    def __init__(self, robot: Robot):
        self.robot = robot

    # -- interface ----------------------------------------------------------------
    def param_names(self, robot: Robot | None = None) -> list[str]:
        """Names of the parameters θ (``<effect>.<joint>[.<term>]``)."""
        raise NotImplementedError

    @property
    def n_params(self) -> int:
        """Number of parameters k."""
        return len(self.param_names())

    def joint_offset(self, theta: np.ndarray, Q: np.ndarray, aux: Any = None) -> tuple[np.ndarray, np.ndarray]:
        """Joint-angle errors dQ (m, n) rad and dQ/dθ (m, n, k); zeros by default."""
        Q = np.atleast_2d(np.asarray(Q, float))
        m, n = Q.shape
        return np.zeros((m, n)), np.zeros((m, n, self.n_params))

    def tool_offset(self, theta: np.ndarray, Q: np.ndarray, aux: Any = None, model: Any = None,
                    p: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Task-space offsets dY (m, 3) m (tracker frame) and dY/dθ (m, 3, k); zeros by default."""
        m = _n_rows(Q)
        return np.zeros((m, 3)), np.zeros((m, 3, self.n_params))

    # -- extras -------------------------------------------------------------------
    def check(self, aux: Any) -> str | None:
        """Why this effect cannot be used with these measurements (a one-line note), or None."""
        for attr in self.requires:
            if aux is None or getattr(aux, attr, None) is None:
                col = {"temperature_c": "temperature", "payload_kg": "payload", "time_s": "time"}.get(attr, attr)
                return f"{self.name}: skipped, the measurements have no '{col}' column"
        return None

    def _theta(self, theta: np.ndarray) -> np.ndarray:
        th = np.asarray(theta, float).reshape(-1)
        if th.size != self.n_params:
            raise InputError(f"{self.name}: expected {self.n_params} parameters "
                             f"({', '.join(self.param_names()[:3])}...), got {th.size}")
        return th

    def _per_joint_offset(self, theta: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Δq_j = θ_k · B_j for one parameter per joint in ``self.joints``: (Δq (m, n), dΔq/dθ (m, n, k))."""
        th = self._theta(theta)
        m, n = B.shape
        D = np.zeros((m, n, th.size))
        D[:, self.joints, np.arange(th.size)] = B[:, self.joints]
        return D @ th, D

    def groups(self) -> list[tuple[str, list[int]]]:
        """Parameters that belong together (selected or dropped as one): ``[(label, [indices]), ...]``.

        Default: every parameter its own group. Periodic effects group a cos/sin pair.
        """
        return [(n, [i]) for i, n in enumerate(self.param_names())]

    def restrict(self, groups: Sequence[int]) -> "Effect":
        """The same effect with only the parameter groups ``groups`` (indices into :meth:`groups`)."""
        gr = self.groups()
        return SubsetEffect(self, sorted(i for g in groups for i in gr[g][1]))

    def describe(self, theta: np.ndarray) -> list[str]:
        """Plain-words lines, one per parameter group, with physical units."""
        th = self._theta(theta)
        return [f"{n} = {v:.4g} {self.unit}".rstrip() for n, v in zip(self.param_names(), th)]

    def to_dict(self) -> dict:
        """Plain description for JSON."""
        return {"name": self.name, "unit": self.unit, "description": self.description,
                "param_names": self.param_names(), "setup_specific": bool(self.setup_specific)}

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.robot.name}, k={self.n_params})"


class _GravityEffect(Effect):
    """Shared machinery of the gravity-driven effects (compliance, backlash): τ_g with a small cache."""

    def __init__(self, robot: Robot, joints: Sequence[str] | str | None = None):
        super().__init__(robot)
        if joints is None:
            mask = loaded_joints(robot)
        elif isinstance(joints, str) and joints == "all":
            mask = np.ones(robot.nq, bool)
        else:
            unknown = [j for j in joints if j not in robot.joint_names]
            if unknown:
                raise InputError(f"{self.name}: unknown joint(s) {unknown} (joints: {', '.join(robot.joint_names)})")
            mask = np.array([j in set(joints) for j in robot.joint_names])
        self.joints = np.flatnonzero(mask)
        self._cache: dict[bytes, np.ndarray] = {}

    def options(self) -> dict:
        """Constructor keyword arguments that rebuild this effect (JSON-able; stored in the model file)."""
        return {"joints": [self.robot.joint_names[int(j)] for j in self.joints]}

    def param_names(self, robot: Robot | None = None) -> list[str]:
        return [f"{self.name}.{self.robot.joint_names[j]}" for j in self.joints]

    def torque(self, Q: np.ndarray, aux: Any = None) -> np.ndarray:
        """Gravity torque (m, n) at Q, with the payload column of ``aux`` if present (cached)."""
        Q = np.atleast_2d(np.asarray(Q, float))
        _check_aux_len(aux, Q.shape[0], self.name)
        pl = None if aux is None else getattr(aux, "payload_kg", None)
        h = hashlib.blake2b(Q.tobytes(), digest_size=16)
        h.update(str(Q.shape).encode())
        if pl is not None:
            h.update(np.asarray(pl, float).tobytes())
        key = h.digest()
        if key not in self._cache:
            if len(self._cache) > 8:
                self._cache.clear()
            self._cache[key] = gravity_torque(self.robot, Q, pl)
        return self._cache[key]

    def _basis(self, tau: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def joint_offset(self, theta, Q, aux=None):
        Q = np.atleast_2d(np.asarray(Q, float))
        return self._per_joint_offset(theta, self._basis(self.torque(Q, aux)))


class JointCompliance(_GravityEffect):
    """Joint elasticity: Δq_j = c_j · τ_g,j(q) (c in rad/(N·m)), gravity from the URDF inertias + payload."""

    name = "joint_compliance"
    unit = "rad/(N*m)"
    plausible_max = 1e-4
    description = "joint deflection = compliance x gravity torque (URDF inertias + payload column)"

    def _basis(self, tau):
        return tau


class Backlash(_GravityEffect):
    """Backlash / lost motion: Δq_j = β_j · sign(τ_g,j(q)) (β in rad), flips with the gravity torque's sign."""

    name = "backlash"
    unit = "rad"
    plausible_max = 1e-2
    description = "joint offset flipping with the sign of the joint's gravity torque"

    def _basis(self, tau):
        return np.sign(tau)


def joint_label(robot: Robot, j: int) -> str:
    """Display name of joint j (``shoulder_lift_joint`` -> ``shoulder_lift``)."""
    n = robot.joint_names[j]
    return n[:-len("_joint")] if n.endswith("_joint") and len(n) > len("_joint") else n


class GearHarmonic(Effect):
    """Gear / encoder eccentricity: harmonics of each joint's own angle (rad).

    Δq_j = Σ_o a_jo sin(o q_j) + b_jo cos(o q_j) over the (joint, order) pairs: by default
    every given joint with ``orders`` (1, 2); ``pairs`` picks (joint, order) pairs one by one
    (e.g. the orders a selection found, :class:`pin_kpi_oed.effects.periodic.TransmissionError`).
    Parameters come in (sin, cos) pairs, one group per pair.
    """

    name = "gear_harmonic"
    unit = "rad"
    plausible_max = 1e-2
    description = "joint-angle errors a sin q + b cos q + c sin 2q + d cos 2q of each joint's own angle"

    def __init__(self, robot: Robot, joints: Sequence[str] | None = None, orders: Sequence[int] = (1, 2),
                 pairs: Sequence[tuple[str | int, int]] | None = None):
        super().__init__(robot)
        rev = robot.is_revolute
        if pairs is None:
            names = robot.joint_names if joints is None else list(joints)
            unknown = [j for j in names if j not in robot.joint_names]
            if unknown:
                raise InputError(f"{self.name}: unknown joint(s) {unknown} (joints: {', '.join(robot.joint_names)})")
            jj = [robot.joint_names.index(j) for j in names if rev[robot.joint_names.index(j)]]
            pairs = [(j, o) for j in jj for o in orders]
        self.pairs: list[tuple[int, int]] = []
        for j, o in pairs:
            if isinstance(j, str):
                if j not in robot.joint_names:
                    raise InputError(f"{self.name}: unknown joint '{j}' (joints: {', '.join(robot.joint_names)})")
                j = robot.joint_names.index(j)
            if not (0 <= int(j) < robot.nq) or not rev[int(j)]:
                raise InputError(f"{self.name}: joint {j} is not a revolute joint of {robot.name}")
            if not (float(o) == int(o) >= 1):
                raise InputError(f"{self.name}: the order must be an integer >= 1 (cycles per revolution), got {o}")
            self.pairs.append((int(j), int(o)))
        if len(set(self.pairs)) != len(self.pairs):
            raise InputError(f"{self.name}: a (joint, order) pair is given twice")
        self.joints = np.array(sorted({j for j, _ in self.pairs}), int)
        self.orders = tuple(sorted({o for _, o in self.pairs}))

    def options(self) -> dict:
        """Constructor keyword arguments that rebuild this effect (JSON-able; stored in the model file)."""
        return {"pairs": [[self.robot.joint_names[int(j)], int(o)] for j, o in self.pairs]}

    def param_names(self, robot=None):
        return [f"{self.name}.{self.robot.joint_names[j]}.{f}{o}" for j, o in self.pairs for f in ("sin", "cos")]

    def groups(self):
        return [(f"{joint_label(self.robot, j)} order {o}", [2 * i, 2 * i + 1]) for i, (j, o) in enumerate(self.pairs)]

    def restrict(self, groups):
        return type(self)(self.robot, pairs=[self.pairs[g] for g in groups])

    def describe(self, theta):
        """``"shoulder_lift: 18 cycles per revolution, 120 µrad amplitude (phase 35°)"`` per pair.

        a sin(o q) + b cos(o q) = A sin(o q + φ), A = √(a² + b²), φ = atan2(b, a).
        """
        th = self._theta(theta)
        out = []
        for i, (j, o) in enumerate(self.pairs):
            a, b = th[2 * i], th[2 * i + 1]
            out.append(f"{joint_label(self.robot, j)}: {o} cycle{'s' if o != 1 else ''} per revolution, "
                       f"{np.hypot(a, b) * 1e6:.0f} µrad amplitude (phase {np.degrees(np.arctan2(b, a)):.0f}°)")
        return out

    def joint_offset(self, theta, Q, aux=None):
        th = self._theta(theta)
        Q = np.atleast_2d(np.asarray(Q, float))
        m, n = Q.shape
        D = np.zeros((m, n, th.size))
        for i, (j, o) in enumerate(self.pairs):
            D[:, j, 2 * i] = np.sin(o * Q[:, j])
            D[:, j, 2 * i + 1] = np.cos(o * Q[:, j])
        return D @ th, D


class JointScale(Effect):
    """Transmission-ratio error: Δq_j = s_j · q_j (dimensionless)."""

    name = "joint_scale"
    unit = "1"
    plausible_max = 1e-2
    description = "joint-angle error proportional to the joint's angle (transmission-ratio error)"

    def __init__(self, robot: Robot, joints: Sequence[str] | None = None):
        super().__init__(robot)
        names = robot.joint_names if joints is None else list(joints)
        unknown = [j for j in names if j not in robot.joint_names]
        if unknown:
            raise InputError(f"{self.name}: unknown joint(s) {unknown} (joints: {', '.join(robot.joint_names)})")
        self.joints = np.array([robot.joint_names.index(j) for j in names], int)

    def options(self) -> dict:
        """Constructor keyword arguments that rebuild this effect (JSON-able; stored in the model file)."""
        return {"joints": [self.robot.joint_names[int(j)] for j in self.joints]}

    def param_names(self, robot=None):
        return [f"{self.name}.{self.robot.joint_names[j]}" for j in self.joints]

    def joint_offset(self, theta, Q, aux=None):
        return self._per_joint_offset(theta, np.atleast_2d(np.asarray(Q, float)))


class ThermalExpansion(Effect):
    """Link lengths scale with 1 + α (T − T_ref); a first-order tool offset (needs ``temperature``)."""

    name = "thermal_expansion"
    unit = "1/K"
    plausible_max = 1e-3
    description = "link lengths (joint placements, tool-frame offset) scale with 1 + alpha (T - T_ref)"
    requires = ("temperature_c",)

    def __init__(self, robot: Robot, t_ref_c: float = 20.0):
        super().__init__(robot)
        if not np.isfinite(t_ref_c):
            raise InputError(f"{self.name}: T_ref must be finite, got {t_ref_c}")
        self.t_ref_c = float(t_ref_c)

    def options(self) -> dict:
        """Constructor keyword arguments that rebuild this effect (JSON-able; stored in the model file)."""
        return {"t_ref_c": float(self.t_ref_c)}

    def param_names(self, robot=None):
        return [f"{self.name}.alpha"]

    def check(self, aux):
        note = super().check(aux)
        if note is None and np.ptp(np.asarray(aux.temperature_c, float)) < 1e-6:
            return f"{self.name}: skipped, the temperature is constant ({aux.temperature_c[0]:g} °C): " \
                   "a constant scale is absorbed by the link lengths"
        return note

    def direction(self, Q: np.ndarray, model: Any, p: np.ndarray | None = None) -> np.ndarray:
        """ΔY per unit strain ε = α ΔT: Σ_j ∂y/∂δ_j,trans R_jᵀ t_j + ∂y/∂r R_toolᵀ t_tool, (m, 3) m."""
        if model is None:
            raise InputError(f"{self.name}: needs the measurement model (TrackerModel) to compute its offset")
        p = np.zeros(model.n_params) if p is None else np.asarray(p, float)
        J = model.jacobian(p, Q)[:, :3, :]  # (m, 3, np)
        L = model.layout
        u = np.zeros(model.n_params)
        rb = model.robot
        for k, jid in enumerate(rb.joint_ids):
            M = rb.model.jointPlacements[jid]
            s = L.joint_slice(k)
            u[s.start:s.start + 3] = M.rotation.T @ M.translation
        Mt = rb.model.frames[rb.tool_frame_id].placement
        u[L.reflector] = Mt.rotation.T @ Mt.translation
        return J @ u

    def tool_offset(self, theta, Q, aux=None, model=None, p=None):
        th = self._theta(theta)
        Q = np.atleast_2d(np.asarray(Q, float))
        note = self.check(aux)
        if aux is None or getattr(aux, "temperature_c", None) is None:
            raise InputError(note or f"{self.name}: the measurements have no 'temperature' column")
        _check_aux_len(aux, Q.shape[0], self.name)
        dT = np.asarray(aux.temperature_c, float) - self.t_ref_c
        V = self.direction(Q, model, p) * dT[:, None]  # (m, 3)
        D = V[:, :, None]
        return D @ th, D

    def to_dict(self):
        d = super().to_dict()
        d["t_ref_c"] = self.t_ref_c
        return d


class JointAngleTable(Effect):
    """Exploratory, opt-in: a joint-angle error lookup table, piecewise linear in each joint's own angle.

    Δq_j = Σ_k θ_jk · B_k(q_j) with hat functions B_k on equally spaced knots over [lo_j, hi_j]
    (constant beyond). The first knot of each joint is held at 0 (a constant offset belongs to
    the geometry). It captures transmission errors of any order (gear/encoder ripple with many
    cycles per revolution) that ``gear_harmonic`` (orders 1 and 2) cannot. It subsumes
    ``gear_harmonic`` and ``joint_scale`` and has many parameters, so it is **not** a default
    candidate of the diagnosis; build it from the training data with :meth:`from_data`.
    """

    name = "joint_angle_table"
    unit = "rad"
    description = "joint-angle error table, piecewise linear in each joint's own angle (any order)"
    plausible_max = 2e-3

    def __init__(self, robot: Robot, joints: Sequence[str], lo: Sequence[float], hi: Sequence[float],
                 step_rad: float = 0.05):
        super().__init__(robot)
        unknown = [j for j in joints if j not in robot.joint_names]
        if unknown:
            raise InputError(f"{self.name}: unknown joint(s) {unknown} (joints: {', '.join(robot.joint_names)})")
        if not (np.isfinite(step_rad) and step_rad > 0):
            raise InputError(f"{self.name}: the knot spacing must be > 0 rad, got {step_rad}")
        self.joints = [robot.joint_names.index(j) for j in joints]
        self.knots = [np.linspace(a, b, max(2, int(np.ceil((b - a) / step_rad)) + 1)) for a, b in zip(lo, hi)]

    @classmethod
    def from_data(cls, robot: Robot, data: Any, step_rad: float = 0.05, joints: Sequence[str] | None = None
                  ) -> "JointAngleTable":
        """Knots every ``step_rad`` over the range each joint covers in ``data`` (a MeasurementSet)."""
        joints = list(joints) if joints is not None else list(robot.joint_names)
        idx = [list(data.joint_names).index(j) for j in joints]
        Q = np.asarray(data.q, float)[:, idx]
        return cls(robot, joints, Q.min(axis=0), Q.max(axis=0), step_rad)

    def param_names(self, robot=None):
        return [f"{self.name}.{self.robot.joint_names[j]}.k{i}" for j, kn in zip(self.joints, self.knots)
                for i in range(1, len(kn))]

    def joint_offset(self, theta, Q, aux=None):
        th = self._theta(theta)
        Q = np.atleast_2d(np.asarray(Q, float))
        m, n = Q.shape
        D = np.zeros((m, n, th.size))
        o = 0
        rows = np.arange(m)
        for j, kn in zip(self.joints, self.knots):
            h = kn[1] - kn[0]
            x = np.clip((Q[:, j] - kn[0]) / h, 0.0, len(kn) - 1.0)
            i = np.clip(np.floor(x).astype(int), 0, len(kn) - 2)
            f = x - i
            B = np.zeros((m, len(kn)))
            B[rows, i] += 1.0 - f
            B[rows, i + 1] += f
            D[:, j, o:o + len(kn) - 1] = B[:, 1:]
            o += len(kn) - 1
        return D @ th, D


class SubsetEffect(Effect):
    """An effect restricted to some of its parameters (the others held at 0).

    Used when the data cannot determine every parameter of an effect (e.g. a joint whose
    gravity torque never changes sign makes its backlash a constant joint offset, which
    the geometric parameters already hold). Keeps the base effect's ``name``.
    """

    def __init__(self, base: Effect, keep: Sequence[int]):
        super().__init__(base.robot)
        self.base = base
        self.keep = np.asarray(keep, int)
        self.name = base.name
        self.unit = base.unit
        self.description = base.description
        self.requires = base.requires
        self.plausible_max = base.plausible_max

    def param_names(self, robot=None):
        names = self.base.param_names(robot)
        return [names[i] for i in self.keep]

    def _full(self, theta):
        th = self._theta(theta)
        full = np.zeros(self.base.n_params)
        full[self.keep] = th
        return full

    def check(self, aux):
        return self.base.check(aux)

    def joint_offset(self, theta, Q, aux=None):
        d, D = self.base.joint_offset(self._full(theta), Q, aux)
        return d, D[:, :, self.keep]

    def tool_offset(self, theta, Q, aux=None, model=None, p=None):
        d, D = self.base.tool_offset(self._full(theta), Q, aux, model, p)
        return d, D[:, :, self.keep]

    def dropped(self) -> list[str]:
        """Names of the parameters held at 0."""
        names = self.base.param_names()
        return [n for i, n in enumerate(names) if i not in set(self.keep.tolist())]


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
            raise InputError(f"--effects: '{item.strip()}' is not NAME=VALUE (e.g. joint_compliance=2e-6)")
        name, opts, val = mt.group(1), mt.group(2), mt.group(3)
        if opts is None:
            eff = make_effect(name, robot)
        else:
            cls = effect_class(name)
            if not hasattr(cls, "from_spec"):
                raise InputError(f"--effects: {name} takes no [options]")
            eff = cls.from_spec(robot, opts)
        if name in seen:
            raise InputError(f"--effects: effect '{name}' given twice")
        seen.add(name)
        try:
            vals = np.array([float(v) for v in val.split(":")])
        except ValueError:
            raise InputError(f"--effects: {name}={val}: not a number (or v1:v2:... list)") from None
        if not np.all(np.isfinite(vals)):
            raise InputError(f"--effects: {name}={val}: values must be finite")
        k = eff.n_params
        if vals.size == 1 and k != 1:
            theta = vals[0] * rng.choice([-1.0, 1.0], size=k) * rng.uniform(0.5, 1.0, size=k)
        elif vals.size == k:
            theta = vals.astype(float)
        else:
            raise InputError(f"--effects: {name} has {k} parameters ({', '.join(eff.param_names())}); "
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


# --------------------------------------------------------------------------- combining effects
def sum_joint_offsets(effects: Sequence[tuple[Effect, np.ndarray]], Q: np.ndarray, aux: Any = None
                      ) -> tuple[np.ndarray, list[np.ndarray]]:
    """Σ dQ of several (effect, θ) and the list of their dQ/dθ."""
    Q = np.atleast_2d(np.asarray(Q, float))
    dQ = np.zeros_like(Q)
    ders = []
    for eff, th in effects:
        d, D = eff.joint_offset(th, Q, aux)
        dQ += d
        ders.append(D)
    return dQ, ders


def sum_tool_offsets(effects: Sequence[tuple[Effect, np.ndarray]], Q: np.ndarray, aux: Any, model: Any,
                     p: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
    """Σ dY of several (effect, θ) and the list of their dY/dθ."""
    Q = np.atleast_2d(np.asarray(Q, float))
    dY = np.zeros((Q.shape[0], 3))
    ders = []
    for eff, th in effects:
        d, D = eff.tool_offset(th, Q, aux, model, p)
        dY += d
        ders.append(D)
    return dY, ders


def predict_with_effects(model: Any, p: np.ndarray, Q: np.ndarray, aux: Any,
                         effects: Sequence[tuple[Effect, np.ndarray]]) -> np.ndarray:
    """Y = model.predict(p, Q + Σ dQ) + Σ dY (positions; orientation rows untouched), (m, nh)."""
    Q = np.atleast_2d(np.asarray(Q, float))
    dQ, _ = sum_joint_offsets(effects, Q, aux)
    Y = model.predict(p, Q + dQ).copy()
    dY, _ = sum_tool_offsets(effects, Q, aux, model, p)
    Y[:, :3] += dY
    return Y


def position_dq(model: Any, p: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """dy/dq of the reflector positions (tracker frame), (m, 3, n), without the costly d²h/dp dq.

    :meth:`~pin_kpi_oed.model.device.MeasurementModel.prediction_dq` of the model.
    """
    return model.prediction_dq(np.asarray(p, float), Q)


def visible_rms(model: Any, p: np.ndarray, Q: np.ndarray, aux: Any,
                effects: Sequence[tuple[Effect, np.ndarray]], base: np.ndarray | None = None) -> float:
    """Per-axis RMS (m) of the part of the effects' displacement the geometric parameters cannot absorb.

    The displacement ΔY = predict_with_effects − predict (positions) is projected out of the span
    of the position Jacobian columns ``base`` (default: all raw parameters) at ``p``; what is left
    is what a geometric calibration leaves in the residuals. Use it to size simulated effects
    relative to the measurement noise ("k × σ").
    """
    Q = np.atleast_2d(np.asarray(Q, float))
    p = np.asarray(p, float)
    D = (predict_with_effects(model, p, Q, aux, effects)[:, :3] - model.predict(p, Q)[:, :3]).ravel()
    J = model.jacobian(p, Q)[:, :3, :]
    if base is not None:
        J = J[:, :, np.asarray(base, int)]
    A = J.reshape(-1, J.shape[-1])
    n = np.linalg.norm(A, axis=0)
    A = A[:, n > 0] / n[n > 0]
    U, s, _ = np.linalg.svd(A, full_matrices=False)
    U = U[:, s > 1e-10 * s[0]]
    r = D - U @ (U.T @ D)
    return float(np.sqrt(np.mean(r ** 2)))


def size_effect(model: Any, p: np.ndarray, Q: np.ndarray, aux: Any, effect: Effect, theta: np.ndarray,
                target_rms_m: float, base: np.ndarray | None = None, iters: int = 3) -> np.ndarray:
    """Rescale ``theta`` so that the effect's visible part (:func:`visible_rms`) is ``target_rms_m`` per axis.

    θ is first shrunk into the linear regime (joint offsets ≤ 10 µrad, tool offsets ≤ 10 µm),
    then scaled by the ratio target / visible a few times (the displacement is linear in θ up
    to second-order kinematics).

    Raises:
        InputError: the effect moves nothing visible with these configurations.
    """
    Q = np.atleast_2d(np.asarray(Q, float))
    th = np.asarray(theta, float).copy()
    dQ, _ = effect.joint_offset(th, Q, aux)
    dY, _ = effect.tool_offset(th, Q, aux, model, p)
    big = max(float(np.abs(dQ).max(initial=0.0)), float(np.abs(dY).max(initial=0.0)))
    if big > 1e-5:
        th *= 1e-5 / big
    for _ in range(iters):
        vis = visible_rms(model, p, Q, aux, [(effect, th)], base)
        if not vis > 0:
            raise InputError(f"{effect.name}: moves nothing a geometric calibration cannot absorb at these "
                             "configurations; it cannot be sized")
        th = th * (float(target_rms_m) / vis)
    return th


def effect_jacobian(model: Any, p: np.ndarray, Q: np.ndarray, aux: Any,
                    effects: Sequence[tuple[Effect, np.ndarray]]) -> np.ndarray:
    """∂Y/∂θ of the positions for the stacked θ of ``effects``: Ydq(Q+ΣdQ)·∂dQ/∂θ + ∂dY/∂θ, (m, 3, Σk)."""
    Q = np.atleast_2d(np.asarray(Q, float))
    dQ, dq_ders = sum_joint_offsets(effects, Q, aux)
    Ydq = position_dq(model, p, Q + dQ) if any(np.any(D) for D in dq_ders) else None
    _, dy_ders = sum_tool_offsets(effects, Q, aux, model, p)
    blocks = []
    for Dq, Dy in zip(dq_ders, dy_ders):
        B = Dy.copy()
        if Ydq is not None and np.any(Dq):
            B += Ydq @ Dq
        blocks.append(B)
    if not blocks:
        return np.zeros((Q.shape[0], 3, 0))
    return np.concatenate(blocks, axis=2)
