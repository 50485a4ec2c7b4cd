"""The parameter criteria under model discrepancy (``D_gp``, ``param_gp``, ``E_gp``, ``cond_gp``, ``O1_gp``…): the
noise-only criteria without discrepancy, exact gradients in the configurations (finite differences, the kernel's
part included), the pool selection's updates against recomputation, the design plumbing and the CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.design.optimize import DesignProblem
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.oed.criteria import CRITERIA, Criterion, DiscrepancyForm, criterion_names, get_criterion
from pin_kpi_oed.oed.discrepancy_criteria import GlsDesignCriterion, gls_value_and_grad
from pin_kpi_oed.oed.discrepancy_pool import GlsState
from pin_kpi_oed.discrepancy.prior import DiscrepancyPrior
from pin_kpi_oed.oed.discrepancy_defaults import default_discrepancy

GP = ["D_gp", "param_gp", "E_gp", "cond_gp", "O1_gp", "O2_gp", "O3_gp", "O4_gp", "O5_gp"]


@pytest.fixture(scope="module")
def problem():
    return DesignProblem(load_cell("kr15"))


def test_every_parameter_criterion_has_its_discrepancy_form():
    """Made on demand for every registered criterion of the parameter information (none is registered), never for
    kpi (its discrepancy-aware form is the kriging kpi_gp) or a criterion of the configurations."""
    assert all(isinstance(get_criterion(n), DiscrepancyForm) and n not in CRITERIA for n in GP)
    assert get_criterion("D_gp").base is get_criterion("D") and get_criterion("D_gp") is get_criterion("D_gp")
    assert set(GP) <= set(criterion_names()) and "kpi_gp" in CRITERIA
    assert not isinstance(get_criterion("kpi_gp"), Criterion) and not isinstance(get_criterion("D_gp"), Criterion)
    with pytest.raises(InputError, match="no discrepancy-aware form"):
        DiscrepancyForm(get_criterion("kpi"))
    with pytest.raises(InputError, match="unknown criterion 'kpi_gp_gp'"):
        get_criterion("kpi_gp_gp")


@pytest.mark.parametrize("name", GP)
def test_zero_discrepancy_is_the_noise_only_criterion(problem, name):
    """k ≡ 0 and w s² = the tracker's σ²: each form equals its noise-only criterion (the same value)."""
    sig = problem.cell.noise.sigma_xyz_m[0]
    assert np.allclose(problem.cell.noise.sigma_xyz_m, sig)
    white = DiscrepancyPrior(None, np.full(3, sig / 2), 4.0)            # w s² = σ²
    crit = GlsDesignCriterion(problem.model, problem.base, white, name, p=problem.p0)
    Q = problem.random_design(20, 3)[0]
    base = name[:-3]
    assert crit.name == name and crit.is_ratio == get_criterion(base).is_ratio
    assert crit.value(Q) == pytest.approx(problem.criterion(base).value(Q), rel=1e-8, abs=1e-9)
    v, g = crit.value_and_grad(Q)
    v0, g0 = problem.criterion(base).value_and_grad(Q)
    assert np.abs(g - g0).max() <= 1e-6 * np.abs(g0).max()


@pytest.mark.parametrize("name,given", [("D_gp", 0), ("param_gp", 0), ("D_gp", 5), ("E_gp", 0), ("cond_gp", 0),
                                        ("O1_gp", 0), ("O5_gp", 5)])
def test_gradient_in_the_configurations_matches_finite_differences(problem, name, given):
    """dφ/dQ through J(Q) and K_QQ (JointKernel.grad_x), with and without poses measured before."""
    Q = problem.random_design(16 + given, 5)[0]
    Qg, Q = (Q[:given], Q[given:]) if given else (None, Q)
    crit = GlsDesignCriterion(problem.model, problem.base, default_discrepancy(6), name, Q_given=Qg, p=problem.p0)
    v, g = crit.value_and_grad(Q)
    assert v == pytest.approx(crit.value(Q), rel=1e-12)
    rng = np.random.default_rng(1)
    h = 1e-6
    for _ in range(2):                               # random directions over all poses and joints
        dQ = h * rng.standard_normal(Q.shape)
        slope = (crit.value(Q + dQ) - crit.value(Q - dQ)) / 2
        assert slope == pytest.approx(float(np.sum(g * dQ)), rel=2e-5, abs=1e-6 * np.abs(g).max() * h)
    assert np.abs(g).max() > 0


@pytest.mark.parametrize("name", ["D_gp", "param_gp"])
def test_kernel_part_of_the_gradient_matches_finite_differences(problem, name):
    """The kernel's own share (Jacobian held fixed): ∂φ/∂G chained with grad_x, against differences of K_QQ."""
    Q = problem.random_design(16, 6)[0]
    d = default_discrepancy(6)
    crit = GlsDesignCriterion(problem.model, problem.base, d, name, p=problem.p0)
    J = crit.pool_jacobians(Q)
    base = crit.crit
    _, g = gls_value_and_grad(base, J, d.covariance(Q), d.scale_m, d.noise, crit.prior_info)
    gk = np.einsum("ij,ijk->ik", g["G"] + g["G"].T, d.grad_x(Q, Q))
    h = 1e-6
    for i, k in [(0, 0), (3, 2), (7, 4)]:
        Qp, Qm = Q.copy(), Q.copy()
        Qp[i, k] += h
        Qm[i, k] -= h
        num = (gls_value_and_grad(base, J, d.covariance(Qp), d.scale_m, d.noise, crit.prior_info, grad=False)[0]
               - gls_value_and_grad(base, J, d.covariance(Qm), d.scale_m, d.noise, crit.prior_info, grad=False)[0]
               ) / (2 * h)
        assert num == pytest.approx(gk[i, k], rel=1e-5, abs=1e-7 * np.abs(gk).max())
    assert np.abs(gk).max() > 0


