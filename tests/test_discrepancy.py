"""Model discrepancy: the kernel (derivatives against finite differences), the Gaussian process (posterior
variance against Monte-Carlo draws of the prior), calibration with a withheld effect (honest σ on held-out
rows, geometry unchanged by the discrepancy), the model-file block (round trip, damaged fields refused)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from pin_kpi_oed.compensation.result import SENDABLE
from pin_kpi_oed.cli.app import main
from pin_kpi_oed.data.measurements import write_measurements
from pin_kpi_oed.discrepancy import Discrepancy, DiscrepancyOptions, JointKernel, fit_discrepancy
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.identification.identify import identify, validate
from pin_kpi_oed.calibrated.model_file import load_model_file
from pin_kpi_oed.upkeep.transfer import predict_table
from tests.withheld import withheld_ur10

NAMES = [f"j{i}" for i in range(6)]


def _kernel(rng):
    return JointKernel(0.7, rng.uniform(0.5, 2, 6), rng.uniform(0.1, 0.5, 6), rng.uniform(0.1, 1, 6))


def test_kernel_gradients_match_finite_differences():
    rng = np.random.default_rng(0)
    k = _kernel(rng)
    X, Y = rng.uniform(-3, 3, (7, 6)), rng.uniform(-3, 3, (4, 6))
    _, G = k(X, eval_gradient=True)
    eps = 1e-6
    for i, th in enumerate(k.theta):
        t = k.theta.copy()
        t[i] = th + eps
        Kp = k.clone_with_theta(t)(X)
        t[i] = th - eps
        Km = k.clone_with_theta(t)(X)
        assert np.abs((Kp - Km) / (2 * eps) - G[..., i]).max() < 1e-6, k.hyperparameters[i].name
    Gx = k.grad_x(X, Y)
    for j in range(6):
        d = np.zeros(6)
        d[j] = eps
        fd = (k(X + d, Y) - k(X - d, Y)) / (2 * eps)
        assert np.abs(fd - Gx[..., j]).max() < 1e-6
    assert np.allclose(k(X + 2 * np.pi, Y), k(X, Y))          # angles wrap: no seam at ±π
    assert np.allclose(np.diag(k(X)), k.diag(X))


def test_kernel_value_without_gradient_equals_the_chord_form():
    """K from outer products of the circle points equals the per-pair chord formula, and the cached chords of
    the gradient path give the same K."""
    from pin_kpi_oed.discrepancy.kernel import chord_squared
    rng = np.random.default_rng(3)
    k = _kernel(rng)
    X, Y = rng.uniform(-7, 7, (40, 6)), rng.uniform(-7, 7, (25, 6))
    c, L, a, ell = k.parts(6)
    D = chord_squared(X, Y)
    K_ref = c ** 2 * np.exp(-0.5 * (D / L ** 2).sum(-1)) + (a ** 2 * np.exp(-0.5 * D / ell ** 2)).sum(-1)
    assert np.abs(k(X, Y) - K_ref).max() < 1e-12
    K_grad, _ = k(X, eval_gradient=True)
    K_grad2, _ = k(X, eval_gradient=True)                     # second call: chords from the cache
    assert np.abs(K_grad - k(X)).max() < 1e-12 and np.array_equal(K_grad, K_grad2)
    K_other, _ = k(X[::-1], eval_gradient=True)              # another training set: the cache is refreshed
    assert np.abs(K_other - k(X[::-1])).max() < 1e-12


@pytest.mark.parametrize("per_joint", [(True, True, True), (False, True, False), (True, False, True)])
def test_kernel_gradient_columns_equal_the_parts_formulas_to_the_last_bit(per_joint):
    """dK/dlog θ equals the parts' formulas concatenated in scikit-learn's order
    (amplitude, joint amplitudes, joint length scales, length scales; a scalar hyper-parameter's column summed over
    the joints) bit for bit, a linear joint included: the regressor compared with it takes the same steps."""
    from pin_kpi_oed.discrepancy.kernel import chord_squared
    rng = np.random.default_rng(11)
    vec_a, vec_ell, vec_L = per_joint
    lin = np.array([True, False, False, False, False, False])
    k = JointKernel(0.7, rng.uniform(0.5, 2, 6) if vec_L else 1.3, rng.uniform(0.1, 0.5, 6) if vec_a else 0.2,
                    rng.uniform(0.1, 1, 6) if vec_ell else 0.6, linear=lin)
    X = rng.uniform(-3, 3, (30, 6))
    c, L, a, ell = k.parts(6)
    D = chord_squared(X, X, lin)
    Dp, Da = D / L ** 2, D / ell ** 2
    P = c ** 2 * np.exp(-0.5 * Dp.sum(-1))
    A = a ** 2 * np.exp(-0.5 * Da)
    want = np.concatenate([2.0 * P[..., None], 2.0 * A if vec_a else 2.0 * A.sum(-1, keepdims=True),
                           A * Da if vec_ell else (A * Da).sum(-1, keepdims=True),
                           P[..., None] * Dp if vec_L else (P * Dp.sum(-1))[..., None]], axis=-1)
    K, G = k(X, eval_gradient=True)
    assert G.shape == want.shape == (30, 30, len(k.theta))
    assert np.array_equal(G, want) and np.array_equal(K, P + A.sum(-1))


def test_kfold_by_block_inversion_equals_refitting_each_fold():
    """The exact K-fold check from one inverse equals building each fold's posterior without its rows."""
    from pin_kpi_oed.discrepancy.fit import kfold_split
    rng = np.random.default_rng(4)
    k = _kernel(rng)
    Q = rng.uniform(-2, 2, (90, 6))
    Y = rng.normal(size=(90, 3))
    scale = np.array([1e-4, 2e-4, 1.5e-4])
    fast = kfold_split(k, 0.2, Q, Y, scale, DiscrepancyOptions(folds=5), NAMES)
    slow = kfold_split(k, 0.2, Q, Y, scale, DiscrepancyOptions(folds=5, max_exact=50, n_inducing=90), NAMES)
    for key in ("mean_without_m", "mean_with_m", "rms_with_m", "z_rms", "inside_95"):
        assert fast[key] == pytest.approx(slow[key], rel=1e-6), key
    assert fast["mean_with_m"] < fast["mean_without_m"] * 1.5


