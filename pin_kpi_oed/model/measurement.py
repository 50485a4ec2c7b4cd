"""Compatibility re-exports: the measurement model now lives in three modules.

* :class:`~pin_kpi_oed.model.tracker.TrackerModel` — the laser tracker / 6-DoF probe
  (:mod:`pin_kpi_oed.model.tracker`), an implementation of
  :class:`~pin_kpi_oed.model.device.MeasurementModel`;
* :class:`~pin_kpi_oed.model.noise.NoiseModel` (:mod:`pin_kpi_oed.model.noise`);
* :class:`~pin_kpi_oed.model.kinematics.Kinematics` and :func:`~pin_kpi_oed.model.kinematics.skew`
  (:mod:`pin_kpi_oed.model.kinematics`).

Import from those modules; this one only keeps code written against the old path working
while the package's branches are merged, and can then be removed.
"""

from __future__ import annotations

from pin_kpi_oed.model.kinematics import Kinematics, skew
from pin_kpi_oed.model.noise import NoiseModel
from pin_kpi_oed.model.tracker import TrackerModel

__all__ = ["Kinematics", "NoiseModel", "TrackerModel", "skew"]
