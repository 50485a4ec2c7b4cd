"""What makes the report a certificate: the lab file (else a draft), held-out rows that are held out, goals grouped by
a stated distance, ISO 9283 against the commanded poses by hand, the GUM budget against Monte-Carlo and the held-out
errors, the ISO 14253-1 decision rule."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from pin_kpi_oed.cli.app import main
from pin_kpi_oed.data.measurements import MeasurementSet, read_measurements, write_measurements
from pin_kpi_oed.report.iso9283 import goal_groups
from pin_kpi_oed.report import figures
from pin_kpi_oed.report.iso_commanded import commanded_figures, commanded_positions
from pin_kpi_oed.report.uncertainty import ball_coverage, conformity, discrepancy_draws, linear_draws
from tests._cache_render import A4_PX, GROUP, browser, browser_view, calibrated_folder, plain_certificate

LAB = """organisation: Test Lab
operator: T. Operator
customer: Test Customer
robot_serial: SIM-1
instrument:
  make: Leica
  model: AT960
  serial: "1"
  calibration_date: 2020-01-01
  calibration_certificate: C-1
"""


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    """The simulated UR10 of tests/test_report.py (240 training rows, 150 held-out rows, identified by the CLI),
    made once per process for both files (tests/_cache_render.py)."""
    return calibrated_folder(tmp_path_factory)


def _report(d: Path, test: str, *extra: str) -> int:
    return main(["report", "--model", str(d / "model.json"), "--train", str(d / "train.csv"), "--validate",
                 str(d / test), "--json", str(d / "gum.json"), "--quiet", *extra])


@pytest.mark.xdist_group(GROUP)
def test_without_a_lab_file_a_draft_with_one_a_certificate(calibrated, tmp_path, capsys):
    """Without --lab: the plain certificate (``report`` without a lab file, made once for this file and
    tests/test_report.py) is a draft naming the fix; with a lab file a certificate; a lab file without a field
    refused in one line."""
    d = calibrated
    cert = plain_certificate(d).cert
    assert cert["title"].startswith("DRAFT") and cert["summary"]["status"]["kind"] == "draft"
    assert "report --lab LAB.yaml" in cert["summary"]["status"]["reason"]  # the fix in the command's words
    (tmp_path / "lab.yaml").write_text(LAB)
    assert _report(d, "test.csv", "--lab", str(tmp_path / "lab.yaml")) == 0
    cert = json.loads((d / "gum.json").read_text())
    assert cert["title"].startswith("Calibration certificate") and cert["identity"]["lab"]["robot_serial"] == "SIM-1"
    (tmp_path / "bad.yaml").write_text(LAB.replace("  serial: \"1\"\n", ""))
    capsys.readouterr()
    assert _report(d, "test.csv", "--lab", str(tmp_path / "bad.yaml")) == 2
    err = capsys.readouterr().err
    assert "instrument: field 'serial' is missing" in err and err.count("\n") == 1


@pytest.mark.xdist_group(GROUP)
def test_reordered_training_rows_are_refused_and_mixed_ones_removed(calibrated, capsys):
    d = calibrated
    train = read_measurements(d / "train.csv")
    write_measurements(train.subset(np.random.default_rng(0).permutation(len(train))), d / "reordered.csv")
    assert _report(d, "reordered.csv") == 2
    err = capsys.readouterr().err
    assert "240 of 240 rows repeat training configurations" in err and err.count("\n") == 1
    test = read_measurements(d / "test.csv")
    mixed = MeasurementSet(test.joint_names, np.vstack([test.q, train.q[:30]]),
                           np.vstack([test.position_m, train.position_m[:30]]), sigma_m=None)
    write_measurements(mixed, d / "mixed.csv")
    assert _report(d, "mixed.csv") == 0
    cert = json.loads((d / "gum.json").read_text())
    assert cert["accuracy"]["repeats_removed"]["removed"] == 30 and cert["accuracy"]["after"]["n"] == 150


def test_goals_are_grouped_by_distance_never_by_chaining():
    G = np.column_stack([np.arange(50) * 0.08e-3, np.zeros(50), np.zeros(50)])  # 0.08 mm apart: one chain
    groups = goal_groups(G, 1e-3)
    span = max(np.ptp(G[g, 0]) for g in groups)
    assert span <= 2e-3 and sorted(np.concatenate(groups).tolist()) == list(range(50)) and len(groups) == 4
    # by hand: the first goal opens a group that takes every goal within 1 mm of it (13 rows: 0 .. 0.96 mm)
    assert groups[0].tolist() == list(range(13)) and groups[1].tolist() == list(range(13, 26))


def test_commanded_pose_figures_equal_a_hand_computation():
    rng = np.random.default_rng(3)
    goals = np.repeat(rng.uniform(-0.5, 0.5, (5, 3)), 30, axis=0)  # 5 poses x 30 cycles
    T = np.eye(4)
    T[:3, 3] = [1.0, 2.0, 0.5]
    bias = rng.normal(0, 2e-4, (5, 3)).repeat(30, axis=0)
    meas = goals + T[:3, 3] + bias + rng.normal(0, 2e-5, goals.shape)
    ms = MeasurementSet([f"j{i}" for i in range(6)], np.repeat(rng.uniform(-1, 1, (5, 6)), 30, axis=0), meas,
                        sigma_m=None, extra={"goal_x": goals[:, 0], "goal_y": goals[:, 1], "goal_z": goals[:, 2]})
    x_c = commanded_positions(ms, T, np.zeros(3))
    groups = goal_groups(goals, 1e-3)
    out = commanded_figures(ms, meas, x_c, ms.q, groups)
    for k, g in enumerate(groups):
        xb = [sum(meas[i][a] for i in g) / len(g) for a in range(3)]
        xc = [goals[g[0]][a] + T[a, 3] for a in range(3)]
        ap = sum((xb[a] - xc[a]) ** 2 for a in range(3)) ** 0.5
        ell = [sum((meas[i][a] - xb[a]) ** 2 for a in range(3)) ** 0.5 for i in g]
        lbar = sum(ell) / len(ell)
        rp = lbar + 3 * (sum((v - lbar) ** 2 for v in ell) / (len(ell) - 1)) ** 0.5
        assert out["AP_vAP"]["per_position"][k]["AP_m"] == pytest.approx(ap, rel=1e-10)
        assert out["RP"]["per_group"][k]["RP_m"] == pytest.approx(rp, rel=1e-10)
    assert out["drift"] is None and any("no drift" in s for s in out["statements"])


def test_iso14253_decision_rule():
    assert conformity(0.2e-3, 0.05e-3, 0.3e-3)["verdict"] == "conforms"
    assert conformity(0.28e-3, 0.05e-3, 0.3e-3)["verdict"] == "undetermined"
    assert conformity(0.32e-3, 0.05e-3, 0.3e-3)["verdict"] == "undetermined"
    assert conformity(0.4e-3, 0.05e-3, 0.3e-3)["verdict"] == "does not conform"


@pytest.mark.xdist_group(GROUP)
def test_budget_against_monte_carlo_and_the_held_out_errors(calibrated, tmp_path):
    """The simulated UR10 (noise-only model, 150 held-out rows): the budget's parameter and tracker terms within 5 % of
    draws of the parameters; the held-out rows within U near the coverage the budget states; a required accuracy
    above the figure + U conforms."""
    d = calibrated
    with open(tmp_path / "work.csv", "w", newline="") as f:
        w = csv.writer(f)
        test = read_measurements(d / "test.csv")
        w.writerow(test.joint_names)
        w.writerows(test.q[:12].tolist())
    assert _report(d, "test.csv", "--work", str(tmp_path / "work.csv"), "--monte-carlo", "2000",
                   "--required-accuracy", "0.005") == 0
    u = json.loads((d / "gum.json").read_text())["uncertainty"]
    assert u["budget"]["n"] == 12 and u["where"].startswith("the working configurations given")
    assert abs(u["monte_carlo"]["median_ratio"] - 1.0) < 0.05
    shares = {c["key"]: c["share"] for c in u["budget"]["contributions"]}
    assert sum(shares.values()) == pytest.approx(1.0) and shares["parameters"] > 0 and shares["tracker"] > 0
    h = u["held_out"]
    assert abs(h["within_U"] - h["coverage_stated"]) < 0.06 and abs(h["within_U_axis"] - 0.9545) < 0.05
    assert u["conformity"]["verdict"] == "conforms"


@pytest.mark.xdist_group(GROUP)
def test_no_legend_covers_data_in_the_certificate_figures(calibrated):
    """Every legend of the certificate's figures lies outside its axes' plotting area (display coordinates after
    drawing): it covers no point, bar or line. The figures are those the plain report drew
    (``report.figures.png_bytes``: the report made once for this file and tests/test_report.py); each figure with a
    legend is laid out again by matplotlib's draw without its pixels (``draw_without_rendering``: the same layout,
    hence the same legend and axes extents as a rendering draw, without rasterising what the PNG already holds)."""
    made = plain_certificate(calibrated).figures
    n = 0
    for fig in made:
        if not any(ax.get_legend() is not None for ax in fig.axes):
            continue
        fig.draw_without_rendering()
        r = fig.canvas.get_renderer()
        for ax in fig.axes:
            leg = ax.get_legend()
            if leg is None:
                continue
            n += 1
            lb, ab = leg.get_window_extent(r), ax.get_window_extent(r)
            assert not lb.overlaps(ab) or lb.y0 >= ab.y1 - 1, "a legend overlaps its axes' data area"
    assert n >= 2


def _chromium():
    return browser()


@pytest.mark.xdist_group(GROUP)
@pytest.mark.skipif(_chromium() is None, reason="no Chromium/Chrome browser (Debian: apt-get install chromium)")
def test_page_layout_at_a4_width_in_chromium(calibrated):
    """Headless Chromium at an A4 width (794 × 1123 CSS px): no text cut or beyond the page (bounding boxes, scroll
    widths), the verdict and the headline figures on the first screen; the page ≤ 5 MB and the PDF printed. The page
    is the plain certificate ``report --html --pdf`` made once for this file and tests/test_report.py, opened in one
    browser launch shared with tests/test_report.py's rendering test."""
    cert = plain_certificate(calibrated)
    lay = browser_view(cert).layout
    assert 700 < lay["W"] <= A4_PX[0], lay  # the page was laid out at the A4 width
    assert lay["bad"] == [] and lay["first"], lay
    assert len(cert.html.encode()) <= 5e6 and cert.pdf.read_bytes()[:5] == b"%PDF-"


