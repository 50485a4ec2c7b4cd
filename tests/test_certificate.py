"""Certificates on a cell: the relaxation bounds every design built from the pool (incl. the optimised ones)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.design.optimality import certify
from pin_kpi_oed.design.optimize import DesignProblem

from .cli_run import run_cli_as_process


@pytest.fixture(scope="module")
def problem():
    return DesignProblem(load_cell("kr15"))


def test_certificate_bounds_pool_designs_and_pool_is_feasible(problem):
    m = 20
    cert = certify(problem, m, pool_size=400, seed=0)
    assert cert.pool_size == 400
    assert cert.approx.max_d_ratio <= 1.0 + 1e-3 + 1e-9  # equivalence theorem at the relaxed optimum
    assert 0.5 < cert.efficiency(cert.pool_selection_trace_cs_m2) <= 1.0
    assert problem.checker.check(cert.Q_pool[cert.pool_selection]).all_feasible
    rng = np.random.default_rng(0)
    from pin_kpi_oed.oed.pool import exact_phi

    Fp = problem.model.weighted_jacobian(problem.p0, cert.Q_pool)[:, :, problem.base]
    for _ in range(10):  # any m-subset of the pool respects the bound
        idx = rng.choice(cert.pool_size, m, replace=False)
        assert cert.efficiency(exact_phi(Fp, idx, problem.E)) <= 1.0


def test_design_cli_certificate_fields(tmp_path):
    out = tmp_path / "d.json"
    res = run_cli_as_process("design", "--cell", "kr15", "--measurements", "15", "--criteria", "random,kpi",
                             "--starts", "1", "--max-iter", "40", "--certificate", "--pool-size", "300", "--json",
                             str(out))
    assert res.returncode == 0, res.stderr
    assert "effic. %" in res.stdout
    d = json.loads(out.read_text())
    lb = d["lower_bound_trace_cs_m2"]
    assert lb > 0 and d["certificate"]["success"] and d["certificate"]["nit"] > 0
    problem = DesignProblem(load_cell("kr15"))
    eff = {}
    for des in d["designs"]:
        # tr(C_s) of the written poses, recomputed here by an explicit inverse
        F = problem.model.weighted_jacobian(problem.p0, np.array(des["q_meas"]))[:, :, problem.base]
        F = F.reshape(-1, problem.base.size)
        trace = np.trace(problem.E @ np.linalg.inv(F.T @ F) @ problem.E.T)
        assert des["efficiency"] * trace == pytest.approx(lb, rel=1e-6)
        # the designs' own poses are in the certificate's pool, so no design can beat the bound
        assert des["efficiency"] <= 1.0 + 1e-9
        eff[des["criterion"]] = des["efficiency"]
    assert eff["kpi"] > eff["random"]
