"""The working region of the discrepancy-aware KPI: W plus seeded configurations within R (sampled in the cell or
pool rows), and ``design --work-radius/--work-samples``."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pin_kpi_oed.design.region import near_rows, region_in_cell, working_region


def test_sampled_region_is_within_the_radius_seeded_and_filtered():
    W = np.array([[0.0, -1.2, 1.1, 0.0, 1.6, 0.0], [0.5, -1.0, 1.3, 0.2, 1.2, 0.3]])
    r = working_region(W, 0.3, 200, seed=7)
    assert r.kept == 200 and r.source == "sampled" and r.configurations().shape == (202, 6)
    d = np.linalg.norm(r.q_near[:, None, :] - W[None, :, :], axis=2).min(axis=1)
    assert np.all(d <= 0.3 + 1e-12)                              # within R in the full joint space too
    assert d.max() > 0.2                                          # and spread over the ball, not at W
    again = working_region(W, 0.3, 200, seed=7)
    assert np.array_equal(r.q_near, again.q_near)                 # seeded = reproducible
    assert not np.allclose(r.q_near, working_region(W, 0.3, 200, seed=8).q_near)
    half = working_region(W, 0.3, 200, seed=7, feasible=lambda Q: Q[:, 0] > 0.2)
    assert half.drawn == 200 and 0 < half.kept < 200 and np.all(half.q_near[:, 0] > 0.2)
    assert np.array_equal(half.q_near, r.q_near[r.q_near[:, 0] > 0.2])
    none = working_region(W, 0.0, 100, seed=7)
    assert none.kept == 0 and none.source == "none" and np.array_equal(none.configurations(), W)


def test_pool_region_is_the_learning_curves_choice():
    rng = np.random.default_rng(3)
    pool, W = rng.uniform(-1, 1, (400, 6)), rng.uniform(-1, 1, (3, 6))
    r = working_region(W, 0.8, 20, seed=5, pool=pool)
    near = near_rows(pool, W, 0.8, 5)
    expect = np.sort(np.random.default_rng([5, 1]).choice(near, 20, replace=False))
    assert near.size > 20 and np.array_equal(r.indices, expect) and np.array_equal(r.q_near, pool[expect])
    few = working_region(W, 0.8, 10_000, seed=5, pool=pool)
    assert np.array_equal(few.indices, near)


def test_problem_region_is_reachable_in_the_cell():
    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.cell.feasibility import FeasibilityChecker
    from pin_kpi_oed.design.optimize import DesignProblem

    cell = load_cell("ur10")
    reg = region_in_cell(cell, 0.5, 60, seed=1)
    problem = DesignProblem(cell, region=reg)
    assert 0 < reg.kept <= 60
    rep = FeasibilityChecker(cell).check(reg.q_near)
    assert np.all(rep.within_bounds & rep.collision_free)
    assert np.all(near_rows(reg.q_near, cell.q_work, 0.5, 5).size == reg.kept)
    assert problem.gp_criterion().Q_work.shape[0] == 2 + reg.kept
    assert problem.gp_criterion(region=False).Q_work.shape[0] == 2


def test_api_run_designs_draws_the_region_the_command_line_draws():
    """run_designs(cell, ['kpi_gp']) builds the working region as design does (same radius, samples, seed and
    cell); without kpi_gp, or with work_radius=0, none."""
    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.design.region import DEFAULT_WORK_RADIUS_RAD, DEFAULT_WORK_SAMPLES, default_region

    cell = load_cell("ur10")
    api = default_region(cell, ["random", "kpi_gp"], seed=3)
    cli = region_in_cell(cell, DEFAULT_WORK_RADIUS_RAD, DEFAULT_WORK_SAMPLES, 3)
    assert api is not None and api.kept > 0
    assert np.array_equal(api.configurations(), cli.configurations())
    assert default_region(cell, ["kpi"], seed=3) is None
    assert default_region(cell, ["kpi_gp"], 0.0, seed=3) is None


def _design(tmp_path, name, *extra):
    from pin_kpi_oed.cli.app import main

    out = tmp_path / f"{name}.json"
    assert main(["design", "--cell", "kr15", "--criteria", "random,kpi_gp", "--measurements", "20", "--starts", "1",
                 "--max-iter", "8", "--start", "random", "--json", str(out), "--quiet", *extra]) == 0
    return json.loads(out.read_text())


def test_cli_design_records_the_region_and_r0_is_the_plain_design(tmp_path, capsys):
    """``design --work-radius/--work-samples`` records the region, seeded (two runs: the same region and designs);
    ``--work-radius 0`` is the plain design of the API. The designs start from the heuristic design (``--start
    random``), not from a selection out of 1,000 feasible candidates per run: the region enters the KPI IPOPT
    optimises either way, and the API run takes the same start."""
    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.design.margins import with_margins
    from pin_kpi_oed.design.optimize import DesignOptions, DesignProblem, ipopt_options, run_designs

    a = _design(tmp_path, "a", "--work-samples", "40")
    b = _design(tmp_path, "b", "--work-samples", "40")
    out = capsys.readouterr().out
    assert "working region: the 1 working configurations + " in out and "over the region um" in out
    reg = a["working_region"]
    assert reg["radius_rad"] == 0.5 and reg["samples_requested"] == 40 and reg["seed"] == 0
    assert 0 < reg["kept"] == len(reg["q_near_rad"]) <= 40 and reg["source"] == "sampled"
    for d in a["designs"]:
        assert d["discrepancy"]["tcp_sigma_region_m"] > 0 and d["discrepancy"]["tcp_sigma_m"] > 0
    assert a["working_region"] == b["working_region"]                     # seeded: the same region and designs
    assert [d["q_meas"] for d in a["designs"]] == [d["q_meas"] for d in b["designs"]]
    z = _design(tmp_path, "z", "--work-radius", "0")
    assert z["working_region"] is None
    assert all("tcp_sigma_region_m" not in d["discrepancy"] for d in z["designs"])
    cell = with_margins(load_cell("kr15"), 0.02, 1.0)
    plain = run_designs(cell, ["random", "kpi_gp"], 20, 0, DesignOptions(n_starts=1, ipopt=ipopt_options(max_iter=8),
                                                                          start="random"), DesignProblem(cell))
    for d, r in zip(z["designs"], plain):
        assert d["criterion"] == r.criterion
        np.testing.assert_allclose(np.array(d["q_meas"]), r.q_meas, atol=1e-12)
    assert not np.allclose(np.array(z["designs"][1]["q_meas"]), np.array(a["designs"][1]["q_meas"]))


@pytest.mark.parametrize("bad", [["--work-radius", "-0.1"], ["--work-samples", "-1"]])
def test_cli_rejects_a_negative_region(bad, capsys):
    from pin_kpi_oed.cli.app import main

    assert main(["design", "--cell", "kr15", "--criteria", "random,kpi_gp", "--measurements", "20", *bad]) == 2


def test_region_sigma_holds_the_held_term_as_tcp_sigma_does():
    """The design's TCP σ over the working region includes G Σ_N Gᵀ at the region's configurations: its held part
    equals tcp_sigma's at the same points (a calibrated model at nominal holding the design's absorption) to
    1e-12, and the region's σ is sqrt((tr C_s + held) / n)."""
    from pin_kpi_oed.calibrated.model_file import CalibratedModel, Setup
    from pin_kpi_oed.calibrated.tcp_sigma import tcp_sigma
    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.design.optimize import DesignProblem
    from pin_kpi_oed.design.scores import discrepancy_scores
    from pin_kpi_oed.oed.held import design_term

    cell = load_cell("ur10")
    problem = DesignProblem(cell, region=region_in_cell(cell, 0.5, 25, seed=1))
    Q, _ = problem.random_design(25, 3)
    sc = discrepancy_scores(problem, [problem.result("random", Q, 0.0)])[0]
    Qr = problem.gp_criterion().Q_work
    held = sc["held_trace_region_m2"]
    assert held > 0.05 * sc["trace_cs_region_m2"]       # the held term is not negligible at a TCP off the reflector
    assert sc["tcp_sigma_region_m"] ** 2 * len(Qr) == pytest.approx(sc["trace_cs_region_m2"] + held, rel=1e-12)

    model = problem.model
    term = design_term(model, problem.base, Q, p=problem.p0)
    setup = Setup(np.asarray(model.tracker_T_base.homogeneous), model.reflector_m)
    cm = CalibratedModel(cell.robot, np.zeros(6 * cell.robot.nq), setups={"s": setup}, noise=model.noise,
                         tcp_m=model.tcp_m, parameters={"names": list(term.rows), "held": term})
    at = tcp_sigma(cm, Qr)
    assert float(np.einsum("maa->", at.held_m2)) == pytest.approx(held, rel=1e-12)
