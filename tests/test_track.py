"""The KR 15 on a linear track (urdf/kr15_track.urdf): a prismatic axis loaded, identified and designed for."""

from __future__ import annotations

import json

import numpy as np
import pinocchio as pin
import pytest

from pin_kpi_oed.cell.cell import cell_from_dict
from pin_kpi_oed.design.optimize import DesignOptions, DesignProblem, ipopt_options, run_designs
from pin_kpi_oed.errors import InputError, RobotLoadError
from pin_kpi_oed.identification.identify import identify, validate
from pin_kpi_oed.simulation.simulator import Tolerances, default_tracker_pose, random_truth, simulate
from pin_kpi_oed.model import kuka
from pin_kpi_oed.model.noise import NoiseModel
from pin_kpi_oed.model.robot import load_robot
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.oed.identifiability import analyse

from .test_cli_core import run


@pytest.fixture(scope="module")
def track():
    return load_robot("kr15_track")


def test_loads_with_a_prismatic_axis_in_metres(track):
    assert track.joint_names == ["joint_e1"] + [f"joint_a{i}" for i in range(1, 7)]
    assert list(track.is_revolute) == [False] + [True] * 6
    assert track.joint_units[0] == "m"
    assert (track.q_lower[0], track.q_upper[0]) == (0.0, 6.4)  # metres, not the ±2π fallback
    assert track.model.velocityLimit[0] == 2.0  # m/s
    kr15 = load_robot("kr15")
    np.testing.assert_array_equal(track.q_lower[1:], kr15.q_lower)
    j = track.summary()["joints"][0]
    assert j == {"name": "joint_e1", "type": "prismatic", "unit": "m", "lower_m": 0.0, "upper_m": 6.4}
    # the travel counts in the reach (unit guards, median-error limit of the identification)
    assert abs(track.reach() - (kr15.reach() + 6.4)) < 1e-12


def test_track_moves_the_kr15_along_the_rail(track):
    kr15 = load_robot("kr15")
    rng = np.random.default_rng(0)
    for s, q in zip(rng.uniform(0.0, 6.4, 5), kr15.random_q(rng, 5)):
        expected = pin.SE3(np.eye(3), np.array([0.0, s, 0.7])) * kr15.oMtool(q)
        got = track.oMtool(np.concatenate([[s], q]))
        assert np.abs(got.homogeneous - expected.homogeneous).max() < 1e-12


def test_units_checked_per_joint_type(track):
    Q = np.concatenate([[6.4], np.zeros(6)])
    track.check_units(Q, "m.csv")  # 6.4 m is a track value, not degrees
    track.check_q(Q, "m.csv")
    with pytest.raises(InputError, match=r"m.csv: joint joint_e1 of measurement 1 is 6400.*looks like mm; convert to"):
        track.check_units(np.concatenate([[6400.0], np.zeros(6)]), "m.csv", first_row=1)
    with pytest.raises(InputError, match=r"joint joint_a2 .* looks like degrees; convert to rad"):
        track.check_units(np.array([1.0, 0.0, 90.0, 0, 0, 0, 0]), "m.csv")
    with pytest.raises(InputError, match=r"joint_e1 = 6.5 m is outside its limits \[0, 6.4\] m"):
        track.check_q(np.concatenate([[6.5], np.zeros(6)]), "q")


@pytest.mark.parametrize("limits", ['lower="0" upper="1e9"', 'lower="0" upper="0"'])
def test_prismatic_joint_without_usable_limits_is_refused(tmp_path, limits):
    """No ±2π "rad" fallback for a prismatic joint: unbounded or empty travel is an error (urdfdom itself
    refuses a prismatic joint without <limit>)."""
    text = kuka.urdf_text(kuka.KR15, kuka.KR15_TRACK).replace('lower="0" upper="6.4"', limits)
    path = tmp_path / "badlimit.urdf"
    path.write_text(text)
    with pytest.raises(RobotLoadError, match="prismatic joint 'joint_e1' needs finite limits in m"):
        load_robot(path)


def test_info_prints_the_track_in_metres():
    res = run("info", "kr15_track")
    assert res.returncode == 0, res.stderr
    line = next(ln for ln in res.stdout.splitlines() if ln.startswith("joint_e1"))
    assert line.split() == ["joint_e1", "prismatic", "0.000", "6.400", "m"]
    assert any(ln.split()[-1] == "deg" for ln in res.stdout.splitlines() if ln.startswith("joint_a1"))
    out = json.loads(run("info", "kr15_track", "--json").stdout)
    assert out["robot"]["joints"][0]["upper_m"] == 6.4
    assert out["identifiability"]["rank"] == 29


