"""The default discrepancy per robot class (oed.discrepancy_defaults): the class from the robot's name, S growing
with the reach beyond the class's reference arm, the KR 15 keeping the generic numbers, and the design output
stating the class."""

from __future__ import annotations

import numpy as np
import pytest

from pin_kpi_oed import load_robot
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.oed.discrepancy_defaults import ROBOT_CLASSES, class_discrepancy, default_discrepancy, robot_class_of


@pytest.mark.parametrize("name, cls", [("ur5", "collaborative"), ("UR10e", "collaborative"), ("panda", "collaborative"),
                                       ("kr15", "industrial"), ("kr500", "industrial"), ("my_arm", "generic")])
def test_class_from_the_name(name, cls):
    assert robot_class_of(name) == cls


def test_kr15_keeps_the_generic_numbers_so_its_designs_are_unchanged():
    robot = load_robot("kr15")
    d, g = class_discrepancy(robot), default_discrepancy(robot.nq)
    assert d.scale_m == pytest.approx(g.scale_m) and d.noise == pytest.approx(g.noise)
    Q = robot.random_q(np.random.default_rng(0), 7)
    assert d.covariance(Q) == pytest.approx(g.covariance(Q))
    assert "industrial class, from the name 'kr15'" in d.source and "not a fit" in d.source


def test_scale_grows_with_the_reach_beyond_the_reference_arm():
    c = ROBOT_CLASSES["industrial"]
    for name in ("kr300", "kr500"):
        robot = load_robot(name)
        d = class_discrepancy(robot)
        assert robot.reach() > c.reach_m
        assert d.scale_m == pytest.approx(np.full(3, c.scale_m * robot.reach() / c.reach_m))
        assert d.noise == pytest.approx(ROBOT_CLASSES["generic"].white_m ** 2 / ROBOT_CLASSES["generic"].scale_m ** 2)
    ur10, ur5 = class_discrepancy(load_robot("ur10")), class_discrepancy(load_robot("ur5"))
    assert ur10.scale_m[0] == pytest.approx(2.5e-4, rel=1e-3)                  # the Series B fit's order
    assert ur5.scale_m[0] == pytest.approx(2.5e-4)                              # a shorter arm keeps S_c
    assert ur10.delta_sigma_m == pytest.approx(ur10.scale_m)                 # k(q, q) = 1


def test_given_class_overrides_the_name_and_an_unknown_class_is_refused():
    robot = load_robot("ur10")
    d = class_discrepancy(robot, "generic")
    assert d.scale_m[0] == ROBOT_CLASSES["generic"].scale_m and "generic class, given" in d.source
    with pytest.raises(InputError, match="robot class 'heavy': unknown"):
        class_discrepancy(robot, "heavy")


def test_cli_design_states_the_class_and_takes_robot_class(tmp_path, capsys):
    """The design command states the discrepancy's class (from the robot's name, or given) and writes its scale. The
    prior is chosen before any optimisation, so the design starts from the heuristic poses (``--start random``): the
    pool selection of the default start (three quarters of each run's cost) does not change what is stated."""
    import json

    from pin_kpi_oed.cli.app import main

    args = ["design", "--cell", "ur10", "--criteria", "random,kpi_gp", "--measurements", "12", "--starts", "1",
            "--max-iter", "5", "--work-samples", "10", "--start", "random", "--quiet"]
    assert main(args + ["--json", str(tmp_path / "a.json")]) == 0
    assert ("discrepancy (default for the collaborative class, from the name 'ur10': "
            "S = 0.25 mm") in capsys.readouterr().out
    assert json.loads((tmp_path / "a.json").read_text())["discrepancy"]["scale_m"] == pytest.approx([2.5e-4] * 3,
                                                                                                    rel=1e-3)
    assert main(args + ["--robot-class", "industrial", "--json", str(tmp_path / "b.json")]) == 0
    assert "industrial class, given" in capsys.readouterr().out
    assert json.loads((tmp_path / "b.json").read_text())["discrepancy"]["scale_m"] == pytest.approx([1e-4] * 3)


def test_the_class_scales_the_honest_trace_not_the_design():
    """The white σ is S/10 in every class: without a parameter prior tr C_s of any poses scales by S², so every
    class ranks designs alike."""
    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.design.optimize import DesignProblem
    from pin_kpi_oed.oed.discrepancy_kpi import DiscrepancyDesignCriterion

    problem = DesignProblem(load_cell("ur10"))
    assert problem.fixed_information() is None
    rng = np.random.default_rng(1)
    Q = problem.cell.robot.random_q(rng, 40)
    robot = problem.cell.robot
    priors = {k: class_discrepancy(robot, k) for k in ("collaborative", "generic")}
    val = {k: DiscrepancyDesignCriterion(problem.model, problem.base, d, problem.cell.q_work, p=problem.p0).value(Q)
           for k, d in priors.items()}
    ratio = (priors["collaborative"].scale_m[0] / priors["generic"].scale_m[0]) ** 2
    assert val["collaborative"] == pytest.approx(ratio * val["generic"], rel=1e-6)
    pool = problem.random_design(120, 3)[0]                                    # the pool selection is the same
    sel = {k: DiscrepancyDesignCriterion(problem.model, problem.base, d, problem.cell.q_work, p=problem.p0)
           .select(pool, 12).indices for k, d in priors.items()}
    assert np.array_equal(sel["collaborative"], sel["generic"])
    assert problem.discrepancy_prior().scale_m[0] == pytest.approx(priors["collaborative"].scale_m[0])
