"""The discrepancy's marginal likelihood on the pairs of rows: value and gradient equal scikit-learn's regressor's
(to rounding) and the finite differences; the fitted hyper-parameters, the K-fold held-out error and the
standardised RMS equal those of the scikit-learn optimisation it replaces, on simulated residuals and on a fixed
subset of the IPA UR10's Series C (skipped without the data)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from pin_kpi_oed.discrepancy import DiscrepancyOptions, JointKernel, fit_discrepancy
from pin_kpi_oed.discrepancy import fit as gp_module
from pin_kpi_oed.discrepancy.marginal import MarginalLikelihood

NAMES = [f"j{i}" for i in range(6)]


def _gp_rows(n: int, d: int, m: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """n configurations and m columns drawn from the discrepancy's prior plus a white level."""
    rng = np.random.default_rng(seed)
    Q = rng.uniform(-np.pi, np.pi, (n, d))
    k = JointKernel(0.6, rng.uniform(0.5, 2, d), rng.uniform(0.1, 0.4, d), rng.uniform(0.2, 0.8, d))
    K = k(Q) + 0.05 * np.eye(n)
    return Q, np.linalg.cholesky(K) @ rng.standard_normal((n, m))


def _sklearn_regressor(d: int, joint_amplitude: float = 0.1, min_noise: float = 1e-5):
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import WhiteKernel

    k0 = JointKernel(0.7, np.ones(d), np.full(d, joint_amplitude), np.full(d, 0.5)) + WhiteKernel(
        max(0.3, 1.5 * min_noise), (min_noise, max(10.0, 4.0 * min_noise)))
    return GaussianProcessRegressor(k0, optimizer=None), k0


@pytest.mark.parametrize("d, m", [(6, 3), (3, 1)])
def test_value_and_gradient_equal_scikit_learns(d, m):
    Q, Y = _gp_rows(120, d, m, seed=d)
    reg, k0 = _sklearn_regressor(d)
    reg.fit(Q, Y)
    f = MarginalLikelihood(Q, Y)
    rng = np.random.default_rng(0)
    for theta in (k0.theta, k0.theta + 0.5 * rng.standard_normal(len(k0.theta))):
        v_ref, g_ref = reg.log_marginal_likelihood(theta, eval_gradient=True)
        v, g = f(theta)
        assert -v == pytest.approx(v_ref, rel=1e-12, abs=1e-9)
        assert np.abs(-g - g_ref).max() <= 1e-9 * np.abs(g_ref).max()


def test_gradient_matches_finite_differences():
    Q, Y = _gp_rows(80, 6, 3, seed=1)
    f = MarginalLikelihood(Q, Y)
    theta = np.log(np.r_[0.5, np.full(6, 0.2), np.full(6, 0.4), np.full(6, 1.2), 0.1])
    _, g = f(theta)
    eps = 1e-6
    for k in range(len(theta)):
        t = theta.copy()
        t[k] += eps
        vp, _ = f(t)
        t[k] -= 2 * eps
        vm, _ = f(t)
        assert (vp - vm) / (2 * eps) == pytest.approx(g[k], rel=1e-5, abs=1e-5)


def _sklearn_hyper_fit(Q, Y, opts, joint_amplitude, min_noise=1e-5, linear=None, joint_span=None, race=None):
    """The optimisation the marginal likelihood on pairs replaced: scikit-learn's regressor, L-BFGS-B."""
    assert linear is None, "the scikit-learn reference knows no linear joints"
    import warnings

    from scipy.optimize import minimize
    from sklearn.exceptions import ConvergenceWarning

    _REFERENCE_CALLS.append(len(Q))
    sub = np.random.default_rng(opts.seed).permutation(len(Q))[:opts.n_fit]
    reg, _ = _sklearn_regressor(Q.shape[1], joint_amplitude, min_noise)

    def lbfgs(obj_func, theta0, bounds):
        res = minimize(obj_func, theta0, method="L-BFGS-B", jac=True, bounds=bounds,
                       options={"maxiter": int(opts.max_iter)})
        return res.x, res.fun

    reg.optimizer = lbfgs
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        reg.fit(Q[sub], Y[sub])
    return reg.kernel_.k1, float(reg.kernel_.k2.noise_level)


