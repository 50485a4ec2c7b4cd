"""The KPI criterion under model discrepancy (``kpi_gp``): the paper's C_s without discrepancy, the exact gradient
in the configurations (finite differences, kernel derivative included), the covariance against Monte-Carlo, and
the pool selection's rank-one / rank-three updates against recomputation from scratch."""

from __future__ import annotations

import numpy as np
import pytest

from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.design.optimize import DesignProblem
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.oed.covariance import covariances, prior_of
from pin_kpi_oed.oed.criteria import CRITERIA, ConfigurationCriterion, Criterion, evaluate_all, get_criterion
from pin_kpi_oed.oed.objective import DesignCriterion
from pin_kpi_oed.discrepancy.prior import DiscrepancyPrior
from pin_kpi_oed.oed.discrepancy_defaults import default_discrepancy
from pin_kpi_oed.oed.discrepancy_kpi import DiscrepancyDesignCriterion
from pin_kpi_oed.oed.kriging import kpi_gp_covariance, kpi_gp_value_and_grad
from pin_kpi_oed.oed.discrepancy_pool import GreedyState

from .fd import fd_rows


@pytest.fixture(scope="module")
def problem():
    return DesignProblem(load_cell("kr15"))


def test_zero_discrepancy_is_the_papers_kpi_covariance(problem):
    """k ≡ 0 and white σ = the tracker's σ: C_s is E C_p Eᵀ of eq. 19 (rotated to the base frame)."""
    sig = problem.cell.noise.sigma_xyz_m[0]
    assert np.allclose(problem.cell.noise.sigma_xyz_m, sig)
    white = DiscrepancyPrior(None, np.full(3, sig), 1.0)
    crit = DiscrepancyDesignCriterion(problem.model, problem.base, white, problem.cell.q_work, p=problem.p0)
    Q = problem.random_design(20, 3)[0]
    F = problem.model.weighted_jacobian(problem.p0, Q)[:, :, problem.base].reshape(-1, problem.base.size)
    Cs_paper = covariances(F, problem.E, prior_of(problem.model, problem.base))[1]
    R = problem.model.tracker_pose(problem.p0).rotation
    t = problem.cell.q_work.shape[0]
    Rb = np.kron(np.eye(t), R.T)
    Cs = crit.covariance(Q)
    assert np.allclose(Cs, Rb @ Cs_paper @ Rb.T, rtol=1e-8, atol=1e-10 * np.abs(Cs_paper).max())
    assert crit.value(Q) == pytest.approx(np.trace(Cs_paper), rel=1e-9)
    assert crit.value(Q) == pytest.approx(problem.kpi_criterion.value(Q), rel=1e-9)
    # a discrepancy only adds uncertainty: tr C_s grows
    gp = DiscrepancyDesignCriterion(problem.model, problem.base, default_discrepancy(6), problem.cell.q_work,
                                    p=problem.p0)
    assert gp.value(Q) > 10 * crit.value(Q)


@pytest.mark.parametrize("given", [0, 7])
def test_gradient_in_the_configurations_matches_finite_differences(problem, given):
    """dφ/dQ through F(Q), K_QQ and K_WQ (JointKernel.grad_x), with and without poses measured before."""
    Q = problem.random_design(16 + given, 5)[0]
    Qg, Q = (Q[:given], Q[given:]) if given else (None, Q)
    crit = DiscrepancyDesignCriterion(problem.model, problem.base, default_discrepancy(6), problem.cell.q_work,
                                      Q_given=Qg, p=problem.p0)
    v, g = crit.value_and_grad(Q)
    assert v == pytest.approx(crit.value(Q), rel=1e-12)
    num = fd_rows(crit.value, Q, 4)
    assert np.abs(num - g[:4]).max() <= 1e-5 * np.abs(g[:4]).max()
    assert np.abs(g[:4]).max() > 0


