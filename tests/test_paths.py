"""Working paths (cell file -> IK on one branch) and the path / 6-D KPI criteria: exact gradients, values against
the per-sample definition, pool selection, and the refusals of paths that cannot be followed."""

from __future__ import annotations

import copy
import json

import numpy as np
import pinocchio as pin
import pytest
import yaml

from pin_kpi_oed.cell.cell import CELL_DIR, cell_from_dict, load_cell, parse_cell_text
from pin_kpi_oed.design.optimize import DesignProblem
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.oed.covariance import information
from pin_kpi_oed.oed.criteria import get_criterion

from .cli_run import run_cli_as_process


@pytest.fixture(scope="module")
def seam_cell():
    return load_cell("kr15_seam")


@pytest.fixture(scope="module")
def seam_problem(seam_cell):
    return DesignProblem(seam_cell, collision=False)


def _seam_dict():
    """The shipped seam cell as a fresh dict (the package's parse, libyaml's: the same values as PyYAML's own,
    ``tests/test_collision.py``)."""
    path = CELL_DIR / "kr15_seam.yaml"
    return parse_cell_text(path.read_text(), path)


def _fk(cell, q):
    data = cell.robot.model.createData()
    pin.framesForwardKinematics(cell.robot.model, data, q)
    M = cell.W_T_base * data.oMf[cell.robot.tool_frame_id]
    return M.act(cell.tcp_m), M.rotation


def test_seam_is_followed_on_one_branch(seam_cell):
    p = seam_cell.paths[0]
    assert p.Q.shape == (161, 6)
    assert np.abs(np.diff(p.Q, axis=0)).max() < 0.05  # 5 mm steps: no joint jumps
    R_t = pin.rpy.rpyToMatrix(0.0, np.radians(150.0), 0.0)
    for i in (0, 57, 160):
        x, R = _fk(seam_cell, p.Q[i])
        assert np.allclose(x, [0.9, -0.4 + 0.8 * i / 160, 1.2], atol=1e-6)
        assert np.linalg.norm(pin.log3(R.T @ R_t)) < 1e-6
    assert p.s_m[-1] == pytest.approx(0.8, abs=1e-6)
    # the point KPI of a cell with paths only: the path's end points
    assert np.allclose(seam_cell.q_work, p.Q[[0, -1]])


def test_arc_path_samples_lie_on_the_circle():
    d = _seam_dict()
    d["working_paths"] = [{"name": "arc", "samples": 40, "seed_deg": [0, -90, 135, 0, 20, 0],
                           "arc": {"start": {"xyz_m": [0.9, -0.3, 1.2]}, "via_m": [0.8, 0.0, 1.2],
                                   "end": {"xyz_m": [0.9, 0.3, 1.2]}}}]
    c = cell_from_dict(d, "arc", CELL_DIR)
    X = c.paths[0].xyz_W
    # circumcentre of the three points on z = 1.2: (x_c, 0) with (0.9 - x_c)^2 + 0.09 = (0.8 - x_c)^2
    xc = (0.8 ** 2 - 0.9 ** 2 - 0.09) / (2 * (0.8 - 0.9))
    r = np.hypot(X[:, 0] - xc, X[:, 1])
    assert np.allclose(r, r[0], atol=1e-6) and np.allclose(X[:, 2], 1.2, atol=1e-6)
    assert X[:, 0].min() == pytest.approx(0.8, abs=2e-3)  # passes the via point


def test_program_path_keeps_its_joint_values(tmp_path, seam_cell):
    Q = seam_cell.paths[0].Q[::40]
    names = seam_cell.robot.joint_names
    rows = [",".join(names)] + [",".join(f"{v:.12g}" for v in q) for q in Q]
    (tmp_path / "prog.csv").write_text("\n".join(rows) + "\n")
    d = _seam_dict()
    d["working_paths"] = [{"name": "prog", "program": "prog.csv", "samples": 17}]
    c = cell_from_dict(d, "prog", tmp_path)
    assert c.paths[0].Q.shape == (17, 6)
    assert np.allclose(c.paths[0].Q[0], Q[0]) and np.allclose(c.paths[0].Q[-1], Q[-1])
    assert np.allclose(c.paths[0].xyz_W[:, 2], 1.2, atol=2e-3)


