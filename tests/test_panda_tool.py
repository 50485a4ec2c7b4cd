"""A Panda cell with tool_frame panda_link8 and a gripper TCP, through design -> simulate -> identify -> compensate with
the CLI's defaults: the tool frame, reflector, TCP and working configurations travel from the cell, the compensated
joints stay on the working configuration's branch and the TRUE simulated robot's TCP lands on the target.

(The defect this catches: ``identify --robot panda`` calibrated ``panda_hand_tcp`` while the cell said ``panda_link8``,
and compensation returned joints 45-50 deg away from the working configuration, every target "ok".)
"""

from __future__ import annotations

import csv
import json

import numpy as np
import pinocchio as pin
import pytest

from tests.cli_run import run_cli

CELL = """\
name: panda_test
robot: panda
tool_frame: panda_link8
base: {xyz_m: [0.0, 0.0, 0.0], rpy_deg: [0.0, 0.0, 0.0]}
tracker: {xyz_m: [2.0, 0.3, 0.6], rpy_deg: [0.0, 0.0, 180.0]}
reflector_m: [0.0, 0.06, 0.07]
tcp_m: [0.0, 0.0, 0.1034]
noise: {sigma_xyz_m: [1.0e-5, 1.0e-5, 1.0e-5]}
robot_capsules:
  - {name: hand, link: panda_hand, a_m: [0.0, 0.0, 0.0], b_m: [0.0, 0.0, 0.06], radius_m: 0.04}
  - {name: forearm, link: panda_link5, a_m: [0.0, 0.0, -0.25], b_m: [0.0, 0.0, 0.0], radius_m: 0.05}
obstacles:
  half_spaces:
    - {name: table, normal: [0.0, 0.0, 1.0], offset_m: 0.0}
beam: {radius_m: 0.005, skip: [hand]}
working_targets:
  - {xyz_m: [0.45, 0.0, 0.25], rpy_deg: [180.0, 0.0, 0.0], seed_deg: [0, -45, 0, -135, 0, 90, 45]}
  - {xyz_m: [0.40, 0.25, 0.30], rpy_deg: [180.0, 0.0, 0.0], seed_deg: [0, -45, 0, -135, 0, 90, 45]}
measurements: 40
"""