@pytest.mark.parametrize("form", ["D", "A"])
def test_pool_updates_equal_recomputation(problem, form):
    """The greedy state's value of every candidate (after rank-one kernel updates, adds and a removal) equals the
    criterion recomputed from scratch for the set plus that candidate."""
    d = default_discrepancy(6)
    crit = GlsDesignCriterion(problem.model, problem.base, d, "D_gp" if form == "D" else "param_gp", p=problem.p0)
    Qp = problem.random_design(40, 8)[0]
    Jp = crit.pool_jacobians(Qp)
    st = GlsState(Jp, Qp, np.zeros((0, 3, Jp.shape[2])), np.zeros((0, 6)), d, crit.prior_info, 0.0)
    st.K = get_criterion(crit.form.base.name).pool_form(None, Jp.shape[2])  # the A form of param: K = I
    for i in range(12):
        st.add(i)
    st = st.without(4)
    S = [i for i in range(12) if i != 4]
    phi = st.values(np.zeros(40, bool))
    for c in (15, 30):
        idx = S + [c]
        ref = gls_value_and_grad(crit.crit, Jp[idx], d.covariance(Qp[idx]), d.scale_m, d.noise, crit.prior_info,
                                 grad=False)[0]
        assert phi[c] == pytest.approx(ref, rel=1e-8, abs=1e-10)


class FirstParametersTrace(Criterion):
    """An A-type criterion written outside the package: tr of the covariance of the first five parameters, with the
    pool matrix K = those rows of I (its GLS pool selection must take the A form from ``pool_form``, not a name)."""

    name, label, unit = "a5", "tr of the first five parameters' covariance", "mixed"

    def value_and_grad_M(self, M0, E=None, prior_info=None, rows=0):
        M = M0 if prior_info is None else M0 + prior_info
        C = np.linalg.inv(M)[:5]
        return float(np.trace(C[:, :5])), -(C.T @ C)

    def pool_form(self, E, nb):
        return np.eye(nb)[:5]


def test_gls_pool_selection_takes_the_a_form_of_any_criterion_with_a_pool_matrix(problem):
    """The GLS selection of an outside criterion with a pool matrix K scores candidates by tr(K M⁻¹ Kᵀ) (equal to the
    criterion recomputed from scratch), not by the D form; its selection differs from the D form's."""
    d = default_discrepancy(6)
    crit = GlsDesignCriterion(problem.model, problem.base, d, FirstParametersTrace(), p=problem.p0)
    Qp = problem.random_design(60, 8)[0]
    Jp = crit.pool_jacobians(Qp)
    sel = crit.select(Qp, 15, J_pool=Jp)
    ref = gls_value_and_grad(crit.crit, Jp[sel.indices], d.covariance(Qp[sel.indices]), d.scale_m, d.noise,
                             crit.prior_info, grad=False)[0]
    assert sel.value == pytest.approx(ref, rel=1e-12)
    d_sel = GlsDesignCriterion(problem.model, problem.base, d, "D", p=problem.p0).select(Qp, 15, J_pool=Jp)
    assert sorted(sel.indices.tolist()) != sorted(d_sel.indices.tolist())
    assert sel.value < crit.value(Qp[d_sel.indices])                     # its own form selects better for it
    st = GlsState(Jp, Qp, np.zeros((0, 3, Jp.shape[2])), np.zeros((0, 6)), d, crit.prior_info, 0.0)
    st.K = FirstParametersTrace().pool_form(None, Jp.shape[2])
    for i in range(12):
        st.add(i)
    phi = st.values(np.zeros(60, bool))
    for c in (20, 41):
        idx = list(range(12)) + [c]
        ref = gls_value_and_grad(crit.crit, Jp[idx], d.covariance(Qp[idx]), d.scale_m, d.noise, crit.prior_info,
                                 grad=False)[0]
        assert phi[c] == pytest.approx(ref, rel=1e-8)


@pytest.mark.parametrize("name", ["D_gp", "param_gp", "O3_gp"])
def test_pool_selection_beats_random_and_reports_its_value(problem, name):
    d = default_discrepancy(6)
    crit = GlsDesignCriterion(problem.model, problem.base, d, name, p=problem.p0)
    Qp = problem.random_design(150, 9)[0]
    sel = crit.select(Qp, 20)
    assert len(set(sel.indices.tolist())) == 20
    assert sel.value == pytest.approx(crit.value(Qp[sel.indices]), rel=1e-10)
    rng = np.random.default_rng(0)
    rand = [crit.value(Qp[rng.choice(150, 20, replace=False)]) for _ in range(5)]
    assert sel.value < min(rand)


def test_design_problem_dispatches_the_forms(problem):
    c = problem.criterion("param_gp")
    assert isinstance(c, GlsDesignCriterion) and c.name == "param_gp"
    assert problem.criterion("kpi_gp").name == "kpi_gp"


def test_cli_design_with_gls_criteria_says_no_certificate(tmp_path, capsys):
    from pin_kpi_oed.cli.app import main

    out = tmp_path / "d.json"
    rc = main(["design", "--cell", "kr15", "--criteria", "random,D_gp,param_gp", "--measurements", "14", "--pool-size",
               "200", "--starts", "1",
               "--max-iter", "15", "--json", str(out), "--quiet"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "D_gp: no optimality certificate" in text and "param_gp: no optimality certificate" in text
    doc = json.loads(out.read_text())
    assert [d["criterion"] for d in doc["designs"]][-2:] == ["D_gp", "param_gp"]
    assert "none exists" in doc["discrepancy"]["certificate"]