_REFERENCE_CALLS: list[int] = []


def _same_fit(Q, R, opts, monkeypatch):
    fast = fit_discrepancy(Q, R, NAMES, opts)
    monkeypatch.setattr(gp_module, "_hyper_fit", _sklearn_hyper_fit)
    _REFERENCE_CALLS.clear()
    ref = fit_discrepancy(Q, R, NAMES, opts)
    assert _REFERENCE_CALLS, "the reference optimisation was not called: the comparison would prove nothing"
    assert fast.kind == ref.kind and fast.kind != "white", "a case where the Gaussian process is kept is needed"
    assert fast.cv["mean_with_m"] == pytest.approx(ref.cv["mean_with_m"], rel=0.01)
    assert abs(fast.cv["z_rms"] - ref.cv["z_rms"]) <= 0.03
    assert fast.noise == pytest.approx(ref.noise, rel=0.05)
    return fast, ref


def test_fit_equals_the_scikit_learn_optimisation_on_simulated_residuals(monkeypatch):
    Q, Y = _gp_rows(200, 6, 3, seed=3)
    R = 1e-4 * Y + np.array([1e-5, -2e-5, 0.0])
    fast, ref = _same_fit(Q, R, DiscrepancyOptions(mode="auto", n_fit=120), monkeypatch)
    a, b = fast.kernel.to_dict(), ref.kernel.to_dict()
    for key in ("amplitude", "length_scale_rad", "joint_amplitude", "joint_length_scale_rad"):
        assert np.allclose(a[key], b[key], rtol=1e-3), key


def _ipa_folder() -> Path | None:
    env = os.environ.get("PIN_KPI_OED_IPA_DATA")
    if env:
        return Path(env)
    for up in Path(__file__).resolve().parents:
        if (up / "shared" / "data" / "ipa_ur10" / "Series_C").is_dir():
            return up / "shared" / "data" / "ipa_ur10"
    return None


def test_fit_equals_the_scikit_learn_optimisation_on_a_series_c_subset(monkeypatch):
    folder = _ipa_folder()
    if folder is None:
        pytest.skip("IPA UR10 data not found (PIN_KPI_OED_IPA_DATA)")
    from pin_kpi_oed import NoiseModel, TrackerModel, load_robot
    from pin_kpi_oed.data.ipa import import_ipa
    from tests._cache_real import IPA, ipa_series
    from pin_kpi_oed.identification.discrepancy_fit import base_frame_residuals
    from pin_kpi_oed.identification.identify import identify

    ms = ipa_series("C") if folder == IPA else import_ipa(folder / "Series_C")  # tests/_cache_real.py: once
    data = ms.subset(np.sort(np.random.default_rng(0).permutation(len(ms.q))[:400]))
    model = TrackerModel(load_robot("ur10"), reflector_m=np.array([0.0, 0.0, 0.109]),
                         noise=NoiseModel(sigma_xyz_m=(1e-4,) * 3))
    res = identify(model, data, discrepancy="none", raise_on_failure=False)
    rows, R = base_frame_residuals(res)
    fast, _ = _same_fit(data.q[rows], R, DiscrepancyOptions(mode="auto", n_fit=150, starts=(0.1,)), monkeypatch)
    assert fast.cv["mean_with_m"] < 0.7 * fast.cv["mean_without_m"]  # the Series C discrepancy is learnt


def test_posterior_from_the_kfold_factor_equals_the_one_formed_again():
    from pin_kpi_oed.discrepancy import Discrepancy

    Q, Y = _gp_rows(150, 6, 3, seed=5)
    fit = fit_discrepancy(Q, 1e-4 * Y, NAMES, DiscrepancyOptions(mode="on", n_fit=100, starts=(0.1,)))
    assert fit.kind == "exact" and fit._chol is not None, "the fit must hand its K-fold factor to the posterior"
    again = Discrepancy.from_dict(fit.to_dict(), NAMES)
    assert again._chol is None
    W = np.random.default_rng(1).uniform(-np.pi, np.pi, (40, 6))
    (m1, v1), (m2, v2) = fit.predict(W), again.predict(W)
    assert np.allclose(m1, m2, rtol=1e-9, atol=1e-18) and np.allclose(v1, v2, rtol=1e-9, atol=1e-22)


