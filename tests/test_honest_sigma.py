"""The σ is honest on every path: the mechanisms pinned one by one.

3m − p correction of the white level against Monte-Carlo, the stated-noise floor, grouped K-fold folds, joint-space
coverage (the combination of the angles), the parameter covariance in a noise-only model's σ, position outliers of
6-D fits, an undetermined effect refused, the API's defaults equal to the command line's.
"""

from __future__ import annotations

import dataclasses
import json
from types import SimpleNamespace

import numpy as np
import pytest

from pin_kpi_oed.cli.app import main
from pin_kpi_oed.data.measurements import write_measurements
from pin_kpi_oed.discrepancy.coverage import JointCoverage
from pin_kpi_oed.discrepancy.fit import fit_discrepancy
from pin_kpi_oed.discrepancy.gp import DiscrepancyOptions, grouped_folds, sigma_plan, white_level
from pin_kpi_oed.effects.thermal import ThermalExpansion
from pin_kpi_oed.errors import InputError, SolverError
from pin_kpi_oed.identification.discrepancy_fit import position_outliers
from pin_kpi_oed.identification.identify import identify
from pin_kpi_oed.calibrated.model_file import load_model_file
from pin_kpi_oed.simulation.simulator import Tolerances, default_tracker_pose, random_truth, simulate
from pin_kpi_oed.model.noise import NoiseModel
from pin_kpi_oed.model.robot import load_robot
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.oed.identifiability import analyse

SIG = 1e-5


@pytest.fixture(scope="module")
def ur10_model():
    robot = load_robot("ur10")
    return TrackerModel(robot, tracker_T_base=default_tracker_pose(robot), reflector_m=np.array([0.03, 0.02, 0.08]),
                        noise=NoiseModel(sigma_xyz_m=(SIG,) * 3))


def _truth(model, seed):
    return random_truth(model, Tolerances(5e-4, 1e-3), seed=seed, only=[i for i in analyse(model).base if i < 36])


# --------------------------------------------------------------------------- white level
def test_white_level_corrects_for_the_fitted_parameters_monte_carlo():
    """Residuals of a least-squares fit of p parameters to 3m components: E[Σ r²] = σ²(3m − p). The white level
    (its small-sample widening divided out) is σ on average over Monte-Carlo draws; the plain residual RMS is
    sqrt((3m − p) / 3m) σ, 0.5 σ here."""
    rng = np.random.default_rng(0)
    m, p, sigma = 12, 18, 2e-4
    F = rng.standard_normal((3 * m, p))
    H = F @ np.linalg.pinv(F)
    est, raw = [], []
    for _ in range(4000):
        r = (np.eye(3 * m) - H) @ (sigma * rng.standard_normal(3 * m))
        level, k, widen = white_level(r.reshape(m, 3), p)
        est.append(np.mean((level / widen) ** 2))
        raw.append(np.mean(r ** 2))
    assert k == 3 * m - p
    assert abs(np.sqrt(np.mean(est)) / sigma - 1.0) < 0.02
    assert abs(np.sqrt(np.mean(raw)) / sigma - np.sqrt(k / (3 * m))) < 0.02
    # the widening makes the 95 % ellipsoid of a new error hold 95 %: 3 F(3, k) quantile over the chi2_3 one
    assert 1.05 < widen < 1.2 and white_level(np.zeros((60, 3)), 18)[2] < 1.03


def test_white_level_never_below_the_stated_noise():
    level, _, _ = white_level(np.full((50, 3), 2e-6), 10, floor_m=np.full(3, 1e-5))
    assert np.allclose(level, 1e-5)
    rng = np.random.default_rng(1)
    Q = rng.uniform(-2, 2, (150, 6))
    R = 2e-6 * rng.standard_normal((150, 3)) + 5e-5 * np.sin(2 * Q[:, :3])        # smooth + noise far below 10 µm
    d = fit_discrepancy(Q, R, [f"j{i}" for i in range(6)], DiscrepancyOptions(mode="on", n_fit=150),
                        noise_floor_m=np.full(3, 1e-5))
    assert np.all(np.sqrt(d.noise_var_m2) >= 1e-5 * (1 - 1e-9)), np.sqrt(d.noise_var_m2)