def test_kernel_part_of_the_gradient_is_not_zero(problem):
    """The kernel's own share: with the Jacobian held fixed, moving a pose changes tr C_s through K alone."""
    Q = problem.random_design(16, 6)[0]
    d = default_discrepancy(6)
    crit = DiscrepancyDesignCriterion(problem.model, problem.base, d, problem.cell.q_work, p=problem.p0)
    J = crit.pool_jacobians(Q)
    _, g = kpi_gp_value_and_grad(J, crit.E, d.covariance(Q), d.covariance(problem.cell.q_work, Q), crit.tr_kww,
                                 d.scale_m, d.noise, crit.prior_info)
    Gs = g["G"] + g["G"].T
    gk = (np.einsum("ij,ijk->ik", Gs, d.grad_x(Q, Q))
          + np.einsum("ti,itk->ik", g["Kwq"], d.grad_x(Q, problem.cell.q_work)))
    h = 1e-6
    Qp, Qm = Q.copy(), Q.copy()
    Qp[2, 1] += h
    Qm[2, 1] -= h

    def phi(Qx):
        return kpi_gp_value_and_grad(J, crit.E, d.covariance(Qx), d.covariance(problem.cell.q_work, Qx), crit.tr_kww,
                                     d.scale_m, d.noise, crit.prior_info, grad=False)[0]
    fd = (phi(Qp) - phi(Qm)) / (2 * h)
    assert fd == pytest.approx(gk[2, 1], rel=1e-5)
    assert abs(fd) > 1e-6 * phi(Q)


@pytest.mark.parametrize("with_prior", [False, True])
def test_covariance_matches_monte_carlo(with_prior):
    """Draw δ from the GP and the white noise, fit θ by GLS (MAP with a prior), krige δ at W: the empirical
    covariance of the TCP prediction error at W is C_s."""
    rng = np.random.default_rng(11)
    m, t, nb, d = 14, 3, 4, 2
    Q = rng.uniform(-np.pi, np.pi, (m, d))
    W = rng.uniform(-np.pi, np.pi, (t, d))
    J = rng.normal(size=(m, 3, nb)) * 1e-3
    E = rng.normal(size=(t, 3, nb)) * 1e-3
    disc = default_discrepancy(d)
    disc = DiscrepancyPrior(disc.kernel, np.array([1e-4, 2e-4, 0.5e-4]), 0.05)
    sig0 = np.array([0.05, 0.1, 0.2, 0.1])
    P = np.diag(1 / sig0 ** 2) if with_prior else None
    Kall = disc.covariance(np.vstack([Q, W]))
    Cs = kpi_gp_covariance(J, E, Kall[:m, :m], Kall[m:, :m], Kall[m:, m:], disc.scale_m, disc.noise, P)
    n = 40000
    Lk = np.linalg.cholesky(Kall + 1e-12 * np.eye(m + t))
    delta = np.einsum("ij,njb->nib", Lk, rng.normal(size=(n, m + t, 3)), optimize=True) * disc.scale_m  # (n, m+t, 3)
    eps = rng.normal(size=(n, m, 3)) * disc.scale_m * np.sqrt(disc.noise)
    theta = rng.normal(size=(n, nb)) * sig0 if with_prior else np.tile(rng.normal(size=nb), (n, 1))
    y = np.einsum("iac,nc->nia", J, theta) + delta[:, :m] + eps
    A = np.linalg.inv(Kall[:m, :m] + disc.noise * np.eye(m))
    s2 = disc.scale_m ** 2
    M = np.einsum("a,iac,ij,jad->cd", 1 / s2, J, A, J) + (P if P is not None else 0)
    b = np.einsum("a,iac,ij,nja->nc", 1 / s2, J, A, y, optimize=True)     # optimize: a chain of products, not one loop
    th = np.linalg.solve(M, b.T).T
    res = y - np.einsum("iac,nc->nia", J, th)
    pred = np.einsum("tac,nc->nta", E, th) + np.einsum("ti,ij,nja->nta", Kall[m:, :m], A, res, optimize=True)
    true = np.einsum("tac,nc->nta", E, theta) + delta[:, m:]
    err = (pred - true).reshape(n, 3 * t)
    emp = err.T @ err / n
    assert np.trace(emp) == pytest.approx(np.trace(Cs), rel=0.03)
    sd = np.sqrt(np.outer(np.diag(Cs), np.diag(Cs)))
    assert np.abs(emp - Cs).max() <= 0.05 * sd.max()


