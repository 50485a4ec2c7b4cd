"""Sim-to-real gap diagnosis: withheld effects (a few seeds), no effect, bad input, K-fold, CLI."""

from __future__ import annotations

import json

import numpy as np
import pinocchio as pin
import pytest

from pin_kpi_oed.cli.app import main as cli_main
from pin_kpi_oed.diagnosis.diagnose import diagnose
from pin_kpi_oed.effects.library import EFFECT_NAMES, parse_effects_spec, size_effect, visible_rms
from pin_kpi_oed.data.measurements import MeasurementSet, write_measurements
from pin_kpi_oed.model.noise import NoiseModel
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.model.robot import load_robot
from pin_kpi_oed.simulation.simulator import Tolerances, default_tracker_pose, random_truth, simulate
from pin_kpi_oed.viz.diagnosis_plots import diagnosis_figures

SIGMA = 1e-5
REFL = np.array([0.05, 0.02, 0.10])


@pytest.fixture(scope="module")
def ur10():
    return load_robot("ur10")


def make_case(rb, effect, seed, n, k=5.0, temperature=True):
    """UR10 data with ``effect`` sized so its visible part is k × σ (per-axis RMS); (nominal model, train, test)."""
    rng = np.random.default_rng(100 + seed)
    truth = TrackerModel(rb, tracker_T_base=default_tracker_pose(rb), reflector_m=REFL, noise=NoiseModel((SIGMA,) * 3))
    p = random_truth(truth, Tolerances(tracker_translation_m=0.01, tracker_rotation_rad=0.01), seed=seed)
    m = 2 * n
    Q = rb.random_q(rng, m)
    aux = {"temperature_c": 20 + 5 * rng.random(m)} if temperature else {}
    effects = []
    if effect:
        (eff, th), = parse_effects_spec(f"{effect}=1", rb, rng)
        ms = MeasurementSet(rb.joint_names, Q, np.zeros((m, 3)), temperature_c=aux.get("temperature_c"))
        th = size_effect(truth, p, Q, ms, eff, th, k * SIGMA)
        assert abs(visible_rms(truth, p, Q, ms, [(eff, th)]) / (k * SIGMA) - 1) < 1e-3
        effects = [(eff, th)]
    data = simulate(truth, Q, p, effects=effects, aux=aux, seed=seed)
    nominal = TrackerModel(rb, reflector_m=REFL, noise=NoiseModel((SIGMA,) * 3))
    return nominal, data.subset(np.arange(n)), data.subset(np.arange(n, m))


#: the tests that read :func:`compliance_case`: on one xdist worker, so that its diagnosis and figures are made once
shares_compliance_case = pytest.mark.xdist_group("diagnosis_compliance_case")


@pytest.fixture(scope="module")
def compliance_case(ur10, tmp_path_factory):
    nominal, tr, te = make_case(ur10, "joint_compliance", 0, 250, k=4.0)
    figs = tmp_path_factory.mktemp("figs")
    rep = diagnose(nominal, tr, te)
    # the two strongest regressors' figures and the effects' (n_top=2): each kind of figure is drawn, and each drawing
    # costs about 0.6 s CPU
    rep.figures = diagnosis_figures(rep, figs, n_top=2)
    return nominal, tr, te, rep, figs


@shares_compliance_case
def test_compliance_named_and_gap_closed(compliance_case):
    _, _, _, rep, figs = compliance_case
    assert rep.gap_detected
    assert rep.dominant_effect == "joint_compliance"
    assert rep.selected_effects[0] == "joint_compliance"
    assert rep.heldout_after["rms_m"] <= 1.1 * rep.noise_floor_m
    assert rep.gap_closed_fraction > 0.9
    top = rep.effects[0]
    assert top.name == "joint_compliance" and top.significant
    # ranked by held-out reduction
    red = [e.heldout_rms_before_m - e.heldout_rms_after_m for e in rep.effects if e.status == "ok"]
    assert red == sorted(red, reverse=True)
    # effects that have nothing to fit are not significant
    assert not rep.effect("thermal_expansion").significant and not rep.effect("joint_scale").significant
    # where: gravity / reach show up among the strongest associations
    assert rep.where["strongest"]
    assert len(rep.where["regions"]) == 8
    # figures: PNG files
    pngs = sorted(figs.glob("*.png"))
    assert len(pngs) == 3 and "effects_heldout_rms.png" in {p.name for p in pngs}
    assert all(p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for p in pngs)
    assert not list(figs.glob(".*.tmp"))


