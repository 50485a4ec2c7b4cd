"""Studies: a study killed midway resumes on a local Dask cluster without losing work; Monte-Carlo with a prior."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from pin_kpi_oed.studies import study

from .cli_run import run_cli
from .conftest import REPO


def test_killed_study_resumes_on_a_local_dask_cluster_without_losing_work(tmp_path):
    """Two arms. A study process killed (SIGKILL) after its first arm: every task file present is complete JSON.
    The same command run again on a local Dask cluster (in this process: the resumption is the study's, not the
    process's) sends only the other arm to the cluster's worker process, gathers its record back in task order
    after the one on disk and leaves that file as it was; the worker starts without Dask's malloc trimming; the KPI
    design beats random poses; the summary, the arms' table and the figure are written; a rerun recomputes nothing
    and states the same result.

    The smallest study that still tests each claim: one arm finished before the kill (the work not to lose), one
    left to the cluster (what is resumed there). A second arm on the cluster would test nothing more: the one worker
    runs one task at a time, so its records come back in the order they were sent whatever the gathering does, and
    each arm costs a design (about 2 s CPU). One worker process: each worker started costs the interpreter's,
    Dask's and the package's imports again. Twelve measurements: more than the 9 that identify the arm's 27
    parameters, so that the random design the KPI design must beat is not one that barely identifies the arm (its
    gain is about 94 % at seed 0, 90 % at 20 measurements; the test asks for 20 %)."""
    from pin_kpi_oed.model.notional_arms import notional_arms

    args = ["study", "notional90", "--out", str(tmp_path), "--arms", "2", "--measurements", "12", "--workers", "1"]
    proc = subprocess.Popen([sys.executable, "-m", "pin_kpi_oed", *args], cwd=REPO, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, start_new_session=True)
    tasks = tmp_path / "tasks"
    deadline = time.time() + 240
    while time.time() < deadline and not (tasks.exists() and list(tasks.glob("*.json"))):
        time.sleep(0.05)  # each moment after the first arm's file is CPU the killed process spends on the second
    os.killpg(proc.pid, signal.SIGKILL)  # kill midway: the first arm is done, the second is not
    proc.wait()
    first = sorted(tasks.glob("*.json"))
    assert len(first) == 1, "the killed study left more or less than its first arm"
    before = {p.name: p.read_text() for p in first}
    for p in first:
        json.loads(p.read_text())  # every file present is complete JSON (atomic writes)

    trim_before = os.environ.get("MALLOC_TRIM_THRESHOLD_")
    rc, _, err = run_cli(*args, "--scheduler", "local-dask")
    assert rc == 0, err
    # the variables the worker's nanny set before starting it, it also wrote into this process's environment
    assert os.environ.get("MALLOC_TRIM_THRESHOLD_") == trim_before, "the worker started with Dask's malloc trimming"
    s = json.loads((tmp_path / "summary.json").read_text())
    assert s["tasks_computed_now"] == 1, "the resumed study recomputed the finished arm (or skipped the other)"
    for name, text in before.items():
        assert (tasks / name).read_text() == text, "the finished arm's record was rewritten"
    assert not list(tmp_path.rglob("*.tmp")), "a temporary file was left behind"
    assert s["arms"] == 2 and not s["failed_arms"], s["failed_arms"]
    assert s["all_collision_free"]
    assert s["mean_improvement_vs_heuristic"] > 0.2, "the KPI design does not beat random poses"
    for key in ("arms", "mean_improvement_vs_heuristic", "mean_improvement_vs_param", "all_collision_free",
                "wall_time_s"):
        assert key in s, f"summary.json has no {key}"
    assert (tmp_path / "notional90.png").stat().st_size > 1000
    rows = (tmp_path / "arms.csv").read_text().splitlines()
    assert [r.split(",")[0] for r in rows[1:]] == [g.name for g in notional_arms()[:2]], "records not in task order"
    again = study.notional_study(tmp_path, m=12, seed=0, arms=2, workers=1)
    assert again["tasks_computed_now"] == 0, "a rerun recomputed finished arms"
    assert again["mean_improvement_vs_heuristic"] == pytest.approx(s["mean_improvement_vs_heuristic"])


def test_monte_carlo_predicts_with_the_model_prior():
    """The predicted C_s of the Monte-Carlo validation includes the model's prior (MAP), as identification does."""
    import numpy as np

    from pin_kpi_oed.oed import identifiability as idf
    from pin_kpi_oed.studies.design_trials import monte_carlo

    from .conftest import make_model

    model = make_model("kr15")
    model.layout.set_prior(["joint_a2.*", "joint_a3.*"], 2e-6)
    rng = np.random.default_rng(4)
    Q, Qw = model.robot.random_q(rng, 12), model.robot.random_q(rng, 1)
    mc = monte_carlo(model, Q, Qw, n_rep=10, seed=0, show_progress=False)
    b = idf.analyse(model).base
    p0 = np.zeros(model.n_params)
    F = model.weighted_jacobian(p0, Q)[:, :, b].reshape(-1, b.size)
    E = model.kpi_jacobian(p0, Qw)[:, b]
    P = np.diag(model.layout.prior_sigma[b] ** -2.0)  # inf -> 0: no prior on the other parameters
    with_prior = E @ np.linalg.inv(F.T @ F + P) @ E.T
    without = E @ np.linalg.inv(F.T @ F) @ E.T
    assert np.trace(with_prior) < 0.9 * np.trace(without)  # the prior matters here ...
    assert np.abs(mc.predicted_cov_m2 - with_prior).max() < 1e-6 * np.abs(with_prior).max()  # ... and is used
    assert mc.nit == 10 and mc.time_s > 0 and mc.to_dict()["success"] == (mc.failures == 0)
