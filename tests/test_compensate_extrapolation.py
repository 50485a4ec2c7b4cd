"""Compensation outside the calibration's joint-space coverage: flagged ``extrapolated`` (never ``ok``), with the
widened σ ``predict`` gives for the same configuration (Python result, CSV, JSON, summary)."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from pin_kpi_oed.cli.app import main
from pin_kpi_oed.data.measurements import MeasurementSet, write_measurements
from pin_kpi_oed.data.targets import TargetSet
from pin_kpi_oed.compensation.compensator import CompensationOptions, compensate
from pin_kpi_oed.identification.identify import identify
from pin_kpi_oed.simulation.simulator import Tolerances, default_tracker_pose, random_truth, simulate
from pin_kpi_oed.model.noise import NoiseModel
from pin_kpi_oed.model.robot import load_robot
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.oed.identifiability import analyse

SIG = 1e-5
CENTRE = np.array([0.3, -1.2, 1.3, -0.6, 1.2, 0.4])  # a regular UR10 configuration (elbow and wrist bent)


@pytest.fixture(scope="module", params=["none", "auto", "on"])
def narrow(request):
    """A UR10 calibrated on 60 simulated poses within ±0.25 rad of one configuration: a noise-only model
    (σ with E C Eᵀ everywhere), the default discrepancy (``auto``: a white level at this size) and a Gaussian
    process (``on``: the universal-kriging term outside)."""
    robot = load_robot("ur10")
    tm = TrackerModel(robot, tracker_T_base=default_tracker_pose(robot), reflector_m=np.array([0.03, 0.02, 0.08]),
                      noise=NoiseModel(sigma_xyz_m=(SIG,) * 3))
    truth = random_truth(tm, Tolerances(5e-4, 1e-3), seed=4, only=[i for i in analyse(tm).base if i < 36])
    rng = np.random.default_rng(21)
    Q = CENTRE + rng.uniform(-0.25, 0.25, (60, 6))
    cm = identify(tm, simulate(tm, Q, truth, seed=22), discrepancy=request.param).calibrated_model()
    cm.tcp_m, cm.tool_source = cm.setups[cm.station(None)].reflector_m.copy(), "the test: the TCP is the reflector"
    Q_in = CENTRE + np.array([0.05, -0.04, 0.03, 0.05, -0.05, 0.02])
    Q_out = CENTRE + np.array([-2.2, 0.7, -2.4, 1.5, 0.3, 1.0])  # far from every training configuration
    Qt = np.vstack([Q_in, Q_out])
    held = simulate(tm, Qt, truth, seed=23)  # where the true robot puts the reflector: reachable targets
    return robot, cm, Qt, held


def test_target_outside_the_coverage_is_extrapolated_with_the_predict_sigma(narrow, tmp_path, capsys):
    robot, cm, Qt, held = narrow
    aux = MeasurementSet(robot.joint_names, np.zeros((2, 6)), np.full((2, 3), np.nan))
    ts = TargetSet(["inside", "far"], held.position_m, None, Qt, list(robot.joint_names), aux, "sim")
    res = compensate(cm, ts, CompensationOptions(frame="cell"))
    assert res.residual_m.max() < 1e-8 and res.branch_step_rad.max() < 0.05  # both reached on their branch
    assert res.target_status == ["ok", "extrapolated"] and not res.success
    assert res.extrapolation.tolist() == [False, True]
    # the σ is predict's at the compensated configuration (one function), widened far from the training
    _, sig, extra = cm.predict_with_sigma(res.q, station=res.station)
    assert extra.tolist() == [False, True]
    assert res.sigma_m == pytest.approx(np.linalg.norm(sig, axis=1), rel=1e-12)
    assert res.sigma_m[1] >= 3.0 * res.sigma_m[0], res.sigma_m
    with capsys.disabled():
        kind = "none" if cm.discrepancy is None else cm.discrepancy.kind
        print(f"\n[compensate extrapolated, discrepancy {kind}] sigma inside {res.sigma_m[0] * 1e3:.4f} mm, "
              f"far outside {res.sigma_m[1] * 1e3:.4f} mm")
    summary = res.summary()
    assert "1 ok, 1 extrapolated" in summary and "1 of them status extrapolated, not ok" in summary
    assert "measure poses near them" in summary and "design --given" in summary
    # the command line: the CSV and JSON say extrapolated; predict gives the same σ for the same configuration
    cm.save(tmp_path / "m.json")
    with open(tmp_path / "t.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["name", "x", "y", "z"] + list(robot.joint_names))
        for n, y, q in zip(ts.names, held.position_m, Qt):
            w.writerow([n] + [f"{v:.17g}" for v in (*y, *q)])
    assert main(["compensate", "--model", str(tmp_path / "m.json"), "--targets", str(tmp_path / "t.csv"),
                 "--out", str(tmp_path / "j.csv"), "--json", str(tmp_path / "j.json")]) == 0
    assert "1 ok, 1 extrapolated" in capsys.readouterr().out
    rows = list(csv.DictReader(open(tmp_path / "j.csv")))
    assert [r["status"] for r in rows] == ["ok", "extrapolated"] and [r["extrapolation"] for r in rows] == ["0", "1"]
    assert json.loads((tmp_path / "j.json").read_text())["target_status"] == ["ok", "extrapolated"]
    Qc = np.array([[float(r[j]) for j in robot.joint_names] for r in rows])
    write_measurements(MeasurementSet(robot.joint_names, Qc, held.position_m), tmp_path / "q.csv")
    assert main(["predict", "--model", str(tmp_path / "m.json"), "--data", str(tmp_path / "q.csv"),
                 "--out", str(tmp_path / "p.csv")]) == 0
    pred = list(csv.DictReader(open(tmp_path / "p.csv")))
    s_pred = np.array([np.linalg.norm([float(r[f"sigma_{a}"]) for a in "xyz"]) for r in pred])
    assert [float(r["extrapolation"]) for r in pred] == [0.0, 1.0]
    assert [float(r["sigma_m"]) for r in rows] == pytest.approx(s_pred, rel=1e-9)
