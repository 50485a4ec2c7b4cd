r"""Coupled shoulder–elbow terms and in-plane link bending: joint-angle errors that follow the links' gravity direction.

The joints of the "arm plane" (on a UR arm shoulder_lift, elbow and wrist_1; on a KUKA arm A2
and A3) have parallel horizontal axes. Let φ_1 = q_2, φ_2 = q_2 + q_3, φ_3 = q_2 + q_3 + q_4 be the
absolute angles of the links of that chain in the arm plane (a joint whose axis points the
other way enters with a minus sign). Gravity acts on link i through cos φ_i and sin φ_i
only, so anything that gravity does to the chain — the joints' elastic wind-up, the bending
of a link in the arm plane, the tilt of a bearing under load — shows up as joint-angle
errors that are linear combinations of these functions::

    Δq_j(q) = Σ_i c_ji cos φ_i + s_ji sin φ_i           (rad), j, i over the chain

with θ = (c_ji, s_ji) in rad. An in-plane bending of link i by an angle β_i ∝ cos(φ_i + ψ_i)
tilts everything beyond it like an error of the next joint's angle, so link i's bending
appears on the joints after it as a term in φ_i: the coupled shoulder–elbow terms (the
elbow's error depending on the upper arm's angle q2) are exactly that. Each (joint, angle)
pair — the cos and the sin — is one group: it is selected, reported and dropped as a whole.

Relation to :class:`~pin_kpi_oed.effects.library.JointCompliance`. Its joint deflection is
c_j · τ_g,j(q) with the gravity torque of the URDF inertias. For a chain whose axes are
parallel and horizontal that torque *is* a fixed combination of the same functions: on the
UR10 τ_2 = −86.8 cos q2 − 34.0 cos(q2+q3) + 0.23 sin(q2+q3+q4) N·m, τ_3 = −34.0 cos(q2+q3) +
0.23 sin(q2+q3+q4) N·m, τ_4 = 0.23 sin(q2+q3+q4) N·m (to 1e-15). So joint_compliance is
link_bending with the ratios fixed by the URDF masses (one parameter per joint), and
link_bending is joint_compliance with the mass distribution, the links' bending and the
cross terms left free. The wrist_1 column of joint_compliance is exactly a link_bending
column. To avoid exact duplicates, ``complement_compliance=True`` (the default of the full
basis) leaves out, for every joint of the chain whose gravity torque lies in the span of
its terms, the one column that torque follows most (the largest share of it): together
with joint_compliance the two then span the same space once. The selection
(:func:`pin_kpi_oed.diagnosis.selection.select_terms`) works without joint_compliance and uses
the full pairs (``complement_compliance=False``). Neither effect models a wrist
configuration-dependent load (q5), payload changes need joint_compliance's payload column.

Parameter names: ``link_bending.<joint>.cos(q2+q3)`` (rad; q<i> is the i-th joint of the
robot, 1-based); :meth:`LinkBending.describe` prints e.g. ``elbow: 450 µrad amplitude in
the angle q2+q3 (phase 35°)``.
"""

from __future__ import annotations

from typing import Any
from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from pin_kpi_oed.effects.base import Effect, joint_label
from pin_kpi_oed.effects.gravity import gravity_torque
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.robot import Robot

__all__ = ["LinkBending", "arm_plane_chain"]

#: |cos| of the angle between two joint axes above which they count as parallel.
PARALLEL_TOL = 1.0 - 1e-6


