"""Designs over the extended model (geometry + effects) with a prior."""

from __future__ import annotations

import numpy as np
import pytest

from pin_kpi_oed.effects.coupled import LinkBending
from pin_kpi_oed.effects.library import predict_with_effects
from pin_kpi_oed.effects.periodic import TransmissionError
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.identification.identify import identify
from pin_kpi_oed.simulation.simulator import simulate
from pin_kpi_oed.model.noise import NoiseModel
from pin_kpi_oed.model.robot import load_robot
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.oed.covariance import prior_square_root
from pin_kpi_oed.oed.extended import ExtendedModel, pool_phi, select_pool
from pin_kpi_oed.oed.identifiability import analyse
from pin_kpi_oed.oed.pool import select


@pytest.fixture(scope="module")
def ur10():
    robot = load_robot("ur10")
    model = TrackerModel(robot, reflector_m=np.array([0.0, 0.0, 0.109]), noise=NoiseModel(sigma_xyz_m=(1e-5,) * 3))
    return robot, model, analyse(model).base


def _ext(robot, model, base, theta_scale=3e-4, prior=None):
    effects = [TransmissionError(robot, pairs=[("shoulder_lift_joint", 7), ("elbow_joint", 18)]),
               LinkBending(robot, terms=[("elbow_joint", "q2+q3", "cos"), ("shoulder_lift_joint", 0, "sin")])]
    rng = np.random.default_rng(1)
    thetas = [theta_scale * rng.standard_normal(e.n_params) for e in effects]
    p = 1e-4 * np.random.default_rng(2).standard_normal(model.n_params)
    return ExtendedModel(model, p, base, effects, thetas, prior_info=prior)


def test_effect_columns_match_finite_differences(ur10):
    robot, model, base = ur10
    ext = _ext(robot, model, base)
    Q = robot.random_q(np.random.default_rng(3), 7)
    J = ext.jacobian(Q, weighted=False)
    h = 1e-7
    for j in range(ext.k):
        th_p = np.concatenate(ext.thetas).copy()
        th_m = th_p.copy()
        th_p[j] += h
        th_m[j] -= h
        ys = []
        for th in (th_p, th_m):
            parts = np.split(th, np.cumsum([e.n_params for e in ext.effects])[:-1])
            ys.append(predict_with_effects(model, ext.p, Q, None, list(zip(ext.effects, parts)))[:, :3])
        fd = (ys[0] - ys[1]) / (2 * h)
        assert np.allclose(J[:, :3, ext.nb + j], fd, rtol=1e-5, atol=1e-9)
    # geometric columns at Q + dQ, and weighting by sigma
    assert np.allclose(ext.jacobian(Q), J / 1e-5)


def test_kpi_jacobian_effect_columns_match_finite_differences(ur10):
    robot, model, base = ur10
    ext = _ext(robot, model, base)
    Qw = robot.random_q(np.random.default_rng(4), 3)
    E = ext.kpi_jacobian(Qw)
    h = 1e-7

    def kpi(th):
        parts = np.split(th, np.cumsum([e.n_params for e in ext.effects])[:-1])
        dQ = sum(e.joint_offset(t, Qw)[0] for e, t in zip(ext.effects, parts))
        return model.kpi(ext.p, Qw + dQ).ravel()

    th0 = np.concatenate(ext.thetas)
    for j in range(ext.k):
        d = np.zeros_like(th0)
        d[j] = h
        assert np.allclose(E[:, ext.nb + j], (kpi(th0 + d) - kpi(th0 - d)) / (2 * h), rtol=1e-5, atol=1e-9)
    dQ = sum(e.joint_offset(t, Qw)[0] for e, t in ext.pairs)
    assert np.allclose(E[:, :ext.nb], model.kpi_jacobian(ext.p, Qw + dQ)[:, base])


def test_prior_square_root_rank_deficient():
    rng = np.random.default_rng(0)
    A = rng.standard_normal((3, 6))
    P = A.T @ A  # rank 3
    R = prior_square_root(P)
    assert R.shape == (3, 6)
    assert np.allclose(R.T @ R, P)


