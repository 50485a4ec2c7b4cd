"""A test per hostile input (one clear line, exit 2, nothing written), the fit-quality gate,
the study-folder lock, and output-path checks before any work."""

from __future__ import annotations

import contextlib
import io
import json
import time
from pathlib import Path

import numpy as np
import pytest

from pin_kpi_oed.cli.app import main
from pin_kpi_oed.errors import InputError
from tests.hostile.cases import CASES, build_inputs, run_case


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("hostile") / "inputs"
    build_inputs(d)
    return d


@pytest.fixture(scope="module")
def work(inputs) -> Path:
    """The one work folder of the cases: each case empties it and links the inputs afresh (``prepare``)."""
    return inputs.parent / "work"


@pytest.mark.parametrize("case", [pytest.param(c, marks=pytest.mark.slow) if c.slow else c for c in CASES],
                         ids=[c.id for c in CASES])
def test_hostile_input_is_refused_in_one_line(case, inputs, work):
    """A refusal: exit 2, one line naming the expected text, nothing written; a warning: said, no input changed;
    never a traceback, never past the case's time bound. An output-path problem (``out-`` cases) is reported before
    any work: under 2 s CPU."""
    out = run_case(case, inputs, work)
    assert out.verdict(case) == "ok", (out.verdict(case), out.rc, out.err[-600:], out.out[-300:], out.changed,
                                       round(out.time_s, 1))
    if case.id.startswith("out-"):
        assert out.rc == 2 and out.cpu_s < 2.0, ("output-path problem not reported before any work", out.cpu_s,
                                                 out.err)


#: the fit-quality gate's and the robust loss's tests fit without a discrepancy (the default fits a Gaussian process
#: to decide, most of a fit's time here): what they test is the parametric fit's verdict and loss; a discrepancy's part
#: in the verdict (it never excuses a poor fit) is tests/test_discrepancy.py's
NO_GP = ("--discrepancy", "none")


def _run(*argv) -> tuple[int, str, str]:
    o, e = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(o), contextlib.redirect_stderr(e):
        rc = main([str(a) for a in argv])
    return rc, o.getvalue(), e.getvalue()


@pytest.fixture(scope="module")
def offset_data(tmp_path_factory) -> Path:
    """KR 15 data (reflector 30, 20, 80 mm, 10 µm noise, sigma columns), and a copy with four 10 cm outliers."""
    d = tmp_path_factory.mktemp("gate")
    assert _run("simulate", "--robot", "kr15", "--n", "300", "--n-test", "100", "--seed", "4", "--out",
                d / "tr.csv", "--test-out", d / "te.csv")[0] == 0
    for f in ("tr.csv", "te.csv"):  # as a tracker writes them: no tool header stating the reflector
        (d / f).write_text("\n".join(ln for ln in (d / f).read_text().splitlines() if not ln.startswith("#")) + "\n")
    lines = (d / "tr.csv").read_text().splitlines()
    head = lines[0].split(",")
    xi = head.index("x")
    for k in (10, 100, 200, 250):
        row = lines[k].split(",")
        row[xi] = repr(float(row[xi]) + 0.1)
        lines[k] = ",".join(row)
    (d / "out4.csv").write_text("\n".join(lines) + "\n")
    return d


def test_zero_reflector_assumed_is_refused_as_poor_fit(offset_data, tmp_path):
    """Hostile case 1: --reflector 0,0,0 on data with an offset: refused, verdict in the JSON, no URDF."""
    d = offset_data
    rc, out, err = _run("identify", "--robot", "kr15", "--data", d / "tr.csv", "--validate", d / "te.csv",
                        "--reflector", "0,0,0", "--json", tmp_path / "r.json", "--urdf-out", tmp_path / "c.urdf",
                        *NO_GP)
    assert rc == 2 and "POOR" in err and "reflector" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "c.urdf").exists()
    q = json.loads((tmp_path / "r.json").read_text())["fit_quality"]
    assert q["verdict"] == "poor" and q["chi2_reduced"] > 16 and q["chi2_interval"][1] < 1.3


