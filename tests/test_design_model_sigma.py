"""design --model states the model's σ at the TCP at the working configurations as predict --at tcp gives it (one
function, calibrated.tcp_sigma.tcp_sigma): widened outside the joint-space coverage and flagged there."""

from __future__ import annotations

import csv
import json

import numpy as np

from tests.cli_run import run_cli, without_times
from pin_kpi_oed import NoiseModel, TrackerModel, load_cell
from pin_kpi_oed.identification.identify import identify
from pin_kpi_oed.simulation.simulator import simulate


def test_design_with_a_model_reports_predicts_sigma_at_the_working_configurations(tmp_path):
    """A UR10 calibrated on 40 poses near its first working configuration: design --model --json holds each working
    configuration's 3-D σ at the cell's TCP equal to predict --at tcp's on the same configurations to 1e-9
    (relative) with the same flags, and
    at least one configuration outside the coverage with a σ above the covered one's; the Python API's run with the
    model's inputs writes the same design file."""
    cell = load_cell("ur10")
    robot = cell.robot
    model = TrackerModel(robot, tracker_T_base=cell.tracker_T_base, reflector_m=np.array([0.0, 0.0, 0.1]),
                         noise=NoiseModel(sigma_xyz_m=(1e-5,) * 3))
    rng = np.random.default_rng(0)
    Q = np.clip(cell.q_work[0] + rng.uniform(-0.3, 0.3, (40, robot.nq)), robot.q_lower, robot.q_upper)
    truth = np.zeros(model.n_params)
    truth[:6 * robot.nq] = rng.normal(0, 2e-4, 6 * robot.nq)
    cm = identify(model, simulate(model, Q, truth, seed=1)).calibrated_model()
    f = tmp_path / "m.json"
    cm.save(f)
    rc, out, err = run_cli("design", "--cell", "ur10", "--model", f, "--criteria", "random,kpi_gp", "--measurements",
                           20, "--starts", 1, "--max-iter", 5, "--json", tmp_path / "d.json", "--quiet")
    assert rc == 0, err
    got = json.loads((tmp_path / "d.json").read_text())["discrepancy"]["model_sigma_at_work"]
    w = tmp_path / "w.csv"
    with open(w, "w", newline="") as fh:
        wr = csv.writer(fh)
        wr.writerow(list(robot.joint_names))
        wr.writerows([[repr(float(v)) for v in q] for q in cell.q_work])
    rc, _, err = run_cli("predict", "--model", f, "--data", w, "--out", tmp_path / "p.csv", "--quiet", "--at", "tcp",
                         "--tcp", ",".join(repr(float(v)) for v in cell.tcp_m))
    assert rc == 0, err
    rows = list(csv.DictReader(open(tmp_path / "p.csv")))
    sig = np.array([float(r["sigma_tcp"]) for r in rows])
    flags = [bool(float(r["extrapolation"])) for r in rows]
    assert np.allclose(got["sigma_m"], sig, rtol=1e-9, atol=0)
    assert got["extrapolated"] == flags and any(flags) and not flags[0]
    assert max(s for s, x in zip(sig, flags) if x) > sig[0]
    assert "predicted sigma now at the TCP at the working configurations" in out and "(outside the coverage)" in out
    # the same run through the Python API (the model's inputs, then design_run) writes the same file, times apart
    from pin_kpi_oed.design.design_writer import write_design
    from pin_kpi_oed.design.runner import DesignSettings, design_run
    from pin_kpi_oed.identification.design_discrepancy import model_design_inputs
    from pin_kpi_oed.calibrated.model_file import load_model_file

    loaded = load_model_file(f)
    inputs = model_design_inputs(loaded, cell, str(f))
    settings = DesignSettings(criteria=("random", "kpi_gp"), measurements=20, n_starts=1, max_iter=5,
                              clearance_margin_m=0.02, incidence_margin_deg=1.0, model=loaded, model_file=str(f),
                              discrepancy=inputs.discrepancy, model_sigma_at_work=inputs.model_sigma)
    write_design(tmp_path / "api.json", design_run(cell, settings))
    cli, api = (json.loads((tmp_path / n).read_text()) for n in ("d.json", "api.json"))
    assert "extended_model" in cli and cli["discrepancy"]["model_sigma_at_work"]["sigma_m"] == got["sigma_m"]
    assert without_times(cli) == without_times(api)
