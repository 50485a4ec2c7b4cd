"""One set of defaults: the command line and the Python API with a cell take the cell's noise and give the same
numbers; the robust loss switches only where outliers are; a model saved through the API keeps its tool (TCP,
working configurations) and compensate refuses a model without a TCP; the fit-quality verdict flags a singular
covariance; the design file's default design is one rule for every command."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

import pin_kpi_oed as pko
from pin_kpi_oed.cell.cell import CELL_DIR
from pin_kpi_oed.cli.app import main
from pin_kpi_oed.data.measurements import write_measurements
from pin_kpi_oed.data.targets import TargetSet
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.compensation.compensator import CompensationOptions, compensate, forward
from pin_kpi_oed.simulation.simulator import default_tracker_pose, random_truth, simulate

NOISE = 2e-5


@pytest.fixture(scope="module")
def cell_files(tmp_path_factory) -> Path:
    """The KR 15 cell with a stated noise of 20 µm (and a copy without a noise field); 35 training and 40 held-out
    rows of a robot with errors on every joint placement, measured with that noise, written without sigma columns
    (as a tracker's export: the noise level is the cell's)."""
    d = tmp_path_factory.mktemp("defaults")
    doc = yaml.safe_load((Path(CELL_DIR) / "kr15.yaml").read_text())
    doc["robot"] = str(pko.load_cell("kr15").robot.urdf_path)
    for key in ("environment",):
        doc.pop(key, None)
    doc["noise"] = {"sigma_xyz_m": [NOISE] * 3}
    (d / "cell.yaml").write_text(yaml.safe_dump(doc))
    doc.pop("noise")
    (d / "cell_nonoise.yaml").write_text(yaml.safe_dump(doc))
    cell = pko.load_cell(str(d / "cell.yaml"))
    model = cell.tracker_model()
    truth = random_truth(model, seed=5)
    rng = np.random.default_rng(6)
    for name, m, seed in (("tr.csv", 35, 7), ("te.csv", 40, 8)):
        write_measurements(simulate(model, cell.robot.random_q(rng, m), truth, seed=seed, record_sigma=False),
                           d / name)
    return d


def test_identify_with_a_cell_takes_its_noise_and_equals_the_api(cell_files, capsys):
    """identify --cell: the cell's noise (χ² tested, covariance not scaled), the TCP σ at the cell's working
    configuration (so labelled); the Python API with cell.tracker_model() gives the same numbers to 1e-12."""
    d = cell_files
    assert main(["identify", "--cell", str(d / "cell.yaml"), "--data", str(d / "tr.csv"), "--validate",
                 str(d / "te.csv"), "--json", str(d / "cli.json")]) == 0
    out = capsys.readouterr().out
    assert f"noise level: the noise of --cell {d / 'cell.yaml'}" in out and "noise level unknown" not in out
    assert "predicted TCP std at 1 working configuration:" in out
    doc = json.loads((d / "cli.json").read_text())
    res, q = doc["result"], doc["fit_quality"]
    assert not res["covariance_scaled"] and q["noise_known"] and q["chi2_interval"] is not None
    assert res["loss"] == "linear" and res["outliers"] == [] and res["tcp_std_at"] == "working"
    cell = pko.load_cell(str(d / "cell.yaml"))
    train, held = pko.read_measurements(str(d / "tr.csv")), pko.read_measurements(str(d / "te.csv"))
    api = pko.identify(cell.tracker_model(), train, Q_work=cell.q_work)
    assert [p["name"] for p in res["parameters"]] == api.names
    assert np.allclose([p["value"] for p in res["parameters"]], api.values, rtol=0, atol=1e-12)
    assert np.allclose([p["std"] for p in res["parameters"]], api.std, rtol=1e-12, atol=0)
    assert np.allclose(res["tcp_std_m"], api.tcp_std_m, rtol=1e-12, atol=0)
    v = pko.validate(api, held)
    assert v["z_rms"] == pytest.approx(doc["validation"]["after"]["z_rms"], rel=1e-12, abs=1e-12)
    assert api.fit_quality.line() == q["message"]


def test_identify_with_a_cell_without_noise_keeps_the_noise_unknown(cell_files, capsys):
    """A cell file without a noise field states no tracker noise: its default (1 µm) is not taken for it."""
    d = cell_files
    assert main(["identify", "--cell", str(d / "cell_nonoise.yaml"), "--data", str(d / "tr.csv"), "--quiet",
                 "--json", str(d / "nn.json")]) == 0
    doc = json.loads((d / "nn.json").read_text())
    assert doc["result"]["covariance_scaled"] and "the cell file states no noise" in doc["noise_source"]
    assert doc["fit_quality"]["chi2_interval"] is None


def test_robust_loss_switches_only_where_outliers_are():
    """Outlier-free Gaussian data (errors on every joint placement): the default loss stays plain and no row is
    flagged, with the noise stated and unknown, on 300 rows (the per-row test at α = 1e-3 flagged a row in about a
    quarter of such fits); three rows moved by 5 mm switch it and are flagged. The 200-fit figure:
    ``python -m benchmarks.robust_switch``."""
    cell = pko.load_cell("kr15")
    cell.noise = pko.NoiseModel(sigma_xyz_m=(NOISE,) * 3)
    model = cell.tracker_model()
    switched = flagged = 0
    for s in range(24):
        rng = np.random.default_rng(100 + s)
        data = simulate(model, cell.robot.random_q(rng, 300), random_truth(model, seed=s), seed=s,
                        record_sigma=False)
        r = pko.identify(model, data, discrepancy="none", scale_covariance=bool(s % 2))
        switched += r.loss != "linear"
        flagged += r.outliers.size > 0
    assert switched <= 1 and flagged <= 1, (switched, flagged)
    rows = np.array([10, 100, 200])
    data.position_m[rows] += 5e-3 * np.array([0.6, -0.8, 0.0])
    r = pko.identify(model, data, discrepancy="none")
    assert r.loss == "soft_l1" and set(rows.tolist()) <= set(r.outliers.tolist())


def test_with_the_robust_loss_the_refit_leaves_out_the_tail_rows_per_row():
    """Once the robust loss is in use (three rows moved by 5 mm), the rows it leaves out are tested one by one at
    α, not family-wise at α/m: of 29 rows moved by 4.8 σ (beyond the per-row bound sqrt(χ²₃(1 − 1e-3)) = 4.0 σ,
    below the family-wise bound sqrt(χ²₃(1 − 1e-3/300)) = 5.6 σ) at least 20 are left out (23 here; 4 with the
    family-wise rows). The family-wise bound decides whether to switch; the per-row one which rows: with the
    family-wise rows real Series C's held-out RMS was 0.199 mm instead of 0.161 mm."""
    cell = pko.load_cell("kr15")
    cell.noise = pko.NoiseModel(sigma_xyz_m=(NOISE,) * 3)
    model = cell.tracker_model()
    rng = np.random.default_rng(7)
    data = simulate(model, cell.robot.random_q(rng, 300), random_truth(model, seed=7), seed=7, record_sigma=False)
    big, tail = np.array([5, 105, 205]), np.arange(10, 300, 10)
    data.position_m[big] += 5e-3 * np.array([0.6, -0.8, 0.0])
    data.position_m[tail] += 4.8 * NOISE * np.array([0.0, 0.0, 1.0])
    r = pko.identify(model, data, discrepancy="none")
    assert r.loss == "soft_l1" and set(big.tolist()) <= set(r.outliers.tolist()), r.outliers
    assert len(set(tail.tolist()) & set(r.outliers.tolist())) >= 20, r.outliers


