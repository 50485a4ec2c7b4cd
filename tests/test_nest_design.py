"""The IPOPT design over pose × nest: the per-pose nest KPI's gradient against finite differences, a cell whose
nest 0 alone leaves the TCP partly held accepted when its nests together determine it, and the alternating design
never worse than the assign-after design it starts from, its poses feasible."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from pin_kpi_oed.model.noise import NoiseModel
from pin_kpi_oed.model.robot import load_robot
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.simulation.simulator import default_tracker_pose

ROOT = Path(__file__).resolve().parents[1]
NESTS = [[0.0, 0.0, 0.05], [0.06, 0.0, 0.05]]  # nest 0 on the last joint's axis, nest 1 off it


@pytest.fixture(scope="module")
def ur5():
    return load_robot("ur5")


def _cell(nests=NESTS):
    """The UR5 example cell with nest 0 on the flange axis (0.05 m out, outside the flange's capsule) and the TCP
    0.15 m out on that axis."""
    from pin_kpi_oed.cell.cell import cell_from_dict

    src = ROOT / "examples" / "ur5_cell.yaml"
    d = yaml.safe_load(src.read_text())
    d.update(reflector_m=nests[0], nests_m=nests, noise={"sigma_xyz_m": [2.5e-5] * 3})
    return cell_from_dict(d, str(src), base_dir=src.parent)


@pytest.fixture(scope="module")
def problem():
    """The design problem of the two-nest UR5 cell."""
    from pin_kpi_oed.design.optimize import DesignProblem

    return DesignProblem(_cell())


@pytest.mark.parametrize("nest", [np.zeros(16, int), np.arange(16) % 2])
def test_nest_kpi_gradient_matches_finite_differences(ur5, nest):
    from pin_kpi_oed.oed.nest_objective import NestObjective
    from pin_kpi_oed.oed.nests import nest_trace

    model = TrackerModel(ur5, tracker_T_base=default_tracker_pose(ur5), reflector_m=NESTS[0], nests_m=NESTS,
                         tcp_m=np.array([0.0, 0.0, 0.15]), noise=NoiseModel(sigma_xyz_m=(2.5e-5,) * 3))
    rng = np.random.default_rng(0)
    Q, Qw = ur5.random_q(rng, 16), ur5.random_q(rng, 3)
    obj = NestObjective(model, nest, Qw)
    v, g = obj.value_and_grad(Q)
    assert v == pytest.approx(nest_trace(model, Q, nest, Qw).total_m2, rel=1e-12)  # the assignment's tr C_s
    h = 1e-6
    fd = np.zeros_like(Q)
    for i in range(Q.shape[0]):
        for k in range(Q.shape[1]):
            d = np.zeros_like(Q)
            d[i, k] = h
            fd[i, k] = (obj.value(Q + d) - obj.value(Q - d)) / (2 * h)
    assert np.max(np.abs(fd - g)) < 1e-4 * np.max(np.abs(g))
    # pose 0 at the other nest is another function of the poses: its gradient differs (with both nests measured;
    # one pose alone at nest 1 would not determine that nest's parameters)
    if nest.any():
        other = nest.copy()
        other[0] = 1 - other[0]
        assert not np.allclose(NestObjective(model, other, Qw).value_and_grad(Q)[1][0], g[0], rtol=1e-3, atol=0)


def test_design_problem_accepts_nests_that_together_determine_the_tcp(problem):
    from pin_kpi_oed.design.optimize import DesignProblem
    from pin_kpi_oed.errors import IdentifiabilityError

    # nest 0 alone leaves the TCP's rotation across the axis held; nest 1 determines it
    assert problem.model.n_nests == 2 and problem.E.shape[0] == 3 * len(problem.cell.q_work)
    with pytest.raises(IdentifiabilityError, match="not estimable"):
        DesignProblem(_cell(NESTS[:1]))  # one nest on the axis: refused as before
    from pin_kpi_oed.oed.evaluate import score_design

    Q = problem.random_design(14, 0)[0]  # a design file's scores: the same rule
    assert np.isfinite(score_design(problem.model, Q, problem.cell.q_work).trace_cs_m2)
    with pytest.raises(IdentifiabilityError, match="not estimable"):
        score_design(_cell(NESTS[:1]).tracker_model(), Q, problem.cell.q_work)


def test_alternating_design_is_no_worse_than_assign_after_and_feasible(problem):
    from pin_kpi_oed.design.ipopt import ipopt_options
    from pin_kpi_oed.design.nest_design import alternate_nests
    from pin_kpi_oed.design.optimize import design_ipopt
    from pin_kpi_oed.oed.nests import assign_nests, nest_trace

    m, opts = 14, ipopt_options(max_iter=60)
    after = design_ipopt(problem, "kpi", m, seed=0, options=opts)  # the poses at nest 0 ...
    nd = assign_nests(problem.model, after.q_meas, problem.cell.q_work)  # ... their nests assigned after
    res = alternate_nests(problem, after.q_meas, seed=0, options=opts)
    assert res.start_trace_m2 == pytest.approx(nd.chosen.total_m2, rel=1e-12)
    assert 1 <= res.nit <= 4 and res.rounds
    assert res.trace_m2 <= nd.chosen.total_m2
    assert res.trace_m2 == pytest.approx(nest_trace(problem.model, res.q_meas, res.nest,
                                                    problem.cell.q_work).total_m2, rel=1e-12)
    assert res.success and problem.checker.check(res.q_meas).all_feasible
    assert res.q_meas.shape == after.q_meas.shape and set(res.nest.tolist()) == {0, 1}
    # the rounds moved the poses and lowered the KPI of the identified parameters
    assert min(r.trace_m2 for r in res.rounds) < nd.chosen.total_m2
    assert not np.allclose(res.q_meas, after.q_meas)
