"""The hedged kpi_gp design under an assumed discrepancy: family, exact gradient, selection between the assumed
prior's optimum and the noise-only KPI's, and the design problem's choice of it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.design.optimize import DesignProblem
from pin_kpi_oed.discrepancy.prior import DiscrepancyPrior
from pin_kpi_oed.oed.discrepancy_kpi import DiscrepancyDesignCriterion
from pin_kpi_oed.oed.hedged_kpi import HedgedDesignCriterion, prior_family
from pin_kpi_oed.studies.hedged_design import gp_discrepancy_sample

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def ur5():
    """The UR5 example cell, its design problem and the plain kpi_gp criterion at its working configuration."""
    cell = load_cell(str(ROOT / "examples" / "ur5_cell.yaml"))
    problem = DesignProblem(cell)
    crit = problem.gp_criterion(region=False)
    pool, _ = problem.random_design(80, seed=np.random.SeedSequence([4, 1]))
    return problem, crit, pool


def test_family_around_the_assumed_prior(ur5):
    _, crit, _ = ur5
    fam = prior_family(crit.discrepancy)
    assert len(fam) == 5 and fam[0] is crit.discrepancy
    k0 = crit.discrepancy.kernel
    assert np.allclose(fam[1].kernel.length_scale, 0.5 * np.asarray(k0.length_scale))
    assert np.allclose(fam[2].kernel.joint_length_scale, 2.0 * np.asarray(k0.joint_length_scale))
    assert fam[3].noise == pytest.approx(crit.discrepancy.noise / 9)
    assert fam[4].kernel is None and fam[4].noise == crit.discrepancy.noise
    assert np.allclose(k0.length_scale, 1.0)                        # the assumed kernel itself is untouched
    white = DiscrepancyPrior(None, crit.discrepancy.scale_m, crit.discrepancy.noise, "white")
    assert prior_family(white) == [white]                            # nothing to hedge: already the noise-only KPI


def test_value_is_the_weighted_geometric_mean_and_gradient_exact(ur5):
    problem, crit, pool = ur5
    h = HedgedDesignCriterion.around(crit)
    Q = pool[:12]
    v = h.member_values(Q)
    assert np.allclose(h.weights, [0.075, 0.075, 0.075, 0.075, 0.7])
    assert h.value(Q) == pytest.approx(float(np.exp(h.weights @ np.log(v))), rel=1e-12)
    val, g = h.value_and_grad(Q)
    assert val == pytest.approx(h.value(Q), rel=1e-12)
    eps = 1e-6
    for i, j in [(0, 0), (3, 1), (7, 2), (11, 4)]:
        Qp, Qm = Q.copy(), Q.copy()
        Qp[i, j] += eps
        Qm[i, j] -= eps
        fd = (h.value(Qp) - h.value(Qm)) / (2 * eps)
        assert fd == pytest.approx(g[i, j], rel=1e-5, abs=1e-9 * abs(val))


def test_selection_beats_every_members_own_selection_on_the_hedged_value(ur5):
    """The hedged set's φ_H is at most that of the assumed prior's and the noise-only KPI's own selections, and the
    exchange passes never raise it above the best member selection."""
    _, crit, pool = ur5
    h = HedgedDesignCriterion.around(crit)
    m = 12
    J = crit.pool_jacobians(pool)
    hedged = h.select(pool, m, J_pool=J, exchange_passes=1, seed=0)
    assumed = crit.select(pool, m, J_pool=J).indices
    noise = h.members[-1].select(pool, m, J_pool=J).indices
    assert len(set(hedged.indices.tolist())) == m
    assert hedged.value == pytest.approx(h.value(pool[hedged.indices]), rel=1e-9)
    assert hedged.value <= min(h.value(pool[assumed]), h.value(pool[noise])) * (1 + 1e-12)
    best_member = h.select(pool, m, J_pool=J, exchange_passes=0)
    assert best_member.nit == 0 and hedged.value <= best_member.value * (1 + 1e-12)
    assert hedged.path[0] == pytest.approx(best_member.value) and np.all(np.diff(hedged.path) <= 1e-12 * hedged.value)


def test_design_problem_hedges_only_an_assumed_discrepancy():
    cell = load_cell(str(ROOT / "examples" / "ur5_cell.yaml"))
    problem = DesignProblem(cell)
    assert isinstance(problem.criterion("kpi_gp"), HedgedDesignCriterion)    # the class default: an assumption
    assert isinstance(problem.replaced(hedge=False).criterion("kpi_gp"), DiscrepancyDesignCriterion)
    fitted = DesignProblem(cell, discrepancy=problem.discrepancy_prior())          # as design --model declares it
    assert not fitted.discrepancy_assumed and problem.discrepancy_assumed
    assert isinstance(fitted.criterion("kpi_gp"), DiscrepancyDesignCriterion)


def test_simulated_discrepancy_sample_has_its_level_and_length_scale():
    rng = np.random.default_rng(0)
    Q = rng.uniform(-np.pi, np.pi, (300, 6))
    d = gp_discrepancy_sample(Q, 1e-4, 0.3, seed=1)
    assert d.shape == (300, 3) and 0.6e-4 < d.std() < 1.4e-4
    near = Q[:50] + 0.01                                                         # 0.025 rad away: nearly equal
    both = gp_discrepancy_sample(np.vstack([Q[:50], near]), 1e-4, 1.0, seed=2)
    assert np.corrcoef(both[:50].ravel(), both[50:].ravel())[0, 1] > 0.99
    assert np.all(gp_discrepancy_sample(Q, 0.0, 1.0, seed=1) == 0.0)


def test_cli_design_says_it_hedges_and_refuses_no_hedge_where_nothing_is_assumed(tmp_path, capsys):
    from pin_kpi_oed.cli.app import main

    cell = load_cell(str(ROOT / "examples" / "ur5_cell.yaml"))
    Q, _ = DesignProblem(cell).random_design(60, seed=np.random.SeedSequence([5, 1]))
    pool = tmp_path / "pool.csv"
    pool.write_text(",".join(cell.robot.joint_names) + "\n"
                    + "".join(",".join(repr(float(v)) for v in q) + "\n" for q in Q))
    args = ["design", "--cell", str(ROOT / "examples" / "ur5_cell.yaml"), "--pool", str(pool), "--criteria", "kpi_gp",
            "--measurements", "12", "--work-radius", "0"]
    assert main(args) == 0
    assert "kpi_gp: the discrepancy is an assumption (no --model): the design hedges" in capsys.readouterr().out
    assert main(args + ["--no-hedge"]) == 0
    assert "the design hedges" not in capsys.readouterr().out
    assert main(args[:6] + ["kpi", "--no-hedge"]) == 2
    assert "--no-hedge applies to kpi_gp without --model" in capsys.readouterr().err


def test_sequential_design_hedges_an_assumed_discrepancy_too():
    """design --given without --model: the poses measured before count in every member of the family."""
    cell = load_cell(str(ROOT / "examples" / "ur5_cell.yaml"))
    Q_given, _ = DesignProblem(cell).random_design(30, seed=np.random.SeedSequence([6, 1]))
    problem = DesignProblem(cell, Q_given=Q_given)
    h = problem.criterion("kpi_gp")
    assert isinstance(h, HedgedDesignCriterion) and len(h.members) == 5
    assert all(c.Q_given is not None and len(c.Q_given) == 30 for c in h.members)
    Q = Q_given[:5] + 0.01
    assert h.value(Q) < h.value(Q[:1])                                     # more poses on top of the given: less
