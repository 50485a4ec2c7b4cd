"""The damped least squares of the working targets (cell/working_targets.py) give, bit for bit, the numbers of the
plain NumPy / Pinocchio calls it replaces (kept here as the reference): ``ndarray.max``, a damping diagonal made per
call, forward kinematics before the frame Jacobian."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

from pin_kpi_oed.cell.working_targets import IK_TOL_M, IK_TOL_RAD, track_target
from pin_kpi_oed.model.robot import load_robot


def _reference(robot, q, p_t, R_t, tcp, max_iter, damping):
    """The descent as written with the plain calls."""
    model, data, fid = robot.model, robot.model.createData(), robot.tool_frame_id
    lo, hi = robot.q_lower, robot.q_upper
    q = np.clip(np.asarray(q, float), lo, hi)
    ep = er = np.inf
    damp = {k: damping ** 2 * np.eye(k) for k in (3, 6)}
    for _ in range(max_iter):
        pin.framesForwardKinematics(model, data, q)
        M = data.oMf[fid]
        r = M.rotation @ tcp
        e_pos = p_t - (M.translation + r)
        J6 = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL_WORLD_ALIGNED)
        S = np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])
        J = J6[:3] - S @ J6[3:]
        e = e_pos
        ep = math.sqrt(e_pos.dot(e_pos))
        er = 0.0
        if R_t is not None:
            e_rot = pin.log3(R_t @ M.rotation.T)
            er = math.sqrt(e_rot.dot(e_rot))
            J = np.concatenate([J, J6[3:]])
            e = np.concatenate([e_pos, e_rot])
        if ep < 1e-3 * IK_TOL_M and er < 1e-3 * IK_TOL_RAD:
            break
        dq = J.T @ np.linalg.solve(J @ J.T + damp[J.shape[0]], e)
        big = float(np.abs(dq).max())
        if big > 0.3:
            dq *= 0.3 / big
        q_new = np.clip(pin.integrate(model, q, dq), lo, hi)
        if np.abs(q_new - q).max() < 1e-14:
            break
        q = q_new
    return q, ep, er


@pytest.mark.parametrize("name", ["kr15", "ur10"])
def test_descent_equals_the_plain_calls_bit_for_bit(name):
    """Reachable and unreachable targets, with and without orientation, from starts near the target or random ones
    (some beyond the bounds, clipped): every returned configuration and residual is the reference's, bit for bit."""
    robot = load_robot(name)
    rng = np.random.default_rng(7)
    tcp = np.array([0.0, 0.0, 0.12])
    Qt = robot.random_q(rng, 12)
    Q0 = np.where(np.arange(12)[:, None] % 3, Qt + rng.normal(0.0, 0.3, Qt.shape), robot.random_q(rng, 12) * 1.2)
    reached = 0
    for k, (qt, q0) in enumerate(zip(Qt, Q0)):
        data = robot.model.createData()
        pin.framesForwardKinematics(robot.model, data, qt)
        M = data.oMf[robot.tool_frame_id]
        p_t = M.act(tcp) + (0.0 if k % 4 else 5.0)  # every fourth out of reach
        R_t = M.rotation if k % 2 else None
        got = track_target(robot, pin.SE3.Identity(), tcp, p_t, R_t, q0, max_iter=80)
        want = _reference(robot, q0, p_t, R_t, tcp, 80, 1e-3)
        assert np.array_equal(got[0], want[0]) and got[1:] == want[1:]
        reached += got[1] <= IK_TOL_M and got[2] <= IK_TOL_RAD
    assert 3 <= reached <= 9, reached  # both outcomes compared
