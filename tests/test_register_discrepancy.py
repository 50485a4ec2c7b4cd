"""Registration of a model with a discrepancy: the set-up is fitted to the model's full prediction (geometry + effects
+ the discrepancy's mean), the same prediction ``predict`` / ``predict_with_sigma`` make with it."""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pytest

from pin_kpi_oed import NoiseModel, TrackerModel, load_robot
from pin_kpi_oed.effects.library import GearHarmonic
from pin_kpi_oed.identification.identify import identify
from pin_kpi_oed.simulation.simulator import Tolerances, default_tracker_pose, random_truth, simulate
from pin_kpi_oed.upkeep.transfer import register_setup
from pin_kpi_oed.oed.identifiability import analyse

T_NEW = pin.SE3(pin.rpy.rpyToMatrix(0.02, -0.01, -1.0), np.array([-2.5, 1.0, 0.2]))


@pytest.fixture(scope="module")
def sessions():
    """A UR10 with geometric errors and an unmodelled gear harmonic (0.3 mrad), σ = 10 µm: a model identified with
    the discrepancy on 80 rows of one tracker pose, and 60 rows of a second session from another tracker pose."""
    robot = load_robot("ur10")
    noise = NoiseModel(sigma_xyz_m=(1e-5,) * 3)
    mA = TrackerModel(robot, tracker_T_base=default_tracker_pose(robot), reflector_m=np.array([0.03, 0.02, 0.08]),
                      noise=noise)
    mB = TrackerModel(robot, tracker_T_base=T_NEW, reflector_m=np.array([0.03, 0.02, 0.08]), noise=noise)
    truth = random_truth(mA, Tolerances(5e-4, 1e-3), seed=4, only=[i for i in analyse(mA).base if i < 36])
    gh = GearHarmonic(robot, joints=["shoulder_lift_joint", "elbow_joint"], orders=(2, 3))
    theta = 3e-4 * np.random.default_rng(5).standard_normal(len(gh.param_names()))
    QA, QB = robot.random_q(np.random.default_rng(6), 80), robot.random_q(np.random.default_rng(7), 60)
    train = simulate(mA, QA, truth, effects=[(gh, theta)], seed=8, source="A.csv")
    new = simulate(mB, QB, truth, effects=[(gh, theta)], seed=9, source="B.csv")
    cm = identify(mA, train, discrepancy="on").calibrated_model()
    assert cm.discrepancy is not None
    return cm, new.subset(np.arange(15)), new.subset(np.arange(15, 60))


def _chi2(model, rows) -> float:
    Y = model.predict(rows.q, rows, station="new")
    return float(np.sum(((rows.position_m - Y[:, :3]) / rows.sigma_m) ** 2))


def _rms(model, rows) -> float:
    Y = model.predict(rows.q, rows, station="new")
    return float(np.sqrt(np.mean(np.sum((rows.position_m - Y[:, :3]) ** 2, axis=1))))


def test_registration_fits_the_prediction_with_the_discrepancy_mean(sessions):
    cm, reg_rows, held_out = sessions
    res = register_setup(cm, reg_rows, station="new", hold_reflector=True, check=False)
    # the residuals the registration reports are those of the model's prediction (discrepancy mean included)
    Y = res.model.predict(reg_rows.q, reg_rows, station="new")
    assert np.allclose(res.errors_m, np.linalg.norm(reg_rows.position_m - Y[:, :3], axis=1), atol=1e-10)
    # ... at the least-squares minimum: no small move of the registered tracker pose fits the full prediction better
    chi_reg = _chi2(res.model, reg_rows)
    st = res.model.setups["new"]
    T0 = pin.SE3(st.tracker_T_base[:3, :3], st.tracker_T_base[:3, 3])
    for i in range(6):
        for h in (-1e-6, 1e-6):
            T = T0 * pin.exp6(pin.Motion(h * np.eye(6)[i]))
            moved = res.model.with_setup("new", dataclasses.replace(st, tracker_T_base=T.homogeneous), default=True)
            assert _chi2(moved, reg_rows) >= chi_reg * (1 - 1e-9), (i, h)
    # ... better than the old way: registering the geometry on the rows minus the discrepancy's mean (rotated by the
    # registered tracker pose, re-fitted to a fixed point) fits the full prediction no better
    delta = cm.discrepancy.predict(reg_rows.q, return_var=False)[0]
    geometry = dataclasses.replace(cm, discrepancy=None)
    setup = register_setup(geometry, reg_rows, station="new", hold_reflector=True, check=False).setups["new"]
    for _ in range(8):
        shifted = dataclasses.replace(reg_rows, position_m=reg_rows.position_m - delta @ setup.tracker_T_base[:3, :3].T)
        setup = register_setup(geometry, shifted, station="new", hold_reflector=True, check=False).setups["new"]
    alt = cm.with_setup("new", setup, default=True)
    chi_alt = _chi2(alt, reg_rows)
    assert chi_reg <= chi_alt * (1 + 1e-6) + 1e-9, (chi_reg, chi_alt)
    d = res.model.setups["new"].tracker_T_base - alt.setups["new"].tracker_T_base
    assert np.abs(d).max() < 1e-5, (d, chi_reg, chi_alt)
    # held-out rows of the new session: no worse than with the rows-minus-mean registration
    assert _rms(res.model, held_out) <= 1.02 * _rms(alt, held_out), (_rms(res.model, held_out), _rms(alt, held_out))
