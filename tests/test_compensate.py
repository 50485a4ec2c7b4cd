"""Compensation: joint values from the calibrated model (Cartesian targets, joint-space programs, CLI)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from pin_kpi_oed import NoiseModel, TrackerModel, load_robot
from pin_kpi_oed.cli.app import main
from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.data.targets import TargetSet, read_targets
from pin_kpi_oed.effects.library import parse_effects_spec, size_effect
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.compensation.compensator import (SENDABLE, CompensationOptions, PoseModel, compensate,
                                                   compensate_program, forward)
from pin_kpi_oed.identification.identify import identify, predict, validate
from pin_kpi_oed.simulation.simulator import Tolerances, default_tracker_pose, random_truth, simulate
from pin_kpi_oed.oed.identifiability import analyse

from tests._cache_real import ipa_series, needs_ipa

SIGMA = 1e-5
REFLECTOR = np.array([0.03, 0.02, 0.08])


def _aux(robot, m):
    return MeasurementSet(robot.joint_names, np.zeros((m, robot.nq)), np.full((m, 3), np.nan))


def _regular(Q):
    """UR configurations away from the elbow (q3 = 0) and wrist (q5 = 0, ±π) singularities."""
    Q = Q.copy()
    Q[:, 2] = np.where(Q[:, 2] < 0, -1.0, 1.0) * np.clip(np.abs(Q[:, 2]), 0.6, 2.5)
    Q[:, 4] = np.clip(np.abs(Q[:, 4]), 0.6, 2.5)
    return Q


def tcp_at_reflector(cm):
    """The model with its TCP stated at the fitted reflector (the point these tests compensate): a model that
    states no TCP is refused by compensate."""
    cm.tcp_m = cm.setups[cm.station(None)].reflector_m.copy()
    cm.tool_source = "the test: the TCP is the reflector"
    return cm


@pytest.fixture(scope="module")
def world():
    """A UR10 with random (identifiable) geometric errors, a tracker-pose error and a withheld gear harmonic,
    calibrated (geometry only) on 200 simulated tracker rows; 100 more rows held out."""
    robot = load_robot("ur10")
    tm = TrackerModel(robot, tracker_T_base=default_tracker_pose(robot), reflector_m=REFLECTOR,
                      noise=NoiseModel((SIGMA,) * 3))
    base = [i for i in analyse(tm).base if i < 6 * robot.nq]
    truth = random_truth(tm, Tolerances(5e-4, 1e-3, 0.01, 0.01), seed=3, only=base + list(range(36, 42)))
    rng = np.random.default_rng(1)
    Q = robot.random_q(rng, 300)
    (eff, th), = parse_effects_spec("gear_harmonic=5e-5", robot, rng)
    th = size_effect(tm, truth, Q, MeasurementSet(robot.joint_names, Q, np.zeros((300, 3))), eff, th, 3 * SIGMA)
    data = simulate(tm, Q, truth, effects=[(eff, th)], seed=2)
    train, held = data.subset(np.arange(200)), data.subset(np.arange(200, 300))
    res = identify(TrackerModel(robot, reflector_m=REFLECTOR, noise=tm.noise), train, discrepancy="none")
    cm = tcp_at_reflector(res.calibrated_model())
    held_err = validate(cm, held)

    def truth_tcp(Qx):  # where the true robot's reflector goes (tracker frame), with the withheld effect
        return predict(tm, truth, Qx, [eff], [th], _aux(robot, len(Qx)))[:, :3]

    return robot, tm, truth, (eff, th), cm, held_err, truth_tcp


def test_simulated_targets_reach_within_twice_the_held_out_error(world, capsys):
    """60 reachable Cartesian targets compensated on the calibrated UR10: each reached by the model, the mean true
    error within twice the calibration's held-out mean and far below the nominal solutions'. 60 targets (each an
    IK with a branch search, the test's whole cost) still make the means real tests: the compensated errors scatter
    by at most about their mean, so the mean of 60 has a standard error of at most about 13 % of it, well inside
    the factor 2; at least three quarters reached as "ok" is the same share as 150 of 200."""
    robot, tm, truth, _, cm, held_err, truth_tcp = world
    n = 60
    Qt = robot.random_q(np.random.default_rng(5), n) * 0.9
    Yt = truth_tcp(Qt)  # reachable Cartesian targets in the cell (tracker) frame
    ts = TargetSet([f"P{i}" for i in range(n)], Yt, None, None, list(robot.joint_names), _aux(robot, n), "sim")
    res = compensate(cm, ts, CompensationOptions(frame="cell"))
    # every target reached; the ones outside the calibration's joint-space coverage say so (never "ok")
    assert set(res.target_status) <= {"ok", "extrapolated"} and res.target_status.count("ok") >= 0.75 * n
    assert [s == "extrapolated" for s in res.target_status] == res.extrapolation.tolist()
    assert res.success == (res.target_status.count("ok") == n)
    assert res.residual_m.max() < 1e-8  # the calibrated model puts the TCP on the target
    e_comp = np.linalg.norm(truth_tcp(res.q) - Yt, axis=1)
    e_nom = np.linalg.norm(truth_tcp(res.q_nominal) - Yt, axis=1)
    with capsys.disabled():
        print(f"\n[compensate] {n} targets: mean error nominal {e_nom.mean() * 1e3:.3f} mm, compensated "
              f"{e_comp.mean() * 1e3:.4f} mm; calibration held-out mean {held_err['mean_m'] * 1e3:.4f} mm")
    assert e_comp.mean() <= 2.0 * held_err["mean_m"]
    assert e_nom.mean() > 20.0 * e_comp.mean()
    # the predicted correction is what the nominal solution misses by, in the truth too (to the model error)
    assert np.abs(res.correction_m - e_nom).max() < 5.0 * held_err["max_m"]


def test_pose_model_matches_model_predict_and_finite_differences(world):
    robot, _, _, _, cm, _, _ = world
    Q = robot.random_q(np.random.default_rng(8), 5)
    pm = PoseModel(cm, "cell")
    assert np.abs(pm.pose(Q)[0] - cm.predict(Q)).max() < 1e-12
    assert np.abs(forward(cm, Q) - cm.predict(Q)).max() < 1e-12
    for nominal in (False, True):
        pmx = PoseModel(cm, "base", tcp_m=np.array([0.01, -0.02, 0.15]), nominal=nominal)
        q = Q[0]
        J = pmx.jacobian(q)
        h = 1e-6
        for k in range(robot.nq):
            dq = np.zeros(robot.nq)
            dq[k] = h
            (p1,), (R1,) = pmx.pose(q + dq)
            (p0,), (R0,) = pmx.pose(q - dq)
            assert np.allclose((p1 - p0) / (2 * h), J[:3, k], atol=1e-7)
            assert np.allclose(pin.log3(R1 @ R0.T) / (2 * h), J[3:, k], atol=1e-7)


def test_six_d_targets_in_the_base_frame(world):
    robot, tm, truth, (eff, th), cm, held_err, _ = world
    Qt = robot.random_q(np.random.default_rng(6), 40) * 0.9
    truth_base = TrackerModel(robot, reflector_m=tm.reflector(truth), noise=tm.noise)
    pt = truth.copy()
    pt[tm.layout.tracker] = 0.0
    Yb = predict(truth_base, pt, Qt, [eff], [th], _aux(robot, 40))[:, :3]  # true TCP in the base frame
    pm_true = PoseModel(cm, "base")
    Rb = np.array([pin.log3(R) for R in pm_true.pose(Qt)[1]])  # orientations the calibrated model can reach
    ts = TargetSet([str(i) for i in range(40)], Yb, Rb, None, list(robot.joint_names), _aux(robot, 40), "six")
    res = compensate(cm, ts, CompensationOptions(frame="base"))
    ok = np.array([s in SENDABLE for s in res.target_status])  # reached (extrapolated: flagged)
    assert ok.sum() >= 30 and res.orientation
    assert res.residual_m[ok].max() < 1e-8 and res.residual_rad[ok].max() < 1e-8
    assert np.all(res.inv_cond[~ok] < 1e-2)  # every target is reachable: what is not ok is at a singularity
    e = np.linalg.norm(predict(truth_base, pt, res.q, [eff], [th], _aux(robot, 40))[:, :3] - Yb, axis=1)
    assert e[ok].mean() <= 2.0 * held_err["mean_m"]


def test_program_compensation_holds_the_nominal_poses(world):
    robot, tm, truth, (eff, th), cm, held_err, _ = world
    Qp = _regular(robot.random_q(np.random.default_rng(9), 30) * 0.8)
    prog = TargetSet([f"L{i}" for i in range(30)], None, None, Qp, list(robot.joint_names), _aux(robot, 30), "prog")
    res = compensate_program(cm, prog)
    ok = np.array([s in SENDABLE for s in res.target_status])  # reached (extrapolated: flagged)
    assert ok.sum() >= 27 and np.array_equal(res.q_nominal, Qp)
    assert np.all(res.inv_cond[~ok] < 1e-2)  # what is not ok is at a singularity
    assert res.residual_m[ok].max() < 1e-8 and res.residual_rad[ok].max() < 1e-8
    # the intended TCP (nominal FK in the base frame) vs where the true robot goes
    truth_base = TrackerModel(robot, reflector_m=tm.reflector(truth), noise=tm.noise)
    pt = truth.copy()
    pt[tm.layout.tracker] = 0.0
    goal = PoseModel(cm, "base", tcp_m=tm.reflector(truth), nominal=True).pose(Qp)[0]
    e_comp = np.linalg.norm(predict(truth_base, pt, res.q, [eff], [th], _aux(robot, 30))[:, :3] - goal, axis=1)
    e_nom = np.linalg.norm(predict(truth_base, pt, Qp, [eff], [th], _aux(robot, 30))[:, :3] - goal, axis=1)
    assert e_comp[ok].mean() < 0.1 * e_nom[ok].mean()


def test_unreachable_and_singular_targets_are_reported(world):
    robot, _, _, _, cm, _, _ = world
    pm = PoseModel(cm, "base")
    q_sing = np.array([0.3, -1.2, 1.4, -0.5, 0.0, 0.7])  # wrist 2 at 0: wrist singularity of the UR
    p, R = pm.pose(q_sing[None])
    ts = TargetSet(["far", "wrist"], np.vstack([[9.0, 0.0, 0.5], p]), np.vstack([[0.0, 0.0, 0.0], pin.log3(R[0])]),
                   np.vstack([robot.neutral(), q_sing]), list(robot.joint_names), _aux(robot, 2), "bad")
    res = compensate(cm, ts, CompensationOptions(frame="base", restarts=2))
    assert res.target_status == ["unreachable", "near_singular"] and not res.success
    assert "target far: unreachable" in res.summary() and "target wrist: near_singular" in res.summary()


def _write(path: Path, header: list[str], rows) -> Path:
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows(rows)
    return path


def test_cli_compensate_targets_in_mm_with_other_names(world, tmp_path, capsys):
    robot, _, _, _, cm, _, truth_tcp = world
    cm.save(tmp_path / "model.json")
    Qt = robot.random_q(np.random.default_rng(11), 12) * 0.9
    Yt = truth_tcp(Qt)
    f = _write(tmp_path / "t.csv", ["Point", "X", "Y", "Z"], [[f"T{i}", *(y * 1e3)] for i, y in enumerate(Yt)])
    out = tmp_path / "joints.csv"
    base = ["compensate", "--model", tmp_path / "model.json", "--targets", f, "--out", out, "--quiet"]
    assert main([str(a) for a in base]) == 2
    err = capsys.readouterr().err
    assert "missing position column(s) x, y, z" in err and "--columns" in err and len(err.strip().splitlines()) == 1
    assert main([str(a) for a in base + ["--columns", "name=Point,x=X,y=Y,z=Z"]]) == 2
    err = capsys.readouterr().err
    assert "looks like mm" in err and "--units" in err and len(err.strip().splitlines()) == 1
    assert main([str(a) for a in base + ["--columns", "name=Point,x=X,y=Y,z=Z", "--units", "mm", "--json",
                                         tmp_path / "r.json"]]) == 0
    import json
    rep = json.loads((tmp_path / "r.json").read_text())
    assert rep["success"] and rep["frame"] == "cell" and len(rep["correction_m"]) == 12
    assert min(rep["correction_m"]) > 1e-4  # the nominal solutions miss by ~mm: the correction is reported
    rows = list(csv.DictReader(open(out)))
    assert [r["name"] for r in rows] == [f"T{i}" for i in range(12)] and all(r["status"] == "ok" for r in rows)
    Q = np.array([[float(r[j]) for j in robot.joint_names] for r in rows])
    assert np.linalg.norm(cm.predict(Q) - Yt, axis=1).max() < 1e-8
    # the honest sigma in the JSON (the CSV's), and the lever arm said when the TCP is away from the reflector
    assert rep["sigma_m"] == pytest.approx([float(r["sigma_m"]) for r in rows]) and min(rep["sigma_m"]) > 0
    assert rep["tcp_from_reflector_m"] == 0.0
    refl = cm.setups[cm.station(None)].reflector_m
    tcp = refl + np.array([0.0, 0.03, 0.04])
    assert main([str(a) for a in base[:-1] + ["--columns", "name=Point,x=X,y=Y,z=Z", "--units", "mm", "--tcp",
                                              ",".join(f"{v:.17g}" for v in tcp), "--json", tmp_path / "r2.json"]]) == 0
    out_text = capsys.readouterr().out
    assert ("lever arm: the discrepancy is learnt at the reflector and the TCP is 50.0 mm from it; "
            "this sigma") in out_text
    assert json.loads((tmp_path / "r2.json").read_text())["tcp_from_reflector_m"] == pytest.approx(0.05)
    # a joint-space program (degrees, other names) through the same options
    names = [f"A{k + 1}" for k in range(robot.nq)]
    Qp = _regular(robot.random_q(np.random.default_rng(12), 5) * 0.8)
    fp = _write(tmp_path / "p.csv", names, np.degrees(Qp).tolist())
    cols = ",".join(f"{j}={a}" for j, a in zip(robot.joint_names, names))
    assert main(["compensate", "--model", str(tmp_path / "model.json"), "--program", str(fp), "--out",
                 str(tmp_path / "pc.csv"), "--columns", cols, "--units", "deg", "--quiet"]) == 0
    rows = list(csv.DictReader(open(tmp_path / "pc.csv")))
    Qn = np.array([[float(r[f"{j}_nominal"]) for j in robot.joint_names] for r in rows])
    assert np.allclose(Qn, Qp, atol=1e-12)


def test_read_targets_refusals(tmp_path):
    joints = ["a", "b"]
    f = _write(tmp_path / "t.csv", ["x", "y", "z", "rx"], [[1, 2, 3, 0.1]])
    with pytest.raises(InputError, match="rx, ry, rz"):
        read_targets(f, joints)
    f = _write(tmp_path / "t2.csv", ["x", "y", "z", "a"], [[1, 2, 3, 0.1]])
    with pytest.raises(InputError, match="all of a, b or none"):
        read_targets(f, joints)
    f = _write(tmp_path / "t3.csv", ["x", "y", "z", "rx", "ry", "rz"], [[1, 2, 3, 90, 0, 0]])
    with pytest.raises(InputError, match="looks like degrees"):
        read_targets(f, joints)
    ts = read_targets(f, joints, units="deg")
    assert np.allclose(ts.rotvec_rad, [[np.pi / 2, 0, 0]]) and ts.names == ["1"]


@needs_ipa
def test_real_ur10_compensated_predictions_match_held_out_rows():
    """Second route to the model's held-out error: commanded joints -> where the compensation module says the TCP
    goes, against the measured positions of held-out IPA rows; and the measured points of 200 of those rows (spread
    evenly over the series) compensated back: each an IK with a branch search, the test's whole cost; 200 still
    tell a share of 95 % "ok" from one of 90 % (the binomial standard error is 1.5 %), and the identity of the
    moved distance holds row by row."""
    from pin_kpi_oed.upkeep.transfer import registration_split

    ms = ipa_series("C")  # imported once per process (tests/_cache_real.py)
    ms = MeasurementSet(ms.joint_names, ms.q, ms.position_m, temperature_c=ms.temperature_c, source="C.csv")
    tr_idx, held_idx = registration_split(len(ms), len(ms) // 2, seed=0)
    robot = load_robot("ur10")
    model = TrackerModel(robot, reflector_m=np.array([0.0, 0.0, 0.109]), noise=NoiseModel(sigma_xyz_m=(1e-4,) * 3))
    cm = tcp_at_reflector(identify(model, ms.subset(tr_idx), discrepancy="none").calibrated_model())
    held = ms.subset(held_idx)
    v = validate(cm, held)
    e = np.linalg.norm(forward(cm, held.q, held) - held.position_m, axis=1)
    assert abs(e.mean() - v["mean_m"]) < 1e-12 and v["mean_m"] < 1e-3
    pick = np.unique(np.linspace(0, len(held) - 1, 200).astype(int))
    part = held.subset(pick)
    ts = TargetSet([str(i) for i in range(len(part))], part.position_m, None, part.q, list(robot.joint_names),
                   part, "held")
    res = compensate(cm, ts)
    ok = np.array([s == "ok" for s in res.target_status])
    assert ok.mean() > 0.95
    # the compensated joints differ from the commanded ones by what the model error amounts to in joint space
    moved = np.linalg.norm(forward(cm, res.q[ok], part.subset(np.flatnonzero(ok))) -
                           forward(cm, part.q[ok], part.subset(np.flatnonzero(ok))), axis=1)
    assert abs(moved.mean() - e[pick][ok].mean()) < 1e-8


# --------------------------------------------------------------------------- calibrated URDF with set-up frames
def test_calibrated_urdf_carries_tracker_reflector_and_tcp_frames(world, tmp_path):
    import yourdfpy

    from pin_kpi_oed.calibrated.urdf_export import write_model_urdf

    robot, _, _, _, cm, _, _ = world
    out = tmp_path / "calibrated.urdf"
    assert write_model_urdf(cm, out, tcp_m=np.array([0.0, 0.0, 0.2])) <= 1e-9
    st = cm.station()
    Q = robot.random_q(np.random.default_rng(21), 4)
    Y = cm.predict(Q)  # reflector in the tracker frame (geometry only: this model has no effects)
    # Pinocchio: the reflector frame seen from the tracker frame is what the model predicts
    model = pin.buildModelFromUrdf(str(out))
    data = model.createData()
    ft, fr = model.getFrameId(f"tracker_{st}"), model.getFrameId(f"reflector_{st}")
    for q, y in zip(Q, Y):
        pin.framesForwardKinematics(model, data, q)
        assert np.allclose((data.oMf[ft].inverse() * data.oMf[fr]).translation, y, atol=1e-9)
    assert np.allclose(data.oMf[model.getFrameId("tcp")].translation,
                       data.oMf[model.getFrameId(robot.tool_frame)].act(np.array([0.0, 0.0, 0.2])), atol=1e-12)
    # yourdfpy (ROS-style tools) sees the same chain
    urdf = yourdfpy.URDF.load(str(out), load_meshes=False, build_collision_scene_graph=False,
                              load_collision_meshes=False)
    urdf.update_cfg(dict(zip(robot.joint_names, Q[-1])))
    T = urdf.get_transform(frame_to=f"reflector_{st}", frame_from=f"tracker_{st}")
    assert np.allclose(T[:3, 3], Y[-1], atol=1e-9)


def test_cli_identify_urdf_frames(world, tmp_path):
    from pin_kpi_oed.data.measurements import write_measurements

    robot, tm, truth, _, _, _, _ = world
    data = simulate(tm, robot.random_q(np.random.default_rng(31), 80), truth, seed=4)
    write_measurements(data, tmp_path / "B.csv")
    assert main(["identify", "--robot", "ur10", "--data", str(tmp_path / "B.csv"), "--reflector", "0.03,0.02,0.08",
                 "--sigma", "1e-5", "--urdf-out", str(tmp_path / "cal.urdf"), "--urdf-frames", "--quiet"]) == 0
    model = pin.buildModelFromUrdf(str(tmp_path / "cal.urdf"))
    assert model.existFrame("tracker_B") and model.existFrame("reflector_B") and model.nq == robot.nq


def test_compensation_uses_the_model_effects(world):
    """A model with effects (here the gear harmonic the calibration withheld, given to it) is compensated through
    them: the calibrated prediction at the compensated joints is the target; without the effect it is not."""
    import dataclasses

    from pin_kpi_oed.effects.library import ThermalExpansion

    robot, _, _, (eff, th), cm, _, truth_tcp = world
    cm_eff = dataclasses.replace(cm, effects=[eff], thetas=[th])
    Qt = robot.random_q(np.random.default_rng(41), 20) * 0.9
    Yt = truth_tcp(Qt)
    ts = TargetSet([str(i) for i in range(20)], Yt, None, None, list(robot.joint_names), _aux(robot, 20), "eff")
    res = compensate(cm_eff, ts)
    assert set(res.target_status) <= set(SENDABLE)
    assert np.linalg.norm(cm_eff.predict(res.q) - Yt, axis=1).max() < 1e-8
    assert np.linalg.norm(cm.predict(res.q) - Yt, axis=1).mean() > 1e-6  # the effect moved the solution
    cm_t = dataclasses.replace(cm, effects=[ThermalExpansion(robot)], thetas=[np.zeros(1)])
    with pytest.raises(InputError, match="temperature") as err:
        compensate(cm_t, ts)  # the targets have no temperature column for the thermal effect
    # the one line names the column and both fixes; the command line says its option
    assert "needs a 'temperature' column" in str(err.value) and "diagnose effects=[]" in str(err.value)
    from pin_kpi_oed.cli.flags import in_flags

    assert "diagnose --effects none" in in_flags(str(err.value))


def _line_program(robot, a, b, n=81):
    Qp = np.asarray(a, float) + np.linspace(0.0, 1.0, n)[:, None] * (np.asarray(b, float) - np.asarray(a, float))
    return TargetSet([f"L{i}" for i in range(n)], None, None, Qp, list(robot.joint_names), _aux(robot, n), "line")


def test_program_compensation_keeps_the_path_continuous(world):
    """A joint-space line: the correction changes between consecutive rows far less than the program's steps (no
    branch change); a line through the wrist singularity (q5 = 0) is reported broken there, never sent as ok."""
    robot, _, _, _, cm, _, _ = world
    res = compensate_program(cm, _line_program(robot, [0.3, -1.2, 1.4, -0.5, 1.0, 0.7],
                                               [0.9, -1.0, 1.6, -0.3, 1.4, 0.9]))
    assert set(res.target_status) <= set(SENDABLE)
    step = np.abs(np.diff(res.q_nominal, axis=0)).max()
    assert res.correction_jump_rad[0] == 0.0 and res.correction_jump_rad.max() < 0.01 * step
    assert np.allclose(res.correction_jump_rad[1:], np.abs(np.diff(res.q - res.q_nominal, axis=0)).max(axis=1))
    assert "continuity: the correction changes by at most" in res.summary() and "broken" not in res.summary()
    sing = compensate_program(cm, _line_program(robot, [0.3, -1.2, 1.4, -0.5, 0.4, 0.7],
                                                [0.5, -1.0, 1.2, -0.3, -0.4, 0.9]))
    good = np.array([s in SENDABLE for s in sing.target_status])
    both = good[1:] & good[:-1]
    assert (~good).any() and sing.correction_jump_rad.max() > 0.1  # the wrist flips where it is not ok
    assert sing.correction_jump_rad[1:][both].max() < np.abs(np.diff(sing.q_nominal, axis=0)).max()
    assert "the program is broken at" in sing.summary()


def test_cli_program_csv_has_the_continuity_column(world, tmp_path):
    from tests.cli_run import run_cli
    from pin_kpi_oed.data.atomic import atomic_write_json

    robot, _, _, _, cm, _, _ = world
    prog = _line_program(robot, [0.3, -1.2, 1.4, -0.5, 1.0, 0.7], [0.9, -1.0, 1.6, -0.3, 1.4, 0.9], n=11)
    atomic_write_json(tmp_path / "m.json", cm.to_dict())
    _write(tmp_path / "prog.csv", list(robot.joint_names), prog.q.tolist())
    rc, out, err = run_cli("compensate", "--model", tmp_path / "m.json", "--program", tmp_path / "prog.csv",
                           "--out", tmp_path / "c.csv")
    assert rc == 0, err
    rows = list(csv.DictReader(open(tmp_path / "c.csv")))
    assert len(rows) == 11 and float(rows[0]["correction_jump_rad"]) == 0.0
    assert 0 < max(float(r["correction_jump_rad"]) for r in rows) < 1e-3
    assert "sigma_rot_rad" not in rows[0]  # a position-only model states no orientation sigma
    assert "continuity:" in out


def test_base_frame_sigma_names_the_base_placement_apart_from_the_tool(world):
    """In the base frame the held σ at a TCP off the reflector has two parts: the tool's (what the tracker frame
    states too; a reflector at the TCP removes it) and the base frame's own placement (the held parameters that
    move no point in the tracker frame: joint 1's placement and what the tracker pose absorbs). The summary names
    each with its fix; the tracker frame has no base part."""
    from pin_kpi_oed.calibrated.tcp_sigma import tcp_sigma

    robot, _, _, _, cm, _, _ = world
    tcp = np.array([0.01, -0.02, 0.15])
    Q = _regular(robot.random_q(np.random.default_rng(12), 3) * 0.8)
    res = {}
    for frame in ("base", "cell"):
        y = PoseModel(cm, frame, tcp_m=tcp).pose(Q)[0]
        ts = TargetSet(["a", "b", "c"], y, None, Q, list(robot.joint_names), _aux(robot, 3), frame)
        res[frame] = compensate(cm, ts, CompensationOptions(frame=frame, tcp_m=tcp))
    b, c = res["base"], res["cell"]
    assert c.base_unobservable_m.size == 0 and "--frame tracker" not in c.summary()
    assert np.allclose(b.tcp_unobservable_m ** 2, c.tcp_unobservable_m ** 2 + b.base_unobservable_m ** 2, rtol=1e-3)
    # the base part, parameter by parameter: the held parameters that move no point in the tracker frame
    for i in range(3):
        tb, tc = (tcp_sigma(cm, b.q[i:i + 1], tcp, frame=f) for f in ("base", "cell"))
        base_only = [k for k, n in enumerate(tb.held_names)
                     if tc.held_contrib_m[tc.held_names.index(n)] < 1e-3 * tb.held_contrib_m[k]]
        assert base_only and any(tb.held_names[k].startswith(robot.joint_names[0]) for k in base_only)
        assert b.base_unobservable_m[i] == pytest.approx(np.sqrt(np.sum(tb.held_contrib_m[base_only] ** 2)), rel=1e-2)
    assert b.base_unobservable_m.min() > 1e-4  # joint 1's 0.5 mm tolerance
    line = next(s for s in b.summary().splitlines() if s.startswith("of which"))
    assert "base frame's own placement" in line and "--frame tracker" in line and "at the tool" in line
    assert b.to_dict()["base_unobservable_m"] == pytest.approx(b.base_unobservable_m.tolist())


def _nearest_row_by_row(pm, Q, Q_ref, pos_t, weights, tol_m, iters=30):
    """The null-space slide one row at a time, with one pose evaluation per step (what compensate did before the
    rows shared their evaluations): the reference of the batched :func:`nearest_to_reference`."""
    robot, nr = pm.robot, len(weights)
    Q = np.array(Q, float)

    def task_error(q, i):
        return (pos_t[i] - pm.pose(q[None], None)[0][0]) * weights

    for i in range(len(Q)):
        q = Q[i]
        for _ in range(iters):
            J = pm.jacobian(q)[:nr] * weights[:, None]
            d = (np.eye(robot.nq) - np.linalg.pinv(J) @ J) @ (Q_ref[i] - q)
            if np.linalg.norm(d) < 1e-9:
                break
            q1 = np.clip(q + d, robot.q_lower, robot.q_upper)
            for _ in range(5):
                e = task_error(q1, i)
                if np.linalg.norm(e) <= 1e-10:
                    break
                q1 = np.clip(q1 + np.linalg.pinv(pm.jacobian(q1)[:nr] * weights[:, None]) @ e, robot.q_lower,
                             robot.q_upper)
            if np.linalg.norm(task_error(q1, i)) > tol_m or \
                    np.linalg.norm(q1 - Q_ref[i]) >= np.linalg.norm(q - Q_ref[i]):
                break
            q = q1
        Q[i] = q
    return Q


def test_nearest_to_reference_batched_equals_row_by_row(world):
    """Position-only targets on the 6-joint UR10 (a 3-D self-motion manifold): the rows slid towards their references
    together equal the rows slid one at a time bit for bit (a row's pose does not depend on the rows evaluated with
    it, and every stopping test compares the same numbers), each row ends nearer its reference and on its target."""
    from pin_kpi_oed.compensation.checks import nearest_to_reference
    from pin_kpi_oed.compensation.compensator import PoseModel

    robot, _, _, _, cm, _, _ = world
    pm = PoseModel(cm, "cell", nominal=True)
    rng = np.random.default_rng(12)
    Q = robot.random_q(rng, 12) * 0.8
    Q_ref = np.clip(Q + rng.normal(0.0, 0.3, Q.shape), robot.q_lower, robot.q_upper)
    pos_t = pm.pose(Q)[0]
    w = np.ones(3)
    got = nearest_to_reference(pm, Q, Q_ref, pos_t, None, w, 1e-6)
    ref = _nearest_row_by_row(pm, Q, Q_ref, pos_t, w, 1e-6)
    assert np.array_equal(got, ref), np.abs(got - ref).max()
    moved = np.linalg.norm(got - Q, axis=1) > 1e-6
    assert moved.sum() >= 6, "most rows must slide for the comparison to mean something"
    assert np.all(np.linalg.norm(got - Q_ref, axis=1) <= np.linalg.norm(Q - Q_ref, axis=1))
    assert np.abs(pm.pose(got)[0] - pos_t).max() < 1e-6

