"""The certificate of a camera calibration: simulate -> identify -> report on the example eye-in-hand UR5 camera
cell through the command line, at the smallest sizes (12 training images, 6 held-out), on a true robot that is not
the package's model (every joint placement, the hand-eye transform and the board off nominal)."""

from __future__ import annotations

import csv
import html
import json

import numpy as np
import pytest

from pin_kpi_oed.calibrated.model_file import load_model_file
from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.identification.camera_identify import camera_model_of
from pin_kpi_oed.report.camera import CAMERA_SECTIONS, NOT_APPLICABLE, build_camera_certificate
from pin_kpi_oed.report.content import CertificateOptions
from tests.camera_cell import camera_cell
from tests.cli_run import run_cli


#: the tests sharing the module fixture ``certified``: on one worker under ``--dist loadgroup``, computed once
GROUP = "test_camera_report_certified"


@pytest.fixture(scope="module")
def certified(tmp_path_factory):
    """The corner files, the model file, predict --at tcp at the cell's working configurations, the certificate."""
    d = tmp_path_factory.mktemp("camera_report")
    cell_path = camera_cell(d)
    steps = {"simulate": run_cli("simulate", "--cell", cell_path, "--n", 12, "--n-test", 6, "--test-out",
                                 d / "test.csv", "--out", d / "train.csv", "--seed", 3),
             "identify": run_cli("identify", "--data", d / "train.csv", "--cell", cell_path, "--model-out",
                                 d / "m.json", "--validate", d / "test.csv")}
    cell = load_cell(str(cell_path))
    (d / "work.csv").write_text(",".join(cell.robot.joint_names) + "\n"
                                + "".join(",".join(repr(float(v)) for v in q) + "\n" for q in cell.q_work))
    steps["predict"] = run_cli("predict", "--model", d / "m.json", "--data", d / "work.csv", "--at", "tcp",
                               "--out", d / "pred.csv")
    steps["report"] = run_cli("report", "--model", d / "m.json", "--train", d / "train.csv", "--validate",
                              d / "test.csv", "--html", d / "cert.html", "--json", d / "cert.json",
                              "--required-accuracy", 0.002, "--monte-carlo", 2000)
    for name, (rc, _, err) in steps.items():
        assert rc == 0, (name, err)
    return d, cell, steps


@pytest.mark.xdist_group(GROUP)
def test_the_pages_U_is_twice_the_tcp_sigma_predict_states(certified):
    d, cell, _ = certified
    with open(d / "pred.csv") as f:
        sigma = np.array([float(r["sigma_tcp"]) for r in csv.DictReader(f)])
    doc = json.loads((d / "cert.json").read_text())
    u = doc["uncertainty"]
    assert u["n"] == len(cell.q_work) == len(sigma) == 2
    np.testing.assert_allclose(u["U_m"], 2.0 * sigma, rtol=1e-9, atol=0)
    assert u["U_max_m"] == pytest.approx(2.0 * sigma.max(), rel=1e-9)
    assert 1e-4 < u["U_max_m"] < 5e-3  # a TCP uncertainty of a camera calibration, not a vacuous number


@pytest.mark.xdist_group(GROUP)
def test_the_page_states_the_held_share_and_what_removes_it(certified):
    d, cell, _ = certified
    doc = json.loads((d / "cert.json").read_text())
    u = doc["uncertainty"]
    ts = load_model_file(d / "m.json").predict_tcp(cell.q_work)
    assert u["held_share"] == pytest.approx(ts.held_share, rel=1e-9) and u["held_share"] > 0.3
    shares = {c["key"]: c["share"] for c in u["contributions"]}
    assert shares["parameters"] + shares["held"] == pytest.approx(1.0, abs=1e-12)
    assert u["held"][0]["name"] == "wrist_3_joint.ty" and u["held"][0]["axial"]  # the flange's axial offset
    page = html.unescape((d / "cert.html").read_text())
    assert f"{u['held_share'] * 100:.0f} % of the TCP's variance is held at nominal" in page
    assert "the flange's axial offset (wrist_3_joint.ty)" in page and "only a measurement of the TCP" in page