def test_posterior_variance_matches_monte_carlo():
    """Draw δ from the prior, condition on noisy rows, predict new rows: the predicted variance is the
    mean squared error over the draws (per axis), within Monte-Carlo error."""
    rng = np.random.default_rng(1)
    k = JointKernel(1.0, np.full(6, 1.2), np.full(6, 0.3), np.full(6, 0.6))
    Qtr, Qte = rng.uniform(-2, 2, (60, 6)), rng.uniform(-2, 2, (15, 6))
    Qall = np.vstack([Qtr, Qte])
    Lk = np.linalg.cholesky(k(Qall) + 1e-9 * np.eye(len(Qall)))
    w = 0.05
    d = Discrepancy("exact", NAMES, np.ones(3), np.zeros(3), w, k, Qtr, np.zeros((60, 3)))
    _, v = d.predict_normalised(Qte)
    err2 = []
    for _ in range(400):
        f = Lk @ rng.standard_normal((len(Qall), 3))
        d.y, d._chol = f[:60] + np.sqrt(w) * rng.standard_normal((60, 3)), None
        mu, _ = d.predict_normalised(Qte, return_var=False)
        err2.append((f[60:] - mu) ** 2)
    mc = np.mean(err2, axis=0).mean(axis=1)                   # per row, averaged over the 3 axes
    assert np.all(np.abs(mc / v - 1) < 0.25), np.round(mc / v, 2)


def test_inducing_posterior_close_to_exact():
    rng = np.random.default_rng(2)
    Q = rng.uniform(-2, 2, (400, 6))
    R = 1e-4 * np.c_[np.sin(2 * Q[:, 1]), np.cos(Q[:, 2] + Q[:, 1]), np.sin(Q[:, 0])] + 1e-6 * rng.standard_normal(
        (400, 3))
    ex = fit_discrepancy(Q, R, NAMES, DiscrepancyOptions(mode="on", n_fit=200, starts=(0.1,)))
    sp = fit_discrepancy(Q, R, NAMES, DiscrepancyOptions(mode="on", n_fit=200, starts=(0.1,), max_exact=300,
                                                         n_inducing=250))
    assert ex.kind == "exact" and sp.kind == "inducing"
    Qn = rng.uniform(-2, 2, (50, 6))
    me, ve = ex.predict(Qn)
    ms, vs = sp.predict(Qn)
    truth = 1e-4 * np.c_[np.sin(2 * Qn[:, 1]), np.cos(Qn[:, 2] + Qn[:, 1]), np.sin(Qn[:, 0])]
    assert np.sqrt(np.mean((ms - truth) ** 2)) < 0.3 * np.sqrt(np.mean(truth ** 2))
    assert np.sqrt(np.mean((me - truth) ** 2)) < 0.3 * np.sqrt(np.mean(truth ** 2))
    assert np.all(vs >= 0) and np.all(np.isfinite(vs))
    back = Discrepancy.from_dict(json.loads(json.dumps(sp.to_dict())), NAMES)
    assert np.allclose(back.predict(Qn)[0], ms) and np.allclose(back.predict(Qn)[1], vs)


