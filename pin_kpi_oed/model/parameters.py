"""Geometric error parameters p of a laser-tracker calibration.

The raw parameter vector stacks, in this order:

* for every actuated joint j, a 6-vector δ_j of its URDF placement error, applied
  as a *right perturbation* ``M_j ← M_j · exp6(δ_j)`` with
  δ_j = (tx, ty, tz, rx, ry, rz) in the joint's parent-placement frame (m, rad).
  Names: ``<joint>.tx`` … ``<joint>.rz`` (e.g. ``joint_a2.tx``);
* the tracker pose relative to the robot base, ``tracker_T_base ← T0 · exp6(δ_t)``
  (``tracker.tx`` … ``tracker.rz``);
* the reflector offset in the tool frame, ``r = r0 + δ_r`` (``reflector.x/y/z``, m);
* for 6-D probes only, the probe orientation in the tool frame,
  ``R_probe = R0 · exp3(ω_p)`` (``probe.rx/ry/rz``, rad).

Users can fix any subset (known quantities) and give a Gaussian prior
N(0, σ²) per parameter (manufacturing tolerances). Zero is the nominal model.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pin_kpi_oed.errors import InputError

POSE_SUFFIXES = ("tx", "ty", "tz", "rx", "ry", "rz")
POINT_SUFFIXES = ("x", "y", "z")
ROT_SUFFIXES = ("rx", "ry", "rz")

#: Groups whose parameters describe the measurement set-up (not the robot).
SETUP_GROUPS = ("tracker", "reflector", "probe")


@dataclass
class ParameterLayout:
    """Names, groups and slices of the raw parameter vector.

    Attributes:
        joint_names: actuated joints, base to tip.
        pose6d: whether the probe orientation parameters are present.
        names: every parameter name, in vector order.
        group: the group of each parameter (joint name, ``tracker``, ``reflector``, ``probe``).
        fixed: parameters held at their given value (not estimated).
        prior_sigma: prior standard deviation per parameter (m or rad); ``inf`` = no prior.
    """

    joint_names: list[str]
    pose6d: bool = False
    names: list[str] = field(default_factory=list)
    group: list[str] = field(default_factory=list)
    fixed: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    prior_sigma: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def __post_init__(self) -> None:
        names, group = [], []
        for j in self.joint_names:
            names += [f"{j}.{s}" for s in POSE_SUFFIXES]
            group += [j] * 6
        names += [f"tracker.{s}" for s in POSE_SUFFIXES]
        group += ["tracker"] * 6
        names += [f"reflector.{s}" for s in POINT_SUFFIXES]
        group += ["reflector"] * 3
        if self.pose6d:
            names += [f"probe.{s}" for s in ROT_SUFFIXES]
            group += ["probe"] * 3
        self.names, self.group = names, group
        if self.fixed.size != len(names):
            self.fixed = np.zeros(len(names), bool)
        if self.prior_sigma.size != len(names):
            self.prior_sigma = np.full(len(names), np.inf)

    @property
    def n(self) -> int:
        """Number of raw parameters."""
        return len(self.names)

    @property
    def n_joints(self) -> int:
        """Number of actuated joints."""
        return len(self.joint_names)

    def joint_slice(self, j: int) -> slice:
        """Slice of joint ``j``'s placement error (0-based, base to tip)."""
        return slice(6 * j, 6 * j + 6)

    @property
    def tracker(self) -> slice:
        """Slice of the tracker pose error."""
        k = 6 * self.n_joints
        return slice(k, k + 6)

    @property
    def reflector(self) -> slice:
        """Slice of the reflector offset error."""
        k = 6 * self.n_joints + 6
        return slice(k, k + 3)

    @property
    def probe(self) -> slice:
        """Slice of the probe orientation error (empty unless ``pose6d``)."""
        k = 6 * self.n_joints + 9
        return slice(k, k + (3 if self.pose6d else 0))

    def is_setup(self) -> np.ndarray:
        """Mask of measurement-set-up parameters (tracker, reflector, probe)."""
        return np.array([g in SETUP_GROUPS for g in self.group])

    def index(self, name: str) -> int:
        """Index of a parameter by name.

        Raises:
            InputError: unknown name (the message lists a few valid ones).
        """
        try:
            return self.names.index(name)
        except ValueError:
            raise InputError(f"unknown parameter '{name}' (e.g. {', '.join(self.names[:3])}, tracker.rz, "
                             "reflector.x)") from None

    def select(self, patterns: list[str] | str) -> np.ndarray:
        """Mask of parameters matching names or glob patterns (``joint_a1.*``, ``tracker.*``).

        Raises:
            InputError: a pattern matching no parameter.
        """
        import fnmatch

        pats = [p.strip() for p in (patterns.split(",") if isinstance(patterns, str) else patterns) if p.strip()]
        mask = np.zeros(self.n, bool)
        for pat in pats:
            hit = np.array([fnmatch.fnmatch(n, pat) for n in self.names])
            if not hit.any():
                raise InputError(f"parameter pattern '{pat}' matches no parameter "
                                 f"(names look like {self.names[0]}, tracker.rz, reflector.x)")
            mask |= hit
        return mask

    def fix(self, patterns: list[str] | str) -> "ParameterLayout":
        """Mark parameters as known (held at their value). Returns self."""
        self.fixed = self.fixed | self.select(patterns)
        return self

    def set_prior(self, patterns: list[str] | str, sigma: float) -> "ParameterLayout":
        """Give matching parameters a Gaussian prior N(0, sigma²) (m or rad). Returns self.

        Raises:
            InputError: sigma not positive and finite.
        """
        if not (np.isfinite(sigma) and sigma > 0):
            raise InputError(f"prior sigma must be positive and finite, got {sigma}")
        self.prior_sigma = np.where(self.select(patterns), float(sigma), self.prior_sigma)
        return self