def test_default_reflector_is_estimated_and_fit_is_good(offset_data, tmp_path):
    d = offset_data
    rc, out, err = _run("identify", "--robot", "kr15", "--data", d / "tr.csv", "--validate", d / "te.csv",
                        "--json", tmp_path / "r.json", *NO_GP)
    assert rc == 0, err
    doc = json.loads((tmp_path / "r.json").read_text())
    assert doc["reflector_nominal_source"] == "estimated"
    assert np.allclose(doc["reflector_nominal_m"], [0.03, 0.02, 0.08], atol=1.5e-3)
    assert doc["fit_quality"]["verdict"] == "good"
    assert doc["validation"]["after"]["rms_m"] < 30e-6  # the noise floor (10 µm per axis -> ~17 µm)


def test_large_outliers_switch_to_robust_loss(offset_data, tmp_path):
    """Hostile case 2: four 10 cm outliers: the default switches to soft_l1; --loss linear is refused."""
    d = offset_data
    rc, out, err = _run("identify", "--robot", "kr15", "--data", d / "out4.csv", "--validate", d / "te.csv",
                        "--json", tmp_path / "r.json", *NO_GP)
    assert rc == 0 and "robust loss soft_l1" in out
    doc = json.loads((tmp_path / "r.json").read_text())
    assert doc["result"]["loss"] == "soft_l1" and doc["validation"]["after"]["rms_m"] < 30e-6
    rc, out, err = _run("identify", "--robot", "kr15", "--data", d / "out4.csv", "--validate", d / "te.csv",
                        "--loss", "linear", "--urdf-out", tmp_path / "c.urdf", *NO_GP)
    assert rc == 2 and "--loss soft_l1" in err and not (tmp_path / "c.urdf").exists()
    rc, *_ = _run("identify", "--robot", "kr15", "--data", d / "out4.csv", "--loss", "linear", "--accept-poor-fit",
                  "--urdf-out", tmp_path / "c.urdf", *NO_GP)
    assert rc == 0 and (tmp_path / "c.urdf").exists()


def test_sigma_too_small_makes_chi2_poor_and_too_large_suspect(offset_data):
    from pin_kpi_oed.identification.quality import assess_fit

    class R:  # a result whose reduced chi2 we choose
        names = ["p"] * 30
        covariance_scaled = False
        loss = "linear"
        residuals_rad = None

        def __init__(self, chi2, n=300):
            self.chi2_reduced = chi2
            self.weighted_errors = np.full(n, np.sqrt(3 * chi2))
            self.errors_m = np.full(n, 1e-5)
            self.outliers = np.array([], int)

    assert assess_fit(R(1.0)).verdict == "good"
    assert assess_fit(R(40.0)).verdict == "poor"
    assert assess_fit(R(3.0)).verdict == "suspect"
    assert assess_fit(R(0.2)).verdict == "suspect" and "sigma too large" in assess_fit(R(0.2)).line()
    worse = assess_fit(R(1.0), {"before": {"rms_m": 1e-3}, "after": {"rms_m": 2e-3}})
    assert worse.verdict == "poor" and "worse than the nominal" in worse.line()


def test_study_folder_is_locked_against_a_second_writer(tmp_path):
    from pin_kpi_oed.data.lock import folder_lock
    from pin_kpi_oed.studies.study import run_tasks

    with folder_lock(tmp_path / "s", "study folder"):
        with pytest.raises(InputError, match="another run"):
            run_tasks([], tmp_path / "s")
    assert run_tasks([], tmp_path / "s") == ([], 0)  # released


def test_task_record_without_designs_is_recomputed(tmp_path):
    from pin_kpi_oed.studies.study import Task, task_finished

    t = Task(key="k", cell="kr15", criteria=("random",), m=10, seed=0, collision=True, n_starts=1, meta={})
    (tmp_path / "tasks").mkdir()
    rec = {**t.to_dict(), "ok": True, "designs": []}
    (tmp_path / "tasks" / "k.json").write_text(json.dumps(rec))
    assert task_finished(tmp_path, t) is None
    rec["designs"] = [{"criterion": "random", "trace_cs_m2": 1.0}]
    (tmp_path / "tasks" / "k.json").write_text(json.dumps(rec))
    assert task_finished(tmp_path, t) is not None


