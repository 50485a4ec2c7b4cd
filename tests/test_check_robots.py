"""The check's study on simulated robots that are not the model: a re-fitting event's re-calibrations on fresh noise
draws and the calibration's own error the re-fit carries (what the verdict's expected errors are about)."""

from __future__ import annotations

import numpy as np
import pytest

from pin_kpi_oed.studies.check_robots import robot_event, simulated_robot

TOL = 1e-4


@pytest.fixture(scope="module")
def robot():
    return simulated_robot(1, noise_m=2.5e-5, tolerance_m=TOL, m_check=12)


def test_recalibration_draws_spread_around_the_expected_error(robot):
    ev = robot_event(robot, "joint_offset", 3.0, 100_001, tolerance_m=TOL, recal_draws=3)
    assert ev.verdict in ("robot_changed", "recalibrate"), ev.verdict
    assert np.isfinite(ev.refit_error_m) and np.isfinite(ev.predicted_refit_m)
    draws = np.array(ev.recal_draws_m)
    assert draws.shape == (3,) and draws[0] == ev.recal_error_m
    assert np.ptp(draws) > 0.0                       # fresh noise: the realisations differ
    # the verdict's expected errors are about these realisations: same order, not a different quantity
    assert 0.5 < draws.mean() / ev.predicted_recal_m < 2.0
    assert 0.5 < ev.refit_error_m / ev.predicted_refit_m < 2.0
    # the re-fit carries the calibration's own error: before the change, at the same working configurations
    assert 0.5 < ev.refit_error_m / ev.calibration_error_m < 2.0


def test_placement_with_tracker_moved_is_named_and_refitted_on_a_reregistered_setup(robot):
    """The combined kind: a joint's placement changed and the tracker moved, each by 3 τ; the robot's change is sized
    without the tracker's, the verdict names the joint, and the re-fit's expected error carries the registration's
    share (above a re-calibration's)."""
    ev = robot_event(robot, "placement_tracker", 3.0, 100_002, tolerance_m=TOL)
    assert ev.kind == "placement_tracker" and ev.joint.endswith("_joint")
    assert ev.tcp_change_m == pytest.approx(3.0 * TOL, rel=0.1)        # the placement's part, linearised
    assert ev.verdict in ("robot_changed", "recalibrate") and ev.right, (ev.verdict, ev.group, ev.joint)
    assert ev.group.startswith(ev.joint)
    assert not ev.setup_held                                           # the tracker moved: re-registered
    assert np.isfinite(ev.refit_error_m) and np.isfinite(ev.recal_error_m)
    assert ev.predicted_refit_m > ev.predicted_recal_m