@shares_compliance_case
def test_report_dict_is_json(compliance_case):
    rep = compliance_case[3]
    d = rep.to_dict()
    text = json.dumps(d, allow_nan=False)
    back = json.loads(text)
    for key in ("gap_detected", "dominant_effect", "effects", "noise_floor_m", "heldout_before", "heldout_after",
                "gap_closed_fraction", "where", "unobservable", "selection"):
        assert key in back
    assert back["dominant_effect"] in list(EFFECT_NAMES) + ["none"]
    for e in back["effects"]:
        for key in ("name", "heldout_rms_before_m", "heldout_rms_after_m", "gap_closed_fraction", "significant"):
            assert key in e
    assert any("range" in n for n in back["unobservable"])
    s = rep.summary()
    assert "dominant effect: joint_compliance" in s and "not observable" in s


@pytest.mark.parametrize("effect,seed", [("gear_harmonic", 1), ("backlash", 2), ("thermal_expansion", 3),
                                         ("joint_scale", 4)])
def test_withheld_effect_named(ur10, effect, seed):
    nominal, tr, te = make_case(ur10, effect, seed, 250, k=3.0)
    rep = diagnose(nominal, tr, te)
    assert rep.gap_detected
    assert rep.dominant_effect == effect
    assert rep.effect(effect).heldout_rms_after_m <= 1.1 * rep.noise_floor_m


@pytest.mark.parametrize("seed", [0, 1])
def test_no_effect_no_gap(ur10, seed):
    nominal, tr, te = make_case(ur10, None, seed, 250)
    rep = diagnose(nominal, tr, te)
    assert not rep.gap_detected
    assert rep.dominant_effect == "none"
    assert rep.heldout_before["rms_m"] <= 1.1 * rep.noise_floor_m


@shares_compliance_case
def test_validation_from_other_tracker_placement(compliance_case):
    nominal, tr, te, _, _ = compliance_case
    moved = MeasurementSet(te.joint_names, te.q, te.position_m + np.array([0.03, -0.01, 0.0]), sigma_m=te.sigma_m,
                           temperature_c=te.temperature_c)
    rep = diagnose(nominal, tr, moved)
    assert rep.validation_mismatch
    assert rep.dominant_effect == "none"
    assert "another robot or tracker placement" in rep.mismatch["message"]
    assert len(rep.effects) == len(EFFECT_NAMES)  # the rest of the report is still produced


@shares_compliance_case
def test_transfer_validation_reregisters_the_setup(compliance_case, tmp_path, capsys):
    """Validation from another session (tracker moved by metres and turned): re-registered on 40 rows, the
    rest scored; without the registration it is a mismatch."""
    nominal, tr, te, rep0, _ = compliance_case
    R = pin.rpy.rpyToMatrix(0.05, -0.03, 1.2)
    t = np.array([1.5, -2.0, 0.3])
    moved = MeasurementSet(te.joint_names, te.q, te.position_m @ R.T + t, sigma_m=te.sigma_m,
                           temperature_c=te.temperature_c, source="moved.csv")
    rep = diagnose(nominal, tr, moved, register_rows=40, seed=2, effects=["joint_compliance", "joint_scale"])
    assert rep.mode == "transfer" and not rep.validation_mismatch
    reg, scored = rep.registration["rows"], rep.registration["scored_rows"]
    assert len(reg) == 40 and rep.n_heldout == len(te) - 40 == len(scored) and not set(reg) & set(scored)
    assert rep.dominant_effect == "joint_compliance"
    assert rep.heldout_after["rms_m"] <= 1.15 * rep.noise_floor_m
    assert "re-registered" in rep.summary() and rep.to_dict()["registration"]["seed"] == 2
    assert rep.success and rep.status == "gap" and rep.nfev > 2
    # the CLI: same on files; JSON names the registration rows
    write_measurements(tr, tmp_path / "a.csv")
    write_measurements(moved, tmp_path / "moved.csv")
    assert cli_main(["diagnose", "--robot", "ur10", "--train", str(tmp_path / "a.csv"), "--validate",
                     str(tmp_path / "moved.csv"), "--register-rows", "40", "--seed", "2", "--reflector",
                     "0.05,0.02,0.1", "--effects", "joint_compliance", "--json", str(tmp_path / "r.json"),
                     "--quiet"]) == 0
    d = json.loads((tmp_path / "r.json").read_text())
    assert d["registration"]["rows"] == reg and d["dominant_effect"] == "joint_compliance" and d["mode"] == "transfer"
    assert cli_main(["diagnose", "--robot", "ur10", "--train", str(tmp_path / "a.csv"), "--kfold", "3",
                     "--register-rows", "40"]) == 2
    assert "need --validate" in capsys.readouterr().err


