"""A new session registered or refused for the true reason: the calibration's residual level in the model file,
the registration gate against it, and the tested cause of a poor registration (effects extrapolating, coverage)."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from pin_kpi_oed import NoiseModel, TrackerModel, load_robot
from pin_kpi_oed.cli.app import main
from pin_kpi_oed.data.measurements import MeasurementSet, write_measurements
from pin_kpi_oed.effects.library import GearHarmonic
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.identification.identify import identify
from pin_kpi_oed.calibrated.model_file import load_model_file
from pin_kpi_oed.identification.problem import align_data
from pin_kpi_oed.upkeep.registration_check import (coverage_share, reference_sigma_m, registration_gates,
                                                            uncovered_ranges)
from pin_kpi_oed.simulation.simulator import Tolerances, random_truth, simulate
from pin_kpi_oed.upkeep.transfer import register_setup
from pin_kpi_oed.oed.identifiability import analyse

NOISE = 1e-4  # m: the sessions' true noise per axis; the models state 1e-6 m (the default), as without --sigma
REFLECTOR = np.array([0.0, 0.0, 0.1])
T_A = pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, 0.5), np.array([2.0, 0.5, -0.3]))
T_C = pin.SE3(pin.rpy.rpyToMatrix(0.05, -0.02, 2.0), np.array([-1.5, 2.0, 0.1]))


def _tracker(robot, T, sigma=NOISE):
    return TrackerModel(robot, tracker_T_base=T, reflector_m=REFLECTOR, noise=NoiseModel(sigma_xyz_m=(sigma,) * 3))


def _no_sigma(ms: MeasurementSet) -> MeasurementSet:
    return dataclasses.replace(ms, sigma_m=None)


@pytest.fixture(scope="module")
def case():
    """A UR10 with random geometric errors: session A (80 rows, shoulder in [-1, 0] rad), session C (another
    tracker pose, 120 rows over the whole workspace), both with 0.1 mm noise and no sigma columns."""
    robot = load_robot("ur10")
    mA = _tracker(robot, T_A)
    truth = random_truth(mA, Tolerances(5e-4, 1e-3), seed=4, only=[i for i in analyse(mA).base if i < 36])
    QA = robot.random_q(np.random.default_rng(5), 80)
    QA[:, 0] = np.random.default_rng(6).uniform(-1.0, 0.0, 80)
    dA = _no_sigma(simulate(mA, QA, truth, seed=7, source="A.csv"))
    QC = robot.random_q(np.random.default_rng(8), 120)
    dC = _no_sigma(simulate(_tracker(robot, T_C), QC, truth, seed=9, source="C.csv"))
    nominal = TrackerModel(robot, reflector_m=REFLECTOR)  # default noise 1e-6 m: far below the real level
    cm = identify(nominal, dA, discrepancy="none").calibrated_model()
    return robot, dA, dC, cm


def test_model_file_records_the_residual_level(case, tmp_path):
    robot, dA, _, cm = case
    level = cm.residual_sigma_m
    assert level is not None and level.shape == (3,)
    assert np.all(np.abs(level / NOISE - 1) < 0.2), level          # the sessions' true noise, not the stated 1e-6
    assert np.all(level > np.asarray(cm.noise.sigma_xyz_m) * 50)
    plain = identify(TrackerModel(robot, reflector_m=REFLECTOR), dA, discrepancy="none")
    naive = np.sqrt(np.mean(plain.residuals_m ** 2, axis=0))
    assert np.all(level > naive)                                   # corrected for the fitted parameters (3m - k)
    path = tmp_path / "m.json"
    cm.save(path)
    assert np.allclose(load_model_file(path).residual_sigma_m, level, rtol=0, atol=0)
    d = json.loads(path.read_text())
    d["fit"]["residual_sigma_m"] = [1e-4, -1e-4, 1e-4]
    path.write_text(json.dumps(d))
    with pytest.raises(InputError, match="fit.residual_sigma_m"):
        load_model_file(path)
    d["fit"]["residual_sigma_m"] = [1e-4, 1e-4]
    path.write_text(json.dumps(d))
    with pytest.raises(InputError, match="fit.residual_sigma_m"):
        load_model_file(path)


def test_register_compares_the_new_session_with_the_residual_level(case, tmp_path, capsys):
    """Same robot, another tracker pose: registered (without the level it was refused at ~100x the stated
    noise); the σ factor then carries the session's level into predict (standardised RMS about 1)."""
    robot, dA, dC, cm = case
    m1, m2, pred = tmp_path / "m.json", tmp_path / "m2.json", tmp_path / "pred.csv"
    cm.save(m1)
    write_measurements(dC.subset(np.arange(40)), tmp_path / "reg.csv")
    write_measurements(dC.subset(np.arange(40, 120)), tmp_path / "held.csv")
    assert main(["register", "--model", str(m1), "--data", str(tmp_path / "reg.csv"), "--model-out", str(m2)]) == 0
    assert ": good" in capsys.readouterr().out
    assert main(["predict", "--model", str(m2), "--data", str(tmp_path / "held.csv"), "--out", str(pred)]) == 0
    p = np.genfromtxt(pred, delimiter=",", names=True)
    z = np.c_[(p["x"] - p["x_pred"]) / p["sigma_x"], (p["y"] - p["y_pred"]) / p["sigma_y"],
              (p["z"] - p["z_pred"]) / p["sigma_z"]]
    assert 0.67 < np.sqrt(np.mean(z ** 2)) < 1.5
    # the same file without its residual level: compared with the stated noise, refused as before
    old = json.loads(m1.read_text())
    del old["fit"]["residual_sigma_m"]
    m0 = tmp_path / "m0.json"
    m0.write_text(json.dumps(old))
    assert main(["register", "--model", str(m0), "--data", str(tmp_path / "reg.csv"), "--model-out",
                 str(tmp_path / "m3.json")]) == 2
    assert "POOR" in capsys.readouterr().err and not (tmp_path / "m3.json").exists()