def test_blocked_kernel_equals_the_whole_arrays_to_the_last_bit():
    """The kernel of the pairs is formed a block of pairs at a time; the optimiser's 60-iteration path depends on
    every bit of it (a rounding-level change moves the hyper-parameters it stops at), so the blocks must give exactly
    what the operations over all pairs at once give, here across several blocks and a linear joint."""
    from pin_kpi_oed.discrepancy.marginal import PAIR_BLOCK

    Q, Y = _gp_rows(150, 6, 3, seed=7)
    Q[:, 5] *= 0.2
    linear = np.array([False] * 5 + [True])
    f = MarginalLikelihood(Q, Y, linear)
    assert f.D.shape[1] > 2 * PAIR_BLOCK, "the case must span several blocks"
    theta = np.log(np.r_[0.6, np.linspace(0.1, 0.3, 6), np.linspace(0.2, 0.7, 6), np.linspace(0.5, 2.0, 6), 0.05])
    c, a, ell, L, _ = f.split(theta)
    f._kernel_pairs(c, a, ell, L)       # what an evaluation forms first (its later steps reuse the arrays)
    P = np.exp(np.matmul(-0.5 / L ** 2, f.D)) * c ** 2
    A = np.exp(f.D * (-0.5 / ell ** 2)[:, None]) * (a ** 2)[:, None]
    K = np.sum(A, axis=0) + P
    assert np.array_equal(f._pairs[0], P)
    assert np.array_equal(f._A, A)
    assert np.array_equal(f._pairs[1], K)


def test_gradient_weights_at_the_pairs_equal_the_whole_matrices_to_the_last_bit():
    """W = ααᵀ − mΣ⁻¹ is formed at the pairs i < j only; value and gradient must be exactly those of W formed over the
    whole matrices (the optimiser's path depends on every bit), here with a linear joint and several blocks."""
    from scipy import linalg as sla

    from pin_kpi_oed.discrepancy.marginal import REGRESSOR_JITTER

    Q, Y = _gp_rows(150, 6, 3, seed=8)
    Q[:, 5] *= 0.2
    f = MarginalLikelihood(Q, Y, np.array([False] * 5 + [True]))
    theta = np.log(np.r_[0.6, np.linspace(0.1, 0.3, 6), np.linspace(0.2, 0.7, 6), np.linspace(0.5, 2.0, 6), 0.05])
    value, grad = f(theta)
    c, a, ell, L, w = f.split(theta)
    n, m = f.n, Y.shape[1]
    f._kernel_pairs(c, a, ell, L)
    P, K = f._pairs[0].copy(), f._pairs[1].copy()
    S = np.zeros((n, n), order="F")
    S.reshape(-1, order="F")[f.flat] = K
    S.reshape(-1, order="F")[::n + 1] = c ** 2 + float(np.sum(a ** 2)) + w + REGRESSOR_JITTER
    U, _ = sla.lapack.dpotrf(S, lower=0, clean=0)
    alpha, _ = sla.lapack.dpotrs(U, Y, lower=0)
    lml = -0.5 * float(np.sum(Y * alpha)) - m * float(np.sum(np.log(np.diag(U)))) - 0.5 * m * n * np.log(2.0 * np.pi)
    Si, _ = sla.lapack.dpotri(U, lower=0)
    W = alpha @ alpha.T
    Wd = float(np.trace(W) - m * np.trace(Si))
    W -= m * Si
    Wp = 2.0 * W.reshape(-1)[f.flat_c]
    WP = Wp * P
    g = np.r_[float(WP.sum()) + c ** 2 * Wd, f._A @ Wp + a ** 2 * Wd,
              0.5 * np.einsum("p,jp,jp->j", Wp, f._A, f.D) / ell ** 2, 0.5 * (f.D @ WP) / L ** 2, 0.5 * w * Wd]
    assert value == -lml
    assert np.array_equal(grad, -g)