@pytest.mark.parametrize("n_work", [0, 12])
def test_pool_updates_equal_recomputation(problem, n_work):
    """Greedy (rank-one kernel, rank-three information) and exchange (downdate) values of every candidate equal
    tr C_s recomputed from scratch, with few working configurations (3t < nb: through R̃ H̃ᵀ) and many (3t ≥ nb);
    the selection beats random poses of the same pool."""
    Qp = problem.random_design(60, 8)[0]
    Qw = problem.cell.q_work if n_work == 0 else problem.random_design(n_work, 9)[0]
    assert (3 * len(Qw) < problem.base.size) == (n_work == 0)
    d = default_discrepancy(6)
    crit = DiscrepancyDesignCriterion(problem.model, problem.base, d, Qw, p=problem.p0)
    Jp = crit.pool_jacobians(Qp)

    def direct(idx):
        return kpi_gp_value_and_grad(Jp[idx], crit.E, d.covariance(Qp[idx]), d.covariance(Qw, Qp[idx]),
                                     crit.tr_kww, d.scale_m, d.noise, crit.prior_info, grad=False)[0]
    st = GreedyState(Jp, Qp, crit.E, Qw, d, crit.prior_info, 0.0)
    S = list(range(0, 30, 2))
    for i in S:
        st.add(i)
    ex = np.zeros(len(Qp), bool)
    ex[S] = True
    vals = st.values(ex)
    for j in (1, 7, 31, 59):
        assert vals[j] == pytest.approx(direct(S + [j]), rel=1e-8)
    assert np.isinf(vals[S]).all()
    down = st.without(S[3])
    ex2 = ex.copy()
    ex2[S[3]] = False
    vals2 = down.values(ex2)
    rest = S[:3] + S[4:]
    for j in (S[3], 5, 44):
        assert vals2[j] == pytest.approx(direct(rest + [j]), rel=1e-7)
    among = np.array([5, 44, 51])
    assert st.values_without(S[3], among) == pytest.approx(vals2[among], rel=1e-9)
    built = st.build(S)
    assert built.values(ex)[[1, 31]] == pytest.approx(vals[[1, 31]], rel=1e-9)
    sel = crit.select(Qp, 15, J_pool=Jp)
    assert sel.value == pytest.approx(direct(list(sel.indices)), rel=1e-12)
    assert len(set(sel.indices.tolist())) == 15
    greedy = crit.select(Qp, 15, J_pool=Jp, exchange_passes=0)
    assert sel.value <= greedy.value * (1 + 1e-9)
    rng = np.random.default_rng(0)
    rand = [direct(list(rng.choice(len(Qp), 15, replace=False))) for _ in range(10)]
    assert sel.value < min(rand)


def test_registered_and_evaluated_through_the_problem(problem):
    """kpi_gp is in the registry as a criterion of the configurations (no form on the information matrix), is left
    out by evaluate_all without a design problem and runs through the design problem (with the documented default
    discrepancy)."""
    assert "kpi_gp" in CRITERIA
    c = get_criterion("kpi_gp")
    assert isinstance(c, ConfigurationCriterion) and not isinstance(c, Criterion)
    with pytest.raises(InputError, match="configurations"):
        DesignCriterion(problem.model, problem.base, "kpi_gp", problem.E)
    Q = problem.random_design(15, 1)[0]
    assert "kpi_gp" not in evaluate_all(problem.model, problem.base, Q, problem.E)
    dc = problem.criterion("kpi_gp")
    assert dc.is_ratio and dc.value(Q) > 0
    assert "default" in problem.discrepancy_prior().describe()


