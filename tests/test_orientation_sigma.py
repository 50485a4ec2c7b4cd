"""The orientation σ of a 6-D calibration (``predict``, ``compensate``): the parametric part against a Monte-Carlo of
identifications, the whole against held-out orientation errors (simulated and the real UR10's Series C)."""

from __future__ import annotations

import csv

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from pin_kpi_oed import NoiseModel, TrackerModel, load_robot
from pin_kpi_oed.data.atomic import atomic_write_json
from pin_kpi_oed.data.measurements import MeasurementSet, write_measurements
from pin_kpi_oed.identification.identify import identify
from pin_kpi_oed.simulation.simulator import Tolerances, default_tracker_pose, random_truth, simulate
from tests._cache_real import C6D_GROUP, needs_ipa, series_c_6d_half
from tests.cli_run import run_cli

REFLECTOR = np.array([0.03, 0.02, 0.08])
NOISE = NoiseModel((1e-5,) * 3, sigma_rot_rad=5e-5)


def _tm(robot, pose=None):
    return TrackerModel(robot, tracker_T_base=pose if pose is not None else default_tracker_pose(robot),
                        reflector_m=REFLECTOR, noise=NOISE, pose6d=True)


def _rot_errors(data, W):
    return (Rotation.from_rotvec(data.rotvec_rad) * Rotation.from_rotvec(W).inv()).as_rotvec()


@pytest.fixture(scope="module")
def sim():
    """A UR10 with random geometric errors measured by a 6-DoF probe; four seeded robots, 30 training and 300
    held-out rows each, calibrated without a discrepancy."""
    robot = load_robot("ur10")
    tm = _tm(robot)
    out = []
    for seed in range(4):
        truth = random_truth(tm, Tolerances(5e-4, 1e-3, 0.01, 0.01), seed=seed)
        data = simulate(tm, robot.random_q(np.random.default_rng(seed + 10), 330), truth, seed=seed + 20)
        tr, te = data.subset(np.arange(30)), data.subset(np.arange(30, 330))
        cm = identify(TrackerModel(robot, reflector_m=REFLECTOR, noise=NOISE, pose6d=True), tr,
                      discrepancy="none").calibrated_model()
        out.append((tm, truth, tr, te, cm))
    return out


def test_orientation_sigma_is_honest_on_held_out_rows(sim):
    z, zl = [], []
    for _, _, _, te, cm in sim:
        assert cm.fit["residual_sigma_rad"].shape == (3,)
        W, s, sl = cm.predict_orientation_with_sigma(te.q, te, length_m=0.2)
        e = _rot_errors(te, W)
        z.append(e / s)
        # the tool axis: the point 0.2 m along it moves by 0.2 (e x z); its 3-D sigma is sl
        model, p = cm.station_model()
        kin = model.kinematics(p, te.q, model.reflector(p))
        axis = kin.R_tool[:, :, 2] @ model.tracker_pose(p).rotation.T
        zl.append(np.linalg.norm(0.2 * np.cross(e, axis), axis=1) / sl)
    z, zl = np.vstack(z), np.concatenate(zl)
    assert 0.85 < np.sqrt(np.mean(z ** 2)) < 1.2
    assert 0.88 < np.mean(np.sum(z ** 2, axis=1) < chi2.ppf(0.95, 3)) < 0.99
    assert 0.85 < np.sqrt(np.mean(zl ** 2)) < 1.2