@pytest.mark.xdist_group(GROUP)
def test_u_along_a_working_path_against_monte_carlo(calibrated, tmp_path, capsys, monkeypatch):
    """A cell with a working path (a joint-space program between two configurations): U (k = 2) at each of its
    samples at the cell's TCP, its largest and median in the page, the budget's parameter and tracker terms within 5 %
    of draws of the parameters on the path; a cell of another robot refused in one line. The page's figures are
    left out (``draw_figures`` draws none): they are the plain certificate's (the same model and rows; the cell
    enters no figure), drawn and checked by the legend and page-layout tests; this test reads the page's text."""
    monkeypatch.setattr(figures, "draw_figures", lambda *args, **kwargs: {})
    d = calibrated
    with open(tmp_path / "path.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(read_measurements(d / "test.csv").joint_names[:6])
        w.writerows([[0.0, -1.745, 1.921, -1.746, -1.571, 0.0], [-0.552, -1.216, 1.686, -2.04, -1.571, -0.552]])
    (tmp_path / "cell.yaml").write_text(
        "name: path_cell\nrobot: ur10\ntool_frame: tool0\nbase: {xyz_m: [0, 0, 0], rpy_deg: [0, 0, 0]}\n"
        "tracker: {xyz_m: [0.3, -2.6, 0.5], rpy_deg: [0, 0, 90]}\nreflector_m: [0.02, 0.01, 0.1]\n"
        "tcp_m: [0.0, 0.05, 0.2]\nnoise: {sigma_xyz_m: [1.0e-5, 1.0e-5, 1.0e-5]}\nrobot_capsules: urdf\n"
        "skip_pairs: [[base_link, upper_arm_link], [forearm_link, wrist_2_link], [wrist_1_link, wrist_3_link]]\n"
        "working_paths:\n  - {name: sweep, program: path.csv, samples: 80}\n")
    assert _report(d, "test.csv", "--cell", str(tmp_path / "cell.yaml"), "--monte-carlo", "2000", "--html",
                   str(tmp_path / "path.html")) == 0
    u = json.loads((d / "gum.json").read_text())["uncertainty"]
    (p,) = u["paths"]
    page = (tmp_path / "path.html").read_text()
    assert "along each working path" in page and f"{p['U_max_m'] * 1e3:.3f} mm" in page
    assert p["name"] == "sweep" and p["n"] == len(p["U_m"]) >= 80
    assert p["U_max_m"] == pytest.approx(max(p["U_m"])) and min(p["U_m"]) <= p["U_median_m"] <= p["U_max_m"]
    assert abs(p["monte_carlo"]["median_ratio"] - 1.0) < 0.05
    shares = {c["key"]: c["share"] for c in p["budget"]["contributions"]}
    assert sum(shares.values()) == pytest.approx(1.0) and shares["held"] > 0  # the cell's TCP is not the reflector
    capsys.readouterr()
    assert _report(d, "test.csv", "--cell", "kr15") == 2
    err = capsys.readouterr().err
    assert "--cell kr15" in err and err.count("\n") == 1


def test_a_reflector_that_conforms_does_not_stand_for_a_tcp_whose_u_exceeds_the_requirement():
    """ISO 14253-1 on the held-out figure (the reflector's) is qualified by the TCP's U at the working
    configurations: above the required accuracy a 'conforms' becomes 'undetermined' with the reason; below it, or
    without a budget, the figure's verdict stands."""
    from pin_kpi_oed.report.certify import conformity_section

    acc, unc = {"p95_m": 0.035e-3}, {"p95_m": 0.006e-3}
    tcp = {"U_max_m": 1.0e-3, "tcp_m": [0.15, 0.0, 0.0]}
    c = conformity_section(acc, unc, 0.05e-3, "p95_m", tcp)
    assert c["verdict"] == "undetermined" and c["tcp_U_max_m"] == pytest.approx(1.0e-3)
    assert "at the TCP ((150, 0, 0) mm in the tool frame) not shown" in c["at_tcp"] and "1.000 mm" in c["at_tcp"]
    assert conformity_section(acc, unc, 2e-3, "p95_m", tcp)["verdict"] == "conforms"
    assert "at_tcp" not in conformity_section(acc, unc, 2e-3, "p95_m", tcp)
    assert conformity_section(acc, unc, 0.05e-3, "p95_m")["verdict"] == "conforms"
    bad = conformity_section({"p95_m": 0.2e-3}, unc, 0.05e-3, "p95_m", tcp)
    assert bad["verdict"] == "does not conform" and "at_tcp" in bad


@pytest.mark.xdist_group(GROUP)
def test_report_states_the_tcp_when_only_the_reflector_conforms(calibrated, tmp_path, monkeypatch):
    """Through the command: a required accuracy between the reflector's held-out figure + U and the TCP's U is
    'undetermined' in the summary, the JSON and the page, naming the TCP's U. The required accuracy is twice the
    reflector's figure + U of the plain certificate (the same rows: a TCP moves no held-out figure, asserted), which
    lies between the two when the TCP's U exceeds 3 × that figure (asserted). The page's figures are left out
    (``draw_figures`` draws none): they are the plain certificate's, checked by the legend and page-layout tests. The
    plain certificate is read first: made here with no figures, it would be the one the page tests read after."""
    plain = plain_certificate(calibrated).cert
    monkeypatch.setattr(figures, "draw_figures", lambda *args, **kwargs: {})
    fig = plain["accuracy"]["after"]["p95_m"] + plain["uncertainty"]["figures"]["p95_m"]
    d = calibrated
    doc = json.loads((d / "model.json").read_text())  # the model with a TCP 15 cm out along the tool axis
    doc["tcp_m"], doc["tool_source"] = [0.02, 0.01, 0.25], "the test: a TCP away from the reflector"
    (tmp_path / "model.json").write_text(json.dumps(doc))
    for f in ("train.csv", "test.csv"):
        (tmp_path / f).write_text((d / f).read_text())
    req = 2.0 * fig
    html = tmp_path / "c.html"
    assert _report(tmp_path, "test.csv", "--required-accuracy", repr(req), "--html", str(html)) == 0
    cert = json.loads((tmp_path / "gum.json").read_text())
    assert cert["accuracy"]["after"]["p95_m"] + cert["uncertainty"]["figures"]["p95_m"] == pytest.approx(fig,
                                                                                                         rel=1e-12)
    U_tcp = cert["uncertainty"]["budget"]["U_max_m"]
    assert U_tcp > 3 * fig  # the held parameters' tolerance at the TCP, which no reflector row sees
    con = cert["uncertainty"]["conformity"]
    assert con["verdict"] == "undetermined" and con["tcp_U_max_m"] == pytest.approx(U_tcp)
    assert cert["summary"]["verdict"]["kind"] == "undetermined" and "at the TCP" in cert["summary"]["verdict"]["text"]
    assert "not shown: its U (k = 2)" in html.read_text()


def test_budget_draws_and_coverage_are_those_of_the_former_one_step_computations():
    """The Monte-Carlo's draws D F z (``linear_draws``: D F formed once, then one product with the draws) equal the
    former one-step contraction of D, F and z to 1e-12 relative, same generator, and so do the discrepancy's draws
    (``discrepancy_draws``: L z as one batched product); ``ball_coverage`` (each row's eigenvalues in one batched
    call, the squared draws formed once) is bit for bit the former per-row loop."""
    rng = np.random.default_rng(8)
    D = rng.standard_normal((40, 3, 12)) * 1e-3
    B = rng.standard_normal((12, 9))
    C = B @ B.T  # rank 9: the clipped eigenvalues of a confounded covariance too
    new = linear_draws(D, C, 500, np.random.default_rng(9))
    w, V = np.linalg.eigh(C)
    F = V * np.sqrt(np.maximum(w, 0.0))
    old = np.einsum("map,pk,nk->nma", D, F, np.random.default_rng(9).standard_normal((500, 12)))
    assert new.shape == (500, 40, 3) and np.abs(new - old).max() < 1e-12 * np.abs(old).max()
    K = np.exp(-0.5 * (np.arange(40)[:, None] - np.arange(40)[None]) ** 2 / 9.0)  # a smooth kernel over 40 rows
    scale, white = np.array([1e-5, 2e-5, 3e-5]), 4e-12
    new = discrepancy_draws(K, scale, white, 300, np.random.default_rng(10))
    g = np.random.default_rng(10)
    Lk = np.linalg.cholesky(K + 1e-12 * np.eye(40))
    old = (np.einsum("ij,nja->nia", Lk, g.standard_normal((300, 40, 3))) * scale
           + g.standard_normal((300, 40, 3)) * np.sqrt(white))
    assert new.shape == (300, 40, 3) and np.abs(new - old).max() < 1e-12 * np.abs(old).max()
    A = rng.standard_normal((60, 3, 3)) * 1e-4
    Cs = A @ np.swapaxes(A, 1, 2)
    U = rng.uniform(1.5, 2.5, 60) * np.sqrt(np.einsum("maa->m", Cs))
    z = np.random.default_rng(0).standard_normal((20000, 3))
    former = [np.mean((z ** 2) @ np.maximum(np.linalg.eigh(0.5 * (c + c.T))[0], 0.0) <= u ** 2) for c, u in zip(Cs, U)]
    got = ball_coverage(Cs, U, seed=0)
    assert np.array_equal(got, former) and 0.3 < got.min() < got.max() < 1.0
