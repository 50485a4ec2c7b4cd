"""The withheld-effect study of the discrepancy-aware KPI (pin_kpi_oed.studies.kpi_withheld), the discrepancy's use
of rows flagged as outliers when too few are left, and the poses-needed answer when the target is already met."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from pin_kpi_oed import NoiseModel, TrackerModel, load_robot
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.simulation.simulator import default_tracker_pose
from pin_kpi_oed.studies.kpi_withheld import (DESIGNS, paired_summary, predicted_tcp, true_tcp, withheld_case,
                                              withheld_truth, working_region)


@pytest.fixture(scope="module")
def model():
    robot = load_robot("ur10")
    return TrackerModel(robot, tracker_T_base=default_tracker_pose(robot), reflector_m=np.array([0.05, 0.0, 0.10]),
                        tcp_m=np.array([0.0, 0.0, 0.15]), noise=NoiseModel(sigma_xyz_m=(1e-5,) * 3))


def test_working_region_keeps_the_working_configurations_and_stays_within_the_radius():
    W0 = np.array([[0.0, -1.5, 1.5, -1.5, -1.5, 0.0], [0.5, -1.0, 1.0, -1.0, -1.5, 0.3]])
    W = working_region(W0, 3, 0.3, seed=1)
    assert W.shape == (8, 6) and np.array_equal(W[:2], W0)
    assert np.all(np.abs(W[2:5] - W0[0]) <= 0.3) and np.all(np.abs(W[5:] - W0[1]) <= 0.3)
    assert np.array_equal(W, working_region(W0, 3, 0.3, seed=1))


def test_withheld_truth_scales_the_harmonic_and_keeps_geometry_and_phases(model):
    p1, [(gh, th1)] = withheld_truth(model, 1e-3, seed=4)
    p0, [(_, th0)] = withheld_truth(model, 0.0, seed=4)
    p3, [(_, th3)] = withheld_truth(model, 3e-4, seed=4)
    assert np.array_equal(p0, p1) and np.all(th0 == 0)
    assert th3 == pytest.approx(0.3 * th1)
    amp = np.hypot(th1[0::2], th1[1::2])                     # one (sin, cos) pair per joint and order
    assert amp == pytest.approx(np.full(amp.size, 1e-3))
    assert amp.size == 3 * 2
    with pytest.raises(InputError):
        withheld_truth(model, -1e-4, seed=4)


def test_true_tcp_moves_by_the_harmonic_at_the_tcp(model):
    p, eff = withheld_truth(model, 1e-3, seed=2)
    Q = model.robot.random_q(np.random.default_rng(0), 20)
    plain = model.kpi(p, Q)
    assert np.allclose(true_tcp(model, p, [(eff[0][0], 0 * eff[0][1])], Q), plain)
    d = np.linalg.norm(true_tcp(model, p, eff, Q) - plain, axis=1)
    # up to 2 mrad per joint on three joints over a reach of about 1.3 m: a fraction of a mm to a few mm
    assert 1e-5 < d.max() < 8e-3


def test_predicted_tcp_is_the_geometry_plus_the_discrepancy_mean(model):
    from pin_kpi_oed.identification.identify import identify
    from pin_kpi_oed.simulation.simulator import simulate

    p, eff = withheld_truth(model, 3e-4, seed=1)
    rng = np.random.default_rng(3)
    Q = model.robot.random_q(rng, 80)
    cm = identify(model, simulate(model, Q, p, effects=eff, seed=5), discrepancy="on").calibrated_model()
    W = model.robot.random_q(rng, 4)
    geo = predicted_tcp(cm.noise_only(), W)
    with_d = predicted_tcp(cm, W)
    R = np.asarray(cm.setups[cm.station()].tracker_T_base)[:3, :3]
    assert with_d - geo == pytest.approx(cm.discrepancy.predict(W, return_var=False)[0] @ R.T, abs=1e-12)
    # the calibration predicts the true TCP to well below the withheld effect's size
    err = np.linalg.norm(with_d - true_tcp(model, p, eff, W), axis=1)
    assert err.max() < 1e-3
    # another TCP: the tool offset moves the prediction by the offset's difference
    moved = predicted_tcp(cm.noise_only(), W, tcp_m=np.array([0.0, 0.0, 0.25]))
    assert np.allclose(np.linalg.norm(moved - geo, axis=1), 0.10, atol=2e-3)


def test_paired_summary_counts_wins_and_tests():
    b = np.linspace(1.0, 2.0, 12)
    s = paired_summary(0.8 * b, b)
    assert s["wins_a"] == 12 and s["n"] == 12 and s["p"] < 0.001
    assert s["median_ratio"] == pytest.approx(0.8) and s["change_mean"] == pytest.approx(-0.2)
    assert paired_summary(b, b)["p"] == 1.0 and paired_summary(b, b)["wins_a"] == 0
    with pytest.raises(InputError):
        paired_summary(b, b[:5])


def test_withheld_case_scores_every_design_and_reuses_the_robot_independent_ones(model):
    rng = np.random.default_rng(0)
    Q_pool, Q_pilot = model.robot.random_q(rng, 90), model.robot.random_q(rng, 70)
    W = working_region(model.robot.random_q(rng, 2), 1, 0.3, seed=1)
    fixed: dict = {}
    r = withheld_case(model, Q_pool, Q_pilot, W, 3e-4, seed=0, sizes=(30,), fixed=fixed)
    assert set(r["error_m"]) == set(DESIGNS) and r["pilot"]["rows"] == 70
    for d in DESIGNS:
        e = r["error_m"][d][0]
        assert 0 < e < 5e-3
    assert set(fixed) == {("kpi_gp_default", 30), ("kpi", 30)}
    kept = {k: v.copy() for k, v in fixed.items()}
    r2 = withheld_case(model, Q_pool, Q_pilot, W, 0.0, seed=0, sizes=(30,), fixed=fixed)
    assert all(np.array_equal(kept[k], fixed[k]) for k in kept)
    # without the harmonic the calibrated TCP is far better than with it (same robot, same noise)
    assert np.mean([r2["error_m"][d][0] for d in DESIGNS]) < np.mean([r["error_m"][d][0] for d in DESIGNS])
    with pytest.raises(InputError):
        withheld_case(model, Q_pool[:20], Q_pilot, W, 0.0, seed=0, sizes=(30,))


def test_flagged_rows_feed_the_discrepancy_when_the_plain_fit_used_them():
    """With the plain loss the flagged rows stay in δ (they were in the parametric fit, and an unmodelled effect
    shows first in the largest residuals: left out, δ's level is too small); with a robust loss they stay out."""
    from pin_kpi_oed.discrepancy import DiscrepancyOptions
    from pin_kpi_oed.identification.discrepancy_fit import keep_flagged_rows, base_frame_residuals

    opts = DiscrepancyOptions(mode="on")
    res = SimpleNamespace(residuals_m=np.ones((60, 3)), outliers=np.array([3, 7]), loss="linear",
                          stations=["s"], station_rows=[np.arange(60)],
                          setups={"s": SimpleNamespace(tracker_T_base=np.eye(4))})
    assert keep_flagged_rows(res, opts)
    assert len(base_frame_residuals(res, keep_flagged=True)[0]) == 60
    assert len(base_frame_residuals(res)[0]) == 58
    assert not keep_flagged_rows(SimpleNamespace(**{**res.__dict__, "loss": "soft_l1"}), opts)  # left out of the fit
    big = SimpleNamespace(**{**res.__dict__, "residuals_m": np.ones((80, 3))})
    assert keep_flagged_rows(big, opts)                                   # also when 78 rows would be enough
    assert not keep_flagged_rows(SimpleNamespace(**{**res.__dict__, "outliers": np.array([], int)}), opts)


def test_poses_needed_says_when_the_measured_poses_already_reach_the_target():
    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.design.optimize import DesignProblem
    from pin_kpi_oed.oed.discrepancy_defaults import default_discrepancy
    from pin_kpi_oed.oed.discrepancy_kpi import DiscrepancyDesignCriterion, poses_needed

    problem = DesignProblem(load_cell("kr15"))
    rng = np.random.default_rng(0)
    Q = problem.cell.robot.random_q(rng, 100)
    crit = DiscrepancyDesignCriterion(problem.model, problem.base, default_discrepancy(6), problem.cell.q_work,
                                      Q_given=Q[:60], p=problem.p0)
    now = np.sqrt(crit.value(np.zeros((0, 6))) / problem.cell.q_work.shape[0])
    curve = poses_needed(crit, Q[60:], 20, n_points=4, target_sigma_m=2 * now, n_random=2)
    assert curve.n_for_target == 0 and "already reach it" in curve.summary()
    curve = poses_needed(crit, Q[60:], 20, n_points=4, target_sigma_m=0.5 * now, n_random=2)
    assert curve.n_for_target != 0


def test_paired_comparison_headline_is_the_median_with_the_sign_test():
    """One pair where b fails (a ratio of means would say −90 %) moves neither the median nor the sign test."""
    from pin_kpi_oed.studies.paired import paired_comparison, paired_text

    b = np.full(20, 1.0)
    b[0] = 100.0  # one reference that barely identifies the robot
    a = np.full(20, 0.9)
    a[15:] = 1.1  # 15 wins, 5 losses
    c = paired_comparison(a, b)
    assert c["change_median"] == pytest.approx(-0.1)
    assert c["change_mean"] < -0.8
    assert (c["wins_a"], c["losses_a"], c["ties"]) == (15, 5, 0)
    from scipy.stats import binomtest
    assert c["p_sign"] == pytest.approx(binomtest(15, 20, 0.5).pvalue)
    assert 0.04 < c["p_sign"] < 0.05
    assert paired_comparison(b, b)["p_sign"] == 1.0 and paired_comparison(b, b)["ties"] == 20
    assert paired_text(c).startswith("median change -10.0 % (15/20 wins, sign test p = 0.041")