@pytest.mark.xdist_group(GROUP)
def test_the_json_is_valid_and_the_page_has_every_section(certified):
    d, _, steps = certified
    doc = json.loads((d / "cert.json").read_text(), parse_constant=lambda c: pytest.fail(f"{c} in the JSON"))
    assert doc["format"] == "pin_kpi_oed.certificate/1" and doc["device"] == "camera"
    assert doc["title"].startswith("DRAFT") and doc["identity"]["status"]["kind"] == "draft"
    assert doc["calibrated"]["train_files_check"]["checked"]
    f = doc["fit"]
    assert f["training"]["images"] == 12 and f["held_out"]["images"] == 6
    assert f["training"]["rms_px"] == pytest.approx(f["training"]["rms_px_recorded"], rel=1e-6)
    assert 0.15 < f["held_out"]["rms_px"] < 0.3 and 0.5 < f["chi2_reduced"] < 2.0  # 0.2 px simulated noise
    for pose in ("hand_eye", "board"):
        p = doc["camera_setup"][pose]
        assert p["estimated"] and all(0 < s < 1e-3 for s in p["sigma_t_m"] + p["sigma_r_rad"])
    assert doc["uncertainty"]["conformity"]["verdict"] == "conforms"
    page = html.unescape((d / "cert.html").read_text())
    for sid, _ in CAMERA_SECTIONS:
        assert f'<section id="{sid}">' in page
    for line in NOT_APPLICABLE.values():  # stated, not silently dropped
        assert line.split(":")[0] in page and "not applicable" in line
    assert "wrote" in steps["report"][1] and "draft: conforms" in steps["report"][1]


def _tcp_by_pinocchio(model, p, q, pm, data):
    """The TCP in the device frame at raw parameters p and one configuration q through Pinocchio's forward
    kinematics of the robot with the joint placements at p (not the package's batched chain, and 20 times cheaper
    a call than ``model.kpi`` for one configuration)."""
    import pinocchio as pin

    rb = model.robot
    for j, M in zip(rb.joint_ids, model.joint_placements(p)):
        pm.jointPlacements[j] = M
    pin.framesForwardKinematics(pm, data, q)
    return model.sensor_pose(p).act(data.oMf[rb.tool_frame_id].act(model.tcp_m))


@pytest.mark.xdist_group(GROUP)
def test_monte_carlo_of_U_on_one_configuration(certified):
    """U against draws of the fitted parameters from their covariance and the held joint placements from their
    tolerances (absorbed by the fit as stored), the TCP through Pinocchio's forward kinematics of each drawn robot
    (checked equal to the camera model's own ``kpi`` on the first draws)."""
    d, cell, _ = certified
    cm = load_model_file(d / "m.json")
    model, p0 = camera_model_of(cm)
    P = cm.parameters
    names = model.layout.names
    col = [names.index("board." + n.split(".", 1)[1] if n.startswith("tracker.") else n) for n in P["names"]]
    held = P["held"]
    A = np.asarray(held["absorption"], float).reshape(len(col), -1)
    hcol = [names.index(n) for n in held["names"]]
    rng = np.random.default_rng(11)
    n = 2500
    eps = rng.multivariate_normal(np.zeros(len(col)), P["covariance"], size=n, method="eigh")
    dN = rng.standard_normal((n, len(hcol))) * np.asarray(held["sigma"], float)
    q = cell.q_work[:1]
    pm = model.robot.model.copy()
    data = pm.createData()
    y0 = _tcp_by_pinocchio(model, p0, q[0], pm, data)
    assert np.abs(y0 - model.kpi(p0, q)[0]).max() < 1e-12, "Pinocchio's TCP is the model's at the fit"
    err = np.empty((n, 3))
    for i in range(n):
        p = p0.copy()
        p[hcol] += dN[i]
        p[col] -= A @ dN[i] + eps[i]
        err[i] = _tcp_by_pinocchio(model, p, q[0], pm, data) - y0
        if i < 3:
            assert np.abs(err[i] + y0 - model.kpi(p, q)[0]).max() < 1e-12, "Pinocchio's TCP is the model's (draw)"
    U_mc = 2.0 * np.sqrt(np.trace(np.cov(err.T)))
    doc = json.loads((d / "cert.json").read_text())
    assert U_mc == pytest.approx(doc["uncertainty"]["U_m"][0], rel=0.05), "U against 2500 drawn robots"
    mc = doc["uncertainty"]["monte_carlo"]  # the page's own check (--monte-carlo 2000)
    assert mc["n"] == 2000 and all(abs(r - 1.0) < 0.05 for r in mc["ratio"]), "the page's own Monte-Carlo"


