"""The KPI after re-registration (:mod:`pin_kpi_oed.oed.reregistration`): the covariance of the re-registered TCP
error against Monte-Carlo of the whole chain (calibration with the discrepancy, a new set-up registered on other
rows), the set-up's own error removed, and the criterion's gradient unchanged in form (finite differences)."""

from __future__ import annotations

import numpy as np
import pytest

from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.design.optimize import DesignProblem
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.discrepancy.prior import DiscrepancyPrior
from pin_kpi_oed.oed.discrepancy_defaults import default_discrepancy
from pin_kpi_oed.oed.discrepancy_kpi import DiscrepancyDesignCriterion
from pin_kpi_oed.oed.kriging import kpi_gp_covariance
from pin_kpi_oed.oed.reregistration import reregistered_covariance, reregistration

from .fd import fd_rows


@pytest.fixture(scope="module")
def problem():
    return DesignProblem(load_cell("kr15"))


@pytest.mark.parametrize("white", [True, False])
def test_reregistered_covariance_matches_monte_carlo(white):
    """GLS calibration + kriging on Q in one set-up; a new set-up s_T registered by least squares on R against the
    calibrated prediction there (geometry + the kriged discrepancy, carried over); the error of the TCP prediction
    at W in the new set-up has covariance C_s(Ẽ) + C_reg: exactly with a white discrepancy, and within a few per cent
    with a correlated one (whose kriging error at R the formula leaves out)."""
    rng = np.random.default_rng(5)
    m, t, r, nb, d = 16, 3, 6, 7, 2
    setup = np.zeros(nb, bool)
    setup[-3:] = True                                        # the last three parameters: the set-up
    Q, W, R = (rng.uniform(-np.pi, np.pi, (k, d)) for k in (m, t, r))
    J, E, JR = (rng.normal(size=(k, 3, nb)) * 1e-3 for k in (m, t, r))
    d0 = default_discrepancy(d)
    disc = DiscrepancyPrior(None if white else d0.kernel, np.array([1e-4, 2e-4, 0.5e-4]), 0.05)
    Kall = disc.covariance(np.vstack([Q, W, R]))
    rr = reregistration(E, JR, setup, disc.scale_m, disc.noise, R)
    assert np.all(rr.E[:, :, setup] == 0)
    Cs = kpi_gp_covariance(J, rr.E, Kall[:m, :m], Kall[m:m + t, :m], Kall[m:m + t, m:m + t], disc.scale_m,
                           disc.noise) + rr.cov_m2
    n = 40000
    s2 = disc.scale_m ** 2
    Lk = np.linalg.cholesky(Kall + 1e-12 * np.eye(m + t + r))
    delta = np.einsum("ij,njb->nib", Lk, rng.normal(size=(n, m + t + r, 3)), optimize=True) * disc.scale_m
    eps = rng.normal(size=(n, m + r, 3)) * disc.scale_m * np.sqrt(disc.noise)
    theta = np.tile(rng.normal(size=nb), (n, 1))
    y = np.einsum("iac,nc->nia", J, theta) + delta[:, :m] + eps[:, :m]
    A = np.linalg.inv(Kall[:m, :m] + disc.noise * np.eye(m))
    M = np.einsum("a,iac,ij,jad->cd", 1 / s2, J, A, J)
    th = np.linalg.solve(M, np.einsum("a,iac,ij,nja->nc", 1 / s2, J, A, y, optimize=True).T).T
    res = y - np.einsum("iac,nc->nia", J, th)
    krig = np.einsum("ti,ij,nja->nta", Kall[m:, :m], A, res, optimize=True)   # the kriged discrepancy at W and R
    # the new session: another set-up; its registration rows measured, the calibrated prediction subtracted
    theta_T = theta.copy()
    theta_T[:, setup] = rng.normal(size=3)
    yR = np.einsum("iac,nc->nia", JR, theta_T) + delta[:, m + t:] + eps[:, m:]
    G = JR[:, :, setup].reshape(3 * r, -1)
    om = np.tile(1 / s2, r)
    th_reg = th.copy()
    rhs = (yR - np.einsum("iac,nc->nia", JR[:, :, ~setup], th[:, ~setup]) - krig[:, t:]).reshape(n, 3 * r)
    th_reg[:, setup] = np.linalg.solve(G.T @ (om[:, None] * G), ((rhs * om) @ G).T).T
    pred = np.einsum("tac,nc->nta", E, th_reg) + krig[:, :t]
    true = np.einsum("tac,nc->nta", E, theta_T) + delta[:, m:m + t]
    err = (pred - true).reshape(n, 3 * t)
    emp = err.T @ err / n
    assert np.trace(emp) == pytest.approx(np.trace(Cs), rel=0.03 if white else 0.1)
    sd = np.sqrt(np.outer(np.diag(Cs), np.diag(Cs)))
    assert np.abs(emp - Cs).max() <= (0.05 if white else 0.15) * sd.max()
    # the exact form (the kriging error at R in the registration) matches in both cases, and equals the criterion's
    # form with a white discrepancy (no kriging error to correlate)
    C_WR = kpi_gp_covariance(J, np.concatenate([E, JR]), Kall[:m, :m], Kall[m:, :m], Kall[m:, m:], disc.scale_m,
                             disc.noise)
    exact = reregistered_covariance(rr, C_WR)
    assert np.trace(emp) == pytest.approx(np.trace(exact), rel=0.03)
    sd = np.sqrt(np.outer(np.diag(exact), np.diag(exact)))
    assert np.abs(emp - exact).max() <= 0.05 * sd.max()
    if white:
        assert exact == pytest.approx(Cs, rel=1e-9, abs=1e-12 * np.abs(Cs).max())