def test_data_of_another_robot_is_still_refused(case):
    """Rows whose joint columns are permuted (the wrong joint order): refused against the residual level, with
    the generic cause (the geometry alone fits no better: nothing to blame on the model's terms)."""
    robot, _, dC, cm = case
    sub = dC.subset(np.arange(40))
    bad = dataclasses.replace(sub, q=sub.q[:, [1, 0, 2, 3, 5, 4]].copy())
    res = register_setup(cm, bad, station="C")
    (gate,) = registration_gates(res, bad, cm, register=register_setup)
    assert gate.poor and "another robot's or another session's data" in gate.line()


def test_poor_registration_names_extrapolating_effects(case):
    """A model whose effect (a 1 mrad gear harmonic on the shoulder, absent from the robot) is what the new rows
    cannot fit: the cause names the effect, the geometry-only fit and the fixes, not "another robot"."""
    robot, _, dC, cm = case
    eff = GearHarmonic(robot, joints=[robot.joint_names[1]])
    bad = dataclasses.replace(cm, effects=[eff], thetas=[np.full(len(eff.param_names()), 1e-3)])
    sub = dC.subset(np.arange(40))
    res = register_setup(bad, sub, station="C")
    assert res.poor and res.to_dict()["poor"] and "gear_harmonic extrapolates" in res.summary()  # the API flags it
    (gate,) = registration_gates(res, sub, bad, register=register_setup)
    assert gate.line() == res.quality[0].line()
    line = gate.line()
    assert gate.poor and "gear_harmonic extrapolates" in line and "geometry alone registers" in line
    assert "diagnose effects=[]" in line and "transfer_prior_rad=1e-4" in line and "another robot" not in line
    from pin_kpi_oed.cli.flags import in_flags  # the command line says its options

    assert "(diagnose --effects none, or identify without --effects)" in in_flags(line)
    assert "(diagnose --term-prior 1e-4)" in in_flags(line)
    good = register_setup(cm, sub, station="C")
    assert not good.poor and not good.quality[0].poor and ": good" in good.summary()


def test_reference_level_and_coverage_helpers(case):
    robot, dA, dC, cm = case
    ref = reference_sigma_m(cm)
    assert np.allclose(ref, cm.residual_sigma_m)                  # the level, not the stated 1e-6 m
    assert np.allclose(reference_sigma_m(dataclasses.replace(cm, fit={})), cm.noise.sigma_xyz_m)
    share = coverage_share(cm, dC.q)                               # every model keeps its joint coverage
    assert share is not None and 0.0 <= share < coverage_share(cm, dA.q)