def test_model_saved_through_the_api_keeps_its_tool(cell_files, tmp_path):
    """The README's flow: identify(cell.tracker_model(), data).calibrated_model().save(path) keeps the tool frame,
    the TCP and the working configurations; the loaded model predicts the same TCP, not the reflector."""
    cell = pko.load_cell(str(cell_files / "cell.yaml"))
    cm = pko.identify(cell.tracker_model(), pko.read_measurements(str(cell_files / "tr.csv"))).calibrated_model()
    cm.save(tmp_path / "model.json")
    back = pko.load_model_file(tmp_path / "model.json")
    assert back.tool_source and back.robot.tool_frame == cell.robot.tool_frame
    assert np.array_equal(back.tcp_m, cell.tcp_m) and np.allclose(back.q_work, cell.q_work, rtol=0, atol=0)
    Q = cell.robot.random_q(np.random.default_rng(3), 5)
    at_tcp = forward(back, Q)
    assert np.allclose(at_tcp, forward(cm, Q), rtol=0, atol=1e-12)
    assert np.allclose(at_tcp, forward(back, Q, tcp_m=cell.tcp_m), rtol=0, atol=1e-15)
    assert np.linalg.norm(at_tcp - back.predict(Q), axis=1).min() > 0.05  # the TCP is 0.1 m from the reflector


