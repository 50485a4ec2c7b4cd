"""The worst-sample path KPI ``kpi_path_max``: the power mean of tr C_s over the path samples, between the mean
(``kpi_path``) and the worst sample, with exact gradients in M and in the configurations (the latter checked
beside the other path criteria's, ``tests/test_paths.py``)."""

from __future__ import annotations

import numpy as np
import pytest

from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.design.optimize import DesignProblem
from pin_kpi_oed.oed.covariance import information
from pin_kpi_oed.oed.path_kpi_max import PathMaxTrace


@pytest.fixture(scope="module")
def seam_problem():
    return DesignProblem(load_cell("kr15_seam"), collision=False)


def _traces(problem, Q):
    F = problem.model.weighted_jacobian(problem.p0, Q)[:, :, problem.base].reshape(-1, problem.base.size)
    C = np.linalg.inv(information(F, problem.kpi_criterion.prior))
    E = problem.model.kpi_jacobian(problem.p0, problem.cell.q_path)[:, problem.base].reshape(-1, 3, problem.base.size)
    return np.einsum("sap,pq,saq->s", E, C, E)


def test_value_is_the_power_mean_between_mean_and_worst(seam_problem):
    Q = seam_problem.cell.robot.random_q(np.random.default_rng(2), 30)
    t = _traces(seam_problem, Q)
    val = seam_problem.criterion("kpi_path_max").value(Q)
    assert val == pytest.approx(np.mean(t ** 16) ** (1 / 16), rel=1e-9)
    assert t.mean() < val <= t.max()
    assert seam_problem.criterion("kpi_path").value(Q) == pytest.approx(t.mean(), rel=1e-9)


def test_sharpness_one_is_the_mean_and_a_large_one_the_worst_sample():
    rng = np.random.default_rng(0)
    F, E = rng.normal(size=(60, 8)), rng.normal(size=(3 * 40, 8))
    M = F.T @ F
    C = np.linalg.inv(M)
    t = np.einsum("sap,pq,saq->s", E.reshape(40, 3, 8), C, E.reshape(40, 3, 8))
    assert PathMaxTrace(1.0).value_and_grad_M(M, E)[0] == pytest.approx(t.mean(), rel=1e-10)
    assert PathMaxTrace(400.0).value_and_grad_M(M, E)[0] == pytest.approx(t.max(), rel=0.01)
    with pytest.raises(ValueError, match="sharpness"):
        PathMaxTrace(0.5)


def test_gradient_in_M_matches_finite_differences():
    rng = np.random.default_rng(1)
    F, E = rng.normal(size=(50, 7)), rng.normal(size=(3 * 25, 7))
    M = F.T @ F
    crit = PathMaxTrace()
    val, G = crit.value_and_grad_M(M, E)
    h = 1e-6 * np.abs(M).max()
    for i, j in [(0, 0), (2, 5), (6, 1), (4, 4)]:
        D = np.zeros_like(M)
        D[i, j] = D[j, i] = h
        fd = (crit.value_and_grad_M(M + D, E)[0] - crit.value_and_grad_M(M - D, E)[0]) / (2 * h)
        expect = G[i, j] * (1 if i == j else 2)
        assert fd == pytest.approx(expect, rel=1e-5, abs=1e-9 * abs(val)), (i, j)


def test_pool_selection_reports_the_worst_sample_criterion(seam_problem):
    rng = np.random.default_rng(3)
    pool = seam_problem.cell.robot.random_q(rng, 300)
    obj = seam_problem.criterion("kpi_path_max")
    sel = obj.select(pool, 20, seed=0)
    assert len(sel.indices) == 20 and sel.approx is None and "no certificate" in sel.message
    Qs = pool[sel.indices]
    assert sel.value == pytest.approx(obj.value(Qs), rel=1e-12)
    assert obj.value(Qs) == pytest.approx(np.mean(_traces(seam_problem, Qs) ** 16) ** (1 / 16), rel=1e-9)
    rand = [obj.value(pool[rng.choice(300, 20, replace=False)]) for _ in range(10)]
    assert obj.value(Qs) < min(rand)


@pytest.mark.slow
def test_path_study_compares_the_worst_sample_criterion(tmp_path):
    from pin_kpi_oed.studies.path_study import format_path_table, path_study

    s = path_study(tmp_path / "new" / "paths", m=20, seeds=(0, 1), mc_reps=0)
    assert (tmp_path / "new" / "paths" / "summary.json").is_file()  # the folder made before the work
    assert {"kpi_path_max_vs_kpi_path_worst_sigma_pos_m", "kpi_path_max_vs_kpi_rms_sigma_pos_m"} <= set(s["paired"])
    for r in s["records"]:  # each design's own criterion: the worst-sample one is no worse there than the mean one
        d = r["designs"]
        assert d["kpi_path_max"]["worst_sigma_pos_m"] <= 1.02 * d["kpi_path"]["worst_sigma_pos_m"]
    assert "kpi_path_max" in format_path_table(s)


def test_measured_poses_count_in_the_worst_sample_criterion(seam_problem):
    cell = seam_problem.cell
    rng = np.random.default_rng(6)
    Q_given, Q = cell.robot.random_q(rng, 20), cell.robot.random_q(rng, 5)
    seq = DesignProblem(cell, Q_given=Q_given, collision=False)
    plain = seam_problem.criterion("kpi_path_max")
    assert seq.criterion("kpi_path_max").value(Q) == pytest.approx(plain.value(np.vstack([Q_given, Q])), rel=1e-9)