def test_coverage_named_with_a_discrepancy(case):
    """A model with a discrepancy keeps its training configurations: the rows beyond the shoulder's measured range
    [-1, 0] rad are named with that range."""
    robot, dA, dC, _ = case
    cm = identify(TrackerModel(robot, reflector_m=REFLECTOR), dA, discrepancy="on").calibrated_model()
    inside = dC.q[:, 0] < 0.0
    share = coverage_share(cm, dC.q)
    assert share is not None and share < coverage_share(cm, dA.q)
    ranges = uncovered_ranges(cm, dC.q)
    assert inside.any() and ranges and ranges[0].startswith(robot.joint_names[0])
    lo, hi = (float(v) for v in ranges[0].split()[1].split(".."))
    n_out, m = (int(v) for v in ranges[0].split("(")[1].split(" rows")[0].split(" of "))
    wrapped = np.mod(dC.q[:, 0] + np.pi, 2 * np.pi) - np.pi
    far = int(np.sum((wrapped < -1.06) | (wrapped > 0.06)))          # beyond the measured [-1, 0] rad and the tolerance
    assert m == len(dC) and n_out >= far > 0 and (lo < -1.0 or hi > 0.0)
    assert robot.q_lower[0] <= lo <= hi <= robot.q_upper[0]          # the rows' own values, within the limits


_here = Path(__file__).resolve()
IPA = next((p / "shared" / "data" / "ipa_ur10" for p in (_here.parents[2], _here.parents[3])
            if (p / "shared" / "data" / "ipa_ur10").is_dir()), _here.parents[2] / "shared" / "data" / "ipa_ur10")


#: (joint index, order) of the transmission-error terms diagnose selected on all of Series B (seed 0, 5-fold).
SERIES_B_TERMS = [(0, k) for k in (1, 6, 9, 15, 18, 19, 21, 25, 29, 30)] \
    + [(1, k) for k in (2, 3, 5, 6, 10, 15, 17, 23, 24, 29, 33, 39)] \
    + [(2, k) for k in (3, 6, 9, 10, 11, 13, 14, 15, 17, 21, 22, 23, 25, 27, 30, 33, 34, 40)] \
    + [(3, k) for k in (6, 9, 11, 15, 18, 23, 24)] + [(4, k) for k in (3, 8, 16, 18, 22)]


@pytest.mark.skipif(not IPA.is_dir(), reason=f"IPA data not found at {IPA}")
def test_real_ur10_series_b_to_c_refused_for_the_extrapolating_terms_geometry_registered():
    """600 rows of the real UR10's Series B, 60 of Series C: a model with the transmission-error terms diagnose selects
    on B is refused on C naming them and the geometry-only fix (the geometry alone fits C's rows better); the
    geometry-only model of the same rows, written without the tracker's noise, is registered (compared with its
    residual level, not the default noise)."""
    from pin_kpi_oed.data.ipa import import_ipa
    from pin_kpi_oed.effects.periodic import TransmissionError

    robot = load_robot("ur10")
    nominal = TrackerModel(robot, reflector_m=np.array([0.0, 0.0, 0.109]))

    def rows(series: str, n: int, seed: int) -> MeasurementSet:
        ms = import_ipa(IPA / f"Series_{series}")
        ms = MeasurementSet(ms.joint_names, ms.q, ms.position_m, source=f"{series}.csv")
        return ms.subset(np.sort(np.random.default_rng(seed).permutation(len(ms))[:n]))

    B, C = rows("B", 600, 0), rows("C", 60, 1)
    geo = identify(nominal, B, discrepancy="none").calibrated_model()
    assert geo.residual_sigma_m is not None and np.all(geo.residual_sigma_m > 1e-4)   # 0.2-0.3 mm, not 1e-6 m
    (gate,) = registration_gates(register_setup(geo, C, station="C"), C, geo, register=register_setup)
    assert not gate.poor, gate.line()
    te = TransmissionError(robot, pairs=[(robot.joint_names[j], k) for j, k in SERIES_B_TERMS])
    cm = identify(nominal, B, effects=[te], discrepancy="none").calibrated_model()
    (gate,) = registration_gates(register_setup(cm, C, station="C"), C, cm, register=register_setup)
    line = gate.line()
    assert gate.poor and "transmission_error extrapolates" in line and "effects=[]" in line, line