def test_map_covariance_and_every_criterion_use_the_prior(ur10):
    robot, model, base = ur10
    ext = _ext(robot, model, base)
    Q = robot.random_q(np.random.default_rng(5), 40)
    Qw = robot.random_q(np.random.default_rng(6), 3)
    sig = np.r_[np.full(ext.nb, np.inf), np.full(ext.k, 1e-4)]
    P = np.diag(np.where(np.isfinite(sig), 1 / sig ** 2, 0.0))
    F = ext.jacobian(Q).reshape(-1, ext.nx)
    E = ext.kpi_jacobian(Qw)
    C_ref = np.linalg.inv(F.T @ F + P)
    ext.prior_info = P
    C, C_s = ext.covariances(Q, Qw)
    assert np.allclose(C, C_ref, rtol=1e-8, atol=0)
    assert np.isclose(ext.criterion("kpi", Q, Qw), np.trace(E @ C_ref @ E.T), rtol=1e-8)
    assert np.isclose(ext.criterion("param", Q), np.trace(C_ref), rtol=1e-8)
    assert np.isclose(ext.criterion("D", Q), -np.linalg.slogdet(F.T @ F + P)[1], rtol=1e-10)
    # the prior only removes uncertainty: tr C_s with the prior is below the one without
    ext.prior_info = None
    assert np.trace(C_s) < np.trace(ext.covariances(Q, Qw)[1])


def test_select_pool_with_prior_consistent_and_better_than_random(ur10):
    robot, model, base = ur10
    ext = _ext(robot, model, base)
    ext.prior_info = np.diag(np.r_[np.zeros(ext.nb), np.full(ext.k, 1e8)])
    Qp = robot.random_q(np.random.default_rng(7), 300)
    Fp = ext.jacobian(Qp)
    K = ext.kpi_jacobian(robot.random_q(np.random.default_rng(8), 2))
    s = select_pool(Fp, 40, K, ext.prior_info)
    idx = s.indices
    assert np.unique(idx).size == 40
    F = Fp[idx].reshape(-1, ext.nx)
    assert np.isclose(s.value, pool_phi(ext.prior_info + F.T @ F, K), rtol=1e-9)
    rng = np.random.default_rng(9)
    rnd = []
    for _ in range(20):
        Fr = Fp[rng.choice(300, 40, replace=False)].reshape(-1, ext.nx)
        rnd.append(pool_phi(ext.prior_info + Fr.T @ Fr, K))
    assert s.value < min(rnd)
    # without a prior it is pool.select
    s0 = select_pool(Fp, 40, K, None)
    assert np.array_equal(np.sort(s0.indices), np.sort(select(Fp, 40, K).indices))
    with pytest.raises(InputError):
        select_pool(Fp, 301, K, ext.prior_info)