def test_too_few_rows():
    rng = np.random.default_rng(3)
    with pytest.raises(InputError, match="too few"):
        fit_discrepancy(rng.uniform(-1, 1, (20, 6)), 1e-4 * rng.standard_normal((20, 3)), NAMES,
                        DiscrepancyOptions(mode="on"))
    d = fit_discrepancy(rng.uniform(-1, 1, (20, 6)), 1e-4 * rng.standard_normal((20, 3)), NAMES)
    assert d.kind == "white" and "fewer than" in d.decision
    assert d.noise_var_m2.shape == (3,) and np.all(d.noise_var_m2 > 0)  # the residual level is the σ


@pytest.fixture(scope="module")
def withheld():
    """A UR10 with geometric errors and a withheld gear harmonic (0.3 mrad on shoulder and elbow):
    400 training rows and 300 held-out rows in the same joint range, σ = 10 µm."""
    model, data = withheld_ur10(700)
    return model, data.subset(np.arange(400)), data.subset(np.arange(400, 700))


#: the tests that read :func:`fits`: on one xdist worker, so that the fits are made once
shares_fits = pytest.mark.xdist_group("discrepancy_fits")


@pytest.fixture(scope="module")
def fits(withheld):
    """The training rows fitted without a discrepancy and with the default one (``auto``: the Gaussian process is
    chosen here, ``exact``), once for the tests that read them (a Gaussian process's hyper-parameter fit is most of
    these tests' time)."""
    model, train, _ = withheld
    return (identify(model, train, discrepancy="none"),
            identify(model, train, discrepancy=DiscrepancyOptions(mode="auto", n_fit=300, seed=0)))


@shares_fits
def test_row_sandwich_equals_the_three_operand_einsum_on_a_fit(withheld, fits):
    """Every σ carries the parameter covariance through each row's Jacobian with ``row_sandwich`` (matrix products):
    on the fit's own Jacobian (400 rows, robot and set-up columns) and its covariance it equals the three-operand
    einsum it replaced within 4e-15 relative, and is symmetric to rounding."""
    from pin_kpi_oed.discrepancy.sandwich import row_sandwich
    from pin_kpi_oed.identification.discrepancy_fit import parameter_jacobian

    _, train, _ = withheld
    res = fits[1]
    F, _ = parameter_jacobian(res, train.q)
    d = res.discrepancy
    C = d.param_cov if d.param_cov is not None else d.param_cov_ls
    assert C is not None and C.shape[0] == F.shape[2] > 20
    got, ref = row_sandwich(F, C), np.einsum("map,pq,mbq->mab", F, C, F)
    assert got.shape == (len(train), 3, 3)
    assert np.max(np.abs(got - ref)) <= 4e-15 * np.max(np.abs(ref))
    assert np.max(np.abs(got - got.transpose(0, 2, 1))) <= 4e-15 * np.max(np.abs(ref))


#: training rows of the command-line tests: 200 of the 400 (a Gaussian process's fit grows with the cube of its rows;
#: 200 distinct poses are still more than three times the 60 the default needs to try one, and the withheld harmonic
#: is learnt from them: the API tests use all 400)
CLI_ROWS = 200


