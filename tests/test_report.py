"""The calibration certificate (``report``): every figure equals identify's / predict's, ISO 9283 figures against
an independent computation, bad input refused in one line, the HTML self-contained with every section."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from pin_kpi_oed import TrackerModel, load_robot
from pin_kpi_oed.cli.app import main
from pin_kpi_oed.data.measurements import MeasurementSet, write_measurements
from pin_kpi_oed.simulation.simulator import simulate
from pin_kpi_oed.report.content import SECTIONS
from pin_kpi_oed.report.iso9283 import clusters, iso_figures, pose_accuracy, repeatability

from tests._cache_real import ipa_series, needs_ipa
from tests._cache_render import GROUP, SIGMA, browser_view, calibrated_folder, plain_certificate

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    """A simulated UR10 (random geometric errors), 240 training rows, 150 held-out rows (30 commanded positions of 5
    rows, and 4 configurations measured 3 times), identified by the CLI with --validate, --json and --model-out
    (made once per process for this file and tests/test_certificate_gum.py: tests/_cache_render.py)."""
    return calibrated_folder(tmp_path_factory)


@pytest.fixture(scope="module")
def report(calibrated) -> tuple[dict, str]:
    """The plain report of the calibrated model (its JSON and its HTML page; the PDF too where a browser is
    installed), made once for the tests that only read it (the same command every one of them ran)."""
    cert = plain_certificate(calibrated)
    return cert.cert, cert.html


@pytest.mark.xdist_group(GROUP)
def test_every_accuracy_figure_equals_identify_validate(calibrated, report):
    d = calibrated
    cert = report[0]
    ident = json.loads((d / "id.json").read_text())
    for k in ("before", "after"):
        mine, theirs = cert["accuracy"][k], ident["validation"][k]
        for key in ("n", "mean_m", "rms_m", "median_m", "p95_m", "max_m"):
            assert mine[key] == pytest.approx(theirs[key], rel=1e-9, abs=1e-12), (k, key)
        e = np.asarray(theirs["errors_m"])
        assert mine["mean_3sigma_m"] == pytest.approx(e.mean() + 3 * e.std(ddof=1), rel=1e-9)
    for key in ("z_rms", "inside_95", "sigma_mean_m", "extrapolation_share"):
        assert cert["honest_sigma"][key] == pytest.approx(ident["validation"]["after"][key], rel=1e-9, abs=1e-12)
    assert cert["fit_quality"]["message"] == ident["fit_quality"]["message"]
    # the parameters are the fit's
    names = [p["name"] for p in ident["result"]["parameters"]]
    assert [r["name"] for r in cert["parameters"]["rows"]] == names
    assert np.allclose([r["std"] for r in cert["parameters"]["rows"]],
                       [p["std"] for p in ident["result"]["parameters"]], rtol=1e-12)
    # the command that made the model and the data it saw are recorded and printed
    assert cert["reproduce"]["calibration"][0].startswith("pin-kpi-oed identify --robot ur10 --data ")
    assert cert["calibrated"]["train_files"][0]["rows"] == 240 and cert["calibrated"]["train_files_check"]["checked"]


@pytest.mark.xdist_group(GROUP)
def test_another_session_re_registered_equals_identify_validate(calibrated, capsys):
    d = calibrated
    args = ["identify", "--robot", "ur10", "--data", str(d / "train.csv"), "--validate", str(d / "test.csv"),
            "--register-rows", "40", "--seed", "1", "--reflector", "0.02,0.01,0.1", "--sigma", str(SIGMA),
            "--json", str(d / "id_t.json"), "--model-out", str(d / "model_t.json"), "--quiet"]
    assert main(args) == 0
    assert main(["report", "--model", str(d / "model_t.json"), "--train", str(d / "train.csv"), "--validate",
                 str(d / "test.csv"), "--register-rows", "40", "--seed", "1", "--json", str(d / "cert_t.json"),
                 "--quiet"]) == 0
    capsys.readouterr()
    cert, ident = json.loads((d / "cert_t.json").read_text()), json.loads((d / "id_t.json").read_text())
    assert cert["accuracy"]["mode"] == "transfer" and cert["accuracy"]["registration"]["n"] == 40
    for k in ("before", "after"):
        for key in ("n", "mean_m", "rms_m", "p95_m", "max_m"):
            assert cert["accuracy"][k][key] == pytest.approx(ident["validation"][k][key], rel=1e-9, abs=1e-12)
    assert cert["honest_sigma"]["z_rms"] == pytest.approx(ident["validation"]["after"]["z_rms"], rel=1e-9)
    # the trust map is drawn with the model as registered there: its sigma is the honest sigma's
    s3 = np.linalg.norm(np.asarray(ident["validation"]["after"]["sigma_axes_m"]), axis=1)
    assert cert["trust_map"]["sigma_median_m"] == pytest.approx(np.median(s3), rel=1e-9)
    assert cert["trust_map"]["sigma_max_m"] == pytest.approx(s3.max(), rel=1e-9)


@pytest.mark.xdist_group(GROUP)
def test_trust_map_numbers_equal_predict(calibrated, report, capsys):
    d = calibrated
    cert = report[0]
    assert main(["predict", "--model", str(d / "model.json"), "--data", str(d / "test.csv"), "--out",
                 str(d / "pred.csv")]) == 0
    capsys.readouterr()
    with open(d / "pred.csv") as f:
        rows = list(csv.DictReader(f))
    s = np.array([[float(r[f"sigma_{a}"]) for a in "xyz"] for r in rows])
    s3 = np.sqrt((s ** 2).sum(axis=1))
    t = cert["trust_map"]
    assert t["sigma_min_m"] == pytest.approx(s3.min(), rel=1e-9)
    assert t["sigma_median_m"] == pytest.approx(np.median(s3), rel=1e-9)
    assert t["sigma_max_m"] == pytest.approx(s3.max(), rel=1e-9)
    err = np.array([float(r["error"]) for r in rows])
    assert cert["accuracy"]["after"]["max_m"] == pytest.approx(err.max(), rel=1e-9)


@pytest.mark.xdist_group(GROUP)
def test_html_is_self_contained_with_every_section(report):
    cert, html = report
    for sid, title in SECTIONS:
        assert f'<section id="{sid}">' in html and title in html
    assert "src=\"http" not in html and "<script" not in html and html.count("data:image/png;base64,") >= 4
    assert len(html.encode()) < 5e6
    a = cert["accuracy"]["after"]
    assert f"{a['rms_m'] * 1e3:.4f} mm" in html  # the printed numbers are the JSON's
    iso = cert["iso9283"]
    assert iso["AP_vAP"]["after"]["n_positions"] == 30 and iso["RP"]["n_groups"] == 4


def _iso_by_hand(resid: np.ndarray, goal: np.ndarray, Q: np.ndarray) -> tuple[list, list, list]:
    """AP, vAP per commanded position and RP per repeated configuration, with plain loops over exact keys."""
    ap, vap, rp = [], [], []
    keys = {}
    for i, g in enumerate(map(tuple, np.round(goal, 6))):
        keys.setdefault(g, []).append(i)
    for rows in keys.values():
        if len(rows) < 2:
            continue
        e = resid[rows]
        ap.append(float(np.sqrt(sum(e[:, a].mean() ** 2 for a in range(3)))))
        by_q = {}
        for i in rows:
            by_q.setdefault(tuple(np.round(Q[i], 6)), []).append(i)
        bary = [resid[v].mean(axis=0) for v in by_q.values()]
        if len(bary) > 1:
            vap.append(max(float(np.linalg.norm(b - c)) for b in bary for c in bary))
    byq = {}
    for i, q in enumerate(map(tuple, np.round(Q, 6))):
        byq.setdefault(q, []).append(i)
    for rows in byq.values():
        if len(rows) >= 3:
            x = resid[rows]
            ell = [float(np.linalg.norm(r - x.mean(axis=0))) for r in x]
            lbar = sum(ell) / len(ell)
            s = (sum((v - lbar) ** 2 for v in ell) / (len(ell) - 1)) ** 0.5
            rp.append(lbar + 3 * s)
    return ap, vap, rp


def test_iso9283_figures_match_an_independent_computation():
    rng = np.random.default_rng(0)
    goal = np.repeat(rng.uniform(-1, 1, (12, 3)), 6, axis=0)  # 12 commanded positions x 6 rows
    Q = rng.uniform(-3, 3, (72, 6))
    Q[1::2] = Q[::2]  # every position reached in 3 configurations, each twice
    Q[60:63] = Q[60]  # one configuration measured 4 times (rows 60-63 share it)
    Q[63] = Q[60]
    resid = rng.normal(0, 1e-4, (72, 3)) + np.repeat(rng.normal(0, 2e-4, (12, 3)), 6, axis=0)
    ms = MeasurementSet([f"j{i}" for i in range(6)], Q, np.zeros((72, 3)),
                        extra={"goal_x": goal[:, 0], "goal_y": goal[:, 1], "goal_z": goal[:, 2]})
    out = iso_figures(ms, Q, resid, resid)
    ap, vap, rp = _iso_by_hand(resid, goal, Q)
    got = out["AP_vAP"]["after"]
    assert sorted(r["AP_m"] for r in got["per_position"]) == pytest.approx(sorted(ap), rel=1e-12)
    assert sorted(r["vAP_m"] for r in got["per_position"] if r["vAP_m"] is not None) == pytest.approx(sorted(vap))
    assert sorted(r["RP_m"] for r in out["RP"]["per_group"]) == pytest.approx(sorted(rp), rel=1e-12)
    assert got["n_positions"] == 12 and got["vAP"]["directions_mean"] == pytest.approx(35 / 12)  # one has 2
    # no repeats: plain statements, no figures
    single = MeasurementSet(ms.joint_names, Q[:12:6], np.zeros((2, 3)),
                            extra={"goal_x": goal[:12:6, 0], "goal_y": goal[:12:6, 1], "goal_z": goal[:12:6, 2]})
    none = iso_figures(single, Q[:12:6], resid[:2], resid[:2])
    assert "AP_vAP" not in none and "RP" not in none
    assert any("no AP" in s for s in none["statements"]) and any("no RP" in s for s in none["statements"])


def test_iso_helpers_on_known_values():
    e = np.array([[1.0, 0, 0], [3.0, 0, 0], [0, 2.0, 0], [0, 4.0, 0]]) * 1e-3
    pa = pose_accuracy(e, [np.arange(4)], np.array([0, 0, 1, 1]))
    assert pa["per_position"][0]["AP_m"] == pytest.approx(np.hypot(1.0, 1.5) * 1e-3)  # barycentre (1, 1.5, 0) mm
    assert pa["per_position"][0]["vAP_m"] == pytest.approx(np.hypot(2.0, 3.0) * 1e-3)  # (2,0,0) vs (0,3,0) mm
    x = np.array([[1.0, 0, 0], [-1.0, 0, 0], [0, 2.0, 0], [0, -2.0, 0]]) * 1e-3
    rp = repeatability(x, [np.arange(4)])
    ell = np.array([1.0, 1.0, 2.0, 2.0])
    assert rp["max_m"] == pytest.approx((ell.mean() + 3 * ell.std(ddof=1)) * 1e-3)
    assert [g.tolist() for g in clusters(np.array([[0.0], [0.5e-3], [0.9e-3], [5.0]]), 1e-3)] == [[0, 1, 2]]


@pytest.mark.xdist_group(GROUP)
def test_bad_input_one_line_exit_2_nothing_written(calibrated, capsys, tmp_path):
    d = calibrated
    out = tmp_path / "c.html"
    base = ["report", "--model", str(d / "model.json"), "--train", str(d / "train.csv"), "--html", str(out)]
    cases = [
        (base, "give --validate FILE"),
        (base[:3] + ["--train", str(d / "test.csv"), "--validate", str(d / "train.csv"), "--html", str(out)],
         "is not a file"),
        (base + ["--validate", str(d / "test.csv"), "--kinematics", str(REPO / "urdf" / "ur" / "ur5.yaml")],
         "not a ur10's kinematics"),
        (base + ["--validate", str(d / "test.csv"), "--kinematics", str(REPO / "urdf" / "ur" / "ur10.yaml")],
         "nominal robot is the ur10 URDF"),
    ]
    doc = json.loads((d / "model.json").read_text())  # a model calibrated on two files, given one of them
    doc["history"][-1]["train_files"].append({"path": "other.csv", "name": "other.csv", "sha256": "0" * 64, "rows": 9})
    (tmp_path / "two.json").write_text(json.dumps(doc))
    cases.append((["report", "--model", str(tmp_path / "two.json")] + base[3:] + ["--validate", str(d / "test.csv")],
                  "give every one of them"))
    text = (d / "test.csv").read_text()  # held-out rows whose tool header names another tool frame
    (tmp_path / "other_tool.csv").write_text("# pin_kpi_oed.tool/1\n# robot: \"ur10\"\n# tool_frame: \"wrist_3_link\"\n"
                                             + "\n".join(ln for ln in text.splitlines() if not ln.startswith("#")))
    cases.append((base + ["--validate", str(tmp_path / "other_tool.csv")], "wrist_3_link"))
    for argv, msg in cases:
        capsys.readouterr()
        assert main(argv) == 2, msg
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and msg in err and "Traceback" not in err, err
        assert not out.exists()


def test_a_hash_mismatch_of_the_kinematics_is_refused(tmp_path, capsys):
    from pin_kpi_oed.calibrated.model_file import CalibratedModel, Setup
    from pin_kpi_oed.calibrated.formats.registry import export_model

    robot = load_robot("ur10", kinematics=REPO / "urdf" / "ur" / "ur10.yaml")
    p = np.zeros(36)
    p[14] = 1e-3
    cm = CalibratedModel(robot, p, setups={"s": Setup(np.eye(4), np.zeros(3))}, default_station="s")
    export_model(cm, tmp_path / "other.yaml", "ur-yaml")  # another calibration of the same type: another hash
    cm.save(tmp_path / "m.json")
    ms = simulate(TrackerModel(robot), robot.random_q(np.random.default_rng(0), 20), seed=0, record_sigma=False)
    write_measurements(ms, tmp_path / "a.csv")
    write_measurements(ms, tmp_path / "b.csv")
    argv = ["report", "--model", str(tmp_path / "m.json"), "--train", str(tmp_path / "a.csv"), "--validate",
            str(tmp_path / "b.csv"), "--kinematics", str(tmp_path / "other.yaml"), "--json", str(tmp_path / "c.json")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "differs from the model's nominal calib_17227329492635474227" in err and err.count("\n") == 1
    assert not (tmp_path / "c.json").exists()


def _browser():
    from pin_kpi_oed.viz.render import find_browser

    return find_browser()


@pytest.mark.xdist_group(GROUP)
@pytest.mark.skipif(_browser() is None, reason="no Chromium/Chrome browser (Debian: apt-get install chromium)")
def test_certificate_renders_in_headless_chromium(calibrated, report):
    """The plain certificate printed to PDF by ``report --pdf`` and opened in headless Chromium (one launch at an A4
    width, shared with tests/test_certificate_gum.py's layout test): the screenshot of its first screen is not blank
    (text and tables), every figure is an image the browser decoded, every section is in the page the browser
    built."""
    from matplotlib.image import imread

    view = browser_view(plain_certificate(calibrated))
    img = imread(view.screenshot)
    assert img.std() > 0.02 and len(np.unique(img)) > 50, "the screenshot is blank"  # text and tables
    assert view.layout["images"] == view.layout["images_drawn"] >= 4, view.layout  # the figures, decoded
    for sid, title in SECTIONS:  # every section is in the page the browser built
        assert f'id="{sid}"' in view.dom and title in view.dom
    assert plain_certificate(calibrated).pdf.read_bytes()[:5] == b"%PDF-"


@pytest.mark.xdist_group(GROUP)
@pytest.mark.skipif(_browser() is not None, reason="a browser is installed: the PDF is made")
def test_without_a_browser_the_pdf_is_skipped_with_a_note(calibrated, capsys, tmp_path):
    d = calibrated
    assert main(["report", "--model", str(d / "model.json"), "--train", str(d / "train.csv"), "--validate",
                 str(d / "test.csv"), "--html", str(tmp_path / "c.html"), "--pdf", str(tmp_path / "c.pdf")]) == 0
    out = capsys.readouterr().out
    assert "PDF not made" in out and (tmp_path / "c.html").exists() and not (tmp_path / "c.pdf").exists()


@pytest.mark.xdist_group(GROUP)
def test_diagnosis_recorded_by_diagnose_is_in_the_certificate(calibrated, capsys):
    d = calibrated
    argv = ["diagnose", "--robot", "ur10", "--train", str(d / "train.csv"), "--validate", str(d / "test.csv"),
            "--reflector", "0.02,0.01,0.1", "--sigma", str(SIGMA), "--effects", "joint_compliance",
            "--discrepancy", "none", "--model-out", str(d / "diag.json"), "--json", str(d / "diag_report.json"),
            "--quiet"]
    assert main(argv) == 0
    capsys.readouterr()
    diag = json.loads((d / "diag_report.json").read_text())
    assert main(["report", "--model", str(d / "diag.json"), "--train", str(d / "train.csv"), "--validate",
                 str(d / "test.csv"), "--json", str(d / "cert_diag.json"), "--quiet"]) == 0
    cert = json.loads((d / "cert_diag.json").read_text())
    assert cert["diagnosis"]["message"] == diag["message"]
    assert cert["reproduce"]["calibration"][-1].startswith("pin-kpi-oed diagnose --robot ur10")


def _root(parent, i):
    while parent[i] != i:
        i = parent[i]
    return i


@needs_ipa
@pytest.mark.parametrize("series,cycles", [("D", 24), ("B", 0), ("A", 0)])
def test_iso_groups_on_the_ipa_series_match_an_independent_computation(series, cycles):
    """Series D (ISO cube, centre repeated), B (154 positions x 10 configurations) and A: commanded positions (the
    rows whose goals lie within 1 mm of the goal of the first unassigned row, in file order) and configurations
    (joints within 1 mrad) by plain loops against the module's grouping; no position spans more than 2 mm; AP and vAP
    on the measured positions as residuals checked by hand; the cycle groups counted."""
    from pin_kpi_oed.report.iso9283 import commanded_groups, direction_keys

    ms = ipa_series(series)  # imported once per process (tests/_cache_real.py)
    goal = np.column_stack([ms.extra[k] for k in ("goal_x", "goal_y", "goal_z")])
    groups = commanded_groups(ms)
    free = np.ones(len(goal), bool)
    want = []
    for i in range(len(goal)):
        if free[i]:
            mine = np.flatnonzero(free & (np.sqrt(((goal - goal[i]) ** 2).sum(axis=1)) <= 1e-3))  # brute force
            free[mine] = False
            if len(mine) >= 2:
                want.append(mine.tolist())
    want = sorted(want)
    assert sorted(sorted(g.tolist()) for g in groups) == want and len(want) > 20
    assert max(np.ptp(goal[g], axis=0).max() for g in want) <= 2e-3
    # configurations: rows linked by max |dq| < 1 mrad, by a plain union-find over every linked pair of a position's
    # rows (all pairs' max |dq| at once: the same pairs as a double loop)
    keys = direction_keys(ms.q)
    resid = ms.position_m - ms.position_m.mean(axis=0)
    vap = []
    for rows in want:
        link = {i: i for i in rows}
        Qr = ms.q[rows]
        close = np.abs(Qr[:, None, :] - Qr[None, :, :]).max(axis=2) <= 1e-3
        for a, b in zip(*np.nonzero(np.triu(close, 1))):
            link[_root(link, rows[a])] = _root(link, rows[b])
        mine = {}
        for i in rows:
            mine.setdefault(keys[i], set()).add(i)
        theirs = {}
        for i in rows:
            theirs.setdefault(_root(link, i), set()).add(i)
        assert sorted(map(sorted, mine.values())) == sorted(map(sorted, theirs.values()))
        bary = [resid[sorted(v)].mean(axis=0) for v in theirs.values()]
        if len(bary) > 1:
            B = np.array(bary)
            vap.append(float(np.sqrt(((B[:, None, :] - B[None, :, :]) ** 2).sum(axis=2)).max()))
    out = iso_figures(ms, ms.q, resid, resid)
    ap = [sum((sum(resid[i][a] for i in g) / len(g)) ** 2 for a in range(3)) ** 0.5 for g in want]
    got = out["AP_vAP"]["after"]
    assert sorted(r["AP_m"] for r in got["per_position"]) == pytest.approx(sorted(ap), rel=1e-12)
    assert sorted(r["vAP_m"] for r in got["per_position"] if r["vAP_m"] is not None) == pytest.approx(sorted(vap))
    assert (out.get("RP", {}).get("n_groups", 0)) == cycles


@needs_ipa
def test_on_the_ipa_data_every_figure_equals_identify_validate(tmp_path, capsys):
    """Real UR10 rows (Series C: 400 to calibrate, 300 held out; Series D re-registered on 60 rows): identify
    --validate --json and report on its model give the same before / after figures and honest sigma."""
    c = ipa_series("C")
    write_measurements(c.subset(np.arange(400)), tmp_path / "train.csv")
    write_measurements(c.subset(np.arange(400, 700)), tmp_path / "test.csv")
    write_measurements(ipa_series("D"), tmp_path / "D.csv")
    for name, held, extra in (("c", "test.csv", []), ("d", "D.csv", ["--register-rows", "60", "--seed", "0"])):
        assert main(["identify", "--robot", "ur10", "--data", str(tmp_path / "train.csv"), "--validate",
                     str(tmp_path / held), "--reflector", "0,0,0.109", "--discrepancy", "none", *extra,
                     "--json", str(tmp_path / f"id_{name}.json"), "--model-out", str(tmp_path / f"m_{name}.json"),
                     "--accept-poor-fit", "--quiet"]) in (0, 2)
        assert main(["report", "--model", str(tmp_path / f"m_{name}.json"), "--train", str(tmp_path / "train.csv"),
                     "--validate", str(tmp_path / held), *extra, "--json", str(tmp_path / f"cert_{name}.json"),
                     "--quiet"]) == 0
        capsys.readouterr()
        cert = json.loads((tmp_path / f"cert_{name}.json").read_text())
        ident = json.loads((tmp_path / f"id_{name}.json").read_text())
        for k in ("before", "after"):
            for key in ("n", "mean_m", "rms_m", "median_m", "p95_m", "max_m"):
                assert cert["accuracy"][k][key] == pytest.approx(ident["validation"][k][key], rel=1e-9), (name, k, key)
        for key in ("z_rms", "inside_95", "sigma_mean_m"):
            assert cert["honest_sigma"][key] == pytest.approx(ident["validation"]["after"][key], rel=1e-9)
        assert cert["fit_quality"]["message"] == ident["fit_quality"]["message"]
    iso = json.loads((tmp_path / "cert_d.json").read_text())["iso9283"]
    assert iso["AP_vAP"]["after"]["n_positions"] > 20 and iso["RP"]["n_groups"] > 10  # the ISO cube, centre repeated