def test_view_recomputes_a_negative_stored_covariance(inputs, tmp_path):
    from pin_kpi_oed.design.design_file import load_design

    d = json.loads((inputs / "d.json").read_text())
    C = np.array(d["designs"][0]["cov_s_m2"])
    d["designs"][0]["cov_s_m2"] = (-C).tolist()
    df = load_design(d)
    assert np.allclose(df.designs[0].cov_s_m2, C, rtol=1e-6)
    assert any("differs" in n for n in df.notes)


def test_oserror_on_output_is_one_line(inputs, tmp_path, monkeypatch):
    import pin_kpi_oed.data.atomic as atomic

    def full(*a, **k):
        raise OSError(28, "No space left on device", str(tmp_path / "x.csv"))

    monkeypatch.setattr(atomic, "atomic_write_bytes", full)
    rc, out, err = _run("simulate", "--robot", "kr15", "--out", tmp_path / "x.csv")
    assert rc == 2 and "No space left on device" in err and len(err.strip().splitlines()) == 1


# --------------------------------------------------------------------------- issue 24
def test_equivalents_are_exact_turns_never_clipped():
    """A joint beyond its limit is never moved onto it: q itself first, the others exactly q + 2πk."""
    from pin_kpi_oed.program.transitions import equivalents

    lo, hi = np.radians([-180.0, -130.0]), np.radians([180.0, 130.0])
    q = np.array([3.0, 2.299])  # the second joint beyond 130°
    E = equivalents(q, lo, hi, np.array([True, True]))
    assert np.array_equal(E[0], q)
    k = (E - q) / (2 * np.pi)
    assert np.allclose(k, np.round(k), atol=1e-12)


def test_export_force_writes_the_design_value_beyond_a_limit(inputs, tmp_path):
    """--force writes a pose beyond a joint limit as designed (no clipping); without it nothing is written."""
    from pin_kpi_oed.program.export import parse_program

    d = json.loads((inputs / "d_a5.json").read_text())
    rc, out, err = _run("export", inputs / "d_a5.json", "--format", "csv", "--out", tmp_path / "p.csv")
    assert rc == 2 and "outside its limits" in err and not (tmp_path / "p.csv").exists()
    rc, out, err = _run("export", inputs / "d_a5.json", "--format", "csv", "--out", tmp_path / "p.csv", "--force")
    assert rc == 0 and "warning (--force)" in out
    Q, poses = parse_program("csv", {".csv": (tmp_path / "p.csv").read_text()}, np.ones(6, bool))
    rows = [r for r in (tmp_path / "p.csv").read_text().splitlines() if r and not r.startswith("#")][1:]
    meas = [q for q, r in zip(Q, rows) if r.split(",")[1] == "measure"]
    qd = np.asarray(d["q_meas"], float)
    for q, p in zip(meas, poses):
        dq = (q - qd[p] + np.pi) % (2 * np.pi) - np.pi
        assert np.max(np.abs(dq)) < 1e-9
    assert any(abs(q[4] - 2.299) < 1e-9 for q in meas)


def test_route_planner_is_seeded_per_call():
    """The same move planned twice (after other plans) gives the same route: the seed is per call. (The first two
    blocked moves of the pool are the ones planned: the pairs are checked until they are found, not all of them.)"""
    import itertools

    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.program.transitions import TransitionChecker

    tc = TransitionChecker(load_cell("kr15"), 0.01)
    pool = tc.safe_pool(30, seed=2)
    blocked = ((a, b) for a in range(len(pool)) for b in range(a + 1, len(pool))
               if not tc.check(pool[a], pool[b]).clear)
    pairs = list(itertools.islice(blocked, 2))
    assert pairs
    a, b = pairs[0]
    r1 = tc.plan_route(pool[a], pool[b], seed=5, max_checks=4000)
    tc.plan_route(pool[pairs[-1][0]], pool[pairs[-1][1]], seed=5, max_checks=2000)  # something in between
    r2 = TransitionChecker(load_cell("kr15"), 0.01).plan_route(pool[a], pool[b], seed=5, max_checks=4000)
    assert (r1 is None) == (r2 is None)
    if r1 is not None:
        assert len(r1) == len(r2) and all(np.array_equal(x, y) for x, y in zip(r1, r2))
        pts = [pool[a], *r1, pool[b]]
        assert all(tc.check(x, y).clear for x, y in zip(pts[:-1], pts[1:]))