@shares_fits
def test_withheld_effect_learnt_with_honest_sigma(withheld, fits, tmp_path):
    model, train, test = withheld
    plain, fit = fits
    # the parametric part is fitted first: the geometry is the same with or without the discrepancy
    assert np.allclose(plain.values, fit.values)
    assert fit.discrepancy.kind == "exact", fit.discrepancy.decision
    v0, v1 = validate(plain, test), validate(fit, test)
    assert v1["mean_m"] < 0.6 * v0["mean_m"], (v0["mean_m"], v1["mean_m"])
    assert 0.67 <= v1["z_rms"] <= 1.5 and 0.85 <= v1["inside_95"] <= 0.995, v1
    assert v0["z_rms"] > 3                                     # the noise-only σ is far too small here
    # the model file carries the discrepancy: predictions and σ reproduced after a round trip
    cm = fit.calibrated_model()
    cm.save(tmp_path / "m.json")
    back = load_model_file(tmp_path / "m.json")
    Q = test.q
    Y0, s0, e0 = cm.predict_with_sigma(Q)
    Y1, s1, e1 = back.predict_with_sigma(Q)
    assert np.allclose(Y0, Y1, atol=1e-12) and np.allclose(s0, s1) and np.array_equal(e0, e1)
    cols, table = predict_table(back, test)
    assert cols[:7] == ["x_pred", "y_pred", "z_pred", "sigma_x", "sigma_y", "sigma_z", "extrapolation"]
    assert np.allclose(table[:, 3:6], s1)


@shares_fits
def test_extrapolation_flag_and_sigma_grow_outside_coverage(withheld, fits):
    """An exact Gaussian process (the default's choice here, as ``on`` would make it) flags configurations outside
    the training range and its σ grows there."""
    model, train, test = withheld
    fit = fits[1]
    assert fit.discrepancy.kind == "exact", fit.discrepancy.decision
    cm = fit.calibrated_model()
    Q_in = test.q[:50]
    Q_out = Q_in.copy()
    Q_out[:, 0] = np.pi - 0.2                                  # shoulder_pan far outside the ±1.5 rad trained
    _, s_in, e_in = cm.predict_with_sigma(Q_in)
    _, s_out, e_out = cm.predict_with_sigma(Q_out)
    assert e_out.all() and e_in.mean() < 0.1
    assert np.linalg.norm(s_out, axis=1).mean() > 1.5 * np.linalg.norm(s_in, axis=1).mean()


