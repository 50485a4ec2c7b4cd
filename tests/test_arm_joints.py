"""Arms as they ship: a continuous joint is a revolute joint of ±2π rad (the URDF's numbers exact, said in a note),
designs, fits, round-trips a model file and exports; joints branching off the chain to the tool (Baxter's other arm
and head) are locked at neutral, said in a note, their links kept in the collision model at that posture."""

from __future__ import annotations

import json
import subprocess

import numpy as np
import pinocchio as pin
import pytest

from pin_kpi_oed.model.robot import erd_root, load_robot

from .cli_run import run_cli_as_process

TURN = 2.0 * np.pi

#: three joints, j1 continuous with a <limit> (its effort and velocity are kept), j3 continuous without one
CONTINUOUS = """<robot name="cont">
  <link name="base"/><link name="l1"/><link name="l2"/><link name="l3"/><link name="flange"/>
  <joint name="j1" type="continuous"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>
    <origin xyz="0 0 0.3" rpy="0 3.14159265359 0"/><limit effort="40" velocity="0.6283" lower="-1" upper="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><axis xyz="0 1 0"/>
    <origin xyz="0.05 0 -0.4" rpy="0.1 0 0"/><limit lower="-2" upper="1.5" effort="1" velocity="1"/></joint>
  <joint name="j3" type="continuous"><parent link="l2"/><child link="l3"/><axis xyz="0.6 0 0.8"/>
    <origin xyz="0.35 0.02 0" rpy="-1.57079632679 0 0.2"/></joint>
  <joint name="flange_joint" type="fixed"><parent link="l3"/><child link="flange"/><origin xyz="0 0 0.1"/></joint>
</robot>
"""

KINOVA = ("kinova_description/robots/kinova.urdf", "j2s6s200_end_effector")
BAXTER = ("baxter_description/urdf/baxter.urdf", "right_gripper")


def _info(*args: str) -> subprocess.CompletedProcess:
    """``pin-kpi-oed info args...`` in this process (what it prints and its exit code are the point, not its
    process: tests/test_cli_startup.py runs the real one)."""
    return run_cli_as_process("info", *args)


def test_continuous_joint_is_revolute_of_one_turn_with_the_urdf_numbers_exact(tmp_path):
    """j1 and j3 load as revolute joints of ±2π rad (compared modulo 2π), the note names them once, the kinematics
    is Pinocchio's own continuous model at (cos q, sin q) to the last bits, the velocity limit is the file's."""
    path = tmp_path / "cont.urdf"
    path.write_text(CONTINUOUS)
    rb = load_robot(str(path), tool_frame="flange")
    assert rb.joint_names == ["j1", "j2", "j3"] and rb.nq == 3 and rb.is_revolute.all()
    assert rb.q_lower.tolist() == [-TURN, -2.0, -TURN] and rb.q_upper.tolist() == [TURN, 1.5, TURN]
    assert rb.periodic_joints.tolist() == [True, False, True]
    assert rb.notes == ["continuous joint(s) j1, j3 taken as revolute with limits ±2π rad (one turn either way)"]
    assert rb.model.velocityLimit[0] == 0.6283 and rb.model.effortLimit[0] == 40.0
    full = pin.buildModelFromUrdf(str(path))  # the file as Pinocchio reads it: j1, j3 as (cos, sin)
    assert full.nq == 5 and full.nv == 3
    fd, fid = full.createData(), full.getFrameId("flange")
    Q = np.vstack([rb.random_q(np.random.default_rng(0), 20), rb.q_lower, rb.q_upper])
    for q in Q:
        q_full = np.array([np.cos(q[0]), np.sin(q[0]), q[1], np.cos(q[2]), np.sin(q[2])])
        pin.framesForwardKinematics(full, fd, q_full)
        assert np.abs(rb.oMtool(q).homogeneous - fd.oMf[fid].homogeneous).max() < 1e-14
    res = _info(str(path), "--tool", "flange")
    assert res.returncode == 0, res.stderr
    notes = [ln for ln in res.stdout.splitlines() if ln.startswith("note: continuous")]
    assert notes == ["note: continuous joint(s) j1, j3 taken as revolute with limits ±2π rad (one turn either way)"]
    limits = {ln.split()[0]: ln for ln in res.stdout.splitlines() if ln.strip().startswith("j")}
    assert "360" in limits["j1"] and "-360" in limits["j1"], limits


@pytest.fixture(scope="module")
def kinova_fit():
    """The Kinova Gen2 (three continuous joints) measured by a tracker at 60 seeded configurations of a truth with
    every joint-placement parameter off, identified."""
    from benchmarks.urdf_rounding import tracker_model
    from pin_kpi_oed.identification.identify import identify
    from pin_kpi_oed.simulation.simulator import Tolerances, random_truth, simulate

    rb = load_robot(str(erd_root() / KINOVA[0]), tool_frame=KINOVA[1])
    tm = tracker_model(rb)
    truth = random_truth(tm, Tolerances(5e-4, 1e-3, 0.02, 0.02, 1e-3), seed=3)
    data = simulate(tm, rb.random_q(np.random.default_rng(4), 60), truth, seed=5)
    return rb, tm, identify(tm, data, discrepancy="none")


