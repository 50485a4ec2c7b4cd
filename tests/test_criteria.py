"""Criteria as objects: closed-form values, pool forms consistent with values, and toy criteria registered from
outside the package (two of the information matrix, one of the configurations) run through the IPOPT design, the
pool selection, ``evaluate`` and the CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.design.ipopt import DesignNLP
from pin_kpi_oed.design.optimize import (DesignOptions, DesignProblem, design_ipopt, ipopt_options,
                                         run_designs)
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.serialize import model_to_dict
from pin_kpi_oed.oed import identifiability as idf
from pin_kpi_oed.oed.criteria import CRITERIA, ConfigurationCriterion, Criterion, get_criterion, register, unregister
from pin_kpi_oed.oed.objective import DesignCriterion, DesignObjective
from pin_kpi_oed.oed.evaluate import score_design
from pin_kpi_oed.oed.pool import exact_phi, select

from .conftest import make_model

M = 14


def _covariance(M0, prior_info):
    return np.linalg.inv(M0 if prior_info is None else M0 + prior_info)


class WorstTcpVariance(Criterion):
    """Toy criterion of the information matrix written outside the package: the largest eigenvalue of C_s (worst TCP
    direction, m²). dλ = vᵀE dC_p Eᵀv with dC_p = −C_p dM C_p, so ∂λ/∂M = −a aᵀ with a = C_p Eᵀ v."""

    name, label, unit, is_ratio, needs_kpi = "cs_max", "largest eigenvalue of C_s", "m^2", True, True

    def value_and_grad_M(self, M0, E=None, prior_info=None, rows=0):
        C_p = _covariance(M0, prior_info)
        w, V = np.linalg.eigh(E @ C_p @ E.T)
        a = C_p @ E.T @ V[:, -1]
        return float(w[-1]), -np.outer(a, a)


class VerticalTcpVariance(Criterion):
    """Toy criterion with a pool form: Σ_t var(z_t) of the TCP, tr(K C_p Kᵀ) with K the z rows of E (m²)."""

    name, label, unit, is_ratio, needs_kpi, has_pool_form = "cs_z", "vertical TCP variance", "m^2", True, True, True

    def value_and_grad_M(self, M0, E=None, prior_info=None, rows=0):
        K = E[2::3]
        CK = _covariance(M0, prior_info) @ K.T
        return float(np.trace(K @ CK)), -(CK @ CK.T)

    def pool_form(self, E, nb):
        return E[2::3]


class TotalInformation(Criterion):
    """Toy criterion of the parameter information alone: −log tr M (Γ = −I / tr M)."""

    name, label, unit = "info", "-log of the total information", "log"

    def value_and_grad_M(self, M0, E=None, prior_info=None, rows=0):
        M = M0 if prior_info is None else M0 + prior_info
        return -float(np.log(np.trace(M))), -np.eye(M.shape[0]) / np.trace(M)


class NearWorkKpi(ConfigurationCriterion):
    """Toy criterion of the configurations written outside the package: tr(C_s) plus a penalty μ Σ_i ‖q_i − q̄‖²
    keeping the measurement poses near the mean working configuration q̄ (μ in m²/rad²): no information matrix
    carries it. Its objective chains the noise-only KPI objective of the design context with the penalty."""

    name, label, unit, is_ratio, needs_kpi = "kpi_near", "tr(C_s) + mu |q - q_work|^2", "m^2", True, True
    mu = 1e-9

    def objective(self, problem):
        return _NearWork(problem, self.mu, self)


class _NearWork(DesignObjective):
    def __init__(self, problem, mu, crit):
        self.kpi = DesignCriterion(problem.model, problem.base, "kpi", problem.E, p=problem.p0)
        self.q_mean, self.mu, self.crit = np.mean(problem.q_work, axis=0), mu, crit

    def value(self, Q):
        return self.kpi.value(Q) + self.mu * float(np.sum((np.atleast_2d(Q) - self.q_mean) ** 2))

    def value_and_grad(self, Q):
        v, g = self.kpi.value_and_grad(Q)
        return v + self.mu * float(np.sum((Q - self.q_mean) ** 2)), g + 2.0 * self.mu * (Q - self.q_mean)


@pytest.fixture
def toys():
    crits = [register(WorstTcpVariance()), register(VerticalTcpVariance), register(NearWorkKpi)]
    yield crits
    for c in crits:
        unregister(c.name)


@pytest.fixture(scope="module")
def problem() -> DesignProblem:
    return DesignProblem(load_cell("kr15"))


@pytest.fixture(scope="module")
def setup():
    model = make_model("kr15")
    ident = idf.analyse(model)
    rng = np.random.default_rng(11)
    Q = model.robot.random_q(rng, 20)
    E = model.kpi_jacobian(np.zeros(model.n_params), model.robot.random_q(rng, 2))[:, ident.base]
    F = model.weighted_jacobian(np.zeros(model.n_params), Q)[:, :, ident.base].reshape(-1, ident.base.size)
    return F, E


def _closed_form(name: str, F: np.ndarray, E: np.ndarray, prior: np.ndarray | None) -> float:
    """Each built-in criterion written independently (inverse, slogdet, eigvalsh, singular values)."""
    M = F.T @ F + (np.diag(prior ** -2.0) if prior is not None else 0.0)
    C = np.linalg.inv(M)
    mu = np.linalg.svd(F, compute_uv=False)  # the observability indices are defined on F (no prior)
    return {"kpi": lambda: np.trace(E @ C @ E.T), "param": lambda: np.trace(C),
            "D": lambda: -np.linalg.slogdet(M)[1], "E": lambda: np.linalg.eigvalsh(C).max(),
            "cond": lambda: mu.max() / mu.min(),
            "O1": lambda: -np.log(np.exp(np.mean(np.log(mu))) / np.sqrt(F.shape[0])),
            "O2": lambda: -np.log(mu.min() / mu.max()), "O3": lambda: -np.log(mu.min()),
            "O4": lambda: -np.log(mu.min() ** 2 / mu.max()), "O5": lambda: np.log(np.sum(1.0 / mu))}[name]()


@pytest.mark.parametrize("name", ["kpi", "param", "D", "E", "cond", "O1", "O2", "O3", "O4", "O5"])
@pytest.mark.parametrize("with_prior", [False, True])
def test_builtin_values_match_independent_closed_forms(setup, name, with_prior):
    F, E = setup
    prior = np.full(F.shape[1], 1e-6) if with_prior else None
    crit = get_criterion(name)
    v, G = crit.value_and_grad_F(F, E, prior)
    assert v == pytest.approx(_closed_form(name, F, E, prior), rel=1e-8)
    # and dφ/dF against central differences in a random direction of F
    D = np.random.default_rng(3).normal(size=F.shape)
    h = 1e-6 * np.linalg.norm(F) / np.linalg.norm(D)
    fd = (crit.value(F + h * D, E, prior) - crit.value(F - h * D, E, prior)) / (2 * h)
    assert np.sum(G * D) == pytest.approx(fd, rel=1e-5, abs=1e-12 * abs(v))


def test_a_prior_changes_the_covariance_criteria(setup):
    F, E = setup
    prior = np.full(F.shape[1], 1e-6)
    for name in ("kpi", "param", "D", "E"):
        assert abs(get_criterion(name).value(F, E, prior) / get_criterion(name).value(F, E) - 1) > 1e-3


def test_pool_forms_agree_with_the_values(setup):
    """For every criterion with a pool form, φ of the pool form at the chosen poses is the criterion's value."""
    F, E = setup
    Fp = F.reshape(20, 3, -1)
    idx = np.arange(3, 17)
    for crit in CRITERIA.values():
        if isinstance(crit, Criterion) and crit.has_pool_form:
            K = crit.pool_form(E, F.shape[1])
            assert exact_phi(Fp, idx, K) == pytest.approx(crit.value(Fp[idx].reshape(-1, F.shape[1]), E), rel=1e-9)