@shares_compliance_case
def test_some_rows_from_elsewhere_are_named_and_left_out(compliance_case):
    nominal, tr, te, _, _ = compliance_case
    pos = te.position_m.copy()
    pos[[3, 7, 11]] += 0.05
    bad = MeasurementSet(te.joint_names, te.q, pos, sigma_m=te.sigma_m, temperature_c=te.temperature_c)
    # two candidates (the withheld one and one with nothing to fit): the rows are named before any effect is fitted,
    # and the named effect is the withheld one with the three rows left out
    rep = diagnose(nominal, tr, bad, effects=["joint_compliance", "joint_scale"])
    assert not rep.validation_mismatch
    assert rep.mismatch["rows"] == [4, 8, 12]
    assert rep.n_heldout == len(te) - 3
    assert rep.dominant_effect == "joint_compliance"


def test_missing_temperature_and_too_few_rows(ur10):
    nominal, tr, te = make_case(ur10, "joint_compliance", 5, 25, k=6.0, temperature=False)
    rep = diagnose(nominal, tr, te)
    th = rep.effect("thermal_expansion")
    assert th.status == "skipped" and "temperature" in th.message
    gh = rep.effect("gear_harmonic")
    assert gh.status == "skipped" and "too few training rows" in gh.message
    assert rep.effect("joint_compliance").status == "ok"
    assert rep.dominant_effect == "joint_compliance"
    assert any("temperature" in n for n in rep.notes)


@shares_compliance_case
def test_kfold_on_one_file(compliance_case):
    nominal, tr, _, _, _ = compliance_case
    rep = diagnose(nominal, tr, kfold=3, effects=["joint_compliance", "joint_scale"])
    assert rep.mode == "kfold" and rep.k_folds == 3 and rep.n_heldout == len(tr)
    assert rep.dominant_effect == "joint_compliance"
    exact = diagnose(nominal, tr, kfold=3, effects=["joint_compliance", "joint_scale"], exact_kfold=True)
    assert np.isclose(exact.heldout_before["rms_m"], rep.heldout_before["rms_m"], rtol=1e-4)
    assert np.isclose(exact.heldout_after["rms_m"], rep.heldout_after["rms_m"], rtol=1e-4)
    with pytest.raises(Exception, match="either"):
        diagnose(nominal, tr)


@shares_compliance_case
def test_cli_diagnose(compliance_case, tmp_path, capsys):
    _, tr, te, _, _ = compliance_case
    write_measurements(tr, tmp_path / "a.csv")
    write_measurements(te, tmp_path / "b.csv")
    out = tmp_path / "r.json"
    rc = cli_main(["diagnose", "--robot", "ur10", "--train", str(tmp_path / "a.csv"), "--validate",
                   str(tmp_path / "b.csv"), "--reflector", "0.05,0.02,0.1", "--json", str(out), "--effects",
                   "joint_compliance,backlash", "--quiet"])
    assert rc == 0
    d = json.loads(out.read_text())
    assert d["dominant_effect"] == "joint_compliance" and d["gap_detected"] is True
    assert "dominant_effect=joint_compliance" in capsys.readouterr().out
    # a file without sigma columns needs --sigma: one-line error, exit code 2
    nosig = MeasurementSet(tr.joint_names, tr.q, tr.position_m)
    write_measurements(nosig, tmp_path / "c.csv")
    rc = cli_main(["diagnose", "--robot", "ur10", "--train", str(tmp_path / "c.csv"), "--kfold", "3"])
    err = capsys.readouterr().err
    assert rc == 2 and "--sigma" in err and len(err.strip().splitlines()) == 1
    rc = cli_main(["diagnose", "--robot", "ur10", "--train", str(tmp_path / "a.csv"), "--kfold", "3",
                   "--effects", "tracker_scale"])
    err = capsys.readouterr().err
    assert rc == 2 and "cannot be observed" in err