@pytest.mark.parametrize("change, words", [
    (lambda e: e["waypoints"][1].update(xyz_m=[0.9, 0.4, 3.0]), ["sample", "not reached", "reach"]),
    (lambda e: e["waypoints"][1].update(xyz_m=[1.3, 0.4, 0.9]), ["sample", "car_", "clear"]),
    (lambda e: e.update(max_joint_step_rad=0.001), ["sample 1", "branch change", "step_m"]),
    (lambda e: e.update(step_m=5.0e-6), ["samples", "mm"]),
])
def test_a_path_that_cannot_be_followed_is_refused_naming_the_sample(change, words):
    d = _seam_dict()
    change(d["working_paths"][0])
    with pytest.raises(InputError) as exc:
        cell_from_dict(d, "bad", CELL_DIR)
    msg = str(exc.value)
    assert "\n" not in msg and "working_paths[0] 'seam'" in msg
    for w in words:
        assert w in msg, msg


def test_orientation_length_in_mm_is_refused():
    d = _seam_dict()
    d["orientation_length_m"] = 200
    with pytest.raises(InputError, match="orientation_length_m.*mm"):
        cell_from_dict(d, "bad", CELL_DIR)


def test_rotation_sensitivity_matches_finite_differences(seam_problem):
    model, Q = seam_problem.model, seam_problem.cell.q_path[::40]
    J = model.kpi_rotation_jacobian(np.zeros(model.n_params), Q).reshape(len(Q), 3, -1)

    def orientation(p):
        kin = model.kinematics(p, Q, model.tcp_m)
        return np.einsum("ab,mbc->mac", model.sensor_pose(p).rotation, kin.R_tool)

    R0, h = orientation(np.zeros(model.n_params)), 1e-7
    rng = np.random.default_rng(0)
    for k in rng.choice(model.n_params, 12, replace=False):
        e = np.zeros(model.n_params)
        e[k] = h
        R1 = orientation(e)
        fd = np.array([pin.log3(R1[i] @ R0[i].T) for i in range(len(Q))]) / h
        assert np.allclose(fd, J[:, :, k], atol=1e-6), k


@pytest.mark.parametrize("name", ["kpi_path", "kpi_path_max", "kpi6"])
def test_gradient_matches_finite_differences(seam_problem, name):
    obj = seam_problem.criterion(name)
    Q = seam_problem.cell.robot.random_q(np.random.default_rng(1), 20)
    val, G = obj.value_and_grad(Q)
    assert val == pytest.approx(obj.value(Q), rel=1e-12)
    h = 1e-6
    for i, j in [(0, 0), (3, 1), (7, 2), (11, 4), (19, 5)]:
        Qp, Qm = Q.copy(), Q.copy()
        Qp[i, j] += h
        Qm[i, j] -= h
        fd = (obj.value(Qp) - obj.value(Qm)) / (2 * h)
        assert fd == pytest.approx(G[i, j], rel=1e-4, abs=1e-8 * abs(val)), (i, j)


def _per_sample(problem, Q, Qs, rot=False):
    F = problem.model.weighted_jacobian(problem.p0, Q)[:, :, problem.base].reshape(-1, problem.base.size)
    C = np.linalg.inv(information(F, problem.kpi_criterion.prior))
    jac = problem.model.kpi_rotation_jacobian if rot else problem.model.kpi_jacobian
    E = jac(problem.p0, Qs)[:, problem.base].reshape(len(Qs), 3, -1)
    return np.einsum("sap,pq,saq->s", E, C, E)


def test_values_are_the_per_sample_definitions(seam_problem):
    Q = seam_problem.cell.robot.random_q(np.random.default_rng(2), 30)
    cs = _per_sample(seam_problem, Q, seam_problem.cell.q_path)
    assert seam_problem.criterion("kpi_path").value(Q) == pytest.approx(cs.mean(), rel=1e-9)
    qw = seam_problem.q_work
    L = seam_problem.cell.orientation_length_m
    six = _per_sample(seam_problem, Q, qw) + L ** 2 * _per_sample(seam_problem, Q, qw, rot=True)
    assert seam_problem.criterion("kpi6").value(Q) == pytest.approx(six.mean(), rel=1e-9)


def test_pool_selection_beats_random_on_its_own_criterion(seam_problem):
    rng = np.random.default_rng(3)
    pool = seam_problem.cell.robot.random_q(rng, 300)
    obj = seam_problem.criterion("kpi_path")
    sel = obj.select(pool, 20, seed=0)
    assert sel.success and len(sel.indices) == 20
    rand = [obj.value(pool[rng.choice(300, 20, replace=False)]) for _ in range(10)]
    assert sel.value < min(rand)
    assert sel.value == pytest.approx(obj.value(pool[sel.indices]), rel=1e-8)