@pytest.mark.xdist_group("test_arm_joints_kinova_fit")
def test_kinova_designs_on_its_continuous_joints(kinova_fit):
    """A tiny KPI design of the Kinova: IPOPT moves the continuous joints within ±2π rad and beats the random design
    it starts from."""
    from pin_kpi_oed.cell.cell import cell_from_dict
    from pin_kpi_oed.design.ipopt import ipopt_options
    from pin_kpi_oed.design.optimize import DesignOptions, run_designs

    rb = kinova_fit[0]
    d = {"name": "kinova", "robot": rb.urdf_path, "tool_frame": rb.tool_frame,
         "tracker": {"xyz_m": [2.0, 0.2, 0.4], "rpy_deg": [0.0, 0.0, 180.0]}, "reflector_m": [0.03, 0.0, 0.05],
         "noise": {"sigma_xyz_m": [1e-5] * 3}, "robot_capsules": [],
         "working_configurations_rad": rb.random_q(np.random.default_rng(1), 2).tolist()}
    cell = cell_from_dict(d, "kinova cell")
    assert "note: continuous joint(s) j2s6s200_joint_1, j2s6s200_joint_4, j2s6s200_joint_6" in cell.summary()
    rnd, kpi = run_designs(cell, ["random", "kpi"], m=12, seed=0,
                           options=DesignOptions(n_starts=1, ipopt=ipopt_options(max_iter=20)))
    assert kpi.feasible and kpi.trace_cs_m2 < rnd.trace_cs_m2
    Q = np.asarray(kpi.q_meas)
    assert Q.shape == (12, 6) and np.all(Q >= rb.q_lower - 1e-9) and np.all(Q <= rb.q_upper + 1e-9)


@pytest.mark.xdist_group("test_arm_joints_kinova_fit")
def test_kinova_model_file_and_calibrated_urdf_round_trip(kinova_fit, tmp_path):
    """The fit's model file reads back to the same robot (joints, ±2π limits, note) and the same predictions with
    their σ; the calibrated URDF keeps the continuous type and reproduces the calibrated kinematics."""
    from pin_kpi_oed.calibrated.formats.registry import export_model
    from pin_kpi_oed.calibrated.model_file import load_model_file

    rb, tm, res = kinova_fit
    assert res.converged and 0.5 < res.chi2_reduced < 1.5
    assert f"  note: {rb.notes[0]}" in res.summary().splitlines()
    cm = res.calibrated_model()
    cm.save(tmp_path / "m.json")
    back = load_model_file(tmp_path / "m.json")
    assert back.robot.joint_names == rb.joint_names and back.robot.notes == rb.notes
    assert back.robot.q_lower.tolist() == rb.q_lower.tolist() and rb.q_lower[0] == -TURN
    Q = rb.random_q(np.random.default_rng(9), 30)
    (y0, s0, _), (y1, s1, _) = cm.predict_with_sigma(Q), back.predict_with_sigma(Q)
    assert np.abs(y1 - y0).max() < 1e-12 and np.abs(s1 - s0).max() < 1e-12
    rep = export_model(cm, tmp_path / "calibrated.urdf", "urdf")
    text = (tmp_path / "calibrated.urdf").read_text()
    assert text.count('type="continuous"') == 3
    cal = load_robot(str(tmp_path / "calibrated.urdf"), tool_frame=rb.tool_frame)
    assert cal.notes == rb.notes and rep is not None
    ref = rb.model.copy()  # the calibrated placements M_k exp(δ_k), as the model file stores them
    for k, j in enumerate(rb.joint_ids):
        ref.jointPlacements[j] = rb.model.jointPlacements[j] * pin.exp6(cm.joint_p[6 * k:6 * k + 6])
    rd = ref.createData()
    for q in Q:
        pin.framesForwardKinematics(ref, rd, q)
        assert np.abs(cal.oMtool(q).translation - rd.oMf[rb.tool_frame_id].translation).max() < 1e-9


@pytest.mark.xdist_group("test_arm_joints_kinova_fit")
def test_kinova_visual_model_has_the_robots_joints(kinova_fit):
    """The scene's visual model reads the continuous joints as the robot does: six joints, the URDF's meshes."""
    from pin_kpi_oed.viz.robot_geometry import visual_model

    rb = kinova_fit[0]
    model, visual, notes = visual_model(rb)
    assert model.nq == rb.nq == 6 and [model.names[j] for j in rb.joint_ids] == rb.joint_names
    assert visual is not None and len(visual.geometryObjects) > 6 and notes == []