def arm_plane_chain(robot: Robot) -> tuple[list[int], list[float]]:
    """The chain of parallel horizontal joint axes (the "arm plane") and each joint's sign.

    Starts at the first revolute joint whose axis (at the neutral configuration, base frame)
    is perpendicular to gravity and continues while the next joints are revolute with a
    parallel axis. The sign is +1 for an axis pointing the same way as the first, −1 for the
    opposite way.

    Returns:
        (joint indices in the robot's joint order, signs).

    Raises:
        InputError: the robot has no revolute joint with a horizontal axis.
    """
    model, data = robot.model, robot.model.createData()
    pin.computeJointJacobians(model, data, pin.neutral(model))
    g = np.asarray(model.gravity.linear, float)
    g = g / (np.linalg.norm(g) or 1.0)
    rev = robot.is_revolute
    axes = [data.J[3:, k] / (np.linalg.norm(data.J[3:, k]) or 1.0) for k in range(robot.nq)]
    start = next((k for k in range(robot.nq) if rev[k] and abs(axes[k] @ g) < 1e-6), None)
    if start is None:
        raise InputError(f"link_bending: {robot.name} has no revolute joint with a horizontal axis (no arm plane)")
    chain, signs = [start], [1.0]
    for k in range(start + 1, robot.nq):
        c = float(axes[k] @ axes[start])
        if not rev[k] or abs(c) < PARALLEL_TOL:
            break
        chain.append(k)
        signs.append(float(np.sign(c)))
    return chain, signs