def test_white_sigma_honest_at_few_poses(ur10_model):
    """No unmodelled effect, 14 poses, a noise model ten times too optimistic (what a white level corrects): the
    white level with 3m − p and the parameter covariance is honest on held-out poses; the residual RMS alone
    (the former white level) is not."""
    model = ur10_model
    rng = np.random.default_rng(3)
    zs = []
    for seed in range(6):
        truth = _truth(model, seed)
        Q, Qh = model.robot.random_q(rng, 14), model.robot.random_q(rng, 100)
        loud = dataclasses.replace(model, noise=NoiseModel(sigma_xyz_m=(1e-4,) * 3))
        train, held = simulate(loud, Q, truth, seed=seed + 10), simulate(loud, Qh, truth, seed=seed + 20)
        train, held = dataclasses.replace(train, sigma_m=None), dataclasses.replace(held, sigma_m=None)
        fit = identify(model, train)
        assert fit.discrepancy.kind == "white" and "3m - p" in fit.discrepancy.decision
        cm = fit.calibrated_model()
        Y, sig, _ = cm.predict_with_sigma(held.q)
        zs.append(((held.position_m - Y) / sig) ** 2)
        raw = np.sqrt(np.mean(fit.residuals_m ** 2, axis=0))
        assert np.all(cm.discrepancy.scale_m > 1.3 * raw)
    z = np.vstack(zs)
    assert 0.8 <= np.sqrt(z.mean()) <= 1.2 and 0.88 <= np.mean(z.sum(1) <= 7.8147) <= 0.99, np.sqrt(z.mean())


# --------------------------------------------------------------------------- grouped folds
def test_grouped_folds_keep_repeated_poses_together_and_the_gain_is_not_leaked():
    rng = np.random.default_rng(4)
    base = rng.uniform(-3, 3, (80, 6))
    Q = np.repeat(base, 3, axis=0) + 1e-3 * rng.standard_normal((240, 6))
    fold, groups = grouped_folds(Q, 5, 0)
    assert groups == 80 and all(len(set(fold[3 * i:3 * i + 3])) == 1 for i in range(80))
    assert np.bincount(fold).min() >= 45                        # balanced: 48 rows per fold
    # each pose has its own error (no smooth structure to learn): repeats make an ungrouped K-fold look like a gain
    R = np.repeat(1e-4 * rng.standard_normal((80, 3)), 3, axis=0) + 1e-6 * rng.standard_normal((240, 3))
    d = fit_discrepancy(Q, R, [f"j{i}" for i in range(6)], DiscrepancyOptions(mode="auto", n_fit=240))
    assert d.cv["grouped"] and d.cv["gain"] < 0.1 and d.kind == "white", d.decision


def test_distinct_poses_count_towards_the_gaussian_process():
    rng = np.random.default_rng(5)
    Q = np.repeat(rng.uniform(-3, 3, (30, 6)), 3, axis=0)
    d = fit_discrepancy(Q, 1e-4 * rng.standard_normal((90, 3)), [f"j{i}" for i in range(6)], DiscrepancyOptions())
    assert d.kind == "white" and "30 distinct poses" in d.decision


# --------------------------------------------------------------------------- coverage
def test_coverage_judges_the_combination_of_angles():
    rng = np.random.default_rng(6)
    # training: two clusters of configurations; each joint's angles cover [-1, 1] and [2, 3]
    A = np.column_stack([rng.uniform(-1, 1, 300)] * 2 + [rng.uniform(-0.5, 0.5, (300, 4))])
    B = np.column_stack([rng.uniform(2, 3, 300)] * 2 + [rng.uniform(-0.5, 0.5, (300, 4))])
    A[:, 1], B[:, 1] = rng.uniform(-1, 1, 300), rng.uniform(2, 3, 300)
    cov = JointCoverage.from_training(np.vstack([A, B]))
    same = np.column_stack([rng.uniform(-1, 1, (100, 2)), rng.uniform(-0.5, 0.5, (100, 4))])
    mixed = same.copy()
    mixed[:, 1] = rng.uniform(2, 3, 100)                 # joint 0 from cluster A, joint 1 from cluster B
    assert cov.share_covered(same) > 0.9
    assert cov.joint_distance(mixed).max() < 0.1         # every angle was measured on its own joint...
    assert cov.share_covered(mixed) < 0.05               # ...but never together: flagged