def test_terms_chosen_on_training_but_not_held_out_are_said_in_the_verdict():
    """15 transmission terms chosen by the K-fold selection and then not selected on the held-out rows: the verdict
    says so (message clause and a note with the numbers), never a bare 'dominant effect: none'."""
    from pin_kpi_oed.diagnosis.diagnose import unconfirmed_terms
    from pin_kpi_oed.diagnosis.report import EffectResult

    ts = {"terms": [{"text": f"t{k}"} for k in range(15)], "cv_rms_m": [178.6e-6, 34.2e-6]}
    e = EffectResult("transmission_error", heldout_rms_before_m=2.1e-4, heldout_rms_after_m=2.0e-4)
    e.heldout_pvalue = 0.4
    notes: list[str] = []
    clause = unconfirmed_terms(ts, ["transmission_error"], [], [e], notes)
    assert clause == "; the 15 term(s) chosen on the training rows are not confirmed held-out"
    assert len(notes) == 1 and "178.6 -> 34.2 µm" in notes[0] and "210.0 -> 200.0 µm, p_heldout 0.4" in notes[0]
    assert unconfirmed_terms(ts, ["transmission_error"], ["transmission_error"], [e], []) == ""
    assert unconfirmed_terms({}, [], [], [], []) == ""


def test_coverage_advice_stays_within_the_joint_limits():
    """Uncovered validation angles of a ±2.90 rad joint on both sides of ±π are advised as their own values (within
    the limits, as intervals), never as a wrapped arc such as 0.51 .. 5.88 rad."""
    from pin_kpi_oed.diagnosis.transfer_gap import joint_ranges_of, gap_poses_to_add

    rng = np.random.default_rng(0)
    Qt = rng.uniform(-0.5, 0.5, (40, 1))
    Qv = np.concatenate([rng.uniform(-2.9, -2.5, 10), rng.uniform(0.51, 2.9, 20)])[:, None]
    cov = np.abs(Qv - 0.0) < 0.5
    joints = joint_ranges_of(["panda_joint1"], Qt, Qv, cov)
    iv = joints[0]["uncovered_intervals"]
    assert -2.9 <= joints[0]["uncovered_min"] and joints[0]["uncovered_max"] <= 2.9
    assert len(iv) == 2 and iv[0][1] < -2.4 and iv[1][0] > 0.5
    text = gap_poses_to_add(joints, np.full(30, 1e-4), np.arange(30), 30)["text"]
    import re
    vals = [float(x) for x in re.findall(r"(-?\d+\.\d+) \.\. (-?\d+\.\d+)", text)[0] + re.findall(
        r"(-?\d+\.\d+) \.\. (-?\d+\.\d+)", text)[1]]
    assert all(-2.9 <= v <= 2.9 for v in vals) and "panda_joint1" in text and " and " in text, text


def test_coverage_advice_for_a_track_is_in_metres_and_never_wrapped():
    """A linear track (m) is compared on the line: its ranges are min .. max within its 6.4 m travel (never wrapped
    mod 2π, which would put 6.3 m next to 0.02 m) and the advice names them in m; a periodic wrist stays an arc in
    rad."""
    from pin_kpi_oed.diagnosis.transfer_gap import joint_ranges_of, gap_poses_to_add
    from pin_kpi_oed.calibrated.coverage import COVERAGE_TOL_RAD, covered_rows
    from pin_kpi_oed.model.robot import load_robot

    robot = load_robot("kr15_track")
    rng = np.random.default_rng(1)
    Qt = np.tile(robot.neutral(), (60, 1))
    Qv = np.tile(robot.neutral(), (30, 1))
    Qt[:, 0], Qv[:, 0] = rng.uniform(0.0, 3.0, 60), rng.uniform(5.0, 6.4, 30)
    Qt[:, 4], Qv[:, 4] = rng.uniform(-3.0, 3.0, 60), rng.uniform(-3.0, 3.0, 30)
    cov = covered_rows(Qt, Qv, COVERAGE_TOL_RAD, robot.periodic_joints)
    joints = joint_ranges_of(robot.joint_names, Qt, Qv, cov, robot.periodic_joints, robot.joint_units)
    track = joints[0]
    assert track["unit"] == "m" and not track["periodic"] and track["coverage"] == 0.0
    assert 5.0 <= track["validate_min"] < track["validate_max"] <= 6.4
    assert 0.0 <= track["train_min"] < track["train_max"] <= 3.0
    assert 5.0 <= track["uncovered_min"] and track["uncovered_max"] <= 6.4
    assert joints[4]["unit"] == "rad" and joints[4]["periodic"]
    text = gap_poses_to_add(joints, np.full(30, 1e-4), np.arange(30), 30)["text"]
    assert f"joint_e1 {track['uncovered_min']:.2f} .. {track['uncovered_max']:.2f} m" in text, text