def test_parametric_part_matches_a_monte_carlo_of_identifications(sim):
    """Repeated identifications (new noise each) of one robot: the spread of the predicted orientation around the
    true one at held-out configurations against the σ's parametric part (σ² minus the white level)."""
    tm, truth, tr, te, _ = sim[0]
    robot = tm.robot
    R_true = Rotation.from_rotvec(tm.predict(truth, te.q)[:, 3:])
    sq, pred = [], []
    for rep in range(25):
        data = simulate(tm, tr.q, truth, seed=100 + rep)
        cm = identify(TrackerModel(robot, reflector_m=REFLECTOR, noise=NOISE, pose6d=True), data,
                      discrepancy="none").calibrated_model()
        W, s, _ = cm.predict_orientation_with_sigma(te.q, te)
        sq.append(np.sum((R_true * Rotation.from_rotvec(W).inv()).as_rotvec() ** 2, axis=1))
        pred.append(np.sum(s ** 2 - cm.fit["residual_sigma_rad"] ** 2, axis=1)
                    / (1.0 if cm.fit["covariance_scaled"] else max(1.0, cm.fit["chi2_reduced"])))
    ratio = np.mean(sq) / np.mean(pred)
    print(f"realised / predicted parametric orientation variance {ratio:.3f}")
    assert 0.7 < ratio < 1.4, ratio


def test_position_only_model_has_no_orientation_sigma(sim):
    from pin_kpi_oed.errors import InputError

    robot = load_robot("ur10")
    _, _, tr, te, _ = sim[0]
    pos = MeasurementSet(tr.joint_names, tr.q, tr.position_m)
    cm = identify(TrackerModel(robot, reflector_m=REFLECTOR, noise=NOISE), pos, discrepancy="none").calibrated_model()
    assert not cm.pose6d
    with pytest.raises(InputError, match="positions only"):
        cm.predict_orientation_with_sigma(te.q)


def test_cli_predict_writes_orientation_sigma_and_refuses_mm(sim, tmp_path):
    _, _, _, te, cm = sim[1]
    atomic_write_json(tmp_path / "m.json", cm.to_dict())
    write_measurements(te, tmp_path / "held.csv")
    rc, out, err = run_cli("predict", "--model", tmp_path / "m.json", "--data", tmp_path / "held.csv",
                           "--out", tmp_path / "p.csv", "--tool-length", "0.3")
    assert rc == 0, err
    assert "predicted orientation sigma (3-D): median" in out and "mrad" in out and "at 300 mm along the tool" in out
    rows = list(csv.DictReader(open(tmp_path / "p.csv")))
    W, s, sl = cm.predict_orientation_with_sigma(te.q, te, length_m=0.3)
    assert float(rows[7]["sigma_ry"]) == pytest.approx(s[7, 1], rel=1e-12)
    assert float(rows[7]["sigma_at_length"]) == pytest.approx(sl[7], rel=1e-12)
    assert float(rows[7]["rot_error"]) == pytest.approx(np.linalg.norm(_rot_errors(te, W)[7]), rel=1e-9)
    rc, out, err = run_cli("predict", "--model", tmp_path / "m.json", "--data", tmp_path / "held.csv",
                           "--out", tmp_path / "q.csv", "--tool-length", "200")
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and "--tool-length" in lines[0] and "in m" in lines[0], err
    assert not (tmp_path / "q.csv").exists()


@needs_ipa
@pytest.mark.xdist_group(C6D_GROUP)
def test_real_ur10_series_c_orientation_sigma_on_held_out_half():
    """The 6-D calibration of Series C's first half (tests/_cache_real.py: the data's sigma columns and 0.1 mrad as
    relative weights, the discrepancy auto; made once per process, test_sigma_6d_registered registers the same
    model on Series D): the orientation σ is honest on the held-out half."""
    _, te, cm = series_c_6d_half()
    W, s, sl = cm.predict_orientation_with_sigma(te.q, te, length_m=0.2)
    z = _rot_errors(te, W) / s
    assert 0.8 < np.sqrt(np.mean(z ** 2)) < 1.25
    assert 0.85 < np.mean(np.sum(z ** 2, axis=1) < chi2.ppf(0.95, 3)) < 0.99