def test_coverage_wraps_only_joints_whose_range_spans_a_turn():
    """A linear track (m) and a revolute joint narrower than 2π are judged linearly; a joint of ±2π wraps."""
    from pin_kpi_oed.calibrated.coverage import covered_rows
    from pin_kpi_oed.model.robot import load_robot

    track = load_robot("kr15_track")                     # joint_e1: prismatic, 0 .. 6.4 m; joint_a2: -2.71 .. 0.61
    per = track.periodic_joints
    assert list(per) == [False, True, False, False, True, False, True]
    rng = np.random.default_rng(8)
    Z = np.column_stack([rng.uniform(0.0, 0.5, 400), rng.uniform(-0.3, 0.3, (400, 6))])
    Z[:, 2] = rng.uniform(-2.7, -2.2, 400)               # joint_a2 near its lower end
    cov = JointCoverage.from_training(Z, periodic=per)
    far = Z[:50].copy()
    far[:, 0] += 2 * np.pi                               # 6.28 m further along the track: the same value mod 2π
    assert cov.share_covered(Z[50:100]) > 0.9 and cov.share_covered(far) == 0.0
    assert np.all(JointCoverage.from_training(Z).covered(far))          # what wrapping every joint said
    assert not covered_rows(Z, far, 0.05, per)[:, 0].any() and covered_rows(Z, far, 0.05)[:, 0].all()
    # the block written to a model file keeps the mask
    back = JointCoverage.from_dict(cov.to_dict(), 7, "coverage")
    assert list(back.periodic) == list(per) and back.share_covered(far) == 0.0
    # a revolute joint's ends are neighbours only when its range spans a turn: -3.1 and +3.1 rad on the UR10's ±2π
    ur10 = load_robot("ur10")
    assert ur10.periodic_joints.all()
    Zu = np.zeros((1, 6))
    Zu[0, 0] = -3.1
    Qu = Zu.copy()
    Qu[0, 0] = 3.1
    assert covered_rows(Zu, Qu, 0.1, ur10.periodic_joints).all()
    narrow = np.array([False] * 6)                       # the same joint limited to ±3.12 rad: 6.2 rad apart
    assert not covered_rows(Zu, Qu, 0.1, narrow)[0, 0]


def test_every_predicting_command_flags_a_new_combination(ur10_model, tmp_path, capsys):
    """predict (the model's σ, noise-only too) flags and widens rows whose combination of angles is new."""
    model = ur10_model
    rng = np.random.default_rng(7)
    Q = np.column_stack([rng.uniform(-1.0, 1.0, 120), np.zeros(120), rng.uniform(1.0, 1.4, 120),
                         rng.uniform(-0.2, 0.2, (120, 3))])
    Q[:, 1] = rng.uniform(-0.8, -0.6, 120) + np.where(Q[:, 0] > 0, -1.2, 0.0)    # shoulder lift tied to the pan
    truth = _truth(model, 1)
    train = simulate(model, Q, truth, seed=3)
    Qn = Q[np.abs(Q[:, 0]) > 0.3][:40].copy()          # away from the pan = 0 border between the halves
    Qn[:, 1] = np.where(Qn[:, 0] > 0, rng.uniform(-0.8, -0.6, 40), rng.uniform(-2.0, -1.8, 40))  # swapped halves
    for disc in ("none", "auto"):
        cm = identify(model, train, discrepancy=disc).calibrated_model()
        _, s_in, e_in = cm.predict_with_sigma(Q[40:80])
        _, s_new, e_new = cm.predict_with_sigma(Qn)
        assert e_new.mean() > 0.9 and e_in.mean() < 0.2, (disc, e_new.mean(), e_in.mean())
        grow = np.median(np.linalg.norm(s_new, axis=1)) / np.median(np.linalg.norm(s_in, axis=1))
        # a Gaussian process adds the universal-kriging term outside; the white and noise-only σ hold E C Eᵀ everywhere
        gp = cm.discrepancy is not None and cm.discrepancy.kind != "white"
        assert grow > (1.5 if gp else 1.0), (disc, grow)
        cm.save(tmp_path / f"{disc}.json")
        back = load_model_file(tmp_path / f"{disc}.json")
        assert np.array_equal(back.predict_with_sigma(Qn)[2], e_new)
    # the command line: the extrapolation column and one line saying how many rows and what the sigma holds
    new = simulate(model, Qn, truth, seed=5)
    write_measurements(new, tmp_path / "new.csv")
    assert main(["predict", "--model", str(tmp_path / "none.json"), "--data", str(tmp_path / "new.csv"), "--out",
                 str(tmp_path / "p.csv")]) == 0
    out = capsys.readouterr().out
    assert f"{int(e_new.sum())} of 40 rows outside the calibration's joint-space coverage" in out
    assert "parameters + noise; no discrepancy (noise-only model)" in out
    head, *rows = (tmp_path / "p.csv").read_text().splitlines()
    col = head.split(",").index("extrapolation")
    assert sum(float(r.split(",")[col]) for r in rows) == e_new.sum()