def test_branched_robot_locks_the_other_limbs_at_neutral():
    """Baxter's right arm: the head and the left arm (gripper fingers included) branch off the chain and are locked at
    neutral (the note says so), the right gripper's fingers beyond the tool as before; the locked links keep their
    collision capsules, placed where the full model puts them at neutral whatever the right arm does."""
    from pin_kpi_oed.cell.cell import capsules_from_urdf

    rb = load_robot(str(erd_root() / BAXTER[0]), tool_frame=BAXTER[1])
    assert rb.joint_names == ["right_s0", "right_s1", "right_e0", "right_e1", "right_w0", "right_w1", "right_w2"]
    branch = ["head_pan", "left_s0", "left_s1", "left_e0", "left_e1", "left_w0", "left_w1", "left_w2",
              "l_gripper_l_finger_joint", "l_gripper_r_finger_joint"]
    assert rb.locked_joints == branch + ["r_gripper_l_finger_joint", "r_gripper_r_finger_joint"]
    assert rb.notes == [f"joint(s) {', '.join(branch)} branch off the chain to 'right_gripper': locked at neutral, "
                        "clipped into their limits (their links stay in the model and its collision geometry at that "
                        "posture)"]
    caps = capsules_from_urdf(rb)
    left = [c for c in caps if c.link.startswith("left_")]
    assert len(left) >= 5 and any(c.link.startswith("right_") for c in caps)
    full = pin.buildModelFromUrdf(rb.urdf_path)
    fd = full.createData()
    for q in rb.random_q(np.random.default_rng(2), 3):
        q_full = pin.neutral(full)
        for name, v in zip(rb.joint_names, q):
            q_full[full.joints[full.getJointId(name)].idx_q] = v
        pin.framesForwardKinematics(full, fd, q_full)
        pin.framesForwardKinematics(rb.model, rb.data, q)
        for c in caps:
            a = rb.data.oMf[rb.model.getFrameId(c.link, pin.FrameType.BODY)]
            b = fd.oMf[full.getFrameId(c.link, pin.FrameType.BODY)]
            assert np.abs(a.homogeneous - b.homogeneous).max() < 1e-12, c.link


def test_cli_info_of_a_branched_robot_says_what_it_locked():
    """``info`` of a robot whose other arm branches off at the base: exit 0, the arm's joints, the note."""
    res = _info(str(erd_root() / BAXTER[0]), "--tool", BAXTER[1], "--json")
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout)["robot"]
    assert [j["name"] for j in summary["joints"]][0] == "right_s0" and "left_s0" in summary["locked_joints"]
    assert len(summary["notes"]) == 1 and "locked at neutral" in summary["notes"][0]


#: j2 branches off the chain base -> j1 -> j3 -> tip; its limits [-2.6, -0.6] rad exclude Pinocchio's neutral 0
BRANCH_OUTSIDE_ZERO = """<robot name="calf">
  <link name="base"/><link name="a"/><link name="leg"/><link name="foot"/><link name="tip"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="a"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="base"/><child link="leg"/><axis xyz="0 1 0"/>
    <origin xyz="0 0.2 0"/><limit lower="-2.6" upper="-0.6" effort="1" velocity="1"/></joint>
  <joint name="foot_joint" type="fixed"><parent link="leg"/><child link="foot"/><origin xyz="0.3 0 0"/></joint>
  <joint name="j3" type="revolute"><parent link="a"/><child link="tip"/><axis xyz="0 1 0"/>
    <origin xyz="0.5 0 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
</robot>
"""


def test_a_branch_whose_limits_exclude_neutral_is_locked_at_its_nearest_limit(tmp_path):
    """A B1's calf (0 rad outside [-2.6, -0.6] rad) is locked at -0.6 rad, a posture the robot can take: the locked
    leg's foot is where the full model puts it at j2 = -0.6 rad, not at the straight leg of j2 = 0."""
    from pin_kpi_oed.model.urdf_joints import locked_posture

    path = tmp_path / "calf.urdf"
    path.write_text(BRANCH_OUTSIDE_ZERO)
    full = pin.buildModelFromUrdf(str(path))
    q_lock = locked_posture(full)
    assert q_lock[full.joints[full.getJointId("j2")].idx_q] == -0.6
    rb = load_robot(str(path), tool_frame="tip")
    assert rb.joint_names == ["j1", "j3"] and rb.locked_joints == ["j2"]
    assert "clipped into their limits" in rb.notes[0]
    fd = full.createData()
    q_full = pin.neutral(full)
    q_full[full.joints[full.getJointId("j2")].idx_q] = -0.6
    pin.framesForwardKinematics(full, fd, q_full)
    pin.framesForwardKinematics(rb.model, rb.data, np.zeros(2))
    foot = full.getFrameId("foot")
    np.testing.assert_allclose(rb.data.oMf[rb.model.getFrameId("foot")].translation, fd.oMf[foot].translation,
                               atol=1e-15)
    q_full[full.joints[full.getJointId("j2")].idx_q] = 0.0
    pin.framesForwardKinematics(full, fd, q_full)
    assert np.linalg.norm(rb.data.oMf[rb.model.getFrameId("foot")].translation - fd.oMf[foot].translation) > 0.1
