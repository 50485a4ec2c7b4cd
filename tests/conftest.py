"""Shared fixtures: robots, a tracker set-up, the path to ../shared."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from pin_kpi_oed.model.noise import NoiseModel
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.model.robot import load_robot

SHARED = Path(__file__).resolve().parents[2] / "shared"
REPO = Path(__file__).resolve().parents[1]


def make_model(name: str = "kr15", reflector=(0.05, 0.03, 0.08), noise: NoiseModel | None = None,
               pose6d: bool = False, tcp=(0.0, 0.0, 0.0)) -> TrackerModel:
    """A tracker set-up 3 m in front of the robot, rotated (a generic pose)."""
    rb = load_robot(name)
    T = pin.SE3(pin.rpy.rpyToMatrix(0.1, 0.2, 2.0), np.array([3.0, 1.0, -0.5]))
    return TrackerModel(rb, tracker_T_base=T, reflector_m=np.array(reflector), tcp_m=np.array(tcp),
                        noise=noise or NoiseModel(), pose6d=pose6d)


@pytest.fixture
def kr15_model() -> TrackerModel:
    return make_model("kr15")
