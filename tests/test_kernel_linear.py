"""The discrepancy kernel on a linear joint (a track in m): Δ² on the line, not 4 sin²(Δ/2) on the circle.

Value, pool path and both gradients against direct formulas and finite differences; the model-file form that
states each joint's unit (older files: every joint on the circle, as written); the fit's starts and the class
default relative to the track's travel; and a fit on a simulated track whose discrepancy varies along it.
"""

from __future__ import annotations

import numpy as np
import pytest

from pin_kpi_oed.discrepancy.kernel import FORM_CIRCLE, FORM_UNITS, JointKernel

D = 7
LIN = np.array([True] + [False] * 6)
TRACK_M = 6.4


def _configs(rng: np.random.Generator, n: int, lo: float = 0.0, hi: float = TRACK_M) -> np.ndarray:
    Q = rng.uniform(-3.0, 3.0, (n, D))
    Q[:, 0] = rng.uniform(lo, hi, n)
    return Q


def _direct(k: JointKernel, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """The kernel from its definition, pair by pair: 4 sin²(Δ/2) on the circle, Δ² on the line."""
    c, L, a, ell = k.parts(X.shape[1])
    lin = np.zeros(X.shape[1], bool) if k.linear is None else np.asarray(k.linear, bool)
    Dq = X[:, None, :] - Y[None, :, :]
    C = np.where(lin, Dq ** 2, 4.0 * np.sin(Dq / 2.0) ** 2)
    return c ** 2 * np.exp(-0.5 * (C / L ** 2).sum(-1)) + (a ** 2 * np.exp(-0.5 * C / ell ** 2)).sum(-1)


@pytest.fixture
def kernel() -> JointKernel:
    rng = np.random.default_rng(4)
    return JointKernel(0.8, rng.uniform(0.5, 2.0, D), rng.uniform(0.1, 0.4, D), rng.uniform(0.2, 0.8, D), linear=LIN)


def test_track_positions_two_pi_metres_apart_are_not_the_same(kernel):
    """On the circle q and q + 2π are one configuration; on a track 6.28 m apart they are the track's two ends."""
    kernel.length_scale = np.r_[1.0, kernel.length_scale[1:]]              # 1 m along the 6.4 m track
    q = np.array([[0.05, 0.3, -0.4, 0.2, 0.1, 0.5, -0.2]])
    far = q.copy()
    far[0, 0] += 2.0 * np.pi
    c, _, a, _ = kernel.parts(D)
    # every part that depends on the track has decayed: only the other joints' one-joint parts are left
    assert kernel(q, far)[0, 0] == pytest.approx(float(np.sum(a[1:] ** 2)), abs=1e-6)
    assert kernel(q)[0, 0] == pytest.approx(c ** 2 + float(np.sum(a ** 2)))
    assert np.allclose(kernel.grad_x(q, far)[..., 0], 0.0, atol=1e-6)
    circle = JointKernel(0.8, kernel.length_scale, kernel.joint_amplitude, kernel.joint_length_scale)
    assert circle(q, far)[0, 0] == pytest.approx(circle(q)[0, 0])          # what every joint as an angle did
    turn = q.copy()
    turn[0, 1] += 2.0 * np.pi                                               # a revolute joint still wraps
    assert kernel(q, turn)[0, 0] == pytest.approx(kernel(q)[0, 0])


def test_value_pool_path_and_gradients(kernel):
    rng = np.random.default_rng(0)
    X, Y = _configs(rng, 40), _configs(rng, 25)
    ref = _direct(kernel, X, Y)
    assert np.abs(kernel(X, Y) - ref).max() < 1e-12
    assert np.abs(kernel.against(X, kernel.features(Y)) - ref).max() < 1e-12
    with pytest.raises(ValueError, match="features"):
        kernel.against(X, (np.cos(Y), np.sin(Y)))
    K, G = kernel(X, eval_gradient=True)
    assert np.abs(K - _direct(kernel, X, X)).max() < 1e-12
    theta, eps = kernel.theta.copy(), 1e-6
    for i in range(theta.size):
        tp, tm = theta.copy(), theta.copy()
        tp[i] += eps
        tm[i] -= eps
        fd = (kernel.clone_with_theta(tp)(X) - kernel.clone_with_theta(tm)(X)) / (2 * eps)
        assert np.abs(fd - G[..., i]).max() < 1e-7, i
    gx = kernel.grad_x(X[:6], Y)
    for j in range(D):
        Xp, Xm = X[:6].copy(), X[:6].copy()
        Xp[:, j] += eps
        Xm[:, j] -= eps
        fd = (kernel(Xp, Y) - kernel(Xm, Y)) / (2 * eps)
        assert np.abs(fd - gx[..., j]).max() < 1e-8, j


def test_marginal_likelihood_gradient_with_a_track(kernel):
    from pin_kpi_oed.discrepancy.marginal import MarginalLikelihood

    rng = np.random.default_rng(1)
    Q = _configs(rng, 30)
    Y = rng.standard_normal((30, 3))
    f = MarginalLikelihood(Q, Y, kernel.linear)
    theta = np.concatenate([kernel.theta, [np.log(0.1)]])
    v, g = f(theta)
    # the same value from the kernel's own matrix
    S = kernel(Q) + (0.1 + 1e-10) * np.eye(30)
    L = np.linalg.cholesky(S)
    lml = -0.5 * np.sum(Y * np.linalg.solve(S, Y)) - 3 * np.sum(np.log(np.diag(L))) - 0.5 * 90 * np.log(2 * np.pi)
    assert v == pytest.approx(-lml, rel=1e-10)
    for i in range(theta.size):
        tp, tm = theta.copy(), theta.copy()
        tp[i] += 1e-6
        tm[i] -= 1e-6
        assert (f(tp)[0] - f(tm)[0]) / 2e-6 == pytest.approx(g[i], rel=1e-4, abs=1e-5), i


def test_model_file_form_states_each_joints_unit(kernel):
    d = kernel.to_dict()
    assert d["form"] == FORM_UNITS and d["joint_units"] == ["m"] + ["rad"] * 6
    back = JointKernel.from_dict(d, D)
    X = _configs(np.random.default_rng(2), 10)
    assert np.array_equal(back(X), kernel(X))
    arm = JointKernel(0.8, kernel.length_scale, kernel.joint_amplitude, kernel.joint_length_scale)
    old = arm.to_dict()
    assert old["form"] == FORM_CIRCLE and "joint_units" not in old            # arms: the file as before
    assert JointKernel.from_dict(old, D).linear is None                      # an older file: all on the circle
    with pytest.raises(ValueError, match="joint_units"):
        JointKernel.from_dict({**d, "joint_units": ["mm"] + ["rad"] * 6}, D)
    with pytest.raises(ValueError, match=r"length_scale: 50000 \(m\) is outside"):
        JointKernel.from_dict({**d, "length_scale": [5e4] + [1.0] * 6}, D)
    with pytest.raises(ValueError, match="joint j0 is in m, but the robot's joint is in rad"):
        kernel.check_units(["rad"] * 7, [f"j{i}" for i in range(7)])
    kernel.check_units(["m"] + ["rad"] * 6, [f"j{i}" for i in range(7)])


def test_starts_and_class_default_follow_the_tracks_travel():
    from pin_kpi_oed.model.robot import load_robot
    from pin_kpi_oed.oed.discrepancy_defaults import class_discrepancy

    k = JointKernel.for_joints(0.7, np.ones(D), np.full(D, 0.3), np.full(D, 0.5), LIN, np.r_[TRACK_M, np.full(6, 6)])
    u = TRACK_M / (2 * np.pi)
    assert k.length_scale[0] == pytest.approx(u) and k.joint_length_scale[0] == pytest.approx(0.5 * u)
    assert np.all(k.length_scale[1:] == 1.0)
    assert np.allclose(np.asarray(k.length_scale_bounds)[0], [1e-2 * u, 1e2 * u])
    plain = JointKernel.for_joints(0.7, np.ones(6), np.full(6, 0.3), np.full(6, 0.5), np.zeros(6, bool))
    assert plain.linear is None and plain.length_scale_bounds == (1e-2, 1e2)
    prior = class_discrepancy(load_robot("kr15_track"))
    assert list(prior.kernel.linear) == [True] + [False] * 6
    assert prior.kernel.length_scale[0] == pytest.approx(u)
    assert "1 m, 1 rad" in prior.describe()
    assert class_discrepancy(load_robot("kr15")).kernel.linear is None


def _track_residuals(Q: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A discrepancy that varies along the track (the rail's waviness: periods of 2.5 m and 1.1 m, 0.1 mm) and with
    two arm joints, plus 10 µm noise (m)."""
    x = Q[:, 0]
    along = 1e-4 * np.sin(2 * np.pi * x / 2.5 + 0.3) + 6e-5 * np.sin(2 * np.pi * x / 1.1)
    arm = 5e-5 * np.sin(Q[:, 1]) * np.cos(Q[:, 2])
    R = np.column_stack([along + arm, 0.5 * along - arm, 0.3 * arm + 0.2 * along])
    return R + 1e-5 * rng.standard_normal(R.shape)


def test_fit_on_the_line_predicts_far_along_the_track_with_an_honest_sigma():
    """Trained on the first 5.2 m of a 6.4 m track, scored at its far end (6.2 .. 6.4 m, 2π m from its start): the
    kernel on the line extrapolates with a sigma that grows; the kernel that took metres for radians sees the
    far end next to the start and is confidently wrong."""
    from pin_kpi_oed.discrepancy.gp import DiscrepancyOptions
    from pin_kpi_oed.discrepancy.fit import fit_discrepancy

    rng = np.random.default_rng(7)
    Qt = _configs(rng, 260, 0.0, 5.2)
    Qv = _configs(rng, 80, 6.2, TRACK_M)
    Rt, Rv = _track_residuals(Qt, rng), _track_residuals(Qv, rng)
    names = [f"j{i}" for i in range(D)]
    opts = DiscrepancyOptions(mode="on", n_fit=260, seed=0)
    span = np.r_[TRACK_M, np.full(6, 6.0)]
    per = np.zeros(D, bool)
    fits = {"line": fit_discrepancy(Qt, Rt, names, opts, periodic=per, linear=LIN, joint_span=span),
            "circle": fit_discrepancy(Qt, Rt, names, opts, periodic=per)}
    assert fits["line"].kernel.linear is not None and fits["circle"].kernel.linear is None
    score = {}
    for key, disc in fits.items():
        mu, var = disc.predict(Qv)
        r = Rv - mu
        z = r / np.sqrt(var + disc.noise_var_m2)
        score[key] = (float(np.mean(np.linalg.norm(r, axis=1))), float(np.sqrt(np.mean(z ** 2))))
    assert score["line"][0] <= score["circle"][0], score
    assert 0.67 <= score["line"][1] <= 1.5, score
    assert score["circle"][1] > 3.0, score            # the old kernel: the far end taken for the start, overconfident


def test_identified_track_model_file_keeps_the_line(tmp_path):
    """identify on a simulated KR 15 on its track whose rail is wavy (0.1 mm along the 6.4 m): the fitted kernel has
    the track on the line, its model file says so, and reads back to the same σ; the file refuses a robot whose
    joint is revolute where the kernel's is in m."""
    import json

    from pin_kpi_oed.identification.identify import identify
    from pin_kpi_oed.calibrated.model_file import load_model_file
    from pin_kpi_oed.simulation.simulator import default_tracker_pose, simulate
    from pin_kpi_oed.errors import InputError
    from pin_kpi_oed.model.noise import NoiseModel
    from pin_kpi_oed.model.robot import load_robot
    from pin_kpi_oed.model.tracker import TrackerModel

    rb = load_robot("kr15_track")
    m = TrackerModel(rb, tracker_T_base=default_tracker_pose(rb, distance_m=4.0), reflector_m=[0.05, 0.02, 0.08],
                     noise=NoiseModel(sigma_xyz_m=(1e-5,) * 3))
    Q = rb.random_q(np.random.default_rng(2), 120)
    data = simulate(m, Q, seed=3)
    wave = 1e-4 * np.sin(2 * np.pi * Q[:, 0] / 2.5)
    data.position_m[:, 2] += wave                                              # the rail's height along it
    cm = identify(m, data, discrepancy="on").calibrated_model()
    k = cm.discrepancy.kernel
    assert list(k.linear) == [True] + [False] * 6
    path = tmp_path / "track_model.json"
    cm.save(path)
    doc = json.loads(path.read_text())
    assert doc["discrepancy"]["kernel"]["form"] == FORM_UNITS
    assert doc["discrepancy"]["kernel"]["joint_units"] == ["m"] + ["rad"] * 6
    back = load_model_file(path)
    Qn = rb.random_q(np.random.default_rng(5), 20)
    assert np.allclose(back.discrepancy.predict(Qn)[1], cm.discrepancy.predict(Qn)[1], rtol=1e-9)
    doc["discrepancy"]["kernel"]["joint_units"] = ["rad"] * 6 + ["m"]
    path.write_text(json.dumps(doc))
    with pytest.raises(InputError, match="joint_units: joint joint_e1 is in rad, but the robot's joint is in m"):
        load_model_file(path)


def test_kpi_gp_on_the_track_cell_has_an_exact_gradient_along_the_track():
    """``kpi_gp`` in the track cell under the industrial class's default (the track on the line): dφ/dQ through the
    kernel's derivative in m along the track matches finite differences, and the track's column is not zero; a pool
    selection runs on the kernel's ``features``."""
    from pin_kpi_oed.cell.cell import cell_from_dict
    from pin_kpi_oed.design.optimize import DesignProblem

    from .fd import fd_rows
    from .test_track import _track_cell

    problem = DesignProblem(cell_from_dict(_track_cell()))
    assert list(problem.discrepancy_prior().kernel.linear) == [True] + [False] * 6
    crit = problem.criterion("kpi_gp")
    Q = problem.random_design(14, 3)[0]
    v, g = crit.value_and_grad(Q)
    assert v == pytest.approx(crit.value(Q), rel=1e-12)
    num = fd_rows(crit.value, Q, 3)
    assert np.abs(num - g[:3]).max() <= 1e-5 * np.abs(g[:3]).max()
    assert np.abs(g[:, 0]).max() > 1e-6 * np.abs(g).max()
    pool = problem.random_design(120, 4)[0]
    sel = crit.select(pool, 14, seed=0)                       # 29 parameters: at least 10 poses
    assert len(sel.indices) == 14 and np.isfinite(sel.value)