def test_diagnose_effects_none_writes_a_geometry_only_model(case, tmp_path, capsys):
    """The fix a refusal names: diagnose --effects none --model-out writes geometry (+ discrepancy) and no effect,
    records its residual level, and says that no effect was tried rather than that none explains the gap."""
    robot, dA, _, _ = case
    write_measurements(dA, tmp_path / "A.csv")
    m = tmp_path / "m.json"
    assert main(["diagnose", "--robot", "ur10", "--train", str(tmp_path / "A.csv"), "--kfold", "3", "--reflector",
                 "0,0,0.1", "--sigma", "1e-5", "--effects", "none", "--discrepancy", "none",
                 "--model-out", str(m)]) == 0
    out = capsys.readouterr().out
    cm = load_model_file(m)
    assert cm.effects == [] and cm.residual_sigma_m is not None
    assert np.all(np.abs(cm.residual_sigma_m / NOISE - 1) < 0.3)
    assert "no candidate effect was tried (--effects none" in out and "not any modelled effect" not in out


def test_registration_gate_reads_the_robots_joint_columns_of_a_wider_file(case):
    """A file read without a robot keeps its other numeric columns beside the joints (the IPA files' goal_* and
    sigma_euler_*): the gate takes the robot's joint columns, as the registration does, and judges the same."""
    robot, _, dC, cm = case
    sub = dC.subset(np.arange(40))
    wide = dataclasses.replace(sub, joint_names=[*sub.joint_names, "goal_x"], q=np.c_[sub.q, np.zeros(len(sub))])
    narrow, widened = register_setup(cm, sub, station="C"), register_setup(cm, wide, station="C")
    assert widened.quality[0].line() == narrow.quality[0].line()


def test_registration_keeps_the_calibrations_reflector_when_the_rows_leave_it_free(case):
    """Rows whose flange axis stays within 0.4° of one direction leave the reflector's offset along it free against
    the tracker translation: the registration says so in one line and keeps the calibration's reflector; rows that
    turn the flange register a reflector of their own (as before), with no note."""
    robot, _, dC, cm = case
    rng = np.random.default_rng(21)
    flat = robot.random_q(rng, 60)
    flat[:, 3] = np.mod(-np.pi / 2 - flat[:, 1] - flat[:, 2] + np.pi, 2 * np.pi) - np.pi   # tool z straight down,
    flat[:, 4] = -np.pi / 2
    flat[:, 3:5] += rng.uniform(-0.005, 0.005, (60, 2))                                  # within 0.4°
    axis = np.array([robot.oMtool(q).rotation[:, 2] for q in flat])
    assert np.all(axis[:, 2] < -np.cos(np.deg2rad(0.5)))
    truth = random_truth(_tracker(robot, T_A), Tolerances(5e-4, 1e-3), seed=4,
                         only=[i for i in analyse(_tracker(robot, T_A)).base if i < 36])
    reg = _no_sigma(simulate(_tracker(robot, T_C), flat, truth, seed=22, source="flat.csv"))
    cal = cm.setups[cm.default_station].reflector_m
    rr = register_setup(cm, reg, station="new")
    assert len(rr.notes) == 1 and "reflector is poorly determined by these 60 rows" in rr.notes[0]
    assert "flat.csv" in rr.notes[0] and "calibration's reflector is kept" in rr.notes[0]
    assert np.array_equal(rr.setups["new"].reflector_m, cal) and rr.notes[0] in rr.summary()
    assert rr.to_dict()["notes"] == rr.notes
    # the kept reflector predicts rows of every flange orientation of that session
    Qh = align_data(robot, dC)
    err = np.linalg.norm(dC.position_m - rr.model.predict(Qh, dC, station="new"), axis=1)
    assert np.sqrt(np.mean(err ** 2)) < 5 * NOISE
    spread = register_setup(cm, dC.subset(np.arange(60)), station="new")
    assert not spread.notes and not np.array_equal(spread.setups["new"].reflector_m, cal)
