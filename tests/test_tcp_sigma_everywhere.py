"""One σ at the TCP: identify, predict (API and command line), compensate, check and report state the same number
for the same model and configurations; design/evaluate's held term matches identify's."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from pin_kpi_oed.data.tool_header import ToolSpec
from pin_kpi_oed.model.noise import NoiseModel
from pin_kpi_oed.model.robot import load_robot
from pin_kpi_oed.model.tolerances import Tolerances
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.simulation.simulator import default_tracker_pose, random_truth, simulate

REFLECTOR_M = np.array([0.04, 0.0, 0.03])
TCP_M = np.array([0.0, 0.0, 0.15])
NOISE = NoiseModel(sigma_xyz_m=(2.5e-5,) * 3)


@pytest.fixture(scope="module")
def case():
    """A UR5 with errors on every joint parameter, measured at 40 random poses; its TCP 0.15 m from the reflector,
    5 working configurations in the data's tool header; identify with default options."""
    from pin_kpi_oed.identification.identify import identify

    rb = load_robot("ur5")
    truth = TrackerModel(rb, tracker_T_base=default_tracker_pose(rb), reflector_m=REFLECTOR_M, tcp_m=TCP_M,
                         noise=NOISE)
    rng = np.random.default_rng(4)
    Q, Qw = rb.random_q(rng, 40), rb.random_q(rng, 5)
    p = random_truth(truth, Tolerances(5e-4, 1e-3, reflector_m=1e-3), seed=4)
    data = simulate(truth, Q, p, seed=5)
    data.tool = ToolSpec(tool_frame=rb.tool_frame, tcp_m=TCP_M, q_work=Qw, source="simulated")
    nominal = TrackerModel(rb, reflector_m=REFLECTOR_M, tcp_m=TCP_M, noise=NOISE)
    res = identify(nominal, data)
    return res, res.calibrated_model(), Qw, (truth, p), data


def test_identify_states_the_models_sigma_at_the_tcp(case):
    """identify's printed TCP std is the calibrated model's at its TCP (discrepancy and held term included) at the
    tool header's working configurations, to 1e-12; it is far above the reflector's σ there (the held term)."""
    res, cm, Qw, _, _ = case
    at = cm.predict_tcp(Qw)
    assert res.tcp_std_m.shape == (5,)
    np.testing.assert_allclose(res.tcp_std_m, at.sigma_m, rtol=1e-12, atol=0)
    np.testing.assert_allclose(res.tcp_held_m, at.held_sigma_m, rtol=1e-12, atol=0)
    assert f"{np.mean(at.sigma_m) * 1e6:.2f} µm" in res.summary()
    refl = np.linalg.norm(cm.predict_with_sigma(Qw)[1], axis=1)
    assert np.all(at.sigma_m > 3 * refl)
    assert at.held_share > 0.5 and at.advice()


def test_tcp_sigma_at_the_reflector_is_predicts(case):
    """At the fitted reflector the σ at a point is predict's σ (the same terms, the same Jacobian), nothing held."""
    _, cm, Qw, _, _ = case
    refl = cm.setups[cm.station()].reflector_m
    at = cm.predict_tcp(Qw, tcp_m=refl)
    Y, sig, _ = cm.predict_with_sigma(Qw)
    np.testing.assert_allclose(at.sigma_m, np.linalg.norm(sig, axis=1), rtol=1e-12)
    np.testing.assert_allclose(at.position_m, Y, rtol=0, atol=1e-12)
    assert not at.held_names


def test_predict_at_tcp_api_and_command_line_agree(case, tmp_path):
    """predict --at tcp on the saved model writes the TCP and the σ the API gives, to 1e-12."""
    from pin_kpi_oed.cli.app import main
    from pin_kpi_oed.compensation.compensator import forward

    _, cm, Qw, _, _ = case
    cm.save(tmp_path / "model.json")
    with open(tmp_path / "work.csv", "w", newline="") as f:  # joint columns only: no measured positions
        w = csv.writer(f)
        w.writerow(cm.robot.joint_names)
        w.writerows([[repr(float(v)) for v in q] for q in Qw])
    assert main(["predict", "--model", str(tmp_path / "model.json"), "--data", str(tmp_path / "work.csv"),
                 "--out", str(tmp_path / "tcp.csv"), "--at", "tcp", "--quiet"]) == 0
    rows = list(csv.DictReader(open(tmp_path / "tcp.csv")))
    at = cm.predict_tcp(Qw)
    np.testing.assert_allclose([float(r["sigma_tcp"]) for r in rows], at.sigma_m, rtol=1e-12)
    np.testing.assert_allclose([float(r["sigma_held"]) for r in rows], at.held_sigma_m, rtol=1e-12)
    pos = np.array([[float(r[k]) for k in ("x_pred", "y_pred", "z_pred")] for r in rows])
    np.testing.assert_allclose(pos, forward(cm, Qw, frame="cell", tcp_m=TCP_M), rtol=0, atol=1e-12)