def test_cli_design_with_default_discrepancy_curve_and_plateau(tmp_path, capsys, monkeypatch):
    """design --criteria random,kpi_gp: the default discrepancy is stated, the honest σ is reported beside the
    paper's, a target below the plateau is answered with the plateau, the curve goes to the JSON and a figure.
    The second run (a reachable target) asks the same designs (the same settings but the target and the curve,
    asserted): the first run's designs are given to it instead of being optimised again (seeded, they are the same);
    its target is answered by the command as ever."""
    import dataclasses
    import json

    from pin_kpi_oed.cli.app import main
    from pin_kpi_oed.design import runner

    optimised, made = runner._optimised, []

    def once(problem, s, m):  # the designs of one run's settings (the target and the curve apart), made once
        key = (dataclasses.replace(s, target_sigma_m=None, poses_needed=False), m)
        hit = next((r for k, r in made if k == key), None)
        if hit is None:
            made.append((key, optimised(problem, s, m)))
        return hit if hit is not None else made[-1][1]

    monkeypatch.setattr(runner, "_optimised", once)
    out_json, png = tmp_path / "d.json", tmp_path / "curve.png"
    assert main(["design", "--cell", "kr15", "--criteria", "random,kpi_gp", "--measurements", "20", "--starts", "1",
                 "--max-iter", "15", "--pool-size", "300", "--target-sigma", "1e-5", "--curve", str(png),
                 "--json", str(out_json), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "discrepancy (default for the industrial class, from the name 'kr15': S = 0.1 mm" in out
    assert "no optimality certificate" in out
    assert "is below what the discrepancy allows" in out
    assert "lever arm: the discrepancy is learnt at the reflector and the TCP is 100.0 mm from it" in out
    assert "0.1 mrad per axis adds 14.1 um" in out     # KR 15 cell: reflector (60, 0, 120) mm, TCP (0, 0, 200) mm
    doc = json.loads(out_json.read_text())
    assert doc["discrepancy"]["scale_m"] == [1e-4] * 3
    assert doc["discrepancy"]["tcp_from_reflector_m"] == pytest.approx(0.1)
    assert doc["discrepancy"]["lever_arm_sigma_per_rad_m"] == pytest.approx(0.1 * np.sqrt(2))
    for d in doc["designs"]:
        # the honest σ is far above the paper's (their identified parts; both σ add the same held term)
        assert d["discrepancy"]["trace_cs_m2"] > 100 * d["trace_cs_m2"]
        assert d["discrepancy"]["held_trace_m2"] == d["held_trace_m2"] > 0
        assert d["discrepancy"]["tcp_sigma_m"] > d["tcp_sigma_m"]
    gp = {d["criterion"]: d["discrepancy"]["tcp_sigma_m"] for d in doc["designs"]}
    assert gp["kpi_gp"] < gp["random"]
    curve = doc["poses_needed"]
    assert curve["n_for_target"] is None and curve["plateau_m"] > 1e-5
    des, rnd = np.array(curve["sigma_designed_m"]), np.array(curve["sigma_random_m"])
    assert np.all(np.diff(des) <= 1e-12) and np.all(des[1:] < rnd[1:])
    assert png.stat().st_size > 10_000
    assert "random + the designs' poses" in out   # the designs' own poses are candidates of the curve
    # a reachable target (the same designs, so the same candidates): the fewest designed poses, verified
    assert main(["design", "--cell", "kr15", "--criteria", "random,kpi_gp", "--measurements", "20", "--starts", "1",
                 "--max-iter", "15", "--pool-size", "300", "--target-sigma", str(1.05 * des[-1]), "--quiet"]) == 0
    assert "designed pose(s) reach it" in capsys.readouterr().out
    assert len(made) == 1  # the second run asked the first run's designs


def test_lever_arm_factor_matches_monte_carlo():
    """An isotropic flange rotation of σ_θ per axis moves a point at d from the reflector by δθ × d, whose 3-D RMS
    is sqrt(2)·σ_θ·|d| (the factor the design output quotes)."""
    from pin_kpi_oed.discrepancy.lever_arm import LEVER_ARM_EXAMPLE_RAD, lever_arm_line, lever_arm_m
    from pin_kpi_oed.model.tracker import TrackerModel
    from pin_kpi_oed.model.robot import load_robot

    rng = np.random.default_rng(0)
    d = np.array([0.03, -0.05, 0.04])
    theta = rng.normal(0.0, LEVER_ARM_EXAMPLE_RAD, (200_000, 3))
    rms = np.sqrt(np.mean(np.sum(np.cross(theta, d) ** 2, axis=1)))
    assert rms == pytest.approx(np.sqrt(2) * LEVER_ARM_EXAMPLE_RAD * np.linalg.norm(d), rel=0.01)
    model = TrackerModel(load_robot("ur10"), reflector_m=np.array([0.0, 0.0, 0.1]), tcp_m=np.array([0.0, 0.0, 0.1]) + d)
    assert lever_arm_m(model.tcp_m, model.reflector_m) == pytest.approx(np.linalg.norm(d))
    assert f"adds {rms * 1e6:.1f} um" in lever_arm_line(lever_arm_m(model.tcp_m, model.reflector_m))


def test_cli_design_without_the_discrepancy_is_unchanged(tmp_path, capsys):
    """Without kpi_gp and without --model, the output and the JSON carry no discrepancy (the paper's design)."""
    import json

    from pin_kpi_oed.cli.app import main

    out_json = tmp_path / "d.json"
    assert main(["design", "--cell", "kr15", "--criteria", "random,kpi", "--measurements", "20", "--starts", "1",
                 "--max-iter", "5", "--json", str(out_json), "--quiet"]) == 0
    assert "discrepancy" not in capsys.readouterr().out
    doc = json.loads(out_json.read_text())
    assert "discrepancy" not in doc and "poses_needed" not in doc
    assert main(["design", "--cell", "kr15", "--criteria", "random,kpi", "--curve", str(tmp_path / "c.png")]) == 2
    assert "--curve needs the discrepancy" in capsys.readouterr().err


def test_cli_design_takes_the_discrepancy_of_a_model_file(tmp_path, capsys):
    """design --model m.json: the discrepancy block's kernel, scale and white level are the design's, named."""
    import json

    from pin_kpi_oed import NoiseModel, TrackerModel, load_robot
    from pin_kpi_oed.cli.app import main
    from pin_kpi_oed.discrepancy import Discrepancy, JointKernel
    from pin_kpi_oed.identification.identify import identify
    from pin_kpi_oed.simulation.simulator import default_tracker_pose, simulate

    cell = load_cell("ur10")
    robot = load_robot("ur10")
    model = TrackerModel(robot, tracker_T_base=default_tracker_pose(robot), reflector_m=np.array([0.03, 0.02, 0.08]),
                         noise=NoiseModel(sigma_xyz_m=(1e-5,) * 3))
    data = simulate(model, robot.random_q(np.random.default_rng(1), 60), np.zeros(model.n_params), seed=2)
    from pin_kpi_oed.discrepancy import DiscrepancyOptions

    cm = identify(model, data, discrepancy=DiscrepancyOptions(mode="none")).calibrated_model()
    k = JointKernel(0.8, np.full(6, 1.3), np.full(6, 0.2), np.full(6, 0.4))
    names = list(robot.joint_names)
    Z = robot.random_q(np.random.default_rng(3), 5)
    cm.discrepancy = Discrepancy("exact", names, np.array([2e-4, 1e-4, 1.5e-4]), np.zeros(3), 0.02, k, Z,
                                 np.zeros((5, 3)), n_rows=5)
    f = tmp_path / "m.json"
    cm.save(f)
    out_json = tmp_path / "d.json"
    assert main(["design", "--cell", "ur10", "--model", str(f), "--criteria", "random,kpi_gp", "--measurements",
                 "20", "--starts", "1", "--max-iter", "5", "--json", str(out_json), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert f"--model {f}" in out and "with discrepancy sigma um" in out
    doc = json.loads(out_json.read_text())
    assert doc["discrepancy"]["scale_m"] == pytest.approx([2e-4, 1e-4, 1.5e-4])
    assert doc["discrepancy"]["kernel"]["length_scale_rad"] == pytest.approx([1.3] * 6)
    assert doc["discrepancy"]["white_sigma_m"] == pytest.approx(np.array([2e-4, 1e-4, 1.5e-4]) * np.sqrt(0.02))
    assert cell.robot.joint_names == robot.joint_names


def test_cli_campaign_refits_the_discrepancy_on_the_measured_batch(tmp_path, capsys):
    """design --given measured.csv --model m.json: the discrepancy is re-fitted on the measured batch (a withheld
    gear harmonic), the next batch designed on top of it, the σ before and after reported."""
    import json

    from pin_kpi_oed import NoiseModel, TrackerModel, load_robot
    from pin_kpi_oed.cli.app import main
    from pin_kpi_oed.data.measurements import write_measurements
    from pin_kpi_oed.discrepancy import Discrepancy, DiscrepancyOptions, JointKernel
    from pin_kpi_oed.effects.library import GearHarmonic
    from pin_kpi_oed.identification.identify import identify
    from pin_kpi_oed.simulation.simulator import default_tracker_pose, simulate

    robot = load_robot("ur10")
    model = TrackerModel(robot, tracker_T_base=default_tracker_pose(robot), reflector_m=np.array([0.03, 0.02, 0.08]),
                         noise=NoiseModel(sigma_xyz_m=(1e-5,) * 3))
    cm = identify(model, simulate(model, robot.random_q(np.random.default_rng(1), 60), np.zeros(model.n_params),
                                  seed=2), discrepancy=DiscrepancyOptions(mode="none")).calibrated_model()
    names = list(robot.joint_names)
    cm.discrepancy = Discrepancy("exact", names, np.full(3, 1e-4), np.zeros(3), 0.02,
                                 JointKernel(0.8, np.full(6, 1.3), np.full(6, 0.2), np.full(6, 0.4)),
                                 robot.random_q(np.random.default_rng(3), 5), np.zeros((5, 3)), n_rows=5)
    f = tmp_path / "m.json"
    cm.save(f)
    problem = DesignProblem(load_cell("ur10"))
    Qg = problem.random_design(70, 4)[0]
    gh = GearHarmonic(robot, joints=["shoulder_lift_joint", "elbow_joint"], orders=(2, 3))
    theta = 3e-4 * np.random.default_rng(5).standard_normal(len(gh.param_names()))
    cmodel = problem.model
    data = simulate(cmodel, Qg, np.zeros(cmodel.n_params), effects=[(gh, theta)], seed=7)
    write_measurements(data, tmp_path / "meas.csv")
    out_json = tmp_path / "d.json"
    assert main(["design", "--cell", "ur10", "--given", str(tmp_path / "meas.csv"), "--model", str(f), "--criteria",
                 "random,kpi_gp", "--measurements", "10", "--starts", "1", "--max-iter", "5", "--json",
                 str(out_json)]) == 0
    out = capsys.readouterr().out
    assert "discrepancy: Gaussian process fitted" in out and "measured poses alone (70)" in out
    doc = json.loads(out_json.read_text())
    assert doc["discrepancy"]["source"].startswith(f"re-fitted on the measured poses {tmp_path / 'meas.csv'}")
    assert doc["discrepancy"]["kernel"]["length_scale_rad"] != pytest.approx([1.3] * 6)
    line = next(ln for ln in out.splitlines() if ln.startswith("measured poses alone"))
    alone = float(line.split("discrepancy ")[1].split(" um")[0]) * 1e-6
    for d in doc["designs"]:
        assert d["discrepancy"]["tcp_sigma_m"] < alone


def test_a_set_downdated_below_identifiability_gives_no_swap_instead_of_an_error(problem):
    """The exchange removes a chosen point before it tries each candidate in its place; from a set too small to
    identify the parameters (3 poses: 9 equations for far more parameters), the information downdated is not
    positive definite at working precision. Its values are then inf (no swap through that removal), never a
    LinAlgError escaping as a traceback, and the full set's values stay those of a fresh state."""
    Qp = problem.random_design(40, 8)[0]
    d = default_discrepancy(6)
    crit = DiscrepancyDesignCriterion(problem.model, problem.base, d, problem.cell.q_work, p=problem.p0)
    Jp = crit.pool_jacobians(Qp)
    st = GreedyState(Jp, Qp, crit.E, problem.cell.q_work, d, crit.prior_info, 0.0)
    for i in range(3):
        st.add(i)
    assert 3 * 3 < problem.base.size
    vals = st.without(0).values(np.zeros(len(Qp), bool))
    assert vals.shape == (len(Qp),) and np.isinf(vals).all()
    fresh = GreedyState(Jp, Qp, crit.E, problem.cell.q_work, d, crit.prior_info, 0.0)
    for i in range(3):
        fresh.add(i)
    ex = np.zeros(len(Qp), bool)
    assert np.array_equal(st.values(ex), fresh.values(ex), equal_nan=True)