def true_tcp(truth, tcp_m: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """TCP of the true simulated robot (geometric errors + effects) in its true tracker frame, (m, 3) m."""
    from pin_kpi_oed.data.measurements import MeasurementSet
    from pin_kpi_oed.identification.identify import predict
    from pin_kpi_oed.model.tracker import TrackerModel

    model, p, effects = truth
    mt = TrackerModel(model.robot, tracker_T_base=model.tracker_T_base, reflector_m=np.asarray(tcp_m, float),
                      noise=model.noise)
    p = p.copy()
    p[mt.layout.reflector] = 0.0  # the TCP point carries no reflector error
    aux = MeasurementSet(list(model.robot.joint_names), Q, np.zeros((len(Q), 3)))
    return predict(mt, p, Q, [e for e, _ in effects], [t for _, t in effects], aux)[:, :3]


def test_panda_link8_tool_travels_and_compensation_keeps_the_branch(tmp_path):
    from pin_kpi_oed.calibrated.model_file import load_model_file
    from pin_kpi_oed.simulation.simulator import load_truth

    cell = tmp_path / "cell.yaml"
    cell.write_text(CELL)
    d, tr, truth, model = (tmp_path / n for n in ("d.json", "tr.csv", "truth.json", "m.json"))
    assert run_cli("design", "--cell", cell, "--criteria", "random", "--json", d, "--quiet")[0] == 0
    rc, out, err = run_cli("simulate", "--design", d, "--truth", truth, "--tol-rotation", "2e-4", "--out", tr)
    assert rc == 0, err
    assert "tool frame panda_link8" in out
    rc, out, err = run_cli("identify", "--robot", "panda", "--data", tr, "--model-out", model, "--quiet")
    assert rc == 0, err  # --robot panda alone: the tool frame comes from the data's header, not panda_hand_tcp
    cm = load_model_file(model)
    assert cm.robot.tool_frame == "panda_link8" and np.allclose(cm.tcp_m, [0, 0, 0.1034]) and cm.q_work.shape == (2, 7)
    rc, _, err = run_cli("identify", "--robot", "panda", "--tool", "panda_hand_tcp", "--data", tr)
    assert rc == 2 and "tool frame 'panda_link8' contradicts 'panda_hand_tcp' from --tool panda_hand_tcp" in err

    # the working targets, in the true tracker frame (what the tracker sees), without joint hints
    tm = load_truth(str(truth))
    T = tm[0].tracker_pose(tm[1])
    rows = []
    for k, q in enumerate(cm.q_work):
        M = cm.robot.oMtool(q)
        rows.append([f"w{k}", *T.act(M.act(cm.tcp_m)), *pin.log3(T.rotation @ M.rotation)])
    targets = tmp_path / "targets.csv"
    with open(targets, "w", newline="") as f:
        csv.writer(f).writerows([["name", "x", "y", "z", "rx", "ry", "rz"]] + rows)
    rc, out, err = run_cli("compensate", "--model", model, "--targets", targets, "--cell", cell, "--out",
                         tmp_path / "j.csv", "--json", tmp_path / "j.json")
    assert rc == 0, err
    assert "TCP [0.0, 0.0, 103.4] mm in tool frame panda_link8" in out and "2 working" in out
    res = json.loads((tmp_path / "j.json").read_text())
    Q = np.array(res["q"])
    # reached and checked; a working configuration the random design did not cover is flagged, never "ok"; one
    # inside is right at the reflector, its TCP's sigma dominated by what no reflector measurement sees: not "ok"
    assert res["target_status"] == ["extrapolated" if e else "tcp_unmeasured" for e in res["extrapolation"]]
    assert res["start"] == ["working", "working"]
    assert np.degrees(np.abs(Q - cm.q_work).max()) < 0.5  # on the working configuration's branch, within 0.5 deg
    # the true TCP near the target: what no reflector measurement sees is left (the flange's placement error, which
    # the fitted reflector offset absorbs: about the 0.5 mm tolerance); the defect put it 0.1 m away
    err_tcp = np.linalg.norm(true_tcp(tm, cm.tcp_m, Q) - np.array([r[1:4] for r in rows], float), axis=1)
    assert np.all(err_tcp < 1e-3), err_tcp
    unseen = np.array(res["tcp_unobservable_m"])  # ... and compensate says so: its sigma holds it
    assert np.all(unseen > 0.3e-3) and np.all(err_tcp <= np.sqrt(7.8147 / 3) * np.array(res["sigma_m"]))
    assert "the reflector cannot see at this TCP" in out
    # at the reflector, the point the calibration measured, the true robot lands on the target
    refl = cm.setups[cm.station()].reflector_m
    for r, q in zip(rows, cm.q_work):
        M = cm.robot.oMtool(q)
        r[1:4] = T.act(M.act(refl))
    with open(targets, "w", newline="") as f:
        csv.writer(f).writerows([["name", "x", "y", "z", "rx", "ry", "rz"]] + rows)
    rc, out, err = run_cli("compensate", "--model", model, "--targets", targets, "--tcp",
                         ",".join(repr(float(v)) for v in refl), "--out", tmp_path / "j.csv",
                         "--json", tmp_path / "j.json")
    assert rc == 0, err
    res = json.loads((tmp_path / "j.json").read_text())
    goal, refl_true = np.array([r[1:4] for r in rows], float), tm[0].reflector(tm[1])  # where the reflector truly is
    err_comp = np.linalg.norm(true_tcp(tm, refl_true, np.array(res["q"])) - goal, axis=1)
    err_nom = np.linalg.norm(true_tcp(tm, refl_true, np.array(res["q_nominal"])) - goal, axis=1)
    assert np.all(err_comp < 0.05e-3), err_comp
    assert res["tcp_unobservable_m"] == [0.0, 0.0]  # the fitted reflector is what the calibration saw
    assert np.all(err_comp < err_nom / 4), (err_comp, err_nom)


@pytest.mark.parametrize("hint_deg, expect", [(None, "working"), (5.0, "hint")])
def test_redundant_arm_keeps_the_hint_or_working_branch_and_flags_limits(tmp_path, hint_deg, expect):
    """A 7-joint arm, position-only targets: the solution stays by the hint / working configuration (minimum-norm
    steps); a target whose solution needs a joint at its limit is 'joint_limit', never 'ok'."""
    from pin_kpi_oed.data.measurements import MeasurementSet
    from pin_kpi_oed.data.targets import TargetSet
    from pin_kpi_oed.compensation.compensator import CompensationOptions, PoseModel, compensate
    from pin_kpi_oed.calibrated.model_file import CalibratedModel, Setup
    from pin_kpi_oed.model.robot import load_robot

    robot = load_robot("panda", "panda_link8")
    rng = np.random.default_rng(1)
    q_work = np.array([[0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]])
    cm = CalibratedModel(robot, rng.normal(0, 2e-4, 6 * robot.nq), setups={"A": Setup(np.eye(4), np.zeros(3))},
                         tcp_m=np.array([0, 0, 0.1034]), q_work=q_work, tool_source="test")
    q_goal = q_work[0] + np.radians([3, -4, 2, 5, -3, 4, 2])
    pos = PoseModel(cm, "base", nominal=True).pose(q_goal[None])[0]
    hint = None if hint_deg is None else (q_goal + np.radians(hint_deg))[None]
    ts = TargetSet(["t"], pos, None, hint, list(robot.joint_names),
                   MeasurementSet(list(robot.joint_names), q_goal[None], np.zeros((1, 3))), "t")
    res = compensate(cm, ts, CompensationOptions(frame="base"))
    assert res.target_status == ["ok"] and res.start == [expect]
    ref = q_work[0] if hint is None else hint[0]
    assert np.abs(res.q[0] - ref).max() < np.radians(10)  # the null space does not wander off
    # the nearest solution: no motion along the self-motion manifold brings the nominal solution nearer the reference
    pm0 = PoseModel(cm, "base", nominal=True)
    J = pm0.jacobian(res.q_nominal[0])[:3]
    N = np.eye(7) - np.linalg.pinv(J) @ J
    assert np.linalg.norm(N @ (ref - res.q_nominal[0])) < 1e-3 * np.linalg.norm(ref - res.q_nominal[0]) + 1e-6
    assert np.linalg.norm(res.q_nominal[0] - ref) <= np.linalg.norm(q_goal - ref) + 1e-9  # nearer than the one it
    # was made from
    # a compensated joint within the limit margin of its limit is flagged, never ok (joint 4 is 0.8 rad from its
    # lower limit at the target: a margin of 1 rad puts it "at" the limit)
    res = compensate(cm, ts, CompensationOptions(frame="base", limit_margin=1.0))
    assert res.target_status == ["joint_limit"] and not res.success


def test_unobservable_tcp_offset_matches_a_refit_of_the_true_robot():
    """The σ compensate adds at a TCP away from the reflector: for true joint-placement errors the fit cannot
    determine (drawn at the tolerances), a noise-free calibration's TCP misses by G δ_u, the linear map the σ
    propagates (within 10 %), and nothing at the fitted reflector."""
    from pin_kpi_oed.data.tool_header import ToolSpec
    from pin_kpi_oed.identification.identify import identify
    from pin_kpi_oed.simulation.simulator import simulate
    from pin_kpi_oed.compensation.tool_offset import unobservable_map, unobservable_tcp_sigma
    from pin_kpi_oed.model.noise import NoiseModel
    from pin_kpi_oed.model.robot import load_robot
    from pin_kpi_oed.model.tracker import TrackerModel

    robot = load_robot("panda", "panda_link8")
    rng = np.random.default_rng(3)
    tcp = np.array([0.0, 0.0, 0.1034])
    nominal = TrackerModel(robot, tracker_T_base=pin.SE3(np.eye(3), np.array([-1.5, 0.2, 0.4])),
                           reflector_m=np.array([0.0, 0.06, 0.07]), tcp_m=tcp, noise=NoiseModel((1e-6,) * 3))
    Q, Qw = robot.random_q(rng, 40), robot.random_q(rng, 4)
    for draw in range(3):
        p_true = np.zeros(nominal.n_params)
        p_true[:6 * robot.nq] = rng.normal(0.0, 1.0, 6 * robot.nq) * np.tile([5e-4] * 3 + [1e-3] * 3, robot.nq)
        data = simulate(nominal, Q, p_true, seed=draw)
        data.sigma_m = None
        data.tool = ToolSpec(tool_frame="panda_link8", tcp_m=tcp, source="sim")
        cm = identify(nominal, data).calibrated_model()
        truth_tcp = TrackerModel(robot, tracker_T_base=nominal.tracker_T_base, reflector_m=tcp).predict(p_true, Qw)
        model_c, p_c = cm.station_model(None)
        cal_tcp = TrackerModel(robot, tracker_T_base=model_c.tracker_T_base, reflector_m=tcp).predict(p_c, Qw)
        G, term = unobservable_map(cm, None, tcp, Qw)
        u = [nominal.layout.names.index(n) for n in term.names]
        linear = np.einsum("mak,k->ma", G, p_true[u])  # calibrated − true TCP: G = E_B A − E_N per unit error
        assert np.linalg.norm(cal_tcp - truth_tcp - linear) < 0.1 * np.linalg.norm(linear), (cal_tcp - truth_tcp,
                                                                                          linear)
        refl = cm.setups[cm.station()].reflector_m
        assert np.all(unobservable_tcp_sigma(cm, None, refl, Qw) == 0.0)
        assert np.all(unobservable_tcp_sigma(cm, None, tcp, Qw) > 1e-4)


def test_collision_and_branch_checks_are_never_ok(tmp_path):
    """With a cell, a compensated configuration that collides is 'collision'; a joint step beyond the branch limit
    is 'off_branch'; otherwise the same targets are 'ok'."""
    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.cell.cell_model import CapsuleSpec
    from pin_kpi_oed.data.measurements import MeasurementSet
    from pin_kpi_oed.data.targets import TargetSet
    from pin_kpi_oed.compensation.compensator import CompensationOptions, PoseModel, compensate
    from pin_kpi_oed.calibrated.model_file import CalibratedModel, Setup

    (tmp_path / "cell.yaml").write_text(CELL)
    cell = load_cell(tmp_path / "cell.yaml")
    robot = cell.robot
    rng = np.random.default_rng(4)
    cm = CalibratedModel(robot, rng.normal(0, 2e-4, 6 * robot.nq),
                         setups={"A": Setup(cell.tracker_T_base.homogeneous, cell.reflector_m)},
                         tcp_m=cell.tcp_m, q_work=cell.q_work, tool_source="test")
    pos, R = PoseModel(cm, "base", nominal=True).pose(cell.q_work)
    rv = np.array([pin.log3(r) for r in R])
    n = len(pos)
    ts = TargetSet([f"w{k}" for k in range(n)], pos, rv, None, list(robot.joint_names),
                   MeasurementSet(list(robot.joint_names), cell.q_work, np.zeros((n, 3))), "t")
    ok = compensate(cm, ts, CompensationOptions(frame="base", cell=cell))
    assert ok.target_status == ["ok"] * n and ok.start == ["working"] * n
    cm.q_work = None  # a model without working configurations: the cell's give the branch
    again = compensate(cm, ts, CompensationOptions(frame="base", cell=cell))
    assert again.start == ["working"] * n and np.allclose(again.q, ok.q, atol=1e-9)
    cm.q_work = cell.q_work
    assert compensate(cm, ts, CompensationOptions(frame="base", max_branch_step_rad=1e-6)).target_status == \
        ["off_branch"] * n  # compensation moves joints by ~1e-3 rad: beyond a branch limit of 1e-6 rad
    W_tcp = cell.W_T_base.act(robot.oMtool(ok.q[0]).act(cell.tcp_m))
    cell.obstacles.append(CapsuleSpec("post", W_tcp + [0.0, 0.0, -0.05], W_tcp + [0.0, 0.0, 0.05], 0.03))
    hit = compensate(cm, ts, CompensationOptions(frame="base", cell=cell))
    assert hit.target_status[0] == "collision" and not hit.success and "post" in hit.collision_pair[0]