def test_kpi_path_needs_a_cell_with_paths():
    prob = DesignProblem(load_cell("kr15"), collision=False)
    with pytest.raises(InputError, match="working_paths"):
        prob.criterion("kpi_path")
    copy.copy(prob)  # the problem stays usable


def test_profile_rms_is_the_path_kpi_and_worst_bounds_it(seam_problem):
    from pin_kpi_oed.design.path_profile import path_profile

    Q = seam_problem.cell.robot.random_q(np.random.default_rng(4), 25)
    prof = path_profile(seam_problem, Q, seam_problem.cell.q_path, 0.2)
    assert prof["rms_sigma_pos_m"] ** 2 == pytest.approx(seam_problem.criterion("kpi_path").value(Q), rel=1e-9)
    pos, rot = np.array(prof["sigma_pos_m"]), np.array(prof["sigma_rot_rad"])
    assert prof["worst_sigma_pos_m"] == pos.max() >= prof["rms_sigma_pos_m"] >= pos.min() > 0
    assert np.allclose(prof["sigma_at_length_m"], np.sqrt(pos ** 2 + 0.04 * rot ** 2))


def test_cli_refuses_a_path_through_the_car_in_one_line(tmp_path):
    d = _seam_dict()
    d["working_paths"][0]["waypoints"][1]["xyz_m"] = [1.3, 0.4, 0.9]
    (tmp_path / "bad.yaml").write_text(yaml.safe_dump(d))
    res = run_cli_as_process("design", "--cell", str(tmp_path / "bad.yaml"), "--criteria", "kpi_path")
    lines = [ln for ln in res.stderr.strip().splitlines() if ln.strip()]
    assert res.returncode == 2 and len(lines) == 1 and "Traceback" not in res.stderr, res.stderr
    assert "working_paths[0] 'seam': sample" in lines[0] and "clear" in lines[0]


def test_kpi_path_takes_the_measured_poses_into_account(seam_cell):
    rng = np.random.default_rng(6)
    Q_given, Q = seam_cell.robot.random_q(rng, 20), seam_cell.robot.random_q(rng, 5)
    seq = DesignProblem(seam_cell, Q_given=Q_given, collision=False)
    both = np.vstack([Q_given, Q])
    plain = DesignProblem(seam_cell, collision=False).criterion("kpi_path")
    assert seq.criterion("kpi_path").value(Q) == pytest.approx(plain.value(both), rel=1e-9)


def test_viewer_draws_the_working_path(tmp_path, seam_cell):
    from pin_kpi_oed.design.design_file import load_design
    from pin_kpi_oed.design.runner import DesignSettings, design_run
    from pin_kpi_oed.design.design_writer import write_design
    from pin_kpi_oed.viz.scene import SceneOptions, build_scene

    run = design_run(seam_cell, DesignSettings(criteria=("random",), measurements=12, seed=0))
    path = tmp_path / "seam.json"
    write_design(path, run)
    doc = json.loads(path.read_text())
    prof = doc["path_profiles"][0]["paths"][0]
    assert doc["path_profiles"][0]["criterion"] == "random" and len(prof["sigma_pos_m"]) == 161
    sc = build_scene(load_design(path), SceneOptions(animate=False))
    obj = sc.recorder.object_dict("/meshcat/working/paths/seam/line")["object"]
    X = np.frombuffer(obj["geometries"][0]["data"]["attributes"]["position"]["array"].data, np.float32).reshape(-1, 3)
    assert np.allclose(X, seam_cell.paths[0].xyz_W, atol=1e-6)


def test_kpi_path_gp_is_the_kriging_kpi_over_the_path_samples(seam_problem):
    problem = seam_problem.replaced(hedge=False)
    obj = problem.criterion("kpi_path_gp")
    Q = problem.cell.robot.random_q(np.random.default_rng(7), 15)
    at_path = problem.gp_criterion(Q_work=problem.cell.q_path)
    assert obj.value(Q) == pytest.approx(at_path.value(Q), rel=1e-12)
    assert obj.value(Q) != pytest.approx(problem.gp_criterion().value(Q), rel=1e-3)  # not the end points
    assert get_criterion("kpi_path_gp").uses_discrepancy and not get_criterion("kpi_path").uses_discrepancy