class LinkBending(Effect):
    """Joint-angle errors of the arm-plane joints in cos/sin of the links' absolute angles (rad).

    Args:
        robot: the arm.
        chain: joint names of the arm-plane chain (default :func:`arm_plane_chain`).
        terms: explicit terms ``(joint, angle, fn)``: the joint (name or index) that gets the
            error, the angle (index into the chain's angles, 0 = q2, 1 = q2+q3, ..., or its label
            ``"q2+q3"``) and ``"cos"`` or ``"sin"``. Default: every chain joint × every angle × both.
        complement_compliance: with the default terms, leave out per joint the column its
            URDF gravity torque follows most (see the module docstring), so that this effect
            and ``joint_compliance`` never hold the same column.

    Raises:
        InputError: unknown joint, a chain of non-parallel axes, an unknown angle or function.
    """

    name = "link_bending"
    unit = "rad"
    plausible_max = 2e-3
    description = ("joint-angle errors of the arm-plane joints in cos/sin of the links' angles to the horizontal "
                   "(coupled shoulder-elbow terms, in-plane link bending; gravity direction), amplitudes in rad")

    def __init__(self, robot: Robot, chain: Sequence[str] | None = None,
                 terms: Sequence[tuple[str | int, str | int, str]] | None = None, complement_compliance: bool = True):
        super().__init__(robot)
        auto, auto_signs = arm_plane_chain(robot)
        if chain is None:
            self.chain, self.signs = auto, auto_signs
        else:
            unknown = [j for j in chain if j not in robot.joint_names]
            if unknown:
                raise InputError(f"{self.name}: unknown joint(s) {unknown} (joints: {', '.join(robot.joint_names)})")
            self.chain = [robot.joint_names.index(j) for j in chain]
            model, data = robot.model, robot.model.createData()
            pin.computeJointJacobians(model, data, pin.neutral(model))
            a0 = data.J[3:, self.chain[0]]
            self.signs = []
            for k in self.chain:
                c = float(data.J[3:, k] @ a0) / (np.linalg.norm(data.J[3:, k]) * np.linalg.norm(a0) or 1.0)
                if abs(c) < PARALLEL_TOL:
                    raise InputError(f"{self.name}: the axis of {robot.joint_names[k]} is not parallel to that of "
                                     f"{robot.joint_names[self.chain[0]]}: not an arm-plane chain")
                self.signs.append(float(np.sign(c)))
        self.labels = [self._label(i) for i in range(len(self.chain))]
        if terms is None:
            self.terms = [(j, i, f) for j in self.chain for i in range(len(self.chain)) for f in ("cos", "sin")]
            if complement_compliance:
                self.terms = self._complement_compliance(self.terms)
        else:
            self.terms = [self._parse_term(t) for t in terms]
        if len(set(self.terms)) != len(self.terms):
            raise InputError(f"{self.name}: a term is given twice")

    # -- construction helpers ---------------------------------------------------------
    def _label(self, i: int) -> str:
        out = ""
        for n, (k, s) in enumerate(zip(self.chain[:i + 1], self.signs[:i + 1])):
            out += ("" if n == 0 and s > 0 else ("+" if s > 0 else "-")) + f"q{k + 1}"
        return out

    def _parse_term(self, t: tuple[str | int, str | int, str]) -> tuple[int, int, str]:
        j, a, f = t
        if isinstance(j, str):
            if j not in self.robot.joint_names:
                raise InputError(f"{self.name}: unknown joint '{j}' (joints: {', '.join(self.robot.joint_names)})")
            j = self.robot.joint_names.index(j)
        if int(j) not in self.chain:
            raise InputError(f"{self.name}: joint {self.robot.joint_names[int(j)]} is not in the arm-plane chain "
                             f"({', '.join(self.robot.joint_names[k] for k in self.chain)})")
        if isinstance(a, str):
            if a.replace(" ", "") not in self.labels:
                raise InputError(f"{self.name}: unknown angle '{a}' (angles: {', '.join(self.labels)})")
            a = self.labels.index(a.replace(" ", ""))
        if not 0 <= int(a) < len(self.chain):
            raise InputError(f"{self.name}: angle index {a} out of range 0..{len(self.chain) - 1}")
        if f not in ("cos", "sin"):
            raise InputError(f"{self.name}: function must be cos or sin, got '{f}'")
        return int(j), int(a), str(f)

    def _complement_compliance(self, terms: list[tuple[int, int, str]]) -> list[tuple[int, int, str]]:
        """Drop, per chain joint whose gravity torque lies in its terms' span, the column it follows most."""
        Q = self.robot.random_q(np.random.default_rng(12345), 200)
        tau = gravity_torque(self.robot, Q)
        B = self.angle_basis(Q)
        drop = set()
        for j in self.chain:
            cols = [t for t in terms if t[0] == j]
            X = np.stack([B[:, a * 2 + (f == "sin")] for _, a, f in cols], 1)
            if not np.linalg.norm(tau[:, j]) > 0:
                continue
            c, *_ = np.linalg.lstsq(X, tau[:, j], rcond=None)
            if np.linalg.norm(X @ c - tau[:, j]) <= 1e-6 * np.linalg.norm(tau[:, j]):
                share = np.abs(c) * np.linalg.norm(X, axis=0)
                drop.add(cols[int(np.argmax(share))])
        return [t for t in terms if t not in drop]

    @classmethod
    def from_spec(cls, robot: Robot, text: str) -> LinkBending:
        """From ``"elbow_joint:q2+q3,wrist_1_joint:q2"`` ((joint, angle) pairs, cos and sin each).

        Raises:
            InputError: an item that is not ``joint:angle``.
        """
        items = [t.strip() for t in str(text).replace(";", ",").split(",") if t.strip()]
        terms = []
        for it in items:
            j, sep, a = it.partition(":")
            if not sep:
                raise InputError(f"{cls.name}[{text}]: '{it}' is not joint:angle (e.g. elbow_joint:q2+q3)")
            terms += [(j.strip(), a.strip(), "cos"), (j.strip(), a.strip(), "sin")]
        if not terms:
            raise InputError(f"{cls.name}[]: give joint:angle pairs, e.g. {cls.name}[elbow_joint:q2+q3]")
        return cls(robot, terms=terms)

    # -- interface --------------------------------------------------------------------
    def angles(self, Q: np.ndarray) -> np.ndarray:
        """Absolute link angles φ_i = Σ_{l ≤ i} s_l q_l of the chain, (m, c) rad."""
        Q = np.atleast_2d(np.asarray(Q, float))
        return np.cumsum(Q[:, self.chain] * np.asarray(self.signs), axis=1)

    def angle_basis(self, Q: np.ndarray) -> np.ndarray:
        """cos φ_1, sin φ_1, cos φ_2, ... (m, 2c)."""
        ph = self.angles(Q)
        return np.stack([f(ph[:, i]) for i in range(ph.shape[1]) for f in (np.cos, np.sin)], 1)

    def options(self) -> dict:
        """Constructor keyword arguments that rebuild this effect (JSON-able; stored in the model file)."""
        return {"chain": [self.robot.joint_names[int(j)] for j in self.chain],
                "terms": [[self.robot.joint_names[int(j)], int(a), str(f)] for j, a, f in self.terms]}

    def param_names(self, robot: Robot | None = None) -> list[str]:
        return [f"{self.name}.{self.robot.joint_names[j]}.{f}({self.labels[a]})" for j, a, f in self.terms]

    def groups(self) -> list[tuple[str, list[int]]]:
        out: dict[tuple[int, int], list[int]] = {}
        for k, (j, a, _) in enumerate(self.terms):
            out.setdefault((j, a), []).append(k)
        return [(f"{joint_label(self.robot, j)} in {self.labels[a]}", idx) for (j, a), idx in out.items()]

    def restrict(self, groups: Sequence[int]) -> LinkBending:
        gr = self.groups()
        keep = sorted(i for g in groups for i in gr[g][1])
        return LinkBending(self.robot, chain=[self.robot.joint_names[k] for k in self.chain],
                           terms=[self.terms[i] for i in keep])

    def joint_offset(self, theta: np.ndarray, Q: np.ndarray, aux: Any = None) -> tuple[np.ndarray, np.ndarray]:
        th = self._theta(theta)
        Q = np.atleast_2d(np.asarray(Q, float))
        m, n = Q.shape
        B = self.angle_basis(Q)
        D = np.zeros((m, n, th.size))
        for k, (j, a, f) in enumerate(self.terms):
            D[:, j, k] = B[:, 2 * a + (f == "sin")]
        return D @ th, D

    def joint_offset_dq(self, Q: np.ndarray) -> np.ndarray:
        """∂D/∂q of the basis cos/sin φ_a, φ_a = Σ_{l ≤ a} s_l q_l: (−sin φ_a / cos φ_a) s_l on q_l, (m, n, k, n)."""
        Q = np.atleast_2d(np.asarray(Q, float))
        m, n = Q.shape
        out = np.zeros((m, n, self.n_params, n))
        ph = self.angles(Q)
        for c, (j, a, f) in enumerate(self.terms):
            g = -np.sin(ph[:, a]) if f == "cos" else np.cos(ph[:, a])
            for l_ in range(a + 1):
                out[:, j, c, self.chain[l_]] = g * self.signs[l_]
        return out

    def describe(self, theta: np.ndarray) -> list[str]:
        """One line per (joint, angle): ``"elbow: 450 µrad amplitude in the angle q2+q3 (phase 35°)"``.

        c cos φ + s sin φ = A sin(φ + ψ), A = √(c² + s²), ψ = atan2(c, s).
        """
        th = self._theta(theta)
        out = []
        for _label, idx in self.groups():
            j, a, _ = self.terms[idx[0]]
            v = {self.terms[i][2]: th[i] for i in idx}
            c, s = v.get("cos", 0.0), v.get("sin", 0.0)
            who = f"{joint_label(self.robot, j)}: {np.hypot(c, s) * 1e6:.0f} µrad"
            if len(idx) == 2:
                out.append(f"{who} amplitude in the angle {self.labels[a]} (phase {np.degrees(np.arctan2(c, s)):.0f}°)")
            else:
                out.append(f"{who} x {self.terms[idx[0]][2]}({self.labels[a]})")
        return out

    def to_dict(self) -> dict:
        d = super().to_dict()
        d["chain"] = [self.robot.joint_names[k] for k in self.chain]
        return d
