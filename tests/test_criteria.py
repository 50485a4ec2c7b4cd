"""Criteria as objects: closed-form values, pool forms consistent with values, and a toy criterion registered
from outside the package run through the IPOPT design, the pool start, ``evaluate`` and the CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.design.optimize import (_NLP, DesignOptions, DesignProblem, design_ipopt, ipopt_options,
                                         run_designs)
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.serialize import model_to_dict
from pin_kpi_oed.oed import identifiability as idf
from pin_kpi_oed.oed.covariance import param_covariance
from pin_kpi_oed.oed.criteria import CRITERIA, Criterion, DesignCriterion, get_criterion, register, unregister
from pin_kpi_oed.oed.evaluate import score_design
from pin_kpi_oed.oed.pool import exact_phi, select

from .conftest import make_model

M = 14


class WorstTcpVariance(Criterion):
    """Toy criterion written outside the package: the largest eigenvalue of C_s (worst TCP direction, m²).

    dλ = vᵀE dC_p Eᵀv with dC_p = −C_p (dFᵀF + FᵀdF) C_p, so dλ/dF = −2 (F a) aᵀ with a = C_p Eᵀ v.
    """

    name, label, unit, is_ratio, needs_kpi = "cs_max", "largest eigenvalue of C_s", "m^2", True, True

    def value_and_grad_F(self, F, E=None, prior_sigma=None):
        C_p = param_covariance(F, prior_sigma)
        w, V = np.linalg.eigh(E @ C_p @ E.T)
        a = C_p @ E.T @ V[:, -1]
        return float(w[-1]), -2.0 * np.outer(F @ a, a)


class VerticalTcpVariance(Criterion):
    """Toy criterion with a pool form: Σ_t var(z_t) of the TCP, tr(K C_p Kᵀ) with K the z rows of E (m²)."""

    name, label, unit, is_ratio, needs_kpi, has_pool_form = "cs_z", "vertical TCP variance", "m^2", True, True, True

    def value_and_grad_F(self, F, E=None, prior_sigma=None):
        K = E[2::3]
        C_p = param_covariance(F, prior_sigma)
        CK = C_p @ K.T
        return float(np.trace(K @ CK)), -2.0 * F @ (CK @ CK.T)

    def pool_form(self, E, nb):
        return E[2::3]


@pytest.fixture
def toys():
    crits = [register(WorstTcpVariance()), register(VerticalTcpVariance)]
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
        if crit.has_pool_form:
            K = crit.pool_form(E, F.shape[1])
            assert exact_phi(Fp, idx, K) == pytest.approx(crit.value(Fp[idx].reshape(-1, F.shape[1]), E), rel=1e-9)


def test_ratio_criteria_are_scaled_and_log_criteria_shifted(problem):
    start = problem.random_design(M, 0)[0]
    x = start.ravel()
    for name in CRITERIA:
        crit = problem.criterion(name)
        nlp = _NLP(crit, problem.cons, M, crit.value(start))
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