def test_compensate_states_the_same_sigma(case):
    """compensate's σ at the compensated joints is the one σ at the TCP there, in either frame."""
    from pin_kpi_oed.calibrated.tcp_sigma import tcp_sigma
    from pin_kpi_oed.compensation.compensator import CompensationOptions, compensate, forward
    from pin_kpi_oed.data.measurements import MeasurementSet
    from pin_kpi_oed.data.targets import TargetSet

    _, cm, Qw, _, _ = case
    for frame in ("cell", "base"):
        pos = forward(cm, Qw, frame=frame, tcp_m=TCP_M) + 2e-4
        ts = TargetSet([f"t{i}" for i in range(len(Qw))], pos, None, Qw, list(cm.robot.joint_names),
                       MeasurementSet(q=Qw, position_m=np.zeros((len(Qw), 3)),
                                           joint_names=list(cm.robot.joint_names)))
        r = compensate(cm, ts, CompensationOptions(frame=frame, tcp_m=TCP_M))
        at = tcp_sigma(cm, r.q, TCP_M, frame=frame)
        np.testing.assert_allclose(r.sigma_m, at.sigma_m, rtol=1e-12)
        np.testing.assert_allclose(r.tcp_unobservable_m, at.held_sigma_m, rtol=1e-12)


def test_compensate_does_not_call_a_held_dominated_tcp_ok(case):
    """A target whose TCP σ² is mostly the held parameters' is ``tcp_unmeasured`` and the result's status says "ok at
    the measured part ... measure the TCP" with the held and the total σ; at the fitted reflector nothing is held and
    every target is plainly ok."""
    from pin_kpi_oed.compensation.compensator import CompensationOptions, compensate, forward
    from pin_kpi_oed.compensation.result import HELD_SHARE_MAX
    from pin_kpi_oed.data.measurements import MeasurementSet
    from pin_kpi_oed.data.targets import TargetSet

    _, cm, _, _, data = case
    refl = cm.setups[cm.station()].reflector_m
    Qw = data.q[:6]  # measured configurations: inside the calibration's coverage, nothing extrapolated

    def run(tcp):
        pos = forward(cm, Qw, tcp_m=tcp) + 2e-4
        ts = TargetSet([f"t{i}" for i in range(len(Qw))], pos, None, Qw, list(cm.robot.joint_names),
                       MeasurementSet(q=Qw, position_m=np.zeros((len(Qw), 3)), joint_names=list(cm.robot.joint_names)))
        return compensate(cm, ts, CompensationOptions(tcp_m=tcp))

    r = run(TCP_M)
    held = r.tcp_unobservable_m ** 2 > HELD_SHARE_MAX * r.sigma_m ** 2
    assert held.any()
    assert r.target_status == ["tcp_unmeasured" if h else "ok" for h in held]
    h = np.sqrt(np.mean(r.tcp_unobservable_m[held] ** 2)) * 1e3
    assert r.success and r.status.startswith("ok at the measured part") and r.status.endswith("measure the TCP")
    assert f"({h:.3g} mm of " in r.status and "tcp unmeasured" in r.summary()
    at = run(refl)
    assert at.target_status == ["ok"] * len(Qw) and at.status == "ok" and np.all(at.tcp_unobservable_m == 0)