# --------------------------------------------------------------------------- parameter covariance
def test_noise_only_sigma_includes_the_parameter_covariance(ur10_model):
    """discrepancy none: σ² = noise² + diag(R E C Eᵀ Rᵀ) with C the fit's covariance of the robot parameters;
    honest on held-out poses of a correct model at few poses (where the noise alone is too small)."""
    model = ur10_model
    rng = np.random.default_rng(8)
    zs, zs_noise = [], []
    for seed in range(5):
        truth = _truth(model, seed)
        train = simulate(model, model.robot.random_q(rng, 15), truth, seed=seed + 30)
        held = simulate(model, model.robot.random_q(rng, 100), truth, seed=seed + 40)
        cm = identify(model, train, discrepancy="none").calibrated_model()
        Y, sig, _ = cm.predict_with_sigma(held.q)
        assert np.all(sig > SIG)
        zs.append(((held.position_m - Y) / sig) ** 2)
        zs_noise.append(((held.position_m - Y) / SIG) ** 2)
    assert 0.85 <= np.sqrt(np.vstack(zs).mean()) <= 1.15, np.sqrt(np.vstack(zs).mean())
    assert np.sqrt(np.vstack(zs_noise).mean()) > 1.3


# --------------------------------------------------------------------------- 6-D and effects
def test_position_outliers_of_a_6d_fit_ignore_the_orientation_rows():
    rng = np.random.default_rng(9)
    r = 1e-5 * rng.standard_normal((150, 3))
    r[:2] += 1e-3
    fake = SimpleNamespace(residuals_m=r, residuals_rad=np.ones((150, 3)), outliers=np.arange(60))
    flagged = set(position_outliers(fake).tolist())
    assert {0, 1} <= flagged and len(flagged) <= 3
    fake3 = SimpleNamespace(residuals_m=r, residuals_rad=None, outliers=np.arange(60))
    assert position_outliers(fake3).size == 60


def test_effect_from_a_constant_temperature_is_refused(ur10_model):
    model = ur10_model
    data = simulate(model, model.robot.random_q(np.random.default_rng(10), 40), _truth(model, 2), seed=1)
    data = dataclasses.replace(data, temperature_c=np.full(len(data), 21.5))
    with pytest.raises(InputError, match="thermal_expansion is not determined by the data: the temperature is "
                                         "constant"):
        identify(model, data, effects=[ThermalExpansion(model.robot)])


def test_thermal_from_a_nearly_constant_temperature_is_a_poor_fit(ur10_model):
    model = ur10_model
    data = simulate(model, model.robot.random_q(np.random.default_rng(11), 40), _truth(model, 2), seed=2)
    data = dataclasses.replace(data, temperature_c=21.5 + 1e-4 * np.random.default_rng(0).standard_normal(len(data)))
    fit = identify(model, data, effects=[ThermalExpansion(model.robot)], discrepancy="none")
    assert fit.fit_quality.poor and "not determined by the data" in fit.fit_quality.line()
    with pytest.raises(SolverError, match="not determined"):
        identify(model, data, effects=[ThermalExpansion(model.robot)], discrepancy="none", on_poor_fit="raise")