def test_ratio_criteria_are_scaled_and_log_criteria_shifted(problem):
    start = problem.random_design(M, 0)[0]
    x = start.ravel()
    for name in CRITERIA:
        if name.startswith("kpi_path") and not problem.cell.paths:  # refused without paths (test_paths.py)
            continue
        crit = problem.criterion(name)
        nlp = DesignNLP(crit, problem.cons, M, crit.value(start))
        assert nlp.objective(x) == pytest.approx(1.0 if crit.is_ratio else 0.0, abs=1e-12)
        assert crit.is_ratio == (get_criterion(name).unit not in ("log",))


def test_registry_refuses_clashes_and_forgets_unregistered(toys):
    with pytest.raises(InputError, match="already taken"):
        register(WorstTcpVariance())
    with pytest.raises(InputError, match="already taken"):
        register(type("R", (VerticalTcpVariance,), {"name": "random"}))
    unregister("cs_max")
    with pytest.raises(InputError, match="unknown criterion 'cs_max'"):
        get_criterion("cs_max")
    register(WorstTcpVariance())  # back for the fixture's clean-up


def test_toy_criterion_gradient_matches_finite_differences(toys):
    model = make_model("kr15")
    ident = idf.analyse(model)
    rng = np.random.default_rng(5)
    Q = model.robot.random_q(rng, 12)
    E = model.kpi_jacobian(np.zeros(model.n_params), model.robot.random_q(rng, 2))[:, ident.base]
    for name in ("cs_max", "cs_z"):
        dc = DesignCriterion(model, ident.base, name, E)
        v, g = dc.value_and_grad(Q)
        gfd = np.zeros_like(g)
        for i in range(Q.shape[0]):
            for k in range(Q.shape[1]):
                Qp, Qm = Q.copy(), Q.copy()
                Qp[i, k] += 1e-6
                Qm[i, k] -= 1e-6
                gfd[i, k] = (dc.value(Qp) - dc.value(Qm)) / 2e-6
        assert np.abs(g - gfd).max() < 1e-5 * np.abs(gfd).max()


