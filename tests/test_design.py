"""Design: Ipopt NLP callbacks (structure, gradients), a small fast design run, fallback, CLI and JSON."""

from __future__ import annotations

import argparse
import json

import numpy as np
import pytest

from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.design.ipopt import DesignNLP
from pin_kpi_oed.design.optimize import (DesignOptions, DesignProblem, DesignResult, design_ipopt, ipopt_options,
                                         run_designs, solve_ipopt)
from pin_kpi_oed.errors import InputError
from tests.cli_run import without_times

M = 14  # small designs keep the suite fast (27 identifiable parameters need >= 9 poses)


@pytest.fixture(scope="module")
def problem() -> DesignProblem:
    return DesignProblem(load_cell("kr15"))


@pytest.fixture(scope="module")
def start(problem) -> np.ndarray:
    return problem.random_design(M, 0)[0]


def test_nlp_structure_and_gradients(problem, start):
    crit = problem.criterion("kpi")
    nlp = DesignNLP(crit, problem.cons, M, crit.value(start))
    x = start.ravel().copy()
    rows, cols = nlp.jacobianstructure()
    g = nlp.constraints(x)
    J = nlp.jacobian(x)
    assert g.size == M * problem.cons.n_rows and J.size == rows.size
    # each row depends on one configuration only (block-diagonal structure)
    assert np.all(rows // problem.cons.n_rows == cols // problem.n)
    dense = np.zeros((g.size, x.size))
    dense[rows, cols] = J
    f, df = nlp.objective(x), nlp.gradient(x)
    assert f == pytest.approx(1.0)
    rng = np.random.default_rng(0)
    for k in rng.choice(x.size, 12, replace=False):
        h = 1e-6
        xp, xm = x.copy(), x.copy()
        xp[k] += h
        xm[k] -= h
        fd_g = (nlp.constraints(xp) - nlp.constraints(xm)) / (2 * h)
        assert np.abs(fd_g - dense[:, k]).max() < 1e-6
        fd_f = (nlp.objective(xp) - nlp.objective(xm)) / (2 * h)
        assert fd_f == pytest.approx(df[k], rel=1e-4, abs=1e-7)


def test_small_design_improves_and_is_feasible(problem, start):
    r0 = problem.result("random", start, problem.criterion("kpi").value(start), status="sampled")
    res = design_ipopt(problem, "kpi", M, seed=0, n_starts=1, start=start, options=ipopt_options(max_iter=60))
    assert isinstance(res, DesignResult)
    assert res.feasible and res.min_clearance_m >= 0 and res.max_incidence_deg <= 30.0 + 1e-9
    assert np.all(res.q_meas >= problem.cell.q_lower) and np.all(res.q_meas <= problem.cell.q_upper)
    assert res.improvement_over(r0) > 20.0
    assert 0 < res.nit <= 60 and res.n_constraints == M * problem.cons.n_rows
    d = res.to_dict()
    json.dumps(d)
    assert np.array(d["q_meas"]).shape == (M, 6) and d["criterion"] == "kpi" and "kpi" in res.summary()


def test_fallback_returns_best_feasible_iterate(problem, start):
    r = solve_ipopt(problem, "kpi", start, ipopt_options(max_iter=3))
    assert r.status == "max_iter" and r.solver_status.startswith("Maximum_Iterations_Exceeded") and r.success
    assert problem.coll.feasible(r.Q).all() and r.f <= 1.0 + 1e-12


def test_naive_formulation_gives_the_same_kind_of_design(start):
    naive = DesignProblem(load_cell("kr15"), aggregate="none")
    r = solve_ipopt(naive, "kpi", start, ipopt_options(max_iter=15))
    assert r.n_constraints == M * naive.coll.n_rows and r.success and r.f < 1.0


def test_run_designs_without_collision_reports_colliding_share():
    cell = load_cell("kr15")
    res = run_designs(cell, ["random", "kpi"], m=M, seed=1,  # IPOPT from the heuristic design: no 1,000-pose pool
                      options=DesignOptions(collision=False, ipopt=ipopt_options(max_iter=40), start="random"))
    rnd, kpi = res
    assert rnd.criterion == "random" and rnd.feasible and rnd.samples >= M  # the heuristic is always collision-free
    assert not kpi.collision_avoidance and 0.0 <= kpi.share_colliding <= 1.0
    assert kpi.trace_cs_m2 < rnd.trace_cs_m2


def test_bad_requests_are_named(problem):
    with pytest.raises(InputError, match="unknown criterion 'A-opt'"):
        run_designs(problem.cell, ["random", "A-opt"], m=M, problem=problem)
    with pytest.raises(InputError, match="at least 9"):
        design_ipopt(problem, "kpi", 5)


def test_cli_design_writes_the_json(tmp_path, capsys):
    """The handler on a namespace that holds only some options (the others take their defaults): the table's
    columns, the file's keys, and the file read back by ``evaluate``. The design starts from the heuristic design
    (``start="random"``): the file's content does not depend on the start."""
    from pin_kpi_oed.cli import design as cli_design

    out = tmp_path / "design.json"
    ns = argparse.Namespace(cell="kr15", criteria="random,kpi", measurements=M, seed=0, json=str(out),
                            no_collision=False, starts=1, max_iter=25, quiet=False, start="random")
    assert cli_design.run(ns) == 0
    text = capsys.readouterr().out
    for col in ("criterion", "tr(C_s) mm^2", "TCP sigma um", "vs random %", "min clr mm", "max inc deg", "iters",
                "time s"):
        assert col in text
    d = json.loads(out.read_text())
    for key in ("robot", "tracker_T_base", "reflector_m", "noise", "q_work", "capsules", "half_spaces", "designs"):
        assert key in d
    assert d["robot"]["urdf_path"].endswith("kr15.urdf") and d["robot"]["tool_frame"] == "tool0"
    assert np.array(d["tracker_T_base"]).shape == (4, 4)
    assert [x["criterion"] for x in d["designs"]] == ["random", "kpi"]
    for x in d["designs"]:
        for key in ("criterion", "q_meas", "trace_cs_m2", "min_clearance_m", "max_incidence_deg", "solve_time_s",
                    "iterations", "status"):
            assert key in x
        assert np.array(x["q_meas"]).shape == (M, 6)
    # the file is a valid input of `pin-kpi-oed evaluate` (set-up + q_meas + q_work)
    from pin_kpi_oed.oed.evaluate import evaluate_file

    ev = evaluate_file(out)
    assert ev.trace_cs_m2 == pytest.approx(d["designs"][1]["trace_cs_m2"], rel=1e-9)


def test_cli_rejects_unknown_criterion():
    from pin_kpi_oed.cli import design as cli_design

    with pytest.raises(InputError, match="unknown criterion 'foo'"):
        cli_design.parse_criteria("random,foo")


def test_cli_registers_design_subcommand():
    from pin_kpi_oed.cli import design as cli_design

    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers(dest="command")
    cli_design.register(sub)
    args = parser.parse_args(["design", "--cell", "kr300", "--criteria", "random,param,kpi,D", "--measurements",
                              "60", "--seed", "3", "--json", "x.json", "--no-collision"])
    assert args.func is cli_design.run and args.no_collision and args.measurements == 60 and args.seed == 3


@pytest.mark.slow
@pytest.mark.parametrize("name", ["kr15", "kr300", "kr500"])
def test_paper_claims_on_kuka_cells(name):
    """60 measurements: KPI design >= 40 % below the heuristic and >= 10 % below the A-on-C_p design, all feasible."""
    res = run_designs(load_cell(name), ["random", "param", "kpi"], m=60, seed=0, options=DesignOptions(n_starts=2))
    rnd, par, kpi = res
    assert all(r.feasible for r in res)
    assert kpi.improvement_over(rnd) >= 40.0
    assert kpi.improvement_over(par) >= 10.0


# ---------------------------------------------------------------------------- user pools (design --pool)
@pytest.mark.parametrize("name", ["kr15", "ur10"])
def test_pool_feasible_set_equals_the_independent_coal_check(name):
    """``design --pool``'s fast check (batched capsule rows, Coal only within 1e-6 m / 1e-8 of the thresholds)
    accepts exactly the candidates :class:`FeasibilityChecker` (Coal, every pair) accepts in the tightened cell,
    also for candidates bisected onto the boundary (1e-12 apart across it), which only Coal decides."""
    from pin_kpi_oed.design.margins import with_margins
    from pin_kpi_oed.design.user_pool import check_candidates

    cell = with_margins(load_cell(name), 0.02, 1.0)
    prob = DesignProblem(cell)
    rng = np.random.default_rng(7)
    Qf, _ = prob.random_design(40, seed=3)
    Q = np.vstack([Qf, np.clip(np.repeat(Qf, 10, axis=0) + rng.normal(0, 0.05, (400, cell.robot.nq)), cell.q_lower,
                                cell.q_upper), cell.robot.random_q(rng, 800)])
    coal = prob.checker.check(Q).feasible
    edge = []  # pairs straddling the boundary, found by bisection on Coal's own verdict
    for a, b in zip(np.flatnonzero(coal)[:12], np.flatnonzero(~coal)[:12]):
        lo, hi = 0.0, 1.0
        for _ in range(45):
            t = 0.5 * (lo + hi)
            if prob.checker.check(Q[a] + t * (Q[b] - Q[a])).feasible[0]:
                lo = t
            else:
                hi = t
        edge += [Q[a] + lo * (Q[b] - Q[a]), Q[a] + hi * (Q[b] - Q[a])]
    Q = np.vstack([Q, edge])
    coal = np.concatenate([coal, prob.checker.check(np.array(edge)).feasible])  # the check is pose by pose
    ok, Fp, n_coal = check_candidates(prob, Q)
    np.testing.assert_array_equal(ok, coal)
    assert 0 < coal.sum() < len(Q) and n_coal >= 12  # the boundary pairs went to Coal ...
    assert n_coal < 0.1 * len(Q)  # ... and few others
    np.testing.assert_allclose(Fp, prob.model.weighted_jacobian(prob.p0, Q[ok])[:, :, prob.base], rtol=1e-12)


def _write_poses(path, names, Q):
    path.write_text(",".join(names) + "\n" + "\n".join(",".join(f"{x:.12f}" for x in q) for q in Q) + "\n")


@pytest.fixture(scope="module")
def sequential_files(tmp_path_factory):
    """40 measured KR 15 poses and a user pool of 500 feasible + 100 unchecked candidates (seeded)."""
    cell = load_cell("kr15")
    Q, _ = DesignProblem(cell).random_design(540, seed=5)
    folder = tmp_path_factory.mktemp("seq")
    pool = np.vstack([Q[40:], cell.robot.random_q(np.random.default_rng(1), 100)])
    _write_poses(folder / "given.csv", cell.robot.joint_names, Q[:40])
    _write_poses(folder / "pool.csv", cell.robot.joint_names, pool)
    return folder, Q[:40], pool


def test_cli_pool_on_top_of_given_poses_is_certified_and_answers_how_many_more(sequential_files):
    from pin_kpi_oed.cli.app import main
    from pin_kpi_oed.oed.objective import DesignCriterion

    folder, Qg, pool = sequential_files
    cell = load_cell("kr15")
    base = DesignProblem(cell)
    crit = DesignCriterion(base.model, base.base, "kpi", base.E)
    target = 0.8 * float(np.sqrt(crit.value(Qg)))  # t = 1 working configuration: sigma = sqrt(tr C_s)
    out = folder / "d.json"
    m = 10
    assert main(["design", "--cell", "kr15", "--given", str(folder / "given.csv"), "--pool", str(folder / "pool.csv"),
                 "--criteria", "random,kpi", "--measurements", str(m), "--clearance-margin", "0",
                 "--incidence-margin", "0", "--target-sigma", str(target), "--quiet", "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    rnd, kpi = doc["designs"]
    Qk = np.array(kpi["q_meas"])
    assert np.min(np.abs(Qk[:, None] - pool[None]).max(axis=2), axis=1).max() < 1e-9  # from the user's pool
    # tr(C_s) counts the measured poses (recomputed from scratch on the stacked poses)
    assert kpi["trace_cs_m2"] == pytest.approx(crit.value(np.vstack([Qg, Qk])), rel=1e-9)
    assert np.trace(np.array(kpi["cov_s_m2"])) == pytest.approx(kpi["trace_cs_m2"], rel=1e-9)
    assert kpi["trace_cs_m2"] < rnd["trace_cs_m2"] < crit.value(Qg)
    # the certificate (measured information as the fixed part) bounds every m-subset of the feasible pool
    bound = doc["lower_bound_trace_cs_m2"]
    seq = DesignProblem(cell, Q_given=Qg)
    feas = pool[seq.checker.check(pool).feasible]
    rng = np.random.default_rng(0)
    for _ in range(20):
        assert bound <= crit.value(np.vstack([Qg, feas[rng.choice(len(feas), m, replace=False)]]))
    assert 0.95 < kpi["efficiency"] <= 1.0 + 1e-9
    # "how many more": adding that many poses of the pool reaches the target, one fewer does not
    u = doc["poses_until"]
    k, Qa = u["n_more"], np.array(u["q_added"])
    assert u["success"] and k == len(Qa) >= 1
    assert np.min(np.abs(Qa[:, None] - feas[None]).max(axis=2), axis=1).max() < 1e-9
    assert np.sqrt(crit.value(np.vstack([Qg, Qa]))) <= target * (1 + 1e-9)
    assert np.sqrt(crit.value(np.vstack([Qg, Qa[:-1]]))) > target


def test_given_prior_counts_in_scores_and_certificate(sequential_files):
    """A prior Σ₀⁻¹ on the robot parameters (here: the covariance of 300 earlier random poses) adds to the
    measured information: C_s = E (F_gᵀF_g + Σ₀⁻¹ + FᵀF)⁻¹ Eᵀ, and the pool selection's bound includes it."""
    from pin_kpi_oed.design.problem_options import prior_information
    from pin_kpi_oed.design.user_pool import design_from_pool

    folder, Qg, pool = sequential_files
    cell = load_cell("kr15")
    seq = DesignProblem(cell, Q_given=Qg)
    Qe = cell.robot.random_q(np.random.default_rng(9), 300)
    Fe = seq.model.weighted_jacobian(seq.p0, Qe)[:, :, seq.base].reshape(-1, seq.base.size)
    names = [seq.ident.names[i] for i in seq.base]
    P = prior_information(seq, names + ["not.a_parameter"], np.pad(np.linalg.inv(Fe.T @ Fe), (0, 1)) + np.diag(
        [0.0] * len(names) + [1.0]))
    robot_rows = [k for k, i in enumerate(seq.base) if seq.model.layout.names[i].split(".")[0]
                  not in seq.model.layout.setup_groups]
    assert np.abs(P[np.ix_(robot_rows, robot_rows)]).max() > 0 and len(robot_rows) < len(names)
    seq = seq.replaced(given_prior=P)
    res, cert, _ = design_from_pool(seq, pool, ["random", "kpi"], 10, seed=0)
    Qk = res[-1].q_meas
    F = seq.model.weighted_jacobian(seq.p0, np.vstack([Qg, Qk]))[:, :, seq.base].reshape(-1, seq.base.size)
    want = np.trace(seq.E @ np.linalg.solve(F.T @ F + P, seq.E.T))
    assert res[-1].trace_cs_m2 == pytest.approx(want, rel=1e-8)
    no_prior = DesignProblem(cell, Q_given=Qg).kpi_criterion.value(Qk)
    assert res[-1].trace_cs_m2 < no_prior
    assert cert.lower_bound_trace_cs_m2 <= res[-1].trace_cs_m2 and cert.efficiency(res[-1].trace_cs_m2) > 0.95
    with pytest.raises(InputError, match="names none"):
        prior_information(seq, ["x.y"], np.eye(1))


def test_cli_bad_given_and_pool_inputs_exit_2_and_write_nothing(sequential_files, tmp_path, capsys):
    from pin_kpi_oed.cli.app import main

    folder, Qg, pool = sequential_files
    cell = load_cell("kr15")
    wrong = tmp_path / "wrong.csv"
    _write_poses(wrong, ["a1", "a2", "a3", "a4", "a5", "a6"], Qg[:3])
    bad = tmp_path / "infeasible.csv"
    Qbad = Qg[:5].copy()
    Qbad[2] = cell.robot.random_q(np.random.default_rng(0), 50)[
        ~DesignProblem(cell).checker.check(cell.robot.random_q(np.random.default_rng(0), 50)).feasible][0]
    _write_poses(bad, cell.robot.joint_names, Qbad)
    few = tmp_path / "few.csv"
    _write_poses(few, cell.robot.joint_names, Qg[:2])  # 2 poses do not identify 27 parameters
    garbage = tmp_path / "model.json"
    garbage.write_text("{not json")
    out = tmp_path / "d.json"
    cases = [["--given", str(folder / "given.csv"), "--pool", str(wrong)],
             ["--given", str(wrong), "--pool", str(folder / "pool.csv")],
             ["--given", str(bad), "--pool", str(folder / "pool.csv")],
             ["--given", str(bad)],
             ["--given", str(tmp_path / "missing.csv")],
             ["--given", str(folder / "given.csv"), "--given-prior", str(garbage)],
             ["--pool", str(folder / "pool.csv"), "--given-prior", str(garbage)],
             ["--given", str(few), "--pool", str(folder / "pool.csv"), "--target-sigma", "1e-6"]]
    for extra in cases:
        assert main(["design", "--cell", "kr15", "--measurements", "5", "--quiet", "--json", str(out), *extra]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and ("--given" in err[0] or "--pool" in err[0]), (extra, err)
        assert not out.exists()
    assert "row 3" in (lambda: (main(["design", "--cell", "kr15", "--given", str(bad), "--quiet"]),
                                capsys.readouterr().err)[1])()


def test_api_writes_the_design_file_view_and_export_read(problem, tmp_path):
    """write_design (the writer ``design --json`` calls) makes a file load_design reads back: same poses, cell, C_s."""
    from pin_kpi_oed.design.design_file import design_document, load_design, write_design
    from pin_kpi_oed.design.runner import DesignRun

    results = run_designs(problem.cell, ["random"], 12, 3, problem=problem)
    run = DesignRun(cell=problem.cell, problem=problem, results=results, m=12, seed=3)
    path = write_design(tmp_path / "d.json", run)
    df = load_design(path)
    entry = df.designs[0]
    assert entry.criterion == "random" and np.allclose(entry.q_meas, results[0].q_meas, atol=0.0)
    assert np.allclose(df.cell.q_work, problem.cell.q_work) and df.cell.robot.name == problem.cell.robot.name
    doc = design_document(run)
    assert np.isclose(np.trace(np.asarray(doc["designs"][0]["cov_s_m2"])), results[0].trace_cs_m2, rtol=1e-9)
    assert json.loads(path.read_text())["q_meas"] == doc["q_meas"]


def test_cli_json_is_the_library_run_written(tmp_path):
    """``design --json`` and ``pko.write_design`` of the same run (``design_run`` with the same settings) write
    the same file: the same keys and numbers, wall times apart; ``demo`` goes through the same calls. The designs
    start from the heuristic design (``--start random``, ``start="random"``): the option reaches the settings like
    the others, and the pool start's 1,000 candidates per run are left to the ``--given`` case below."""
    import pin_kpi_oed as pko
    from pin_kpi_oed.cli.app import main

    args = ["--cell", "kr15", "--criteria", "random,kpi", "--measurements", "14", "--starts", "1", "--max-iter", "15",
            "--start", "random", "--certificate", "--pool-size", "300", "--clearance-margin", "0.01", "--seed", "2",
            "--quiet"]
    assert main(["design", *args, "--json", str(tmp_path / "cli.json")]) == 0
    settings = pko.DesignSettings(criteria=("random", "kpi"), measurements=14, seed=2, n_starts=1, max_iter=15,
                                  start="random", certificate=True, certificate_pool_size=300,
                                  clearance_margin_m=0.01, incidence_margin_deg=1.0)
    run = pko.design_run(pko.load_cell("kr15"), settings)
    pko.write_design(tmp_path / "api.json", run)
    cli, api = (json.loads((tmp_path / f"{n}.json").read_text()) for n in ("cli", "api"))
    assert cli["clearance_margin_m"] == 0.01 and "certificate" in cli and "pose_clearance_m" in cli["designs"][1]
    assert without_times(cli) == without_times(api)


@pytest.mark.parametrize("mode", ["pool", "given"])
def test_cli_json_is_the_library_run_written_with_pool_and_given(sequential_files, tmp_path, mode):
    """With measured poses (``--given``) and "how many more" (``--target-sigma``), selected from a user pool
    (``--pool``) or optimised on top: ``design --json`` and ``pko.write_design`` of ``design_run`` with the same
    settings write the same file (wall times apart)."""
    import pin_kpi_oed as pko
    from pin_kpi_oed.cli.app import main

    folder, Qg, _ = sequential_files
    target = 0.8 * DesignProblem(load_cell("kr15"), Q_given=Qg).sigma_tcp()
    given, pool = str(folder / "given.csv"), str(folder / "pool.csv")
    args = ["--cell", "kr15", "--criteria", "random,kpi", "--measurements", "10", "--seed", "1", "--given", given,
            "--target-sigma", repr(target), "--pool-size", "300", "--quiet"]
    kw: dict = dict(criteria=("random", "kpi"), measurements=10, seed=1, given_file=given, target_sigma_m=target,
                    certificate_pool_size=300, clearance_margin_m=0.02, incidence_margin_deg=1.0)
    if mode == "pool":
        args, kw = args + ["--pool", pool], {**kw, "pool_file": pool}
    else:
        args, kw = args + ["--starts", "1", "--max-iter", "10"], {**kw, "n_starts": 1, "max_iter": 10}
    assert main(["design", *args, "--json", str(tmp_path / "cli.json")]) == 0
    pko.write_design(tmp_path / "api.json", pko.design_run(pko.load_cell("kr15"), pko.DesignSettings(**kw)))
    cli, api = (json.loads((tmp_path / f"{n}.json").read_text()) for n in ("cli", "api"))
    assert cli["given"]["file"] == given and cli["poses_until"]["n_more"] >= 1
    assert ("certificate" in cli) == (mode == "pool")
    assert without_times(cli) == without_times(api)


def test_cli_pool_drops_and_counts_infeasible_candidates(sequential_files, tmp_path, capsys):
    """Candidates outside the cell's joint bounds or infeasible are dropped and counted in one line, by reason;
    the design is made from the others (the file is not refused for one bad pose)."""
    from pin_kpi_oed.cli.app import main

    folder, _, pool = sequential_files
    cell = load_cell("kr15")
    out_of_bounds = pool[:3].copy()
    out_of_bounds[:, 1] = cell.q_upper[1] + 0.5  # rad, beyond the cell's bound of joint 2 (not degrees)
    _write_poses(tmp_path / "pool.csv", cell.robot.joint_names, np.vstack([pool, out_of_bounds]))
    assert main(["design", "--cell", "kr15", "--pool", str(tmp_path / "pool.csv"), "--criteria", "random,kpi",
                 "--measurements", "10", "--clearance-margin", "0", "--incidence-margin", "0", "--quiet",
                 "--json", str(tmp_path / "d.json")]) == 0
    line = next(ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("--pool:"))
    n = len(pool) + 3
    assert f"{n} candidates in" in line and f"3 outside the cell's joint bounds (rows {n - 2}, {n - 1}, {n})" in line
    feasible = int(line.split(": ")[2].split(" feasible")[0])
    assert f"{n - feasible} dropped" in line and feasible <= 500 + 100
    counted = sum(int(part.split(" ")[0]) for part in line.split("dropped (")[1].rstrip(")").split("; "))
    assert counted == n - feasible  # every dropped candidate has its reason
    q = np.array(json.loads((tmp_path / "d.json").read_text())["q_meas"])
    assert np.all(q[:, 1] <= cell.q_upper[1] + 1e-9)


def test_demo_is_the_library_run(monkeypatch):
    """``demo`` declares its run (KR 15, random / param / kpi, 60 poses, the certificate) and hands it to
    ``design_run``, the call ``design`` and the Python API use (no command-line namespace in between)."""
    import pin_kpi_oed.design.runner as runner
    from pin_kpi_oed.cli.app import main

    seen = {}

    class Stop(BaseException):
        pass

    def stop(cell, settings, problem=None, **kw):
        seen.update(cell=cell.name, settings=settings)
        raise Stop

    monkeypatch.setattr(runner, "design_run", stop)
    with pytest.raises(Stop):
        main(["demo", "--seed", "4"])
    s = seen["settings"]
    assert seen["cell"] == load_cell("kr15").name and s.criteria == ("random", "param", "kpi")
    assert (s.measurements, s.seed, s.certificate, s.clearance_margin_m) == (60, 4, True, 0.0)