def test_compensate_states_the_orientation_sigma(sim):
    """A 6-D calibration: compensated 6-D targets carry the orientation σ of the measured frame and the σ it causes
    at the tool length; the true robot's probe orientation error at the compensated joints lies within it."""
    from pin_kpi_oed.data.targets import TargetSet
    from pin_kpi_oed.compensation.compensator import CompensationOptions, PoseModel, compensate
    from pin_kpi_oed.calibrated.prediction_sigma import orientation_sigma

    tm, truth, _, te, cm = sim[2]
    robot = tm.robot
    Qt = te.q[:40]
    pos, R = PoseModel(cm, "cell").pose(Qt)  # tracker frame: the calibration's base is the tracker's
    aux = MeasurementSet(robot.joint_names, np.zeros((40, robot.nq)), np.full((40, 3), np.nan))
    ts = TargetSet([str(i) for i in range(40)], pos, Rotation.from_matrix(R).as_rotvec(), Qt,
                   list(robot.joint_names), aux, "six")
    lab = cm.station(None)
    res = compensate(cm, ts, CompensationOptions(frame="cell", tool_length_m=0.15, tcp_m=cm.setups[lab].reflector_m))
    W, s, sl = orientation_sigma(cm, res.q, None, lab, np.array([lab] * 40, dtype=object), 0.15)
    assert np.allclose(res.sigma_rot_rad, np.linalg.norm(s, axis=1), rtol=1e-12)
    assert np.allclose(res.sigma_at_length_m, sl, rtol=1e-12) and res.tool_length_m == 0.15
    assert "predicted orientation sigma (3-D, the measured probe's frame): mean" in res.summary()
    assert "at 150 mm" in res.summary()
    # where the true probe points at the compensated joints against where the calibration says it points
    e = np.linalg.norm(_rot_errors_of(tm.predict(truth, res.q)[:, 3:], W), axis=1)
    ok = np.array([st in ("ok", "extrapolated") for st in res.target_status])
    assert ok.sum() >= 30 and np.sqrt(np.mean((e[ok] / res.sigma_rot_rad[ok]) ** 2)) < 1.2
    # the σ holds the white level (the probe's noise, which a compensated pose does not have); without it, the
    # parametric part alone is the size of the error
    param = np.sqrt(res.sigma_rot_rad ** 2 - np.sum(cm.fit["residual_sigma_rad"] ** 2))
    assert 0.6 < np.sqrt(np.mean((e[ok] / param[ok]) ** 2)) < 1.5


def _rot_errors_of(rv_true, rv_pred):
    return (Rotation.from_rotvec(rv_true) * Rotation.from_rotvec(rv_pred).inv()).as_rotvec()


def test_cli_compensate_program_of_a_6d_model(sim, tmp_path):
    _, _, _, te, cm = sim[3]
    atomic_write_json(tmp_path / "m.json", cm.to_dict())
    names = list(cm.robot.joint_names)
    with open(tmp_path / "prog.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(names)
        w.writerows(te.q[:8].tolist())
    tcp = ",".join(f"{v:.17g}" for v in cm.setups[cm.station(None)].reflector_m)  # the measured point
    rc, out, err = run_cli("compensate", "--model", tmp_path / "m.json", "--program", tmp_path / "prog.csv",
                           "--out", tmp_path / "c.csv", "--tool-length", "0.25", "--tcp", tcp)
    assert rc == 0, err
    assert "predicted orientation sigma (3-D, the measured probe's frame)" in out and "at 250 mm" in out
    rows = list(csv.DictReader(open(tmp_path / "c.csv")))
    assert all(float(r["sigma_rot_rad"]) > 0 and float(r["sigma_at_length_m"]) > 0 for r in rows)
    rc, out, err = run_cli("compensate", "--model", tmp_path / "m.json", "--program", tmp_path / "prog.csv",
                           "--out", tmp_path / "d.csv", "--tool-length", "250", "--tcp", tcp)
    assert rc == 2 and "--tool-length" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "d.csv").exists()