def test_urscript_moves_at_the_speed_of_the_predicted_time():
    from pin_kpi_oed.program.export import ProgramInfo, write_urscript
    from pin_kpi_oed.program.timing import move_time

    speeds = np.array([2.0, 2.0, 3.0, 3.0, 3.0, 3.0])
    Q = np.array([[0.0] * 6, [1.0, 0.5, 0.0, 0.0, 0.0, 0.0], [1.0, 0.5, 2.4, 0.0, 0.0, 0.1]])
    info = ProgramInfo("c", "d", "ur10", [f"j{k}" for k in range(6)], np.ones(6, bool), speeds=speeds)
    text = write_urscript(Q, ["home", "measure", "measure"], [-1, 0, 1], info)[".script"]
    vs = [float(x) for x in __import__("re").findall(r"v=([0-9.eE+-]+)\)", text)]
    for k in (1, 2):
        t = np.max(np.abs(Q[k] - Q[k - 1])) / vs[k]
        assert t == pytest.approx(move_time(Q[k - 1], Q[k], speeds), rel=1e-5)
    assert "v per move" in text


def test_register_says_it_replaces_a_station(inputs, tmp_path):
    import shutil

    shutil.copy(inputs / "reg20.csv", tmp_path / "tr.csv")  # the model's station is named 'tr'
    rc, out, err = _run("register", "--model", inputs / "m.json", "--data", tmp_path / "tr.csv", "--model-out",
                        tmp_path / "o.json")
    assert rc == 0 and "station 'tr' replaced" in out, err


def test_outliers_with_unknown_noise_use_the_robust_loss(tmp_path):
    """10 % of the rows 5 mm off, no sigma columns: soft_l1 is used; a plain fit is never 'good'."""
    assert _run("simulate", "--robot", "kr15", "--n", "150", "--n-test", "60", "--seed", "7", "--out",
                tmp_path / "tr.csv", "--test-out", tmp_path / "te.csv")[0] == 0
    lines = [ln for ln in (tmp_path / "tr.csv").read_text().splitlines() if not ln.startswith("#")]
    head = lines[0].split(",")
    keep = [i for i, h in enumerate(head) if not h.startswith("sigma")]
    xi = [head[i] for i in keep].index("x")
    rows = [[r.split(",")[i] for i in keep] for r in lines[1:]]
    for k in range(0, len(rows), 10):
        rows[k][xi] = repr(float(rows[k][xi]) + 0.005)
    (tmp_path / "o.csv").write_text("\n".join([",".join(head[i] for i in keep)] + [",".join(r) for r in rows]) + "\n")
    rc, out, err = _run("identify", "--robot", "kr15", "--data", tmp_path / "o.csv", "--validate", tmp_path / "te.csv",
                        "--json", tmp_path / "r.json", *NO_GP)
    assert rc == 0 and "robust loss soft_l1" in out
    doc = json.loads((tmp_path / "r.json").read_text())
    assert doc["result"]["loss"] == "soft_l1" and doc["validation"]["after"]["rms_m"] < 0.1e-3
    rc, out, err = _run("identify", "--robot", "kr15", "--data", tmp_path / "o.csv", "--loss", "linear", *NO_GP)
    assert "fit quality: good" not in out and "SUSPECT" in out


def test_new_checks_are_fast(inputs):
    """The checks added for issue 24 cost well under 50 ms per command."""
    from pin_kpi_oed.identification.quality import assess_registration
    from pin_kpi_oed.model.robot import load_robot
    from pin_kpi_oed.validation.robot_checks import check_points_against_joints
    from pin_kpi_oed.validation.schema import validate_model_dict

    d = json.loads((inputs / "m.json").read_text())
    validate_model_dict(d, "m.json")  # the validator is built once
    robot = load_robot("kr15")
    Q = robot.random_q(np.random.default_rng(0), 2000)
    P = np.array([robot.oMtool(q).translation for q in Q])
    t0 = time.process_time()  # CPU time: the checks' cost, not the machine's load
    validate_model_dict(d, "m.json")
    check_points_against_joints(robot, Q, P, "a", "b")
    assess_registration("s", P, P, np.full(2000, 1e-5), np.full(3, 1e-5), 9)
    assert time.process_time() - t0 < 0.05 * 2  # two commands' worth