def test_compensate_refuses_a_model_without_a_tcp(tmp_path):
    """A model fitted without a cell or a header stating the TCP: compensate refuses (the reflector is not the TCP),
    naming the fix; with tcp_m it compensates."""
    robot = pko.load_robot("ur10")
    tm = pko.TrackerModel(robot, tracker_T_base=default_tracker_pose(robot), reflector_m=np.array([0.03, 0.02, 0.08]),
                          noise=pko.NoiseModel((1e-5,) * 3))
    data = simulate(tm, robot.random_q(np.random.default_rng(0), 60), random_truth(tm, seed=1), seed=2)
    cm = pko.identify(pko.TrackerModel(robot, reflector_m=tm.reflector_m, noise=tm.noise), data,
                      discrepancy="none").calibrated_model()
    assert not cm.tool_source
    Q = robot.random_q(np.random.default_rng(4), 3) * 0.8
    ts = TargetSet(["a", "b", "c"], forward(cm, Q, tcp_m=np.array([0.0, 0.0, 0.2])), None, Q,
                   list(robot.joint_names), None, "t")
    with pytest.raises(InputError, match=r"states no TCP .*tcp_m=\[x, y, z\]"):
        compensate(cm, ts)
    res = compensate(cm, ts, CompensationOptions(tcp_m=np.array([0.0, 0.0, 0.2])))
    assert np.allclose(res.tcp_m, [0.0, 0.0, 0.2]) and res.residual_m.max() < 1e-8


def test_fit_quality_flags_a_singular_covariance():
    """Poses that hardly move the last joint (±0.03 rad): the fit converges, its covariance is ill-conditioned along
    the wrist's parameters; the verdict is poor, names them and the fix. The same robot on varied poses is good."""
    robot = pko.load_robot("ur5")
    tm = pko.TrackerModel(robot, tracker_T_base=default_tracker_pose(robot), reflector_m=np.array([0.03, 0.02, 0.08]),
                          noise=pko.NoiseModel((1e-6,) * 3))
    truth = random_truth(tm, seed=1)
    rng = np.random.default_rng(0)
    Q = robot.random_q(rng, 40)
    good = pko.identify(tm, simulate(tm, Q, truth, seed=2), discrepancy="none")
    assert good.fit_quality.verdict == "good", good.fit_quality.line()
    Q[:, 5] = 0.3 + 3e-2 * rng.normal(size=40)
    bad = pko.identify(tm, simulate(tm, Q, truth, seed=2), discrepancy="none")
    line = bad.fit_quality.line()
    assert bad.fit_quality.poor and "singular or ill-conditioned covariance" in line
    assert "correlated beyond |r| 0.999" in line and "wrist_3_joint" in line and "identify --fix '" in line


def test_design_file_default_is_one_rule(tmp_path):
    """export, evaluate and simulate --design take the same design of a file when none is named: its q_meas design
    (the kpi design, else the last), not the file's last entry."""
    path = tmp_path / "d.json"
    assert main(["design", "--cell", "kr15", "--criteria", "random", "--measurements", "12", "--seed", "2",
                 "--quiet", "--json", str(path)]) == 0
    doc = json.loads(path.read_text())
    other = json.loads(json.dumps(doc["designs"][0]))
    other["criterion"], other["q_meas"] = "D", other["q_meas"][::-1]
    doc["designs"].append(other)  # the last entry is not the file's q_meas design
    path.write_text(json.dumps(doc))
    df = pko.load_design(str(path))
    assert df.default_criterion == doc["q_meas_criterion"] == "random"
    assert main(["simulate", "--design", str(path), "--out", str(tmp_path / "s.csv")]) == 0
    got = pko.read_measurements(str(tmp_path / "s.csv"))
    assert np.allclose(got.q, np.asarray(doc["q_meas"]), rtol=0, atol=0)


def test_import_tracker_help_names_only_its_own_options():
    from pin_kpi_oed.cli.app import build_parser

    sub = next(a for a in build_parser()._actions if a.dest == "command")
    tool = next(a for a in sub.choices["import-tracker"]._actions if a.dest == "tool")
    assert "taken from --cell" not in tool.help and "identify takes them" in tool.help
