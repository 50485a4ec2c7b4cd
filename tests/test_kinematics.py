"""The batched kinematics core (pin_kpi_oed.model.kinematics) against Pinocchio, revolute and prismatic joints."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.cell.collision import CollisionModel
from pin_kpi_oed.errors import InputError, RobotLoadError
from pin_kpi_oed.model.kinematics import (Chain, placement_jacobian, point_velocity, revolute_mask, se3_from_matrix,
                                          skew)
from pin_kpi_oed.model.robot import load_robot
from pin_kpi_oed.model.tracker import TrackerModel

# a chain mixing unaligned revolute and prismatic axes, a prismatic joint in the middle, a fixed tool
MIXED_URDF = """<?xml version="1.0"?>
<robot name="mixed">
  <link name="base"/><link name="a"/><link name="b"/><link name="c"/><link name="d"/><link name="tool0"/>
  <joint name="r1" type="revolute"><parent link="base"/><child link="a"/><origin xyz="0 0 0.3" rpy="0.1 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" velocity="1" effort="1"/></joint>
  <joint name="p2" type="prismatic"><parent link="a"/><child link="b"/><origin xyz="0.2 0.05 0.1" rpy="0 0.3 0.2"/>
    <axis xyz="0.6 0 0.8"/><limit lower="-0.5" upper="1.5" velocity="1" effort="1"/></joint>
  <joint name="r3" type="revolute"><parent link="b"/><child link="c"/><origin xyz="0.4 0 0" rpy="0 0 0.4"/>
    <axis xyz="0.2 0.9 -0.3"/><limit lower="-3" upper="3" velocity="1" effort="1"/></joint>
  <joint name="p4" type="prismatic"><parent link="c"/><child link="d"/><origin xyz="0.1 -0.2 0.3" rpy="0.5 0 0"/>
    <axis xyz="0 -1 0"/><limit lower="0" upper="0.4" velocity="1" effort="1"/></joint>
  <joint name="t" type="fixed"><parent link="d"/><child link="tool0"/><origin xyz="0.05 0 0.12" rpy="0 1.2 0"/></joint>
</robot>
"""


@pytest.fixture(scope="module")
def mixed_robot(tmp_path_factory):
    path = Path(tmp_path_factory.mktemp("urdf")) / "mixed.urdf"
    path.write_text(MIXED_URDF)
    return load_robot(path)


def _frames_vs_pinocchio(model: pin.Model, joint_ids, chain: Chain, Q, placements=None, tool_id=None, point=None):
    """Largest deviation of the chain's frames, twists and tool point from Pinocchio (per configuration)."""
    fr = chain.frames(Q, placements)
    kin = chain.tool_point(Q, point, placements) if point is not None else None
    data = model.createData()
    worst = 0.0
    for i, q in enumerate(Q):
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        for k, j in enumerate(joint_ids):
            A = data.oMi[model.parents[j]] * model.jointPlacements[j]
            worst = max(worst, np.abs(fr.R[i, k + 1] - data.oMi[j].rotation).max(),
                        np.abs(fr.t[i, k + 1] - data.oMi[j].translation).max(),
                        np.abs(fr.R_A[i, k] - A.rotation).max(), np.abs(fr.t_A[i, k] - A.translation).max())
        worst = max(worst, np.abs(fr.twist[i] - data.J).max())
        if kin is not None:
            worst = max(worst, np.abs(kin.p[i] - data.oMf[tool_id].act(point)).max(),
                        np.abs(kin.R_tool[i] - data.oMf[tool_id].rotation).max(),
                        np.abs(kin.twist[i] - data.J).max())
    return worst


@pytest.mark.parametrize("name", ["kr15", "ur10", "panda", "kr15_track"])
def test_chain_matches_pinocchio_at_perturbed_placements(name):
    robot = load_robot(name)
    tm = TrackerModel(robot)
    rng = np.random.default_rng(0)
    p = rng.normal(scale=1e-2, size=tm.n_params)
    Q = robot.random_q(rng, 5)
    point = np.array([0.07, -0.03, 0.11])
    pm = tm.pinocchio_model(p)
    worst = _frames_vs_pinocchio(pm, robot.joint_ids, tm.chain, Q, tm.joint_placements(p), robot.tool_frame_id, point)
    assert worst < 1e-12
    # the measurement model's kinematics is the same computation
    kin = tm.kinematics(p, Q, point)
    ref = tm.chain.tool_point(Q, point, tm.joint_placements(p))
    assert np.array_equal(kin.p, ref.p) and np.array_equal(kin.twist, ref.twist)


