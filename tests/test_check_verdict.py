"""The check's verdict by the tolerance at the working TCPs: a significant change below it holds (with its size ± σ),
one above it is named and re-fitted (exit 1), residuals far beyond the model's σ everywhere re-calibrate (exit 3),
a moved tracker is re-registered (exit 1); the exit codes of the command; a model file's K-fold fields range-checked
(one line naming the file and the field, exit 2)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from pin_kpi_oed import load_robot
from pin_kpi_oed.calibrated.model_file import load_model_file
from pin_kpi_oed.cli.app import main
from pin_kpi_oed.data.measurements import MeasurementSet, write_measurements
from pin_kpi_oed.discrepancy.gp import Discrepancy
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.studies.check_events import simulated_model
from pin_kpi_oed.upkeep.check import CheckResult, check_calibration, shown_above, sidak

SIGMA = 2e-5
TOL = 1e-4


@pytest.fixture(scope="module")
def setting():
    rb = load_robot("ur10")
    rng = np.random.default_rng(0)
    qw = 0.5 * rng.uniform(rb.q_lower, rb.q_upper, size=(5, rb.nq))
    model = simulated_model(rb, qw, SIGMA, 0)
    Qc = 0.7 * rng.uniform(rb.q_lower, rb.q_upper, size=(12, rb.nq))
    return rb, model, Qc


def _offset_truth(model, joint: int, tcp_m: float):
    """The model with joint ``joint``'s offset changed so that the working TCPs move by ``tcp_m`` RMS (base frame)."""
    wm, p = model.station_model()
    lin, ang = wm.joint_axes
    cols = np.arange(6 * joint, 6 * joint + 6)
    d = np.r_[lin[joint], ang[joint]]
    E = wm.kpi_jacobian(p, model.q_work)[:, cols]
    per = np.linalg.norm(E @ d) / np.sqrt(len(model.q_work))
    jp = model.joint_p.copy()
    jp[cols] += d * tcp_m / per
    return dataclasses.replace(model, joint_p=jp)


def _rows(model, truth, Q, seed: int, noise: float = SIGMA) -> MeasurementSet:
    rng = np.random.default_rng(seed)
    Y = truth.predict(Q, station="A") + rng.normal(size=(len(Q), 3)) * noise
    return MeasurementSet(list(model.robot.joint_names), Q, Y, source="check rows")


def test_sidak_and_the_decision_rule():
    assert sidak(0.05) == pytest.approx(1 - 0.95 ** 0.5)
    assert 1 - (1 - sidak(0.05, 3)) ** 3 == pytest.approx(0.05)
    assert shown_above(0.2e-3, 0.01e-3, TOL, 0.05) and not shown_above(0.11e-3, 0.01e-3, TOL, 0.05)
    assert not shown_above(float("nan"), 0.0, TOL, 0.05)


def test_a_significant_change_below_the_tolerance_holds_and_says_so(setting):
    rb, model, Qc = setting
    truth = _offset_truth(model, 2, 0.4 * TOL)
    r = check_calibration(model, _rows(model, truth, Qc, 1), tolerance_m=TOL)
    assert r.chi2 > r.threshold                                   # detected: significant ...
    assert r.verdict == "holds" and r.exit_code == 0              # ... but it does not matter
    assert r.group.startswith(rb.joint_names[2]) and r.change_tcp_m < TOL
    assert r.change_tcp_m == pytest.approx(0.4 * TOL, rel=0.35)
    line = r.summary()
    assert line.startswith("check: holds (a change of") and "not shown above the tolerance" in line
    assert "\n" not in line


def test_a_change_above_the_tolerance_is_named_and_refitted(setting):
    rb, model, Qc = setting
    truth = _offset_truth(model, 2, 3 * TOL)
    r = check_calibration(model, _rows(model, truth, Qc, 2), tolerance_m=TOL)
    assert r.verdict == "robot_changed" and r.exit_code == 1 and r.group.startswith(rb.joint_names[2])
    assert r.change_tcp_m - 1.645 * r.change_tcp_sigma_m > TOL
    assert r.change_tcp_m == pytest.approx(3 * TOL, rel=0.1)
    # the re-fit against a re-calibration: the calibration's own TCP σ in both, the change's error in the re-fit's
    assert r.recalibrate_error_m <= r.refit_error_m <= 1.1 * r.recalibrate_error_m
    assert "re-fitted (expected TCP error" in r.summary() and "above the tolerance" in r.summary()


