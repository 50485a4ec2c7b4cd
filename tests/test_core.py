"""Calibration core: derivatives vs finite differences, identifiability, covariances, Monte-Carlo."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from pin_kpi_oed.oed import covariance as cov
from pin_kpi_oed.oed import identifiability as idf
from pin_kpi_oed.oed.criteria import CRITERIA, Criterion
from pin_kpi_oed.oed.objective import DesignCriterion
from pin_kpi_oed.errors import IdentifiabilityError, InputError
from pin_kpi_oed.model.noise import NoiseModel

from .conftest import make_model

EPS = 1e-6


def _fd_rot(ya, yb):
    """Central difference of rotation-vector outputs in the world (tracker) frame."""
    return np.array([pin.log3(pin.exp3(a) @ pin.exp3(b).T) for a, b in zip(ya, yb)])


@pytest.mark.parametrize("name,pose6d", [("kr15", False), ("ur10", False), ("ur10", True), ("panda", False)])
def test_parameter_jacobian_matches_finite_differences(name, pose6d):
    model = make_model(name, pose6d=pose6d, noise=NoiseModel(range_a_m=5e-6, range_b=1e-6))
    rng = np.random.default_rng(0)
    p = rng.normal(scale=1e-2, size=model.n_params)  # away from nominal: checks the exp6 right Jacobians
    Q = model.robot.random_q(rng, 5)
    J = model.jacobian(p, Q)
    Jfd = np.zeros_like(J)
    for i in range(model.n_params):
        dp = np.zeros(model.n_params)
        dp[i] = EPS
        yp, ym = model.predict(p + dp, Q), model.predict(p - dp, Q)
        Jfd[:, :3, i] = (yp[:, :3] - ym[:, :3]) / (2 * EPS)
        if pose6d:
            Jfd[:, 3:, i] = _fd_rot(yp[:, 3:], ym[:, 3:]) / (2 * EPS)
    assert np.abs(J - Jfd).max() < 1e-7 * max(1.0, np.abs(J).max())


@pytest.mark.parametrize("name,pose6d", [("kr15", False), ("ur10", True)])
def test_jacobian_q_derivatives_match_finite_differences(name, pose6d):
    model = make_model(name, pose6d=pose6d, noise=NoiseModel(range_a_m=5e-6, range_b=1e-6))
    rng = np.random.default_rng(1)
    p = rng.normal(scale=1e-2, size=model.n_params)
    Q = model.robot.random_q(rng, 4)
    _, J, dJ, Ydq = model.jacobian_dq(p, Q)
    F, dF = model.weighted_jacobian_dq(p, Q)
    c, dc = model.incidence_cos(p, Q, with_grad=True)
    for k in range(model.robot.nq):
        dq = np.zeros(model.robot.nq)
        dq[k] = EPS
        dJ_fd = (model.jacobian(p, Q + dq) - model.jacobian(p, Q - dq)) / (2 * EPS)
        dF_fd = (model.weighted_jacobian(p, Q + dq) - model.weighted_jacobian(p, Q - dq)) / (2 * EPS)
        dc_fd = (model.incidence_cos(p, Q + dq) - model.incidence_cos(p, Q - dq)) / (2 * EPS)
        dy_fd = (model.predict(p, Q + dq)[:, :3] - model.predict(p, Q - dq)[:, :3]) / (2 * EPS)
        assert np.abs(dJ[..., k] - dJ_fd).max() < 1e-7
        assert np.abs(dF[..., k] - dF_fd).max() < 1e-7 * np.abs(dF).max()
        assert np.abs(dc[:, k] - dc_fd).max() < 1e-7
        assert np.abs(Ydq[..., k] - dy_fd).max() < 1e-7
    assert np.array_equal(model.prediction_dq(p, Q), Ydq)  # the cheap path the effects use


def test_batched_kinematics_matches_pinocchio():
    model = make_model("ur10")
    rng = np.random.default_rng(2)
    p = rng.normal(scale=1e-2, size=model.n_params)
    Q = model.robot.random_q(rng, 6)
    point = np.array([0.1, -0.02, 0.03])
    kin = model.kinematics(p, Q, point)
    pm = model.pinocchio_model(p)
    data = pm.createData()
    for i, q in enumerate(Q):
        pin.computeJointJacobians(pm, data, q)
        pin.updateFramePlacements(pm, data)
        assert np.abs(data.J - kin.twist[i]).max() < 1e-12
        assert np.abs(data.oMf[model.robot.tool_frame_id].act(point) - kin.p[i]).max() < 1e-12


@pytest.mark.parametrize("name", ["ur5", "ur10", "kr15"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_rank_is_27_with_off_axis_reflector(name, seed):
    model = make_model(name)
    ident = idf.analyse(model, seed=seed)
    assert ident.n_raw == 45
    assert ident.rank == 27
    assert len(ident.base) == 27
    # the convention: joint 1's placement is held, the tracker pose kept
    assert all(n.startswith("tracker") is False for n in (d["name"] for d in ident.dropped))
    assert any(d["convention"] for d in ident.dropped)


@pytest.mark.parametrize("name", ["ur10", "kr15"])
def test_on_axis_reflector_drops_two_and_says_why(name):
    model = make_model(name, reflector=(0.0, 0.0, 0.08))
    ident = idf.analyse(model)
    assert ident.rank == 25
    assert any("axis" in n and "rank drops by 2" in n for n in ident.notes)
    E = model.kpi_jacobian(np.zeros(model.n_params), model.robot.random_q(np.random.default_rng(0), 1))
    with pytest.raises(IdentifiabilityError, match="not estimable"):
        idf.check_kpi(ident, model, E)


def test_kpi_in_base_frame_is_not_estimable_with_unknown_tracker(kr15_model):
    model = kr15_model
    ident = idf.analyse(model)
    Qw = model.robot.random_q(np.random.default_rng(3), 1)
    E = model.kpi_jacobian(np.zeros(model.n_params), Qw)
    idf.check_kpi(ident, model, E)  # tracker frame: estimable
    E_base = model.tracker_T_base.rotation.T @ E  # same point in the base frame ...
    E_base[:, model.layout.tracker] = 0.0  # ... does not depend on the tracker pose
    with pytest.raises(IdentifiabilityError, match="tracker"):
        idf.check_kpi(ident, model, E_base)


def _design(model, m=60, seed=0):
    rng = np.random.default_rng(seed)
    return model.robot.random_q(rng, m), model.robot.random_q(rng, 2)


def test_trace_cs_invariant_to_identifiable_choice_and_cp_is_not(kr15_model):
    model = kr15_model
    Q, Qw = _design(model)
    p0 = np.zeros(model.n_params)
    F = model.weighted_jacobian(p0, Q).reshape(-1, model.n_params)
    E = model.kpi_jacobian(p0, Qw)
    a = idf.analyse(model)
    b = idf.analyse(model, prefer=["joint_a1.*"])  # keep joint 1's placement instead of the tracker pose
    assert set(a.base_names) != set(b.base_names)
    tr_a = np.trace(cov.kpi_covariance(F[:, a.base], E[:, a.base]))
    tr_b = np.trace(cov.kpi_covariance(F[:, b.base], E[:, b.base]))
    assert abs(tr_a - tr_b) < 1e-8 * tr_a
    # against the convention (wrist placement kept instead of the reflector offset)
    c = idf.analyse(model, prefer=["joint_a6.*", "joint_a5.*"])
    cp = [np.trace(cov.param_covariance(F[:, s.base])) for s in (a, c)]
    assert abs(cp[0] - cp[1]) > 1e-3 * cp[0]  # tr(C_p) depends on the choice ...
    tr_c = np.trace(cov.kpi_covariance(F[:, c.base], E[:, c.base]))
    assert abs(tr_c - tr_a) > 1e-3 * tr_a  # ... and so does a TCP away from the reflector: the convention matters
    # the reflector point as KPI (its sensitivity is the measurement Jacobian at q_work):
    # invariant under any choice, even against the convention
    Er = model.jacobian(p0, Qw).reshape(-1, model.n_params)
    tr_r = [np.trace(cov.kpi_covariance(F[:, s.base], Er[:, s.base])) for s in (a, b, c)]
    assert np.ptp(tr_r) < 1e-8 * tr_r[0]


def test_kkt_form_equals_explicit_formula(kr15_model):
    model = kr15_model
    Q, Qw = _design(model, 40, 4)
    p0 = np.zeros(model.n_params)
    ident = idf.analyse(model)
    F = model.weighted_jacobian(p0, Q)[:, :, ident.base].reshape(-1, ident.base.size)
    E = model.kpi_jacobian(p0, Qw)[:, ident.base]
    prior = np.full(ident.base.size, 1e-3)
    for pr in (None, prior):
        Cs = cov.kpi_covariance(F, E, pr)
        Cp2, Cs2 = cov.kpi_covariance_kkt(F, E, pr)
        assert np.abs(Cs - Cs2).max() < 1e-8 * np.abs(Cs).max()
        assert np.abs(cov.param_covariance(F, pr) - Cp2).max() < 1e-8 * np.abs(Cp2).max()


def test_singular_design_is_reported():
    model = make_model("kr15")
    Q = np.repeat(model.robot.random_q(np.random.default_rng(0), 1), 30, axis=0)  # one pose, 30 times
    ident = idf.analyse(model)
    F = model.weighted_jacobian(np.zeros(model.n_params), Q)[:, :, ident.base].reshape(-1, ident.base.size)
    with pytest.raises(IdentifiabilityError, match="singular"):
        cov.param_covariance(F, names=ident.base_names)


@pytest.mark.parametrize("name", [n for n, c in CRITERIA.items() if isinstance(c, Criterion)])
def test_criterion_gradients_match_finite_differences(name):
    """Criteria of F (those of the configurations, kpi_gp, have their finite-difference test in test_kpi_gp)."""
    model = make_model("kr15", noise=NoiseModel(range_a_m=5e-6, range_b=1e-6))
    ident = idf.analyse(model)
    rng = np.random.default_rng(5)
    Q = model.robot.random_q(rng, 12)
    E = model.kpi_jacobian(np.zeros(model.n_params), model.robot.random_q(rng, 2))[:, ident.base]
    dc = DesignCriterion(model, ident.base, name, E)
    v, g = dc.value_and_grad(Q)
    assert np.isfinite(v)
    gfd = np.zeros_like(g)
    for i in range(Q.shape[0]):
        for k in range(Q.shape[1]):
            Qp, Qm = Q.copy(), Q.copy()
            Qp[i, k] += EPS
            Qm[i, k] -= EPS
            gfd[i, k] = (dc.value(Qp) - dc.value(Qm)) / (2 * EPS)
    assert np.abs(g - gfd).max() < 1e-5 * np.abs(gfd).max()


def test_monte_carlo_tcp_covariance_matches_cs():
    """300 simulated 60-pose experiments (noise only, start = truth): empirical TCP covariance vs C_s. Two
    Gauss-Newton steps on the nonlinear model: the second is below 1e-3 of the first in every experiment (asserted),
    so a third (quadratic convergence: ~1e-7 of the first, measured 4e-8) would move no estimate by a visible share
    of its error."""
    model = make_model("kr15", noise=NoiseModel(sigma_xyz_m=(2e-5, 2e-5, 2e-5)))
    rng = np.random.default_rng(7)
    Q, Qw = _design(model, 60, 7)
    ident = idf.analyse(model)
    b = ident.base
    p_true = np.zeros(model.n_params)
    p_true[b] = rng.normal(scale=1e-4, size=b.size)  # a truth away from nominal
    Y_true = model.predict(p_true, Q)
    s_true = model.kpi(p_true, Qw).ravel()
    F = model.weighted_jacobian(p_true, Q)[:, :, b].reshape(-1, b.size)
    E = model.kpi_jacobian(p_true, Qw)[:, b]
    C_s = cov.kpi_covariance(F, E)
    sig = np.asarray(model.noise.sigma_xyz_m)
    errs, converged = [], []
    for _ in range(300):
        eta = Y_true + rng.normal(size=Y_true.shape) * sig
        p = p_true.copy()
        steps = []
        for _ in range(2):  # Gauss-Newton on the nonlinear model
            r = ((eta - model.predict(p, Q)) / sig).ravel()
            Jw = (model.jacobian(p, Q) / sig[None, :, None])[:, :, b].reshape(-1, b.size)
            steps.append(np.linalg.lstsq(Jw, r, rcond=None)[0])
            p[b] += steps[-1]
        converged.append(np.linalg.norm(steps[1]) < 1e-3 * np.linalg.norm(steps[0]))
        errs.append(model.kpi(p, Qw).ravel() - s_true)
    assert all(converged), "the Gauss-Newton fit has converged after two steps"
    C_emp = np.cov(np.array(errs).T)
    assert abs(np.trace(C_emp) / np.trace(C_s) - 1.0) < 0.15


def test_noise_model_rejects_bad_values():
    with pytest.raises(InputError, match="sigma"):
        NoiseModel(sigma_xyz_m=(1e-6, float("nan"), 1e-6))
    with pytest.raises(InputError, match="distance-dependent"):
        NoiseModel(range_a_m=-1.0)


def test_check_q_names_joint_and_value(kr15_model):
    rb = kr15_model.robot
    q = rb.neutral()
    q[1] = 3.0
    with pytest.raises(InputError, match=r"joint_a2 = 3 rad is outside"):
        rb.check_q(q, "q_meas")
    q = rb.neutral()
    q[4] = np.nan
    with pytest.raises(InputError, match="joint_a5 is nan"):
        rb.check_q(q, "q_meas")


def test_pivoted_qr_diagonal_is_lapacks():
    """The rank's pivoted QR in NumPy against LAPACK's geqp3 (SciPy): the same rank at the analysis' threshold and
    the same |R_kk| to rounding, on random matrices of every rank, badly scaled columns included."""
    import scipy.linalg as sla

    rng = np.random.default_rng(3)
    for _ in range(60):
        m, n = int(rng.integers(5, 200)), int(rng.integers(2, 50))
        r = int(rng.integers(1, n + 1))
        A = rng.standard_normal((m, r)) @ rng.standard_normal((r, n)) * rng.lognormal(0.0, 2.0, n)
        ref = np.abs(np.diag(sla.qr(A, mode="economic", pivoting=True)[1]))
        got = idf.pivoted_qr_diagonal(A)
        k = min(r, m, n)
        assert int(np.sum(got > 1e-7 * got[0])) == int(np.sum(ref > 1e-7 * ref[0])) == k
        assert np.abs(got[:k] - ref[:k]).max() <= 1e-12 * ref[0]