# --------------------------------------------------------------------------- API = CLI
def test_api_defaults_equal_the_command_line(ur10_model, tmp_path, capsys):
    """The same data, reflector and noise: identify's Python defaults and the command line give the same model
    (discrepancy auto, same seed) and the same predicted σ; the API flags the gate's verdict."""
    model = ur10_model
    rng = np.random.default_rng(12)
    from pin_kpi_oed.effects.library import GearHarmonic
    gh = GearHarmonic(model.robot, joints=["shoulder_lift_joint", "elbow_joint"], orders=(2, 3))
    th = 3e-4 * rng.standard_normal(len(gh.param_names()))
    # no sigma columns: the command line's --sigma and the API's noise model weight the rows alike (sigma columns
    # of the same value give the same fit to 1e-9 m, which the hyper-parameters' optimiser may amplify)
    data = simulate(model, model.robot.random_q(rng, 90), _truth(model, 3), effects=[(gh, th)], seed=4,
                    record_sigma=False)
    held = simulate(model, model.robot.random_q(rng, 50), _truth(model, 3), effects=[(gh, th)], seed=5)
    write_measurements(data, tmp_path / "d.csv")
    out = tmp_path / "m.json"
    rc = main(["identify", "--robot", "ur10", "--data", str(tmp_path / "d.csv"), "--reflector", "0.03,0.02,0.08",
               "--sigma", str(SIG), "--model-out", str(out), "--accept-poor-fit", "--quiet"])
    assert rc == 0
    fit = identify(model, data)
    assert fit.fit_quality is not None and fit.fit_quality.line() in fit.summary()
    cli, api = load_model_file(out), fit.calibrated_model()
    assert cli.discrepancy.kind == api.discrepancy.kind
    Yc, sc, ec = cli.predict_with_sigma(held.q)
    Ya, sa, ea = api.predict_with_sigma(held.q)
    assert np.allclose(Yc, Ya, atol=1e-9) and np.allclose(sc, sa, rtol=1e-6) and np.array_equal(ec, ea)
    assert json.loads(out.read_text())["coverage"]["measure"] == "joint_space_nearest/1"


def test_api_and_command_line_switch_to_the_robust_loss_alike(ur10_model, tmp_path):
    """A file with gross outliers: the command line and the Python API take the same default loss decision (one
    place: identify's loss="auto") and give the same numbers; loss="linear" keeps the plain fit in both."""
    model = ur10_model
    rng = np.random.default_rng(13)
    data = simulate(model, model.robot.random_q(rng, 120), _truth(model, 3), seed=6, record_sigma=False)
    bad = np.array([23])
    data.position_m[bad] += 5e-3 * np.array([0.6, -0.8, 0.0])           # 5 mm against 10 µm noise
    write_measurements(data, tmp_path / "d.csv")
    base = ["identify", "--robot", "ur10", "--data", str(tmp_path / "d.csv"), "--reflector", "0.03,0.02,0.08",
            "--discrepancy", "none", "--accept-poor-fit", "--quiet"]
    common = base + ["--sigma", str(SIG)]
    assert main(common + ["--json", str(tmp_path / "cli.json")]) == 0
    cli = json.loads((tmp_path / "cli.json").read_text())["result"]
    api = identify(model, data, discrepancy="none")
    assert api.loss == cli["loss"] == "soft_l1" and "far beyond the noise" in api.loss_decision
    assert api.loss_decision in api.summary() and cli["loss_decision"] == api.loss_decision
    par = cli["parameters"]
    assert [p["name"] for p in par] == api.names
    assert np.allclose([p["value"] for p in par], api.values, rtol=0, atol=1e-12)
    assert np.allclose([p["std"] for p in par], api.std, rtol=1e-9, atol=0)
    assert set(bad.tolist()) <= set(api.outliers.tolist())
    # the plain fit on request, in both: the outliers pull it
    assert main(common + ["--loss", "linear", "--json", str(tmp_path / "lin.json")]) == 0
    lin = json.loads((tmp_path / "lin.json").read_text())["result"]
    plain = identify(model, data, discrepancy="none", loss="linear")
    assert lin["loss"] == plain.loss == "linear" and not plain.loss_decision
    assert np.allclose([p["value"] for p in lin["parameters"]], plain.values, rtol=0, atol=1e-12)
    assert np.median(api.errors_m) < 0.5 * np.median(plain.errors_m)
    # the noise level unknown (no --sigma; the API's scale_covariance): any flagged outlier switches, in both
    assert main(base + ["--json", str(tmp_path / "unknown.json")]) == 0
    unk = json.loads((tmp_path / "unknown.json").read_text())["result"]
    api_unk = identify(model, data, discrepancy="none", scale_covariance=True)
    assert unk["loss"] == api_unk.loss == "soft_l1" and unk["loss_decision"] == api_unk.loss_decision
    assert np.allclose([p["value"] for p in unk["parameters"]], api_unk.values, rtol=0, atol=1e-12)


def test_design_says_how_the_sigma_will_be_obtained():
    few = sigma_plan(35, 33)
    assert "fewer than the 60" in few and "3m - p = 72" in few and "parameter covariance" in few
    assert "Gaussian process" in sigma_plan(80, 33) and "repeated poses in one fold" in sigma_plan(80, 33)
    assert "no residual" in sigma_plan(10, 33)