def test_chain_mixed_revolute_prismatic_unaligned_axes(mixed_robot):
    rb = mixed_robot
    assert list(rb.is_revolute) == [True, False, True, False]
    assert rb.joint_units == ["rad", "m", "rad", "m"]
    chain = Chain.from_robot(rb)
    Q = rb.random_q(np.random.default_rng(1), 7)
    point = np.array([0.02, 0.03, -0.04])
    assert _frames_vs_pinocchio(rb.model, rb.joint_ids, chain, Q, None, rb.tool_frame_id, point) < 1e-12


def test_point_derivatives_match_finite_differences(mixed_robot):
    rb = mixed_robot
    tm = TrackerModel(rb)
    rng = np.random.default_rng(2)
    Q = rb.random_q(rng, 4)
    point = np.array([0.02, 0.03, -0.04])
    kin = tm.kinematics(np.zeros(tm.n_params), Q, point)
    blk, pdot = placement_jacobian(kin), point_velocity(kin)
    h = 1e-6
    for k in range(rb.nq):
        dq = np.zeros(rb.nq)
        dq[k] = h
        fd = (tm.kinematics(np.zeros(tm.n_params), Q + dq, point).p
              - tm.kinematics(np.zeros(tm.n_params), Q - dq, point).p) / (2 * h)
        assert np.abs(pdot[:, :, k] - fd).max() < 1e-8
    for i in range(6 * rb.nq):
        dp = np.zeros(tm.n_params)
        dp[i] = h
        fd = (tm.kinematics(dp, Q, point).p - tm.kinematics(-dp, Q, point).p) / (2 * h)
        assert np.abs(blk[:, i // 6, :, i % 6] - fd).max() < 1e-8


def test_collision_model_uses_the_core_chain():
    cell = load_cell("kr15")
    coll = CollisionModel(cell)
    assert isinstance(coll.fk, Chain)
    Q = cell.robot.random_q(np.random.default_rng(3), 3)
    fr = coll.fk.frames(Q)
    kin = TrackerModel(cell.robot).kinematics(np.zeros(TrackerModel(cell.robot).n_params), Q, np.zeros(3))
    assert np.array_equal(fr.twist, kin.twist)


def test_revolute_mask_refuses_helical_joint():
    model = pin.Model()
    model.addJoint(0, pin.JointModelHX(0.01), pin.SE3.Identity(), "screw")
    with pytest.raises(RobotLoadError, match="screw.*neither revolute nor prismatic"):
        revolute_mask(model, [1])
    model = pin.Model()
    model.addJoint(0, pin.JointModelPY(), pin.SE3.Identity(), "slide")
    assert list(revolute_mask(model, [1])) == [False]


def test_chain_rejects_wrong_joint_count():
    chain = Chain.from_robot(load_robot("kr15"))
    with pytest.raises(InputError, match="6 joint values"):
        chain.frames(np.zeros((2, 7)))


def test_skew_is_the_cross_product():
    rng = np.random.default_rng(4)
    a, b = rng.normal(size=(5, 3)), rng.normal(size=(5, 3))
    assert np.abs(np.einsum("mij,mj->mi", skew(a), b) - np.cross(a, b)).max() < 1e-15


def test_se3_from_matrix_checks_and_projects():
    R = pin.rpy.rpyToMatrix(0.1, -0.2, 0.3)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R + 1e-9, [1.0, 2.0, 3.0]  # rounding in a file
    M = se3_from_matrix(T, "f.json: tracker_T_base")
    assert np.abs(M.rotation.T @ M.rotation - np.eye(3)).max() < 1e-14  # the input is off by ~2e-9
    assert np.abs(M.rotation - R).max() < 1e-8 and np.allclose(M.translation, [1, 2, 3])
    with pytest.raises(InputError, match="f.json: T: expected a finite 4x4"):
        se3_from_matrix(np.eye(3), "f.json: T")
    bad = np.eye(4)
    bad[0, 0] = -1.0  # a reflection
    with pytest.raises(InputError, match="not a proper rotation"):
        se3_from_matrix(bad, "T")


def test_cross3_is_np_cross_bit_for_bit():
    """The chain's twists use cross3: np.cross's numbers exactly (the same bytes), broadcast as np.cross does."""
    from pin_kpi_oed.model.kinematics import cross3

    rng = np.random.default_rng(5)
    for sa, sb in [((3,), (3,)), ((7, 3), (7, 3)), ((4, 5, 3), (5, 3)), ((1, 3), (6, 3))]:
        a = rng.normal(size=sa) * 10.0 ** rng.integers(-8, 8, size=sa)
        b = rng.normal(size=sb)
        assert cross3(a, b).tobytes() == np.cross(a, b).tobytes(), (sa, sb)
        assert cross3(a, b).shape == np.cross(a, b).shape
