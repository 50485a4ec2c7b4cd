"""Joint-angle effects of a joint's own angle: gear / encoder harmonics, transmission-ratio scale, a table."""

from __future__ import annotations

from typing import Any
from collections.abc import Sequence

import numpy as np

from pin_kpi_oed.effects.base import Effect, joint_label
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.robot import Robot

__all__ = ["GearHarmonic", "JointScale", "JointAngleTable"]

#: The last few harmonic bases (key -> read-only (m, n, k) array): a fit asks for the same configurations at every
#: step with new coefficients, and the basis depends on the configurations only. Process-wide and short, so the
#: memory stays a few bases whatever the number of effect objects.
_BASES: dict[tuple, np.ndarray] = {}
_BASES_KEPT = 4


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
        D = self._basis(np.atleast_2d(np.asarray(Q, float)), th.size)
        return D @ th, D

    def _basis(self, Q: np.ndarray, k: int) -> np.ndarray:
        """The basis D (m, n, k) (read-only; remembered for the last few configurations, :data:`_BASES`)."""
        key = (tuple(self.pairs), k, Q.shape, Q.tobytes())
        D = _BASES.get(key)
        if D is None:
            m, n = Q.shape
            D = np.zeros((m, n, k))
            for i, (j, o) in enumerate(self.pairs):
                D[:, j, 2 * i] = np.sin(o * Q[:, j])
                D[:, j, 2 * i + 1] = np.cos(o * Q[:, j])
            D.flags.writeable = False
            while len(_BASES) >= _BASES_KEPT:
                try:
                    _BASES.pop(next(iter(_BASES)))
                except (KeyError, RuntimeError, StopIteration):  # another thread changed it meanwhile
                    break
            _BASES[key] = D
        return D

    def joint_offset_dq(self, Q: np.ndarray) -> np.ndarray:
        """∂D/∂q of the basis sin/cos(o q_j): o cos(o q_j), −o sin(o q_j) on joint j, (m, n, k, n)."""
        Q = np.atleast_2d(np.asarray(Q, float))
        m, n = Q.shape
        out = np.zeros((m, n, self.n_params, n))
        for i, (j, o) in enumerate(self.pairs):
            out[:, j, 2 * i, j] = o * np.cos(o * Q[:, j])
            out[:, j, 2 * i + 1, j] = -o * np.sin(o * Q[:, j])
        return out


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
                  ) -> JointAngleTable:
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