def test_cli_identify_predict_and_damaged_block(withheld, tmp_path, capsys):
    model, train, test = withheld
    write_measurements(train.subset(np.arange(CLI_ROWS)), tmp_path / "train.csv")
    write_measurements(test, tmp_path / "test.csv")
    r = tmp_path / "m.json"
    assert main(["identify", "--robot", "ur10", "--data", str(tmp_path / "train.csv"), "--reflector", "0.03,0.02,0.08",
                 "--sigma", "1e-5", "--model-out", str(r), "--accept-poor-fit", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "discrepancy: Gaussian process fitted" in out
    doc = json.loads(r.read_text())
    assert doc["discrepancy"]["kind"] == "exact"
    pred = tmp_path / "pred.csv"
    assert main(["predict", "--model", str(r), "--data", str(tmp_path / "test.csv"), "--out", str(pred)]) == 0
    head = pred.read_text().splitlines()[0].split(",")
    assert {"sigma_x", "sigma_y", "sigma_z", "extrapolation"} <= set(head)
    for field, value, needle in [("kernel", {"form": "joint_wrapped_se/1"}, "discrepancy.kernel.amplitude"),
                                 ("scale_m", "abc", "discrepancy.scale_m"),
                                 ("joint_names", ["a", "b"], "discrepancy.joint_names"),
                                 ("y", {"shape": [2, 3], "float64_b64": "!!"}, "discrepancy.y")]:
        bad = json.loads(r.read_text())
        bad["discrepancy"][field] = value
        f = tmp_path / f"bad_{field}.json"
        f.write_text(json.dumps(bad))
        out_csv = tmp_path / f"pred_{field}.csv"
        assert main(["predict", "--model", str(f), "--data", str(tmp_path / "test.csv"), "--out", str(out_csv)]) == 2
        err = capsys.readouterr().err
        assert needle in err and str(f) in err and "Traceback" not in err, err
        assert not out_csv.exists()


def test_cli_diagnose_model_out_feeds_register_and_predict(withheld, tmp_path, capsys):
    """diagnose --model-out writes the reported model (with its discrepancy); register keeps the robot's
    discrepancy and re-fits the set-up only; predict then writes σ."""
    model, train, test = withheld
    write_measurements(train.subset(np.arange(CLI_ROWS)), tmp_path / "train.csv")
    write_measurements(test.subset(np.arange(40)), tmp_path / "reg.csv")
    write_measurements(test.subset(np.arange(40, 300)), tmp_path / "held.csv")
    m = tmp_path / "diag_model.json"
    assert main(["diagnose", "--robot", "ur10", "--train", str(tmp_path / "train.csv"), "--kfold", "3",
                 "--reflector", "0.03,0.02,0.08", "--sigma", "1e-5", "--effects", "joint_compliance,gear_harmonic",
                 "--model-out", str(m), "--quiet"]) == 0
    doc = json.loads(m.read_text())
    assert "discrepancy" in doc and doc["discrepancy"]["kind"] in ("exact", "white")
    reg = tmp_path / "reg_model.json"
    assert main(["register", "--model", str(m), "--data", str(tmp_path / "reg.csv"), "--model-out", str(reg)]) == 0
    back = load_model_file(reg)
    assert back.discrepancy is not None and back.discrepancy.to_dict() == load_model_file(m).discrepancy.to_dict()
    pred = tmp_path / "pred.csv"
    assert main(["predict", "--model", str(reg), "--data", str(tmp_path / "held.csv"), "--out", str(pred)]) == 0
    p = np.genfromtxt(pred, delimiter=",", names=True)
    z = np.c_[p["x"] - p["x_pred"], p["y"] - p["y_pred"], p["z"] - p["z_pred"]] / np.c_[p["sigma_x"], p["sigma_y"],
                                                                                      p["sigma_z"]]
    assert 0.5 < np.sqrt(np.mean(z ** 2)) < 2.0


@shares_fits
def test_compensation_includes_the_discrepancy(withheld, fits):
    """Compensated joints put the calibrated TCP — discrepancy included (the fitted Gaussian process of
    :func:`fits`) — on the targets; each carries its σ."""
    from pin_kpi_oed.data.measurements import MeasurementSet
    from pin_kpi_oed.data.targets import TargetSet
    from pin_kpi_oed.compensation.compensator import CompensationOptions, compensate, forward

    model, train, test = withheld
    assert fits[1].discrepancy.kind == "exact", fits[1].discrepancy.decision
    cm = fits[1].calibrated_model()
    Q = test.q[:8]
    goal = forward(cm, Q, frame="base")
    plain = forward(dataclasses_replace(cm), Q, frame="base")
    assert np.abs(goal - plain).max() > 1e-6                    # the discrepancy moves the predicted TCP
    ts = TargetSet([f"t{i}" for i in range(8)], goal, None, None, list(cm.robot.joint_names),
                   MeasurementSet(list(cm.robot.joint_names), Q, np.full((len(Q), 3), np.nan)))
    refl = cm.setups[cm.station(None)].reflector_m  # forward's point: the TCP these targets are at
    res = compensate(cm, ts, CompensationOptions(frame="base", tcp_m=refl))
    ok = np.array([s in SENDABLE for s in res.target_status])  # reached (extrapolated, TCP unmeasured: flagged)
    assert ok.sum() >= 6 and [s == "extrapolated" for s in res.target_status] == res.extrapolation.tolist()
    assert np.abs(forward(cm, res.q[ok], frame="base") - goal[ok]).max() < 1e-9
    assert res.sigma_m.shape == (8,) and np.all(res.sigma_m > 0)


def dataclasses_replace(cm):
    import dataclasses

    return dataclasses.replace(cm, discrepancy=None)


def test_cli_too_few_rows_for_the_discrepancy(withheld, tmp_path, capsys):
    """--discrepancy on with fewer rows than a Gaussian process needs: one line, exit 2, nothing written."""
    model, train, _ = withheld
    write_measurements(train.subset(np.arange(30)), tmp_path / "few.csv")
    out = tmp_path / "m.json"
    rc = main(["identify", "--robot", "ur10", "--data", str(tmp_path / "few.csv"), "--reflector", "0.03,0.02,0.08",
               "--sigma", "1e-5", "--discrepancy", "on", "--model-out", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and "too few" in err and "--discrepancy" in err and "Traceback" not in err
    assert not out.exists()


@shares_fits
def test_fit_quality_counts_the_discrepancy_but_never_excuses_a_poor_fit(withheld, fits):
    """Residuals three times the stated noise: suspect for the noise-only model, good when a Gaussian process with an
    honest K-fold σ explains them (said so); residuals six times the noise stay poor with or without it. (The
    Gaussian process's white level is never below the stated noise: at twice the noise that floor makes the K-fold
    σ 1.5x too large, standardised RMS 0.67.) The hyper-parameters are fitted on a seeded subset of 150 of the 400
    rows (the K-fold check the verdict reads uses all 400): the claim is about the verdict, not the subset's size,
    and the check's standardised RMS is 0.92 there (0.76 on 300 rows), both inside the verdict's [0.67, 1.5]; a
    Gaussian process's fit grows with the cube of its subset."""
    from pin_kpi_oed.identification.quality import assess_fit
    model, train, _ = withheld
    r = np.sqrt(np.mean(fits[0].residuals_m ** 2))  # residual RMS per axis (m)
    for factor, plain_verdict, gp_verdict in [(3.0, "suspect", "good"), (6.0, "poor", "poor")]:
        data = dataclasses.replace(train, sigma_m=np.full((len(train), 3), r / factor))
        plain = assess_fit(identify(model, data, discrepancy="none"))
        with_gp = assess_fit(identify(model, data, discrepancy=DiscrepancyOptions(mode="on", n_fit=150, seed=0)))
        assert plain.verdict == plain_verdict and "chi2" in plain.line(), plain.line()
        assert with_gp.verdict == gp_verdict, with_gp.line()
        if gp_verdict == "good":
            assert "model discrepancy" in with_gp.line() and with_gp.to_dict()["explained_by_discrepancy"]


def test_cli_diagnose_transfer_section_reports_the_written_models_sigma(withheld, tmp_path, capsys):
    """With validation data and --model-out, the transfer section scores the written model with the σ predict
    writes (same registration rows and seed): its figures equal validate_transfer's on the model file."""
    from pin_kpi_oed.upkeep.transfer import validate_transfer
    model, train, test = withheld
    write_measurements(train.subset(np.arange(CLI_ROWS)), tmp_path / "train.csv")
    write_measurements(test, tmp_path / "val.csv")
    m, rep = tmp_path / "m.json", tmp_path / "rep.json"
    assert main(["diagnose", "--robot", "ur10", "--train", str(tmp_path / "train.csv"), "--validate",
                 str(tmp_path / "val.csv"), "--register-rows", "40", "--seed", "3", "--reflector", "0.03,0.02,0.08",
                 "--sigma", "1e-5", "--effects", "joint_compliance", "--discrepancy", "on", "--model-out", str(m),
                 "--json", str(rep)]) == 0
    out = capsys.readouterr().out
    assert "the written model's sigma at the validation rows" in out
    ms = json.loads(rep.read_text())["transfer"]["model_sigma"]
    from pin_kpi_oed.data.measurements import read_measurements
    ref = validate_transfer(load_model_file(m), read_measurements(tmp_path / "val.csv"), register_rows=40, seed=3)
    assert ms["z_rms"] == pytest.approx(ref["z_rms"], rel=1e-6) and ms["n"] == ref["n"] == 260
    assert 0.67 <= ms["z_rms"] <= 1.5 and "discrepancy" in ms["model"]


def test_coverage_of_a_training_remembered_equals_the_one_computed():
    """Every fit of a diagnosis states its training's coverage (and the discrepancy's fit again): the second time it is
    remembered, every number equal to the one computed, with arrays of its own (changing one changes no later
    coverage); a training forgotten after ``REMEMBERED`` others is computed again to the same numbers, and another
    seed or periodic mask is another coverage."""
    from pin_kpi_oed.discrepancy.coverage import REMEMBERED, JointCoverage

    rng = np.random.default_rng(2024)
    Q = rng.uniform(-3.0, 3.0, (2300, 6))                          # above MAX_STORED: the seed draws the subset
    per = np.array([True, True, False, True, True, True])

    def same(a, b):
        return (np.array_equal(a.Z, b.Z) and a.radius_rad == b.radius_rad and a.n_rows == b.n_rows
                and np.array_equal(a.joint_radius_rad, b.joint_radius_rad) and np.array_equal(a.periodic, b.periodic))
    first = JointCoverage.from_training(Q, 3, per)
    again = JointCoverage.from_training(Q.copy(), 3, per)
    assert same(first, again) and again.Z is not first.Z
    again.Z[:] = 0.0
    again.joint_radius_rad[:] = 9.0
    assert same(first, JointCoverage.from_training(Q, 3, per))
    other_seed = JointCoverage.from_training(Q, 4, per)
    assert not np.array_equal(other_seed.Z, first.Z)
    assert not np.array_equal(JointCoverage.from_training(Q, 3, None).periodic, first.periodic)
    for k in range(REMEMBERED):
        JointCoverage.from_training(Q[k:k + 50], 3, per)
    assert same(first, JointCoverage.from_training(Q, 3, per))      # computed again