def test_toy_criterion_through_ipopt_design_and_evaluate(toys, problem, tmp_path, capsys):
    start = problem.random_design(M, 0)[0]
    f0 = problem.criterion("cs_max").value(start)
    res = design_ipopt(problem, "cs_max", M, seed=0, start=start, options=ipopt_options(max_iter=40))
    assert res.criterion == "cs_max" and res.feasible and res.nit > 0
    assert res.value < 0.8 * f0  # the optimiser lowered the toy criterion
    score = score_design(problem.model, res.q_meas, problem.cell.q_work, problem.ident)
    # evaluate reports the toy, equal to the largest eigenvalue of its own C_s
    assert score.criteria["cs_max"] == pytest.approx(np.linalg.eigvalsh(score.cov_s_m2)[-1], rel=1e-9)
    assert score.criteria["cs_max"] == pytest.approx(res.value, rel=1e-9)
    assert score.criteria["cs_z"] == pytest.approx(np.trace(score.cov_s_m2[2::3, 2::3]), rel=1e-9)
    # the evaluate command (in-process, the registry is this process's) prints it with its unit
    from pin_kpi_oed.cli.app import main

    path = tmp_path / "d.json"
    path.write_text(json.dumps({**model_to_dict(problem.model), "q_meas": res.q_meas.tolist(),
                                "q_work": problem.cell.q_work.tolist()}))
    assert main(["evaluate", str(path), "--json", str(tmp_path / "s.json")]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("cs_max"))
    assert "[m^2]" in line and float(line.split()[1]) == pytest.approx(res.value, rel=1e-5)
    assert json.loads((tmp_path / "s.json").read_text())["criteria"]["cs_max"] == pytest.approx(res.value, rel=1e-9)


def test_toy_pool_form_selects_for_itself(toys, problem):
    """Selecting by the toy's pool form gives a lower vertical TCP variance than selecting by tr(C_s)."""
    Q = problem.random_design(400, 3)[0]
    Fp = problem.model.weighted_jacobian(problem.p0, Q)[:, :, problem.base]
    toy, kpi = get_criterion("cs_z"), get_criterion("kpi")
    by_toy = select(Fp, M, toy.pool_form(problem.E, problem.base.size)).indices
    by_kpi = select(Fp, M, kpi.pool_form(problem.E, problem.base.size)).indices
    nb = problem.base.size
    assert toy.value(Fp[by_toy].reshape(-1, nb), problem.E) < toy.value(Fp[by_kpi].reshape(-1, nb), problem.E)
    assert kpi.value(Fp[by_kpi].reshape(-1, nb), problem.E) < kpi.value(Fp[by_toy].reshape(-1, nb), problem.E)
    # and run_designs starts the toy's optimisation from its pool selection (the CLI accepts the name)
    from pin_kpi_oed.cli.design import parse_criteria

    names = parse_criteria("random,cs_z")
    rnd, des = run_designs(problem.cell, names, M, 0, DesignOptions(ipopt=ipopt_options(max_iter=15), pool_size=300),
                           problem)
    assert des.criterion == "cs_z" and des.feasible
    assert des.value < toy.value(problem.model.weighted_jacobian(problem.p0, rnd.q_meas)[:, :, problem.base]
                                 .reshape(-1, nb), problem.E)