def _monte_carlo_one_draw_at_a_time(cm, Q, n, seed):
    """The sampled σ of ``camera_monte_carlo`` as it was computed before its draws were batched: the same random
    numbers in the same order, each drawn truth's TCP by ``model.kpi``, one draw at a time."""
    model, p0 = camera_model_of(cm)
    P = cm.parameters
    names = model.layout.names
    col = [names.index(f"{model.frame_group}.{s.split('.', 1)[1]}" if s.startswith("tracker.") else s)
           for s in P["names"]]
    rng = np.random.default_rng(seed)
    eps = rng.multivariate_normal(np.zeros(len(col)), np.asarray(P["covariance"], float), size=n, method="eigh")
    held = P["held"]
    hcol = [names.index(h) for h in held["names"]]
    A = np.asarray(held["absorption"], float).reshape(len(col), len(hcol))
    dN = rng.standard_normal((n, len(hcol))) * np.asarray(held["sigma"], float)
    y0 = model.kpi(p0, Q)
    E = np.empty((n, len(Q), 3))
    for i in range(n):
        p = p0.copy()
        p[hcol] += dN[i]
        p[col] -= A @ dN[i] + eps[i]
        E[i] = model.kpi(p, Q) - y0
    return np.sqrt(np.sum(np.var(E, axis=0, ddof=1), axis=1))


@pytest.mark.xdist_group(GROUP)
def test_the_batched_monte_carlo_is_the_one_draw_at_a_time(certified):
    """``camera_monte_carlo`` (its draws through one batched pass of the kinematics) states the σ of the former
    per-draw computation (same seed, same random numbers) to 1e-12 relative, at the cell's working configurations
    (100 draws: the equality is per draw, not statistical)."""
    from pin_kpi_oed.report.camera import camera_monte_carlo

    d, cell, _ = certified
    cm = load_model_file(d / "m.json")
    Q = np.asarray(cell.q_work, float)
    mc = camera_monte_carlo(cm, Q, n=100, seed=4)
    ref = _monte_carlo_one_draw_at_a_time(cm, Q, 100, 4)
    np.testing.assert_allclose(mc["sigma_m"], ref, rtol=1e-12, atol=0)
    assert mc["n"] == 100 and np.all(ref > 1e-5)

@pytest.mark.xdist_group(GROUP)
def test_conformity_is_undetermined_when_U_exceeds_the_requirement(certified):
    d, _, _ = certified
    u_max = json.loads((d / "cert.json").read_text())["uncertainty"]["U_max_m"]
    cert = build_camera_certificate(str(d / "m.json"), [str(d / "train.csv")], str(d / "test.csv"),
                                    options=CertificateOptions(required_accuracy_m=0.5 * u_max))
    c = cert.data["uncertainty"]["conformity"]
    assert c["verdict"] == "undetermined" and c["U_m"] == pytest.approx(u_max, rel=1e-9)


@pytest.mark.xdist_group(GROUP)
def test_bad_camera_report_input_is_one_line(certified, tmp_path):
    d, _, _ = certified
    other = tmp_path / "other.csv"
    other.write_text((d / "train.csv").read_text().replace("pose_0000", "pose_0099", 1))
    base = ("report", "--model", d / "m.json", "--html", tmp_path / "x.html")
    for argv, says in (
            ((*base, "--train", d / "train.csv"), "held-out corner file"),
            ((*base, "--train", other, "--validate", d / "test.csv"), "is not a file"),
            ((*base, "--train", d / "train.csv", "--validate", d / "train.csv"), "is the training file"),
            ((*base, "--train", d / "train.csv", "--validate", d / "test.csv", "--goal-radius", 0.002),
             "report --goal-radius: not for camera measurements")):
        rc, out, err = run_cli(*argv)
        assert rc == 2 and says in err and len(err.strip().splitlines()) == 1, (argv, err)
    assert not (tmp_path / "x.html").exists()


@pytest.mark.xdist_group(GROUP)
def test_a_lab_file_makes_the_page_a_certificate(certified, tmp_path):
    d, _, _ = certified
    lab = tmp_path / "lab.yaml"
    lab.write_text("organisation: Test Lab\noperator: T. Operator\ncustomer: Test Customer\nrobot_serial: SIM-1\n"
                   "instrument:\n  make: Basler\n  model: acA1300\n  serial: \"7\"\n  calibration_date: 2020-01-01\n"
                   "  calibration_certificate: C-7\n")
    rc, out, err = run_cli("report", "--model", d / "m.json", "--train", d / "train.csv", "--validate", d / "test.csv",
                           "--lab", lab, "--html", tmp_path / "c.html")
    assert rc == 0, err
    page = (tmp_path / "c.html").read_text()
    assert "<title>Calibration certificate: ur5 (camera)</title>" in page and "Basler acA1300, serial 7" in page
    assert "DRAFT" not in page and "certificate: no required accuracy stated" in out