def test_orientation_sigma_matches_monte_carlo(seam_problem):
    """The tool orientation's predicted σ along the seam against 40 simulated identifications (random true geometric
    errors within the tolerances, the cell's noise): realised / predicted mean square within sampling error. The
    fits skip the discrepancy term (``discrepancy="none"``): it is fitted after the parameters and leaves them, the
    only thing read here, unchanged, at half the fit's cost."""
    from pin_kpi_oed.design.path_profile import path_profile
    from pin_kpi_oed.identification.identify import identify
    from pin_kpi_oed.simulation.simulator import random_truth, simulate

    model, cell = seam_problem.model, seam_problem.cell
    Q = cell.robot.random_q(np.random.default_rng(8), 30)
    Qs = cell.q_path[::20]
    prof = path_profile(seam_problem, Q, Qs, 0.2)
    predicted = float(np.mean(np.square(prof["sigma_rot_rad"])))

    def orientation(mdl, p):
        kin = mdl.kinematics(p, Qs, mdl.tcp_m)
        return np.einsum("ab,mbc->mac", mdl.sensor_pose(p).rotation, kin.R_tool)

    errs = []
    for k in range(40):
        p_true = random_truth(model, seed=100 + k, only=seam_problem.base)
        res = identify(model, simulate(model, Q, p_true, seed=200 + k, record_sigma=False), ident=seam_problem.ident,
                       raise_on_failure=False, discrepancy="none")
        R_hat, R_true = orientation(res.model, res.p), orientation(model, p_true)
        errs.append([np.sum(pin.log3(R_hat[i] @ R_true[i].T) ** 2) for i in range(len(Qs))])
    ratio = float(np.mean(errs)) / predicted
    print(f"orientation sigma: realised / predicted mean square {ratio:.3f}")
    assert 0.6 < ratio < 1.5, ratio


def test_compensated_seam_program_stays_continuous(seam_problem):
    """A joint-space program along the seam compensated on a calibrated model: every row ok, the compensated steps
    between consecutive samples follow the program's (no branch change), within 1 mrad per joint."""
    from pin_kpi_oed.data.measurements import MeasurementSet
    from pin_kpi_oed.data.targets import TargetSet
    from pin_kpi_oed.compensation.compensator import compensate_program
    from pin_kpi_oed.identification.identify import identify
    from pin_kpi_oed.simulation.simulator import random_truth, simulate

    model, cell = seam_problem.model, seam_problem.cell
    Q = cell.robot.random_q(np.random.default_rng(9), 40)
    p_true = random_truth(model, seed=3, only=seam_problem.base)
    cm = identify(model, simulate(model, Q, p_true, seed=4, record_sigma=False), ident=seam_problem.ident,
                  raise_on_failure=False).calibrated_model()
    Qp = cell.paths[0].Q
    names = list(cell.robot.joint_names)
    aux = MeasurementSet(names, Qp, np.full((len(Qp), 3), np.nan))
    prog = TargetSet([str(i) for i in range(len(Qp))], None, None, Qp, names, aux, "seam")
    res = compensate_program(cm, prog)
    # reached, none extrapolated; the TCP 0.1 m from the reflector rests on the flange's axial offset no reflector sees
    assert set(res.target_status) <= {"ok", "tcp_unmeasured"}, set(res.target_status)
    assert np.abs(res.q - Qp).max() > 1e-6  # the calibration changes the joints
    jump = np.abs(np.diff(res.q, axis=0) - np.diff(Qp, axis=0)).max()
    print(f"compensation: largest joint change {np.abs(res.q - Qp).max():.2e} rad, "
          f"largest change of a step {jump:.2e} rad")
    assert jump < 1e-3


def test_kpi6_is_not_scored_without_the_cells_length(seam_problem):
    from pin_kpi_oed.oed.criteria import evaluate_all
    from pin_kpi_oed.oed.objective import DesignContext

    ctx = DesignContext(seam_problem.model, seam_problem.base, seam_problem.E, seam_problem.p0, seam_problem.q_work)
    Q = seam_problem.cell.robot.random_q(np.random.default_rng(10), 20)
    scores = evaluate_all(seam_problem.model, seam_problem.base, Q, seam_problem.E, ctx)
    assert "kpi" in scores and "kpi6" not in scores and "kpi_path" not in scores
    with pytest.raises(InputError, match="orientation_length_m"):
        get_criterion("kpi6").objective(ctx)