def test_pool_gains_match_the_criterion_change_and_the_exchange_is_a_local_optimum(ur10):
    """Woodbury gains (adding a block; swapping one out, then adding) are exactly −Δφ; no single swap improves."""
    from pin_kpi_oed.errors import IdentifiabilityError
    from pin_kpi_oed.oed.pool_search import InformationState

    robot, model, base = ur10
    ext = _ext(robot, model, base)
    ext.prior_info = np.diag(np.r_[np.zeros(ext.nb), np.full(ext.k, 1e8)])
    Fp = ext.jacobian(robot.random_q(np.random.default_rng(11), 120))
    K = ext.kpi_jacobian(robot.random_q(np.random.default_rng(12), 2))
    N, nh, nx = Fp.shape
    F0 = Fp[:50].reshape(-1, nx)
    M = ext.prior_info + F0.T @ F0
    for KK in (K, None):
        st = InformationState(Fp, KK, M)
        assert np.isclose(st.phi, pool_phi(M, KK), rtol=1e-9, atol=0.0)
        ref = np.array([pool_phi(M, KK) - pool_phi(M + Fp[i].T @ Fp[i], KK) for i in range(N)])
        assert np.allclose(st.add_gains(), ref, rtol=1e-7, atol=1e-12 * abs(pool_phi(M, KK)))
        for o in (3, 17):
            Mm = M - Fp[o].T @ Fp[o]
            phi_m, g = st.swap_gains(o)
            assert np.isclose(phi_m, pool_phi(Mm, KK), rtol=1e-9, atol=1e-12)
            ref = np.array([pool_phi(Mm, KK) - pool_phi(Mm + Fp[i].T @ Fp[i], KK) for i in range(N)])
            assert np.allclose(g, ref, rtol=1e-7, atol=1e-12 * abs(pool_phi(M, KK)))
        # nh > 3 path (blocks of two measurements stacked) agrees with the closed form
        st6 = InformationState(Fp.reshape(N // 2, 2 * nh, nx), KK, M)
        F6 = [Fp[2 * i:2 * i + 2].reshape(-1, nx) for i in range(N // 2)]
        ref6 = np.array([pool_phi(M, KK) - pool_phi(M + F.T @ F, KK) for F in F6])
        assert np.allclose(st6.add_gains(), ref6, rtol=1e-7, atol=1e-12 * abs(pool_phi(M, KK)))
    with pytest.raises(IdentifiabilityError, match="not positive definite"):
        InformationState(Fp, K, -np.eye(nx))

    with pytest.raises(IdentifiabilityError, match="chosen candidates"):
        select_pool(Fp, 2, K, ext.prior_info)  # 6 rows cannot determine the geometry without a prior
    s = select_pool(Fp, 20, K, ext.prior_info)
    chosen = list(s.indices)
    for pos in range(0, 20, 4):
        for j in range(0, N, 7):
            if j in chosen:
                continue
            trial = chosen.copy()
            trial[pos] = j
            Ft = Fp[trial].reshape(-1, nx)
            assert pool_phi(ext.prior_info + Ft.T @ Ft, K) >= s.value * (1 - 1e-9)


def test_from_calibrated_model_prior_by_name(ur10):
    robot, model, base = ur10
    eff = TransmissionError(robot, pairs=[("elbow_joint", 18)])
    Q = robot.random_q(np.random.default_rng(10), 80)
    data = simulate(model, Q, effects=[(eff, np.array([2e-4, -1e-4]))], seed=1)
    res = identify(model, data, use_orientation=False, effects=[eff])
    ext = ExtendedModel.from_result(res, prior="model")
    assert ext.k == 2 and ext.names[-2:] == eff.param_names()
    P = ext.prior_info
    setup = [i for i, n in enumerate(ext.names) if n.split(".")[0] in model.layout.setup_groups]
    assert setup and np.allclose(P[setup], 0.0)
    # the effect block of the prior is the inverse of the fit's (marginal) covariance of the matched names
    names = list(res.names)
    keep = [names.index(n) for n in ext.names if n in names and ext.names.index(n) not in setup]
    Cm = np.asarray(res.covariance)[np.ix_(keep, keep)]
    ii = [ext.names.index(names[j]) for j in keep]
    assert np.allclose(P[np.ix_(ii, ii)] @ Cm, np.eye(len(keep)), atol=1e-6)
    tol = ExtendedModel.from_result(res, prior="tolerances", effect_sigma_rad=1e-4)
    assert np.allclose(np.diag(tol.prior_info)[-2:], 1e8)
    with pytest.raises(InputError):
        ExtendedModel.from_result(res, prior="bogus")


def test_bias_option_rescales_weights_only(ur10):
    robot, model, base = ur10
    ext = _ext(robot, model, base)
    Q = robot.random_q(np.random.default_rng(11), 200)
    F = ext.jacobian(Q)
    ext.bias_sigma_m = 3e-5
    Fb = ext.jacobian(Q)
    assert np.allclose(Fb, F * 1e-5 / np.hypot(1e-5, 3e-5))
    K = ext.kpi_jacobian(robot.random_q(np.random.default_rng(12), 2))
    # no prior: a uniform bias does not change what the design achieves (A-type criteria are scale
    # invariant; the exchange heuristic may end in an equally good neighbour)
    a, b = select_pool(F, 30, K).indices, select_pool(Fb, 30, K).indices
    phi_a, phi_b = (pool_phi(F[i].reshape(-1, ext.nx).T @ F[i].reshape(-1, ext.nx), K) for i in (a, b))
    assert abs(phi_b / phi_a - 1) < 0.02


def test_extended_design_validation_simulated(ur10):
    from pin_kpi_oed.studies.design_trials import near_training, extended_design_validation

    robot, model, base = ur10
    Qw = np.zeros((2, 6))
    Q = np.array([[0.1, 0, 0, 0, 0, 3.0], [0.0, 0.6, 0, 0, 0, 0], [2.0, 0, 0, 0, 0, 0]])
    assert near_training(Q, Qw, 0.5, 5).tolist() == [0]
    eff = TransmissionError(robot, pairs=[("elbow_joint", 3)])
    data = simulate(model, robot.random_q(np.random.default_rng(13), 240), effects=[(eff, np.array([4e-4, 2e-4]))],
                    seed=2, record_sigma=False)
    r = extended_design_validation(model, data, n_meas=40, n_splits=2, radius_rad=1.5, max_terms=2, max_order=4,
                                   methods=("random", "kpi_ext"), show_progress=False)
    assert r.n_terms.min() >= 1  # the transmission error is found on the training pool
    # calibrated with the extended model, the held-out error is near the 10 um noise, far below the effect's size
    assert all(v.max() < 1e-4 for v in r.error_m.values())
    assert "kpi_ext" in r.summary() and r.to_dict()["methods"]["kpi_ext"]["vs_random"]["n"] == 2
    with pytest.raises(InputError):
        extended_design_validation(model, data, methods=("bogus",))


@pytest.mark.parametrize("noise", ["uniform", "range"])
def test_continuous_design_gradient_matches_finite_differences(ur10, noise):
    from pin_kpi_oed.oed.extended import ExtendedDesignCriterion

    robot, model0, base = ur10
    nz = NoiseModel(sigma_xyz_m=(1e-5,) * 3) if noise == "uniform" else NoiseModel(range_a_m=5e-6, range_b=5e-6)
    model = TrackerModel(robot, reflector_m=np.array([0.0, 0.0, 0.109]), noise=nz)
    ext = _ext(robot, model, base, theta_scale=2e-3)  # theta != 0: qe = q + dQ(q) is exercised
    ext.prior_info = np.diag(np.r_[np.zeros(ext.nb), np.full(ext.k, 1e8)])
    Q = robot.random_q(np.random.default_rng(14), 30)
    F, dF = ext.jacobian_dq(Q)
    assert np.allclose(F, ext.jacobian(Q), rtol=1e-10, atol=0)
    h = 1e-6
    for i, j in [(0, 0), (3, 1), (7, 2), (11, 3), (20, 4)]:
        Qp, Qm = Q.copy(), Q.copy()
        Qp[i, j] += h
        Qm[i, j] -= h
        fd = (ext.jacobian(Qp)[i] - ext.jacobian(Qm)[i]) / (2 * h)
        assert np.allclose(dF[i, :, :, j], fd, rtol=1e-5, atol=1e-6 * np.abs(fd).max())
    Qw = robot.random_q(np.random.default_rng(15), 2)
    for name in ("kpi", "param", "D"):
        crit = ExtendedDesignCriterion(ext, name, Qw)
        v, g = crit.value_and_grad(Q)
        assert np.isclose(v, ext.criterion(name, Q, Qw), rtol=1e-10)
        for i, j in [(2, 1), (9, 2), (25, 0)]:
            Qp, Qm = Q.copy(), Q.copy()
            Qp[i, j] += h
            Qm[i, j] -= h
            fd = (crit.value(Qp) - crit.value(Qm)) / (2 * h)
            assert np.isclose(g[i, j], fd, rtol=1e-4, atol=1e-7 * abs(v))


def test_ipopt_design_over_the_extended_model_kr15():
    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.design.optimize import DesignOptions, DesignProblem, ipopt_options, run_designs
    from pin_kpi_oed.effects.library import GearHarmonic
    from pin_kpi_oed.oed.extended import ExtendedDesignCriterion

    cell = load_cell("kr15")
    problem = DesignProblem(cell)
    rb = problem.model.robot
    ext = ExtendedModel(problem.model, problem.p0, problem.base, [GearHarmonic(rb, joints=rb.joint_names[1:3])])
    ext.prior_info = np.diag(np.r_[np.zeros(ext.nb), np.full(ext.k, 2e-4 ** -2)])
    problem = problem.replaced(extended=ext)
    crit = problem.criterion("kpi")
    assert isinstance(crit, ExtendedDesignCriterion)
    rnd, kpi = run_designs(cell, ["kpi"], 30, 0, DesignOptions(n_starts=1, ipopt=ipopt_options(max_iter=15),
                                                                pool_size=300), problem)
    assert kpi.feasible
    # the design minimised the extended KPI: far below the heuristic design's
    assert crit.value(kpi.q_meas) < 0.5 * crit.value(rnd.q_meas)
    # design table and JSON report the extended-model tr(C_s) (with the prior), the geometric one labelled beside it
    from pin_kpi_oed.cli.design import table
    from pin_kpi_oed.design.scores import extended_scores
    from pin_kpi_oed.design.design_file import design_document
    from pin_kpi_oed.design.runner import DesignRun

    sc = extended_scores(problem, [rnd, kpi], cell.q_work)
    assert np.isclose(sc[1]["trace_cs_m2"], crit.value(kpi.q_meas), rtol=1e-9, atol=0.0)
    assert np.isclose(np.trace(sc[0]["cov_s_m2"]), crit.value(rnd.q_meas), rtol=1e-9, atol=0.0)
    assert not np.isclose(sc[1]["trace_cs_m2"], kpi.trace_cs_m2, rtol=1e-3, atol=0.0)  # not the geometric value
    t = len(cell.q_work)  # the TCP sigma holds what no reflector measurement determines, as the geometric one does
    for s_, r in zip(sc, (rnd, kpi)):
        assert s_["held_trace_m2"] == r.held_trace_m2 and r.held_trace_m2 > 0
        assert s_["tcp_sigma_m"] == pytest.approx(np.sqrt((s_["trace_cs_m2"] + r.held_trace_m2) / t), rel=1e-12)
    txt = table([rnd, kpi], rnd, None, sc)
    assert f"{100 * (sc[1]['trace_cs_m2'] / sc[0]['trace_cs_m2'] - 1):+.1f}" in txt.splitlines()[-1]  # ext vs random
    assert "ext tr(C_s) mm^2" in txt and "geo tr(C_s) mm^2" in txt
    assert f"{sc[1]['trace_cs_m2'] * 1e6:.4e}" in txt.splitlines()[-1]
    assert extended_scores(DesignProblem(cell), [kpi], cell.q_work) is None
    doc = design_document(DesignRun(cell=cell, problem=problem, results=[rnd, kpi], m=30, seed=0,
                                    extended_scores=sc, model_file="m.json", prior="tolerances"))
    assert doc["designs"][1]["extended"]["trace_cs_m2"] == sc[1]["trace_cs_m2"]
    assert doc["designs"][1]["trace_cs_m2"] == kpi.trace_cs_m2
    assert doc["extended_model"]["prior"] == "tolerances" and doc["extended_model"]["n_effect"] == ext.k


def test_cli_design_model_bad_inputs(tmp_path):
    from .cli_run import run_cli_as_process

    bad = tmp_path / "m.json"
    bad.write_text('{"format": "something else"}')
    for name, args in (("missing.json", ["--model", str(tmp_path / "missing.json")]),
                       ("m.json", ["--model", str(bad)])):
        res = run_cli_as_process("design", "--cell", "kr15", "--criteria", "kpi", "--quiet", *args)
        assert res.returncode == 2, res.stderr
        assert "Traceback" not in res.stderr and name in res.stderr.splitlines()[-1]