def test_move_check_bound_gives_the_exact_decisions(inputs):
    """The lower bound only skips samples it proves clear: decisions and smallest clearances are the exact ones."""
    from pin_kpi_oed.design.design_file import load_design
    from pin_kpi_oed.program.transitions import TransitionChecker

    df = load_design(inputs / "d.json")
    Q = np.vstack([df.cell.q_work[0], df.designs[0].q_meas, df.cell.q_work[0]])
    fast, exact = TransitionChecker(df.cell, 0.01), TransitionChecker(df.cell, 0.01, use_bound=False)
    assert fast.bound is not None and fast.bound.ok
    for a, b in zip(Q[:-1], Q[1:]):
        assert fast.check(a, b).clear == exact.check(a, b).clear
        assert fast.check(a, b, stop_early=False).min_clearance_m == pytest.approx(
            exact.check(a, b, stop_early=False).min_clearance_m, abs=1e-12)
    X = df.cell.robot.random_q(np.random.default_rng(1), 200)
    lb = fast.bound.pairs(X)
    E = np.array([fast.checker.pair_distances(q) for q in X])
    assert np.all(lb[np.isfinite(lb)] <= E[np.isfinite(lb)] + 1e-9)
    for cap in (0.03, 0.1):  # balls instead of closest points far above the cap: still a bound, the same below it
        capped = fast.bound.pairs(X, cap)
        assert np.all(capped[np.isfinite(capped)] <= E[np.isfinite(capped)] + 1e-9)
        low, low_capped = lb.min(axis=1), capped.min(axis=1)
        below = low < cap
        assert below.any() and np.array_equal(low_capped[below], low[below]) and np.all(low_capped[~below] >= cap)


def test_the_second_of_two_concurrent_writers_is_refused(tmp_path, monkeypatch):
    """Another process writes the output while a command runs: the command refuses to replace it, in one line."""
    import subprocess
    import sys

    import pin_kpi_oed.data.atomic as atomic

    out = tmp_path / "tr.csv"
    real = atomic._folder_lock
    code = f"from pin_kpi_oed.data.atomic import atomic_write_text; atomic_write_text({str(out)!r}, 'other\\n')"

    def other_process_first(directory):  # the command's write is about to replace the file
        if not out.exists():
            subprocess.run([sys.executable, "-c", code], check=True)
        return real(directory)

    monkeypatch.setattr(atomic, "_folder_lock", other_process_first)
    rc, _, err = _run("simulate", "--robot", "kr15", "--n", "30", "--seed", "1", "--out", out)
    last = err.strip().splitlines()[-1] if err.strip() else ""
    assert rc == 2 and f"cannot write '{out}'" in last and "another process wrote it" in last, err
    assert out.read_text() == "other\n" and not list(tmp_path.glob(".*.tmp"))
    monkeypatch.setattr(atomic, "_folder_lock", real)
    rc, _, err = _run("simulate", "--robot", "kr15", "--n", "30", "--seed", "1", "--out", out)  # one after the other
    assert rc == 0, err
    assert out.read_text().count("\n") > 30


def test_a_claimed_output_can_be_written_again_by_its_own_command(tmp_path):
    from pin_kpi_oed.data.atomic import atomic_write_text
    from pin_kpi_oed.validation.paths import claim_output, release_outputs

    p = tmp_path / "x.txt"
    claim_output(p)
    atomic_write_text(p, "a")
    atomic_write_text(p, "b")  # its own earlier write is no other writer
    assert p.read_text() == "b"
    p.write_text("changed by someone else")
    with pytest.raises(InputError, match="another process wrote it"):
        atomic_write_text(p, "c")
    claim_output(p)  # a new command checks the file again: it may replace it
    atomic_write_text(p, "d")
    assert p.read_text() == "d"
    release_outputs()  # a command's claims end with it: a later write of the file is no conflict
    p.write_text("edited")
    atomic_write_text(p, "e")
    assert p.read_text() == "e"