def test_residuals_far_beyond_the_sigma_everywhere_re_calibrate(setting):
    rb, model, Qc = setting
    r = check_calibration(model, _rows(model, model, Qc, 3, noise=8 * SIGMA), tolerance_m=TOL)
    assert r.verdict in ("discrepancy_level", "recalibrate") and r.exit_code == 3
    assert r.excess_tcp_m > TOL and "re-calibrate" in r.summary()
    # the same residuals against a tolerance they do not reach: holds, the excess stated
    r2 = check_calibration(model, _rows(model, model, Qc, 3, noise=8 * SIGMA), tolerance_m=10 * TOL)
    assert r2.verdict == "holds" and "no group explains" in r2.note


def test_command_exit_codes(setting, tmp_path, capsys):
    import pinocchio as pin

    rb, model, Qc = setting
    mp = tmp_path / "model.json"
    model.save(mp)
    st = model.setups["A"]
    moved = model.with_setup("A", dataclasses.replace(st, tracker_T_base=(
        pin.SE3(st.tracker_T_base) * pin.exp6(np.r_[0.01, 0.0, 0.0, 0.0, 0.0, 0.005])).homogeneous))
    cases = {"holds": (model, 0), "moved": (moved, 1), "changed": (_offset_truth(model, 2, 3 * TOL), 1)}
    for name, (truth, code) in cases.items():
        data = _rows(model, truth, Qc, 4)
        path = tmp_path / f"{name}.csv"
        write_measurements(data, path)
        out = tmp_path / f"{name}_model.json"
        got = main(["check", "--model", str(mp), "--data", str(path), "--model-out", str(out), "--json",
                    str(tmp_path / f"{name}.json")])
        assert got == code, (name, capsys.readouterr().out)
        assert json.loads((tmp_path / f"{name}.json").read_text())["exit_code"] == code
        assert out.exists()
    noisy = tmp_path / "noisy.csv"
    write_measurements(_rows(model, model, Qc, 3, noise=8 * SIGMA), noisy)
    assert main(["check", "--model", str(mp), "--data", str(noisy)]) == 3
    capsys.readouterr()
    with pytest.raises(SystemExit):
        main(["check", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "exit codes: 0" in text and "3 re-calibrate" in text and "2 bad input" in text


@pytest.mark.parametrize("field,value", [("z_rms", 60.0), ("z_rms", 0.0), ("z_rms", "1.0"), ("z_kurtosis", None),
                                         ("z_kurtosis", -3.0), ("dof_factor", -1.0)])
def test_a_model_files_kfold_fields_are_range_checked(setting, tmp_path, capsys, field, value):
    rb, model, Qc = setting
    disc = Discrepancy("white", list(rb.joint_names), np.full(3, SIGMA), np.zeros(3), 1.0,
                       cv={"z_rms": 1.05, "z_kurtosis": 0.8, "dof_factor": 1.02})
    good = dataclasses.replace(model, discrepancy=disc)
    d = good.to_dict()
    path = tmp_path / "m.json"
    path.write_text(json.dumps(d))
    assert load_model_file(path).discrepancy.cv["z_rms"] == 1.05          # the written file reads back
    d["discrepancy"]["cv"][field] = float("nan") if value is None else value
    path.write_text(json.dumps(d).replace("NaN", "NaN"))
    with pytest.raises(InputError) as exc:
        load_model_file(path)
    assert str(path) in str(exc.value) and f"cv.{field}" in str(exc.value)
    write_measurements(_rows(model, model, Qc, 5), tmp_path / "rows.csv")
    assert main(["check", "--model", str(path), "--data", str(tmp_path / "rows.csv")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"cv.{field}" in err and "Traceback" not in err


def test_the_changes_sigma_at_the_tcp_matches_monte_carlo(setting):
    """The σ of the change's size at the TCP against the spread of the size over seeded rows (a tool change: the
    same displacement at every working TCP; a joint offset)."""
    rb, model, Qc = setting
    st = model.setups["A"]
    tool = dataclasses.replace(model, setups={"A": dataclasses.replace(st, reflector_m=st.reflector_m
                                                                       + np.array([0.0, 2e-4, 1e-4]))})
    for truth, name in ((tool, "tool"), (_offset_truth(model, 3, 2 * TOL), rb.joint_names[3])):
        res = [check_calibration(model, _rows(model, truth, Qc, 50 + s), tolerance_m=TOL) for s in range(16)]
        assert all(r.group.startswith(name) for r in res)
        sizes = np.array([r.change_tcp_m for r in res])
        sd = np.median([r.change_tcp_sigma_m for r in res])
        assert 0.5 < np.std(sizes, ddof=1) / sd < 1.8, (name, np.std(sizes, ddof=1), sd)


def test_a_change_the_check_cannot_size_says_re_calibrate_without_a_size(setting, tmp_path, capsys):
    """Changes far beyond the linear range (an elbow offset moving the TCP by 6 mm, 20 mm, 0.1 m) and a tool change
    the rows fit exactly but no calibrated robot has (20 mm): *re-calibrate*, "the check cannot size this change", no
    size in mm; a change of 3 τ on the same rows is still sized."""
    rb, model, Qc = setting
    for tcp_m in (6e-3, 0.02, 0.1):
        r = check_calibration(model, _rows(model, _offset_truth(model, 2, tcp_m), Qc, 7), tolerance_m=TOL)
        assert r.verdict == "recalibrate" and r.exit_code == 3 and not r.sized, (tcp_m, r.summary())
        assert np.isnan(r.change_tcp_m) and np.isnan(r.refit_error_m) and np.isnan(r.excess_tcp_m)
        line = r.summary()
        assert "the check cannot size this change" in line and " mm RMS at the TCP" not in line, line
        assert "mm beyond it" not in line, line
    st = model.setups["A"]
    tool = dataclasses.replace(model, setups={"A": dataclasses.replace(st, reflector_m=st.reflector_m
                                                                       + np.array([0.0, 0.02, 0.0]))})
    r2 = check_calibration(model, _rows(model, tool, Qc, 8), tolerance_m=TOL)
    assert r2.verdict == "recalibrate" and not r2.sized and "cannot size" in r2.summary(), r2.summary()
    assert "5 mm" in r2.summary() and " mm RMS at the TCP" not in r2.summary()
    assert r2.to_dict()["sized"] is False
    ok = check_calibration(model, _rows(model, _offset_truth(model, 2, 3 * TOL), Qc, 2), tolerance_m=TOL)
    assert ok.sized and ok.verdict == "robot_changed"


def test_the_action_line_states_the_held_part_it_leaves_out():
    """The re-fit / re-calibration comparison leaves out the TCP σ of the held joint placements (common to both):
    the line says how much, as the RMS over the working configurations; nothing is said when there is none."""
    base = dict(n_rows=12, dof=30, alpha=0.01, chi2=80.0, threshold=50.0, p_value=1e-6, setup_shift_m=0.0,
                setup_distance=1.0, group="joint_a6 placement", refit_error_m=3.2e-5, recalibrate_error_m=2.8e-5)
    held = np.array([4e-4, 5e-4, 6e-4])
    r = CheckResult(verdict="recalibrate", tcp_held_m=held, **base)
    rms = np.sqrt(np.mean(held ** 2)) * 1e3
    text = r.action_text()
    assert "0.028 mm against the re-fit's 0.032 mm" in text
    assert f"the {rms:.3f} mm of the TCP's sigma that no measurement determines" in text
    assert "same either way and left out" in text
    assert "left out" in CheckResult(verdict="robot_changed", tcp_held_m=held, **base).action_text()
    assert "left out" not in CheckResult(verdict="recalibrate", tcp_held_m=np.zeros(3), **base).action_text()