def test_a_pure_setup_error_is_removed_by_registering_at_the_work(problem):
    """Registering at the working configurations themselves: an error of the set-up parameters alone leaves no
    TCP error there (Ẽ's set-up columns are zero and its robot columns see no set-up direction)."""
    crit = DiscrepancyDesignCriterion(problem.model, problem.base, default_discrepancy(6), problem.cell.q_work,
                                      p=problem.p0)
    setup = problem.model.layout.is_setup()[problem.base]
    E0 = crit.E.copy()
    assert np.abs(E0[:, :, setup]).max() > 0
    crit.set_registration(problem.random_design(12, 4)[0])
    assert np.all(crit.E[:, :, setup] == 0)
    assert crit.tr_register > 0
    assert not np.allclose(crit.E[:, :, ~setup], E0[:, :, ~setup])
    # set again: computed from the un-registered E, not from Ẽ
    E1 = crit.E.copy()
    crit.set_registration(crit.Q_register)
    assert np.allclose(crit.E, E1)


def test_gradient_with_reregistration_matches_finite_differences(problem):
    Q = problem.random_design(16, 5)[0]
    crit = DiscrepancyDesignCriterion(problem.model, problem.base, default_discrepancy(6), problem.cell.q_work,
                                      p=problem.p0, Q_register=problem.random_design(8, 9)[0])
    v, g = crit.value_and_grad(Q)
    assert v == pytest.approx(crit.value(Q), rel=1e-12)
    assert v == pytest.approx(np.trace(crit.covariance(Q)), rel=1e-9)
    num = fd_rows(crit.value, Q, 3)
    assert np.abs(num - g[:3]).max() <= 1e-5 * np.abs(g[:3]).max()
    sel = crit.select(problem.random_design(80, 2)[0], 12)
    assert sel.value == pytest.approx(crit.value(problem.random_design(80, 2)[0][sel.indices]), rel=1e-9)



def test_exact_form_of_the_criterion(problem):
    """The criterion's exact re-registered covariance: its own covariance without registration and with a white
    discrepancy (no kriging error at R to carry); with a correlated one it differs, and a wrong C_WR is refused."""
    Q = problem.random_design(16, 5)[0]
    R = problem.random_design(8, 9)[0]
    d = default_discrepancy(6)
    white = DiscrepancyPrior(None, d.scale_m, d.noise)
    crit = DiscrepancyDesignCriterion(problem.model, problem.base, white, problem.cell.q_work, p=problem.p0)
    assert np.allclose(crit.reregistered_covariance(Q), crit.covariance(Q))
    crit.set_registration(R)
    C = crit.covariance(Q)
    assert np.allclose(crit.reregistered_covariance(Q), C, rtol=1e-9, atol=1e-12 * np.abs(C).max())
    corr = DiscrepancyDesignCriterion(problem.model, problem.base, d, problem.cell.q_work, p=problem.p0,
                                      Q_register=R)
    exact, approx = np.trace(corr.reregistered_covariance(Q)), corr.value(Q)
    assert exact > 0 and abs(exact / approx - 1) > 1e-4
    with pytest.raises(InputError, match="C_WR must be"):
        reregistered_covariance(corr.reg, np.eye(3))

def test_too_few_registration_configurations_are_refused(problem):
    crit = DiscrepancyDesignCriterion(problem.model, problem.base, default_discrepancy(6), problem.cell.q_work,
                                      p=problem.p0)
    with pytest.raises(InputError, match="do not determine the set-up"):
        crit.set_registration(problem.random_design(1, 4)[0])


def test_cli_design_for_another_session(tmp_path, capsys):
    """design --reregister work: said in one line; the honest σ is the re-registered one (the old set-up's error
    no longer counts, so it is below the same design's σ in the set-up it is measured in); refused without the
    discrepancy, with too few configurations, with one clear line. Ipopt starts from the heuristic design
    (``--start random``): the pool selection of the default start was two thirds of the cost, and what is asserted
    (the line, the random design's σ in both set-ups, the refusals) does not depend on where the optimiser starts."""
    import json

    from pin_kpi_oed.cli.app import main

    base = ["design", "--cell", "kr15", "--criteria", "random,kpi_gp", "--measurements", "20", "--starts", "1",
            "--start", "random", "--max-iter", "10", "--work-samples", "30", "--quiet"]
    assert main(base + ["--json", str(tmp_path / "a.json")]) == 0
    capsys.readouterr()
    assert main(base + ["--reregister", "work", "--json", str(tmp_path / "b.json")]) == 0
    assert "registered again on" in capsys.readouterr().out
    a, b = (json.loads((tmp_path / f).read_text()) for f in ("a.json", "b.json"))
    ra = {d["criterion"]: d["discrepancy"]["tcp_sigma_m"] for d in a["designs"]}
    rb = {d["criterion"]: d["discrepancy"]["tcp_sigma_m"] for d in b["designs"]}
    assert rb["random"] != pytest.approx(ra["random"], rel=1e-3) and rb["random"] < ra["random"]
    one = tmp_path / "one.csv"
    one.write_text("joint_a1,joint_a2,joint_a3,joint_a4,joint_a5,joint_a6\n0,-1.5,1.5,0,0.5,0\n")
    assert main(base + ["--reregister", str(one)]) == 2
    err = capsys.readouterr().err
    assert "do not determine the set-up" in err and len(err.strip().splitlines()) == 1
    assert main(base + ["--work-radius", "0", "--reregister", "work"]) == 2   # one working configuration
    err = capsys.readouterr().err
    assert "--reregister" in err and len(err.strip().splitlines()) == 1
    assert main(["design", "--cell", "kr15", "--criteria", "random,kpi", "--reregister", "work"]) == 2
    assert "--reregister needs the discrepancy" in capsys.readouterr().err
