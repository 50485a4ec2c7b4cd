"""Calibration core in a few lines: identifiable parameters and the TCP covariance of a random design.

Run: python examples/kpi_covariance.py
"""

import numpy as np
import pinocchio as pin

from pin_kpi_oed.oed.covariance import kpi_covariance, kpi_covariance_kkt
from pin_kpi_oed.oed.criteria import evaluate_all
from pin_kpi_oed.oed.identifiability import analyse, check_kpi
from pin_kpi_oed.model.noise import NoiseModel
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.model.robot import load_robot

robot = load_robot("kr15")  # or a URDF path, or "ur10", "panda", ...
model = TrackerModel(
    robot,
    tracker_T_base=pin.SE3(pin.rpy.rpyToMatrix(0, 0, np.pi), np.array([3.0, 0.0, -0.5])),  # base in tracker frame
    reflector_m=np.array([0.05, 0.02, 0.05]),  # reflector in tool0 (m)
    noise=NoiseModel(range_a_m=5e-6, range_b=2e-6),  # sigma = 5 um + 2 um/m * range
)
ident = analyse(model)
print(ident.summary())

rng = np.random.default_rng(0)
Q_meas = robot.random_q(rng, 60)  # a random 60-pose design (rad)
Q_work = robot.neutral()[None]  # the working configuration (KPI)
p0 = np.zeros(model.n_params)
E = model.kpi_jacobian(p0, Q_work)
check_kpi(ident, model, E)  # raises if the TCP is not estimable
b = ident.base
F = model.weighted_jacobian(p0, Q_meas)[:, :, b].reshape(-1, b.size)
C_s = kpi_covariance(F, E[:, b])
_, C_s_kkt = kpi_covariance_kkt(F, E[:, b])
print(f"tr(C_s) = {np.trace(C_s) * 1e6:.6e} mm^2 (KKT form: {np.trace(C_s_kkt) * 1e6:.6e} mm^2)")
for name, value in evaluate_all(model, b, Q_meas, E[:, b]).items():
    print(f"  {name:<6} {value: .5g}")