def test_outside_criteria_of_both_kinds_design_select_and_evaluate(toys, problem):
    """One class each, registered from outside: a criterion of the information matrix (cs_z) on the noise-only, the
    measured-poses and the GLS information models, and a criterion of the configurations (kpi_near), each through
    the pool selection, the IPOPT design and evaluate."""
    from pin_kpi_oed.design.user_pool import design_from_pool
    from pin_kpi_oed.oed.discrepancy_criteria import GlsDesignCriterion

    Q = problem.random_design(60, 4)[0]
    near = problem.criterion("kpi_near")
    assert isinstance(near, DesignObjective) and near.name == "kpi_near" and near.is_ratio
    # pool selection: the generic greedy + exchange of a configuration criterion beats every random subset
    results, cert, _ = design_from_pool(problem, Q, ["random", "cs_z", "kpi_near"], M, seed=0)
    by = {r.criterion: r for r in results}
    rng = np.random.default_rng(0)
    rnd = [near.value(Q[rng.choice(60, M, replace=False)]) for _ in range(20)]
    assert by["kpi_near"].value < min(rnd) and by["kpi_near"].value == pytest.approx(near.value(by["kpi_near"].q_meas))
    assert by["cs_z"].value == pytest.approx(problem.criterion("cs_z").value(by["cs_z"].q_meas), rel=1e-12)
    # IPOPT from the random start lowers the configuration criterion; its gradient matches finite differences
    start = problem.random_design(M, 0)[0]
    v, g = near.value_and_grad(start)
    d = 1e-6 * np.random.default_rng(2).standard_normal(start.shape)
    assert (near.value(start + d) - near.value(start - d)) / 2 == pytest.approx(np.sum(g * d), rel=1e-4)
    res = design_ipopt(problem, "kpi_near", M, seed=0, start=start, options=ipopt_options(max_iter=30))
    assert res.criterion == "kpi_near" and res.feasible and res.value < 0.8 * v
    # evaluate scores both (the configuration criterion on the design file's set-up)
    score = score_design(problem.model, res.q_meas, problem.cell.q_work, problem.ident)
    assert score.criteria["kpi_near"] == pytest.approx(res.value, rel=1e-9)
    assert score.criteria["cs_z"] == pytest.approx(np.trace(score.cov_s_m2[2::3, 2::3]), rel=1e-9)
    assert "kpi_gp" not in score.criteria  # needs a design problem's discrepancy
    # the same information criterion on two more information models: the measured poses and the GLS information
    seq = problem.replaced(Q_given=Q[:10])
    given = seq.criterion("cs_z")
    assert given.value(Q[10:20]) == pytest.approx(get_criterion("cs_z").value(
        problem.model.weighted_jacobian(problem.p0, Q[:20])[:, :, problem.base].reshape(-1, problem.base.size),
        problem.E), rel=1e-9)
    # a criterion registered later gets its GLS form on demand (no registration loop); cs_z needs E: its
    # discrepancy-aware form is the kriging kpi_gp
    register(TotalInformation)
    try:
        form = get_criterion("info_gp")
        gls = problem.criterion("info_gp")
        assert form.base is get_criterion("info") and isinstance(gls, GlsDesignCriterion) and gls.name == "info_gp"
        sel = gls.select(Q, M)
        assert sel.value == pytest.approx(gls.value(Q[sel.indices]), rel=1e-9)
        assert sel.value < min(gls.value(Q[rng.choice(60, M, replace=False)]) for _ in range(10))
        with pytest.raises(InputError, match="unknown criterion 'cs_z_gp'"):
            get_criterion("cs_z_gp")
    finally:
        unregister("info")