def test_identifiability_of_the_track():
    """Rank 27 of the arm + 2: the arm's tilt about the two axes across the rail becomes visible; the
    rail's own placement and the arm's shift / turn about the rail direction are the tracker's."""
    m = TrackerModel(load_robot("kr15_track"), reflector_m=[0.05, 0.02, 0.08])
    ident = analyse(m)
    assert ident.n_raw == 51 and ident.rank == 29
    dropped = {d["name"] for d in ident.dropped}
    assert {f"joint_e1.{s}" for s in ("tx", "ty", "tz", "rx", "ry", "rz")} <= dropped
    assert {"joint_a1.tx", "joint_a1.ty", "joint_a1.tz", "joint_a1.ry"} <= dropped  # y = rail direction
    assert "joint_a1.rx" in ident.base_names and "joint_a1.rz" in ident.base_names


def test_simulate_and_identify_on_the_track():
    rb = load_robot("kr15_track")
    m = TrackerModel(rb, tracker_T_base=default_tracker_pose(rb, distance_m=4.0), reflector_m=[0.05, 0.02, 0.08],
                     noise=NoiseModel(sigma_xyz_m=(1e-5,) * 3))
    ident = analyse(m)
    truth = random_truth(m, Tolerances(), seed=1, only=ident.base)
    rng = np.random.default_rng(2)
    Q = rb.random_q(rng, 80)
    assert np.ptp(Q[:, 0]) > 5.0  # the measurements use the track (m)
    res = identify(m, simulate(m, Q, truth, seed=3))
    assert res.converged
    # the robot's identifiable parameters are recovered within their standard deviations
    base = ident.base
    robot_cols = [k for k, i in enumerate(base) if not m.layout.is_setup()[i]]
    z = (res.p - truth)[base][robot_cols] / res.std[:base.size][robot_cols]
    assert np.abs(z).max() < 4.5
    assert np.abs(res.tracker_T_base[:3, 3] - m.tracker_pose(truth).translation).max() < 1e-4
    # held-out, noise-free positions predicted to the noise level (nominal model: millimetres off)
    Qt = rb.random_q(rng, 30)
    test = simulate(m, Qt, truth, seed=4, noise=NoiseModel(sigma_xyz_m=(1e-12,) * 3))
    assert validate(res, test)["median_m"] < 1e-5
    nominal = np.linalg.norm(m.predict(np.zeros(m.n_params), Qt) - test.position_m, axis=1)
    assert np.median(nominal) > 1e-3


def _track_cell() -> dict:
    """A small cell: the track along y at the floor, a wall behind, the tracker 3 m in front of the rail's middle."""
    return {
        "name": "kr15_track_test", "robot": "kr15_track",
        "base": {"xyz_m": [0.0, 0.0, 0.0], "rpy_deg": [0.0, 0.0, 0.0]},
        "tracker": {"xyz_m": [3.0, 3.2, 1.4], "rpy_deg": [0.0, 0.0, 180.0]},
        "reflector_m": [0.06, 0.0, 0.12], "tcp_m": [0.0, 0.0, 0.2],
        "noise": {"sigma_xyz_m": [1e-6, 1e-6, 1e-6]},
        "robot_capsules": "urdf",
        "obstacles": {"half_spaces": [{"name": "floor", "normal": [0, 0, 1], "offset_m": -0.01},
                                      {"name": "wall", "normal": [1, 0, 0], "offset_m": -0.6}]},
        "skip_pairs": [["link_2", "link_4"], ["link_4", "link_6"]],
        "incidence_max_deg": 30.0,
        # the track value in m, the arm's in rad (KR 15 cell's working pose, 3.2 m along the rail)
        "working_configurations_rad": [[3.2] + np.radians([0.0, -70.652, 65.653, 0.0, 94.999, 0.0]).tolist()],
        "measurements": 20,
    }


def test_short_design_on_the_track():
    cell = cell_from_dict(_track_cell())
    problem = DesignProblem(cell)
    assert problem.base.size == 29
    res = run_designs(cell, ["random", "kpi"], m=20, seed=0, problem=problem,
                      options=DesignOptions(start="pool", pool_size=200, ipopt=ipopt_options(max_iter=40)))
    rnd, kpi = res
    assert kpi.feasible and rnd.feasible  # independent dense check (Pinocchio FK + Coal)
    assert kpi.trace_cs_m2 < 0.5 * rnd.trace_cs_m2
    q = kpi.q_meas
    assert np.all((q[:, 0] >= -1e-9) & (q[:, 0] <= 6.4 + 1e-9)) and np.ptp(q[:, 0]) > 1.0