def test_near_duplicate_pool_poses_are_named_by_row(tmp_path):
    """A pool of 4 poses taught 20 times each (1e-9 rad apart): one line naming the duplicate rows, nothing written."""
    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.design.margins import with_margins
    from pin_kpi_oed.design.optimize import DesignProblem
    from pin_kpi_oed.design.user_pool import near_duplicates

    cell = with_margins(load_cell("kr15"), 0.02, 1.0)
    Q0, _ = DesignProblem(cell).random_design(4, seed=3, max_tries=10 ** 5)
    Q = np.clip(np.repeat(Q0, 20, axis=0) + np.random.default_rng(0).normal(0, 1e-9, (80, 6)), cell.q_lower,
                cell.q_upper)
    groups = near_duplicates(Q)
    assert sorted(map(len, groups)) == [20, 20, 20, 20] and list(groups[0]) == list(range(20))
    assert near_duplicates(Q0) == []
    pool = tmp_path / "pool.csv"
    rows = [",".join(cell.robot.joint_names)] + [",".join(f"{x:.12f}" for x in q) for q in Q]
    pool.write_text("\n".join(rows) + "\n")
    out = tmp_path / "d.json"
    rc, _, err = _run("design", "--cell", "kr15", "--pool", pool, "--criteria", "random,kpi", "--json", out)
    last = err.strip().splitlines()[-1]
    assert rc == 2 and "only 4 distinct poses" in last and "rows 1, 2, 3, 4, 5 (+15 more)" in last, err
    assert "rows 21, 22, 23, 24, 25" in last and str(pool) in last and len(last) < 400
    assert not out.exists()


def test_every_option_that_writes_is_a_declared_output():
    """The one output-path check knows every output: an option whose help says it writes (or a figure / folder)
    is in OUTPUTS / FOLDERS of its command, so it is checked against every input and every other output."""
    import argparse

    from pin_kpi_oed.cli.app import build_parser
    from pin_kpi_oed.validation.options import FOLDERS, OUTPUTS

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    missing = []
    for cmd, p in sub.choices.items():
        for a in p._actions:
            h = (a.help or "").lower()
            if a.nargs == 0 or not a.option_strings or a.choices:
                continue
            if h.startswith("write") or " write " in h or "output folder" in h:
                if a.dest not in OUTPUTS.get(cmd, []) + FOLDERS.get(cmd, []):
                    missing.append(f"{cmd} {a.option_strings[0]}")
    assert not missing, missing


def test_a_figure_is_written_in_the_format_its_name_says(inputs, tmp_path):
    """predict --figure t.pdf writes a PDF (not PNG bytes under a .pdf name); .svg an SVG."""
    for name, magic in (("t.pdf", b"%PDF"), ("t.svg", b"<?xml"), ("t.png", b"\x89PNG")):
        rc, _, err = _run("predict", "--model", inputs / "m.json", "--data", inputs / "te.csv", "--out",
                          tmp_path / "p.csv", "--figure", tmp_path / name, "--quiet")
        assert rc == 0, err
        assert (tmp_path / name).read_bytes()[:len(magic)] == magic


def test_a_criterion_that_is_not_finite_at_the_start_names_its_source():
    """'criterion kpi_gp is nan at the start design' names the discrepancy it was computed with (file and fields)."""
    from types import SimpleNamespace

    from pin_kpi_oed.design.ipopt import ipopt_start_value
    from pin_kpi_oed.errors import SolverError

    crit = SimpleNamespace(name="kpi_gp", is_ratio=True, value=lambda Q: float("nan"),
                           discrepancy=SimpleNamespace(source="--model m.json, fitted on 120 rows (exact)"))
    with pytest.raises(SolverError) as e:
        ipopt_start_value(crit, np.zeros((3, 6)))
    assert "kpi_gp is nan" in str(e.value) and "--model m.json" in str(e.value) and "scale_m" in str(e.value)
    plain = SimpleNamespace(name="kpi", is_ratio=True, value=lambda Q: 0.0)
    with pytest.raises(SolverError, match="cell's noise"):
        ipopt_start_value(plain, np.zeros((3, 6)))
