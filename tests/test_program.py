"""Measurement programs: move times, dense transition checks, ordering (OR-Tools), exports."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.cell.collision import CollisionModel, random_feasible
from pin_kpi_oed.cell.feasibility import FeasibilityChecker
from pin_kpi_oed.program.ordering import ProgramOptions, plan_program, solve_tour
from pin_kpi_oed.program.timing import joint_speeds, move_time, path_time, time_matrix
from pin_kpi_oed.program.transitions import TransitionChecker


@pytest.fixture(scope="module")
def kr15():
    return load_cell("kr15")


@pytest.fixture(scope="module")
def poses(kr15):
    """14 feasible (collision-free, visible) KR 15 poses, seeded."""
    Q, _ = random_feasible(CollisionModel(kr15), 14, np.random.default_rng(3), 200_000)
    return Q


def test_speeds_from_urdf_and_move_time(kr15):
    v = joint_speeds(kr15.robot)
    # urdf/kr15.urdf <limit velocity=...> in rad/s: 156, 156, 156, 335, 355, 647 deg/s
    np.testing.assert_allclose(np.degrees(v), [156, 156, 156, 335, 355, 647], rtol=1e-6)
    qa, qb = np.zeros(6), np.radians([78.0, 0, 0, 0, 0, 647.0])
    assert move_time(qa, qb, v) == pytest.approx(1.0)  # 647 deg at 647 deg/s beats 78 deg at 156 deg/s
    assert move_time(qa, np.radians([156.0, 0, 0, 0, 0, 0]), v * 0.5) == pytest.approx(2.0)
    T = time_matrix(np.vstack([qa, qb, -qb]), v)
    assert T[1, 2] == pytest.approx(2.0) and T[0, 1] == pytest.approx(1.0) and np.allclose(T, T.T)
    assert path_time(np.vstack([qa, qb, qa]), v) == pytest.approx(2.0)


def test_solve_tour_finds_the_optimum_of_a_small_instance():
    rng = np.random.default_rng(0)
    P = rng.random((8, 2))
    C = np.linalg.norm(P[:, None] - P[None], axis=2)
    tour = solve_tour(C, time_limit_s=1.0)
    assert sorted(tour) == list(range(8)) and tour[0] == 0

    def length(t):
        return sum(C[a, b] for a, b in zip(t, t[1:] + t[:1]))

    best = min(length([0, *p]) for p in itertools.permutations(range(1, 8)))
    assert length(tour) == pytest.approx(best, abs=8e-3)  # the solver sees costs rounded to 1e-3


def test_dense_samples_never_step_more_than_one_degree(kr15):
    tc = TransitionChecker(kr15)
    qa, qb = np.zeros(6), np.radians([100.0, -30.0, 20.0, 250.0, 0.0, -10.0])
    S = tc.samples(qa, qb)
    assert np.max(np.abs(np.diff(S, axis=0))) <= math.radians(1.0) + 1e-12
    np.testing.assert_allclose(S[0], qa) and np.testing.assert_allclose(S[-1], qb)
    assert len(S) == 251


def test_colliding_move_is_found_and_agrees_with_a_finer_independent_check(kr15, poses):
    tc = TransitionChecker(kr15)
    fc = FeasibilityChecker(kr15)
    found = None
    for a, b in itertools.combinations(range(len(poses)), 2):
        if not tc.check(poses[a], poses[b]).clear:
            found = (a, b)
            break
    assert found is not None, "14 random poses of the KR 15 cell always have a colliding straight move"
    qa, qb = poses[found[0]], poses[found[1]]
    fine = qa + np.linspace(0, 1, 2001)[:, None] * (qb - qa)
    d = fc.distances(fine)[:, :fc.n_pairs].min(axis=1)
    assert d.min() < 0  # the finer check sees the penetration too
    full = tc.check(qa, qb, stop_early=False)
    assert full.min_clearance_m == pytest.approx(d.min(), abs=0.02)


def test_program_orders_checks_and_repairs(kr15, poses):
    prog = plan_program(kr15, poses, ProgramOptions(margin_m=0.005, time_limit_s=0.5, via_pool=150))
    assert sorted(prog.order) == list(range(len(poses)))
    assert prog.success and prog.n_colliding == 0
    # independent re-check of every move at 0.25 deg steps, without the planner's checker
    fc = FeasibilityChecker(kr15)
    path = np.vstack([prog.path, prog.path[:1]])
    for a, b in zip(path[:-1], path[1:]):
        k = max(2, int(np.ceil(np.max(np.abs(b - a)) / np.radians(0.25))))
        S = a + np.linspace(0, 1, k + 1)[:, None] * (b - a)
        d = fc.distances(S)[:, :fc.n_pairs].min(axis=1)
        # the margin, or the end poses' own clearance when a pose is closer (1 deg sampling: 2 mm slack)
        assert d.min() >= min(0.005, d[0], d[-1]) - 2e-3
    v = joint_speeds(kr15.robot)
    assert prog.cycle_time_s == pytest.approx(path_time(path, v))
    assert prog.cycle_time_s < prog.as_designed_time_s
    assert prog.waypoints[0].kind == "home" and sum(w.kind == "measure" for w in prog.waypoints) == len(poses)
