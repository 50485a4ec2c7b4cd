"""A simulated UR10 with a withheld gear harmonic, shared by the tests of the discrepancy and the check."""

from __future__ import annotations

import numpy as np

from pin_kpi_oed.effects.joint_angle import GearHarmonic
from pin_kpi_oed.simulation.simulator import Tolerances, default_tracker_pose, random_truth, simulate
from pin_kpi_oed.model.noise import NoiseModel
from pin_kpi_oed.model.robot import load_robot
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.oed.identifiability import analyse


def withheld_ur10(n_rows: int):
    """A UR10 with geometric errors (0.5 mm / 1 mrad) and a withheld gear harmonic (orders 2 and 3 of the shoulder
    lift and the elbow, 0.3 mrad), σ = 10 µm, measured at ``n_rows`` seeded random configurations (base joint in
    ±1.5 rad).

    Returns:
        (nominal measurement model, simulated measurements).
    """
    robot = load_robot("ur10")
    model = TrackerModel(robot, tracker_T_base=default_tracker_pose(robot), reflector_m=np.array([0.03, 0.02, 0.08]),
                         noise=NoiseModel(sigma_xyz_m=(1e-5,) * 3))
    truth = random_truth(model, Tolerances(5e-4, 1e-3), seed=4, only=[i for i in analyse(model).base if i < 36])
    gh = GearHarmonic(robot, joints=["shoulder_lift_joint", "elbow_joint"], orders=(2, 3))
    theta = 3e-4 * np.random.default_rng(5).standard_normal(len(gh.param_names()))
    rng = np.random.default_rng(6)
    Q = robot.random_q(rng, n_rows)
    Q[:, 0] = rng.uniform(-1.5, 1.5, n_rows)
    return model, simulate(model, Q, truth, effects=[(gh, theta)], seed=7)
