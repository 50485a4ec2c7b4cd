"""Manufacturing tolerances of the geometric parameters: the spread of real robots around the nominal model.

Used to simulate robots with errors and as a prior covariance Σ₀ of a (re-)identification.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.tracker import TrackerModel

__all__ = ["Tolerances", "held_columns"]


@dataclass
class Tolerances:
    """Standard deviations of the simulated geometric errors (SI).

    Attributes:
        joint_translation_m: per joint-placement translation component (m).
        joint_rotation_rad: per joint-placement rotation component (rad).
        tracker_translation_m: deviation of the tracker pose from its nominal value (m).
        tracker_rotation_rad: same, rotation (rad).
        reflector_m: deviation of the reflector offset from its nominal value (m).
        probe_rotation_rad: deviation of the probe orientation (6-D only, rad).
    """

    joint_translation_m: float = 5e-4
    joint_rotation_rad: float = 1e-3
    tracker_translation_m: float = 0.0
    tracker_rotation_rad: float = 0.0
    reflector_m: float = 0.0
    probe_rotation_rad: float = 0.0

    def __post_init__(self) -> None:
        for k, v in asdict(self).items():
            if not (np.isfinite(v) and v >= 0):
                raise InputError(f"tolerance {k} must be a finite value >= 0, got {v}")

    def sigma_vector(self, model: TrackerModel) -> np.ndarray:
        """Standard deviation of every raw parameter of ``model`` (m or rad)."""
        L = model.layout
        s = np.zeros(L.n)
        for j in range(L.n_joints):
            sl = L.joint_slice(j)
            s[sl.start:sl.start + 3] = self.joint_translation_m
            s[sl.start + 3:sl.stop] = self.joint_rotation_rad
        s[L.tracker.start:L.tracker.start + 3] = self.tracker_translation_m
        s[L.tracker.start + 3:L.tracker.stop] = self.tracker_rotation_rad
        s[L.reflector] = self.reflector_m
        s[L.probe] = self.probe_rotation_rad
        return s


def held_columns(model: TrackerModel, identified: list[str] | np.ndarray) -> np.ndarray:
    """The joint-placement parameters a calibration holds at nominal although they are not known: free (not fixed
    by the layout) and not among the identified ones (the identifiability analysis dropped them: no measurement of
    the reflector determines them). Their manufacturing tolerance (:meth:`Tolerances.sigma_vector`) is their prior.

    Args:
        model: the measurement model (its layout).
        identified: the identified parameters, as raw indices or layout names.

    Returns:
        Raw indices (ascending) of the held joint-placement parameters.
    """
    L = model.layout
    ids = list(identified)
    known = {L.names[int(i)] for i in ids} if ids and not isinstance(ids[0], str) else set(map(str, ids))
    return np.array([i for i in range(6 * L.n_joints) if L.names[i] not in known and not L.fixed[i]], int)
