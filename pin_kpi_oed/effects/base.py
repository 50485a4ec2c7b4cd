"""The Effect interface: the base class of every unmodelled effect, and an effect restricted to some parameters."""

from __future__ import annotations

import abc
from typing import Any
from collections.abc import Sequence

import numpy as np

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.robot import Robot

__all__ = ["Effect", "SubsetEffect", "joint_label", "n_rows", "check_aux_len"]


def n_rows(Q: np.ndarray) -> int:
    """Number of configurations in Q ((n,) or (m, n))."""
    return int(np.atleast_2d(Q).shape[0])


def check_aux_len(aux: Any, m: int, what: str) -> None:
    """Refuse auxiliary data (a measurement set) whose row count differs from the m configurations.

    Raises:
        InputError: the lengths differ.
    """
    if aux is not None and hasattr(aux, "q") and len(aux) != m:
        raise InputError(f"{what}: the measurement set has {len(aux)} rows but {m} configurations were given")


class Effect(abc.ABC):
    """Abstract base of an unmodelled effect (Effect interface, ``docs/ARCHITECTURE.md``).

    An effect owns its value, its parameter Jacobian and its joint-angle derivative:
    :meth:`joint_offset` / :meth:`tool_offset` return the value (dQ rad, dY m) and its exact
    derivative w.r.t. θ (``dQ`` and ``dY`` are linear in θ); :meth:`joint_offset_dq` returns the
    derivative of the joint-angle basis ∂dQ/∂θ w.r.t. the configuration (what the continuous
    extended design needs). Subclasses set ``name``, ``unit`` (of θ), ``description``, implement
    :meth:`param_names` and override :meth:`joint_offset` and/or :meth:`tool_offset` (and
    :meth:`joint_offset_dq` when the design may use them).

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
    #: Joint indices (n,) of the effects with one parameter per joint (:meth:`_per_joint_offset`).
    joints: Sequence[int] | np.ndarray

    def __init__(self, robot: Robot):
        self.robot = robot

    # -- interface ----------------------------------------------------------------
    @abc.abstractmethod
    def param_names(self, robot: Robot | None = None) -> list[str]:
        """Names of the parameters θ (``<effect>.<joint>[.<term>]``)."""

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
        m = n_rows(Q)
        return np.zeros((m, 3)), np.zeros((m, 3, self.n_params))

    def joint_offset_dq(self, Q: np.ndarray) -> np.ndarray:
        """Exact ∂D/∂q of the joint-angle basis D = ∂dQ/∂θ, (m, n, k, n) (rad/rad per unit of θ).

        The basis must not depend on auxiliary data. By default there is none: the effect is not
        available to the continuous (IPOPT) extended design, only to pool selection.

        Args:
            Q: configurations, (m, n) rad.

        Raises:
            InputError: the effect has no exact q-derivative of its basis.
        """
        raise InputError(f"effect '{self.name}': the continuous design has no exact q-derivative of its basis "
                         "(supported: gear_harmonic, transmission_error, link_bending); use pool selection")

    # -- extras -------------------------------------------------------------------
    def missing_column(self, aux: Any) -> str | None:
        """The first column this effect needs that ``aux`` (measurements or targets) lacks (``temperature``,
        ``payload``, ``time``), or None."""
        for attr in self.requires:
            if aux is None or getattr(aux, attr, None) is None:
                return {"temperature_c": "temperature", "payload_kg": "payload", "time_s": "time"}.get(attr, attr)
        return None

    def check(self, aux: Any) -> str | None:
        """Why this effect cannot be used with these measurements (a one-line note), or None."""
        col = self.missing_column(aux)
        return None if col is None else f"{self.name}: skipped, the measurements have no '{col}' column"

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

    def restrict(self, groups: Sequence[int]) -> Effect:
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


def joint_label(robot: Robot, j: int) -> str:
    """Display name of joint j (``shoulder_lift_joint`` -> ``shoulder_lift``)."""
    n = robot.joint_names[j]
    return n[:-len("_joint")] if n.endswith("_joint") and len(n) > len("_joint") else n


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

    def joint_offset_dq(self, Q: np.ndarray) -> np.ndarray:
        """The base effect's basis derivative, restricted to the kept parameters, (m, n, k, n)."""
        return self.base.joint_offset_dq(Q)[:, :, self.keep, :]

    def dropped(self) -> list[str]:
        """Names of the parameters held at 0."""
        names = self.base.param_names()
        return [n for i, n in enumerate(names) if i not in set(self.keep.tolist())]