def test_check_and_report_state_the_same_sigma(case, tmp_path):
    """check's TCP σ at the working configurations is the re-registered model's σ at the TCP plus the
    registration's share (its held part equal to 1e-12); the certificate's is the model's at its working
    configurations."""
    from pin_kpi_oed.calibrated.model_file import load_model_file
    from pin_kpi_oed.calibrated.tcp_sigma import tcp_sigma
    from pin_kpi_oed.data.measurements import write_measurements
    from pin_kpi_oed.report.content import build_certificate
    from pin_kpi_oed.upkeep.check import CHECK_STATION, check_calibration

    res, cm, Qw, (truth, p), data = case
    rb = cm.robot
    fresh = simulate(truth, rb.random_q(np.random.default_rng(9), 12), p, seed=11)
    chk = check_calibration(cm, fresh, q_work=Qw)
    assert chk.verdict in ("holds", "setup_moved"), chk.summary()
    st = chk.model.setups[CHECK_STATION]
    import dataclasses
    at = tcp_sigma(chk.model.with_setup(CHECK_STATION, dataclasses.replace(st, sigma_scale=1.0)), Qw,
                   station=CHECK_STATION)
    np.testing.assert_allclose(chk.tcp_held_m, at.held_sigma_m, rtol=1e-12)
    assert np.all(chk.tcp_sigma_m >= at.sigma_m) and np.all(chk.tcp_sigma_m < 1.2 * at.sigma_m)
    assert "no check of this reflector sees" in chk.summary()

    cm.save(tmp_path / "model.json")
    write_measurements(data, tmp_path / "train.csv")
    write_measurements(simulate(truth, rb.random_q(np.random.default_rng(12), 20), p, seed=13),
                       tmp_path / "test.csv")
    cert = build_certificate(str(tmp_path / "model.json"), [str(tmp_path / "train.csv")],
                             str(tmp_path / "test.csv"), figures=False).data
    loaded = load_model_file(tmp_path / "model.json")
    t = cert["tcp_sigma"]
    assert t["where"] == "working configurations"
    np.testing.assert_allclose(t["sigma_m"], loaded.predict_tcp(Qw).sigma_m, rtol=1e-12)
    np.testing.assert_allclose(t["sigma_m"], res.tcp_std_m, rtol=1e-9)
    assert t["advice"] and "at the reflector; not at a TCP" in cert["parameters"]["identifiable"]["in_words"]


def test_evaluate_counts_the_held_term_as_identify_does(case):
    """score_design's held part of tr C_s (at the nominal model) equals identify's held σ at the same working
    configurations (at the fitted model) within the parameters' size (linearisation point), and its TCP σ
    includes it."""
    from pin_kpi_oed.oed.evaluate import score_design

    res, cm, Qw, _, data = case
    model = TrackerModel(cm.robot, tracker_T_base=cm.station_model()[0].tracker_T_base, reflector_m=REFLECTOR_M,
                         tcp_m=TCP_M, noise=NOISE)
    sc = score_design(model, data.q, Qw)
    assert sc.held_trace_m2 == pytest.approx(float(np.sum(res.tcp_held_m ** 2)), rel=0.02)
    assert sc.tcp_sigma_m == pytest.approx(np.sqrt((sc.trace_cs_m2 + sc.held_trace_m2) / len(Qw)), rel=1e-12)
    assert "no measurement of this reflector removes" in sc.summary()


def test_identify_command_states_the_sigma_of_the_model_file_it_writes(case, tmp_path, capsys):
    """The command fits the discrepancy after the parametric fit: the TCP std it prints (and its JSON) is the one the
    model file it writes gives at the tool header's working configurations (what predict --at tcp, check and report
    state), not the one before the discrepancy was fitted."""
    import json

    from pin_kpi_oed.calibrated.model_file import load_model_file
    from pin_kpi_oed.cli.app import main
    from pin_kpi_oed.data.measurements import write_measurements

    _, _, Qw, _, data = case
    write_measurements(data, tmp_path / "train.csv")
    assert main(["identify", "--robot", "ur5", "--data", str(tmp_path / "train.csv"), "--reflector",
                 ",".join(map(str, REFLECTOR_M)),
                 "--model-out", str(tmp_path / "m.json"), "--json", str(tmp_path / "r.json")]) == 0
    out = capsys.readouterr().out
    cm = load_model_file(tmp_path / "m.json")
    assert cm.discrepancy is not None  # the command's own discrepancy (auto: a white level at 40 poses)
    at = cm.predict_tcp(Qw)
    doc = json.loads((tmp_path / "r.json").read_text())
    np.testing.assert_allclose(doc["result"]["tcp_std_m"], at.sigma_m, rtol=1e-9, atol=0)
    assert f"predicted TCP std at 5 working configurations: mean {np.mean(at.sigma_m) * 1e6:.2f} µm" in out
