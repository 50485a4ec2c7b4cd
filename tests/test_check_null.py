"""The check's statistic under no change: the rows' joint honest covariance (its diagonal the honest σ, its
off-diagonal the discrepancy's posterior and the parameters' shared error) and the law of T from the model's own
K-fold held-out errors (scaled χ² against Monte-Carlo of heavy-tailed sums)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from pin_kpi_oed.discrepancy.gp import DiscrepancyOptions
from pin_kpi_oed.upkeep.check import check_null
from pin_kpi_oed.identification.identify import identify
from pin_kpi_oed.calibrated.prediction_sigma import predictive_covariance
from pin_kpi_oed.oed.check_power import CheckNull
from pin_kpi_oed.oed.check_power import test_threshold as chi2_threshold
from tests.withheld import withheld_ur10


@pytest.fixture(scope="module")
def gp_model():
    """A UR10 calibrated with a Gaussian-process discrepancy (a withheld gear harmonic), 200 rows, σ = 10 µm: the
    assertions are on the structure of the rows' joint covariance, the posterior's formula and the K-fold law, which
    any exact Gaussian process has (200 rows cost a third of 300 in the marginal likelihood's n³)."""
    model, data = withheld_ur10(260)
    fit = identify(model, data.subset(np.arange(200)), discrepancy=DiscrepancyOptions(mode="on", n_fit=200, seed=0))
    return fit.calibrated_model(), data.subset(np.arange(200, 260)), data.subset(np.arange(200))


def test_joint_covariance_holds_the_honest_sigma_and_the_rows_correlations(gp_model):
    cm, held, train = gp_model
    assert cm.discrepancy.kind == "exact"
    lab = cm.station(None)
    # rows inside the coverage, a row next to another (correlated through the posterior), rows far outside
    Q = np.vstack([held.q[:6], held.q[:1] + 0.02, np.clip(3.0 * held.q[6:9], cm.robot.q_lower, cm.robot.q_upper)])
    Y, sig, out = cm.predict_with_sigma(Q)
    assert out[-3:].any() and not out[:6].all()
    Y2, C = predictive_covariance(cm, Q, None, lab)
    np.testing.assert_allclose(Y2, Y, atol=1e-12)
    np.testing.assert_allclose(np.sqrt(np.diag(C)).reshape(-1, 3), sig, rtol=1e-9)
    assert np.allclose(C, C.T) and np.linalg.eigvalsh(C).min() > -1e-12 * np.abs(C).max()
    corr = C / np.sqrt(np.outer(np.diag(C), np.diag(C)))
    assert np.max(np.abs(corr[0:3, 18:21].diagonal())) > 0.3           # a pose and its neighbour share δ
    # the discrepancy's posterior covariance is the textbook formula
    d = cm.discrepancy
    K = d.kernel(d.Z) + (d.noise + 1e-10) * np.eye(len(d.Z))
    Kqz = d.kernel(Q, d.Z)
    ref = d.kernel(Q) - Kqz @ np.linalg.solve(K, Kqz.T)
    np.testing.assert_allclose(d.posterior_covariance(Q), ref, atol=1e-6 * np.abs(ref).max())


def test_null_law_of_heavy_tailed_sums_monte_carlo():
    """Sums of 24 squared t(8) errors scaled by f = 1.1 (excess kurtosis 1.5): the plain χ²(24) raises 3x the stated
    false alarms, the scaled χ² of (f, κ) keeps them at α."""
    rng = np.random.default_rng(0)
    nu_t, f, dof, alpha = 8.0, 1.1, 24, 0.05
    z = f * rng.standard_t(nu_t, size=(40000, dof)) / np.sqrt(nu_t / (nu_t - 2))
    T = np.sum(z ** 2, axis=1)
    kurt = 6.0 / (nu_t - 4)
    plain = np.mean(T > chi2_threshold(dof, alpha))
    law = CheckNull(factor=f, kurtosis=kurt)
    scaled = np.mean(T > law.threshold(dof, alpha))
    assert plain > 2.5 * alpha
    assert abs(scaled - alpha) < 0.01, scaled
    assert law.sf(law.threshold(dof, alpha), dof) == pytest.approx(alpha, rel=1e-9)
    # the plain law is the χ² and its power the non-central χ²'s
    assert CheckNull().threshold(dof, alpha) == pytest.approx(stats.chi2.isf(alpha, dof))
    assert CheckNull().power(30.0, dof, alpha) == pytest.approx(stats.ncx2.sf(stats.chi2.isf(alpha, dof), dof, 30.0))
    assert law.power(30.0, dof, alpha) < CheckNull().power(30.0, dof, alpha)


def test_check_null_is_the_models_kfold_check(gp_model):
    cm, _, _ = gp_model
    law = check_null(cm)
    cv = cm.discrepancy.cv
    assert law.factor == pytest.approx(cv["z_rms"]) and law.kurtosis == pytest.approx(max(cv["z_kurtosis"], 0.0))
    assert "z_kurtosis" in cv and np.isfinite(cv["z_kurtosis"])
    plain = cm.noise_only()
    assert check_null(plain) == CheckNull()


def test_naming_prefers_the_group_that_explains_far_better():
    """A one-column group that passes its fit test is not named when a three-column group explains the rows far
    better (Akaike's criterion, not the smallest passing group); the fit test of the named group is at α/5."""
    from pin_kpi_oed.upkeep.check import FIT_SHARE, check_group_name
    from pin_kpi_oed.oed.check_power import CheckGroup, CheckPower

    rng = np.random.default_rng(3)
    F = rng.standard_normal((30, 10))
    delta = np.array([1.0, -0.8, 0.6])
    F[:, 6] = F[:, 7:10] @ delta + 0.25 * rng.standard_normal(30)          # the offset mimics most of the tool change
    z = F[:, 7:10] @ (2.0 * delta) + rng.standard_normal(30)
    G = F[:, :6]
    z = z - G @ np.linalg.lstsq(G, z, rcond=None)[0]
    groups = [CheckGroup("j offset", "offset", np.array([6]), np.eye(1), np.eye(1)),
              CheckGroup("tool", "tool", np.arange(7, 10), np.eye(3), np.eye(3))]
    crit = CheckPower(np.arange(6), groups)
    law = CheckNull()
    out = check_group_name(crit, F, z, 24, 0.05, law)
    rows = {t["name"]: t for t in out["table"]}
    assert rows["j offset"]["explains"] and rows["tool"]["explains"]      # both pass: the old rule named the offset
    assert rows["tool"]["chi2_remaining"] + 6 < rows["j offset"]["chi2_remaining"] + 2
    assert out["best"][0].name == "tool"
    np.testing.assert_allclose(out["best"][1], 2.0 * delta, atol=0.5)
    assert FIT_SHARE == 5.0 and law.threshold(21, 0.05 / FIT_SHARE) > law.threshold(21, 0.05)


def test_parts_the_rows_do_not_tell_apart_are_named_together():
    """A joint's placement whose columns the check rows see exactly as the tool's: the verdict names both ("tool or
    wrist"); with the joint's columns independent of the tool's, the tool alone. A joint's offset and placement are
    one part (never named "or" each other)."""
    from pin_kpi_oed.upkeep.check import check_group_name
    from pin_kpi_oed.oed.check_power import CheckGroup, CheckPower

    rng = np.random.default_rng(4)
    delta = np.array([1.0, -0.8, 0.6])

    def named(same: bool) -> dict:
        F = rng.standard_normal((36, 13))
        if same:
            F[:, 10:13] = F[:, 7:10] @ np.diag([1.0, -1.0, 2.0])            # the wrist's columns: the tool's
        z = F[:, 7:10] @ (3.0 * delta) + rng.standard_normal(36)
        G = F[:, :6]
        z = z - G @ np.linalg.lstsq(G, z, rcond=None)[0]
        groups = [CheckGroup("j offset", "offset", np.array([6]), np.eye(1), np.eye(1)),
                  CheckGroup("tool", "tool", np.arange(7, 10), np.eye(3), np.eye(3)),
                  CheckGroup("wrist offset", "offset", np.array([10]), np.eye(1), np.eye(1)),
                  CheckGroup("wrist placement", "placement", np.arange(10, 13), np.eye(3), np.eye(3))]
        return check_group_name(CheckPower(np.arange(6), groups), F, z, 30, 0.05, CheckNull())

    alike = named(True)
    assert alike["best"][0].name in ("tool", "wrist placement")
    assert alike["alike"] == (["wrist"] if alike["best"][0].name == "tool" else ["tool"])
    apart = named(False)
    assert apart["best"][0].name == "tool" and apart["alike"] == []


def test_the_verdict_line_names_the_parts_together():
    from pin_kpi_oed.upkeep.check import CheckResult

    r = CheckResult(verdict="robot_changed", n_rows=20, dof=54, alpha=0.05, chi2=300.0, threshold=75.0, p_value=0.0,
                    setup_shift_m=0.0, setup_distance=1.0, group="tool", alike=["wrist_3_joint"], determined=True,
                    change=np.array([2e-4, 0.0, 0.0]), std=np.full(3, 1e-5), change_tcp_m=2e-4,
                    change_tcp_sigma_m=1e-5, refit_error_m=3e-5, recalibrate_error_m=3e-5)
    line = r.summary()
    assert "tool by [+0.200" in line and "or a change of wrist_3_joint (the check rows do not tell the two apart" \
        in line, line
    assert r.to_dict()["alike"] == ["wrist_3_joint"]


def test_powers_of_many_changes_equal_the_scalar_formula_bit_for_bit():
    """``CheckNull.powers`` (one critical value and one χ'² survival over the groups' non-centralities, what the check
    and its design evaluate thousands of times) gives each entry exactly the scalar law P(χ'²(ν/c, max(λ/(f²c),
    1e-12)) > χ²_{1−α}(ν/c)), tiny and zero non-centralities included."""
    lam = np.concatenate([[0.0, 1e-14, 1e-3], np.random.default_rng(3).uniform(0.0, 60.0, 20)])
    for null in (CheckNull(), CheckNull(1.3, 0.8), CheckNull(0.9, -0.2)):
        for dof, alpha in ((24, 0.05), (7, 0.0253), (90, 0.2)):
            nu = dof / null.spread
            want = [float(stats.ncx2.sf(stats.chi2.isf(alpha, nu), nu, max(float(x) / null.scale, 1e-12)))
                    for x in lam]
            got = null.powers(lam, dof, alpha)
            assert got.shape == lam.shape and got.tolist() == want
            assert null.power(float(lam[5]), dof, alpha) == want[5]
    assert 0.0 < want[0] < want[-1] < 1.0


def test_thresholds_and_survivals_of_many_groups_equal_the_scalar_laws_bit_for_bit():
    """``CheckNull.thresholds`` / ``sfs`` (the naming's laws of every group at once; ``threshold`` / ``sf`` are them
    of one) give each entry exactly the scalar laws f²c·χ²_{1−α}(ν/c) and P(χ²(ν/c) > T/(f²c)); a number of degrees
    of freedom that is not positive gives NaN (no group is named on it)."""
    dofs = np.array([24, 23, 21, 18, 1, 0])
    T = np.array([30.0, 2.5, 0.0, 41.7, 3.2, 1.0])
    for null in (CheckNull(), CheckNull(1.3, 0.8)):
        for alpha in (0.01, 0.05 / 5):
            want = [null.scale * float(stats.chi2.isf(alpha, int(d) / null.spread)) for d in dofs[:-1]]
            got = null.thresholds(dofs, alpha)
            assert got[:-1].tolist() == want and np.isnan(got[-1])
            assert [null.threshold(int(d), alpha) for d in dofs[:-1]] == want
        want = [float(stats.chi2.sf(float(t) / null.scale, int(d) / null.spread)) for t, d in zip(T[:-1], dofs[:-1])]
        got = null.sfs(T, dofs)
        assert got[:-1].tolist() == want and [null.sf(float(t), int(d)) for t, d in zip(T[:-1], dofs[:-1])] == want
        assert np.isnan(got[-1]) and 0.0 < got[0] < 1.0 and got[2] == 1.0