@pytest.mark.parametrize("n, linear", [(300, None), (257, [True] + [False] * 5), (128, None), (1, None)])
def test_lower_triangle_equals_the_whole_kernel_to_the_last_bit(n, linear):
    """The K-fold check and the inducing posterior factor the kernel matrix from its lower triangle alone
    (``JointKernel.lower``): every entry of it must be exactly the whole matrix's, so that the factor, the check's
    figures and the decision do not change, across several blocks of rows and with a linear joint."""
    rng = np.random.default_rng(n)
    Q = rng.uniform(-np.pi, np.pi, (n, 6))
    lin = None if linear is None else np.array(linear)
    k = JointKernel(0.6, rng.uniform(0.5, 2, 6), rng.uniform(0.1, 0.4, 6), rng.uniform(0.2, 0.8, 6), linear=lin)
    low, whole = k.lower(Q), k(Q)
    il = np.tril_indices(n)
    assert np.array_equal(low[il], whole[il])
    if n > 128:
        assert np.count_nonzero(low) < 0.75 * n * n, "the entries above the diagonal blocks are not formed"
    S = low + 0.05 * np.eye(n)
    assert np.array_equal(np.linalg.cholesky(S), np.linalg.cholesky(whole + 0.05 * np.eye(n)))


def test_start_race_stops_and_leaves_out_only_a_start_far_behind():
    from pin_kpi_oed.discrepancy.marginal import StartRace

    race = StartRace(at=3, nats=100.0)
    race.record([-900.0, -700.0, -600.0, -500.0], -400.0)
    assert not race.behind(2, -2000.0)                         # compared at iteration `at` only
    assert race.behind(3, -700.5) and not race.behind(3, -699.5)
    race.record([-950.0, -800.0, -650.0], None)                # a start stopped there
    race.record([-990.0, -880.0, -690.0, -520.0], -450.0)      # 50 nats behind at the end: still a contender
    race.record([-990.0, -880.0, -690.0, -600.0], -501.0)      # 101 nats behind
    assert race.lead == [-900.0, -700.0, -600.0]
    assert race.contenders() == [True, False, True, False]


def _additive_rows(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Residuals of one-joint functions of the joint angles: the second start (small one-joint amplitudes) explains
    them far worse than the first."""
    rng = np.random.default_rng(seed)
    Q = rng.uniform(-np.pi, np.pi, (n, 6))
    Y = np.stack([np.sin(2 * Q[:, 1]) + 0.5 * np.cos(Q[:, 2]), np.cos(3 * Q[:, 1]) - 0.4 * np.sin(2 * Q[:, 3]),
                  np.sin(Q[:, 2] + 0.3)], 1)
    return Q, 1e-4 * (Y + 0.05 * rng.standard_normal((n, 3)))


def test_a_start_far_behind_is_stopped_and_the_fit_is_the_one_without_the_race(monkeypatch):
    from pin_kpi_oed.discrepancy import marginal

    Q, R = _additive_rows(200, seed=2)
    opts = DiscrepancyOptions(mode="on", n_fit=150)
    checked: list[float] = []
    kfold = gp_module.kfold_split

    def counting(*args, **kw):
        out = kfold(*args, **kw)
        checked.append(out["mean_with_m"])
        return out
    monkeypatch.setattr(gp_module, "kfold_split", counting)
    evaluations = []
    call = marginal.MarginalLikelihood.__call__
    monkeypatch.setattr(marginal.MarginalLikelihood, "__call__", lambda f, t: evaluations.append(1) or call(f, t))
    raced = fit_discrepancy(Q, R, NAMES, opts)
    n_raced, cv_raced = len(evaluations), list(checked)
    monkeypatch.setattr(marginal, "RACE_NATS", np.inf)
    evaluations.clear()
    checked.clear()
    full = fit_discrepancy(Q, R, NAMES, opts)
    assert len(cv_raced) == 1 and len(checked) == 2, "the second start must be left out of the check by the race"
    assert checked[1] > checked[0], "the start the race stopped loses the K-fold check without the race"
    assert n_raced < len(evaluations) - 30                     # stopped at iteration 10 of 60
    assert raced.kernel.to_dict() == full.kernel.to_dict() and raced.noise == full.noise
    assert raced.cv == full.cv
