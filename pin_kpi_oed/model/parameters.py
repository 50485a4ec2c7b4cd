"""Geometric error parameters p of a calibration: the robot's joint placements, then the device's set-up.

The raw parameter vector stacks, in this order (laser tracker):

* for every actuated joint j, a 6-vector δ_j of its URDF placement error, applied
  as a *right perturbation* ``M_j ← M_j · exp6(δ_j)`` with
  δ_j = (tx, ty, tz, rx, ry, rz) in the joint's parent-placement frame (m, rad).
  Names: ``<joint>.tx`` … ``<joint>.rz`` (e.g. ``joint_a2.tx``);
* the tracker pose relative to the robot base, ``tracker_T_base ← T0 · exp6(δ_t)``
  (``tracker.tx`` … ``tracker.rz``);
* the reflector offset in the tool frame, ``r = r0 + δ_r`` (``reflector.x/y/z``, m);
* for 6-D probes only, the probe orientation in the tool frame,
  ``R_probe = R0 · exp3(ω_p)`` (``probe.rx/ry/rz``, rad).

The set-up groups after the joints are the measurement device's (the list above is the laser
tracker's, :class:`~pin_kpi_oed.model.tracker.TrackerModel`); another device declares its own
as ``(name, kind)`` pairs (:data:`GROUP_KINDS`), e.g. ``(("camera", "pose"), ("marker", "point"))``.

Users can fix any subset (known quantities) and give a Gaussian prior
N(0, σ²) per parameter (manufacturing tolerances). Zero is the nominal model.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pin_kpi_oed.errors import InputError

#: Separator between a set-up parameter group and its station label: ``tracker@B.tx``.
STATION_SEP = "@"

POSE_SUFFIXES = ("tx", "ty", "tz", "rx", "ry", "rz")
POINT_SUFFIXES = ("x", "y", "z")
ROT_SUFFIXES = ("rx", "ry", "rz")
#: a camera's intrinsics in OpenCV's convention: focal lengths and principal point (px), distortion (dimensionless)
INTRINSIC_SUFFIXES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")

#: Kinds of set-up parameter groups -> component suffixes. ``pose``: right perturbation exp6 of an
#: SE(3) pose (m, rad); ``point``: additive offset (m); ``rotation``: right perturbation exp3 (rad);
#: ``intrinsics``: additive offsets of a camera's intrinsics (px, then dimensionless).
GROUP_KINDS: dict[str, tuple[str, ...]] = {"pose": POSE_SUFFIXES, "point": POINT_SUFFIXES,
                                           "rotation": ROT_SUFFIXES, "intrinsics": INTRINSIC_SUFFIXES}

#: The laser tracker's set-up groups (3-D reflector), and with a 6-DoF probe.
TRACKER_SETUP: tuple[tuple[str, str], ...] = (("tracker", "pose"), ("reflector", "point"))
PROBE_SETUP: tuple[tuple[str, str], ...] = TRACKER_SETUP + (("probe", "rotation"),)


@dataclass
class ParameterLayout:
    """Names, groups and slices of the raw parameter vector.

    Attributes:
        joint_names: actuated joints, base to tip.
        pose6d: whether the probe orientation parameters are present (used when ``setup`` is None).
        names: every parameter name, in vector order.
        group: the group of each parameter (joint name or set-up group).
        fixed: parameters held at their given value (not estimated).
        prior_sigma: prior standard deviation per parameter (m or rad); ``inf`` = no prior.
        setup: the device's set-up groups ``(name, kind)`` after the joints; default the laser
            tracker's (:data:`TRACKER_SETUP`, or :data:`PROBE_SETUP` with ``pose6d``).

    Raises:
        InputError: an unknown group kind, or a group name that is also a joint name or repeated.
    """

    joint_names: list[str]
    pose6d: bool = False
    names: list[str] = field(default_factory=list)
    group: list[str] = field(default_factory=list)
    fixed: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    prior_sigma: np.ndarray = field(default_factory=lambda: np.zeros(0))
    setup: tuple[tuple[str, str], ...] | None = None

    def __post_init__(self) -> None:
        if self.setup is None:
            self.setup = PROBE_SETUP if self.pose6d else TRACKER_SETUP
        self.setup = tuple((str(g), str(k)) for g, k in self.setup)
        seen = set(self.joint_names)
        for g, kind in self.setup:
            if kind not in GROUP_KINDS:
                raise InputError(f"set-up group '{g}': unknown kind '{kind}' (kinds: {', '.join(GROUP_KINDS)})")
            if g in seen:
                raise InputError(f"set-up group '{g}': name already used by a joint or another group")
            seen.add(g)
        names, group = [], []
        for j in self.joint_names:
            names += [f"{j}.{s}" for s in POSE_SUFFIXES]
            group += [j] * 6
        self._slices: dict[str, slice] = {}
        for g, kind in self.setup:
            sfx = GROUP_KINDS[kind]
            self._slices[g] = slice(len(names), len(names) + len(sfx))
            names += [f"{g}.{s}" for s in sfx]
            group += [g] * len(sfx)
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
    def setup_groups(self) -> tuple[str, ...]:
        """Names of the set-up groups, in vector order (e.g. ``("tracker", "reflector")``)."""
        return tuple(g for g, _ in self.setup)

    def group_kind(self, name: str) -> str:
        """Kind (``pose``, ``point``, ``rotation``) of a set-up group.

        Raises:
            InputError: not a set-up group of this layout.
        """
        for g, kind in self.setup:
            if g == name:
                return kind
        raise InputError(f"no set-up group '{name}' (groups: {', '.join(self.setup_groups)})")

    def group_slice(self, name: str) -> slice:
        """Slice of a set-up group's parameters; an empty slice at the end if the layout has no such group."""
        return self._slices.get(name, slice(len(self.names), len(self.names)))

    @property
    def tracker(self) -> slice:
        """Slice of the tracker pose error (laser-tracker layouts)."""
        return self.group_slice("tracker")

    @property
    def reflector(self) -> slice:
        """Slice of the reflector offset error (laser-tracker layouts)."""
        return self.group_slice("reflector")

    @property
    def probe(self) -> slice:
        """Slice of the probe orientation error (empty unless the layout has a probe)."""
        return self.group_slice("probe")

    def is_setup(self) -> np.ndarray:
        """Mask of measurement-set-up parameters (the device's groups, e.g. tracker, reflector, probe)."""
        groups = set(self.setup_groups)
        return np.array([g in groups for g in self.group])

    def index(self, name: str) -> int:
        """Index of a parameter by name.

        Raises:
            InputError: unknown name (the message lists a few valid ones).
        """
        try:
            return self.names.index(name)
        except ValueError:
            raise InputError(f"unknown parameter '{name}' (e.g. {', '.join(self.names[:3])}, "
                             f"{', '.join(self._examples())})") from None

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
                                 f"(names look like {self.names[0]}, {', '.join(self._examples())})")
            mask |= hit
        return mask

    def _examples(self) -> list[str]:
        """One example name per set-up group (last component), for error messages."""
        return [self.names[self.group_slice(g).stop - 1] for g in self.setup_groups if self.group_slice(g).stop > 0]

    def fix(self, patterns: list[str] | str) -> ParameterLayout:
        """Mark parameters as known (held at their value). Returns self."""
        self.fixed = self.fixed | self.select(patterns)
        return self

    def set_joint_prior(self, translation_m: float, rotation_rad: float) -> ParameterLayout:
        """Give every joint placement a Gaussian prior around the nominal model: N(0, translation_m²) on its
        translation and N(0, rotation_rad²) on its rotation components (the set-up groups keep theirs). A weak
        prior (e.g. 5 mm and 10 mrad, ten times the manufacturing tolerances) changes nothing the data determine
        and keeps a fit of few poses from landing on another geometric solution. Returns self.

        Raises:
            InputError: a value not positive and finite.
        """
        for what, v in (("translation", translation_m), ("rotation", rotation_rad)):
            if not (np.isfinite(v) and v > 0):
                raise InputError(f"joint-placement prior: the {what} sigma must be positive and finite, got {v}")
        for j in range(self.n_joints):
            sl = self.joint_slice(j)
            self.prior_sigma[sl.start:sl.start + 3] = float(translation_m)
            self.prior_sigma[sl.start + 3:sl.stop] = float(rotation_rad)
        return self

    def set_prior(self, patterns: list[str] | str, sigma: float) -> ParameterLayout:
        """Give matching parameters a Gaussian prior N(0, sigma²) (m or rad). Returns self.

        Raises:
            InputError: sigma not positive and finite.
        """
        if not (np.isfinite(sigma) and sigma > 0):
            raise InputError(f"prior sigma must be positive and finite, got {sigma}")
        self.prior_sigma = np.where(self.select(patterns), float(sigma), self.prior_sigma)
        return self
