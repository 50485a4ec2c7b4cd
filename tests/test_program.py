"""Measurement programs: move times, dense transition checks, ordering (OR-Tools), exports."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.cell.collision import CollisionModel
from pin_kpi_oed.cell.sampling import random_feasible
from pin_kpi_oed.cell.feasibility import FeasibilityChecker
from pin_kpi_oed.program.ordering import ProgramOptions, plan_program, solve_tour
from pin_kpi_oed.program.timing import joint_speeds, move_time, path_time, time_matrix
from pin_kpi_oed.program.transitions import TransitionChecker, equivalents


@pytest.fixture(scope="module")
def kr15():
    return load_cell("kr15")


@pytest.fixture(scope="module")
def poses(kr15):
    """14 feasible (collision-free, visible) KR 15 poses, seeded."""
    Q, _ = random_feasible(CollisionModel(kr15), 14, np.random.default_rng(3), 200_000)
    return Q


def _smallest_pair_distance(fc: FeasibilityChecker, S: np.ndarray) -> np.ndarray:
    """The smallest pair distance (m) at each configuration of S, read from every pair: the first ``n_pairs``
    columns of :meth:`FeasibilityChecker.distances` without its beam and incidence columns (a move need not keep
    the tracker's beam clear), at a quarter of their cost."""
    return np.array([fc.pair_distances(q).min() for q in S])


@pytest.fixture(scope="module")
def kr15_program(kr15, poses):
    """The KR 15 poses' program (5 mm margin, a via pool of 150), planned once for the tests that read it."""
    return plan_program(kr15, poses, ProgramOptions(margin_m=0.005, via_pool=150))


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
    d = _smallest_pair_distance(fc, fine)
    assert d.min() < 0  # the finer check sees the penetration too
    full = tc.check(qa, qb, stop_early=False)
    assert full.min_clearance_m == pytest.approx(d.min(), abs=0.02)


@pytest.mark.xdist_group("test_program_kr15_program")
def test_program_orders_checks_and_repairs(kr15, poses, kr15_program):
    prog = kr15_program
    assert sorted(prog.order) == list(range(len(poses)))
    assert prog.success and prog.n_colliding == 0
    # independent re-check of every move at 0.25 deg steps, without the planner's checker
    fc = FeasibilityChecker(kr15)
    path = prog.path
    assert np.array_equal(path[0], path[-1]) and prog.n_moves == len(path) - 1
    for a, b in zip(path[:-1], path[1:]):
        k = max(2, int(np.ceil(np.max(np.abs(b - a)) / np.radians(0.25))))
        S = a + np.linspace(0, 1, k + 1)[:, None] * (b - a)
        d = _smallest_pair_distance(fc, S)
        # the margin, or the end poses' own clearance when a pose is closer (1 deg sampling: 2 mm slack)
        assert d.min() >= min(0.005, d[0], d[-1]) - 2e-3
    v = joint_speeds(kr15.robot)
    assert prog.cycle_time_s == pytest.approx(path_time(path, v))
    assert prog.cycle_time_s < prog.as_designed_time_s
    assert prog.waypoints[0].kind == prog.waypoints[-1].kind == "home"
    assert sum(w.kind == "measure" for w in prog.waypoints) == len(poses)


@pytest.mark.xdist_group("test_program_kr15_program")
def test_program_does_not_depend_on_the_machines_speed(kr15, poses, kr15_program, monkeypatch):
    """The tour search stops by a solution count, not the clock: a machine ten times slower gives the same program."""
    from pin_kpi_oed.program import ordering

    first = kr15_program
    real_solve = ordering.solve_tour
    slow = {"calls": 0}

    def slow_solve(cost, time_limit_s, *a, **k):  # a ten times slower machine: a tenth of the time
        slow["calls"] += 1
        return real_solve(cost, time_limit_s / 10, *a, **k)

    monkeypatch.setattr(ordering, "solve_tour", slow_solve)
    again = plan_program(kr15, poses, ProgramOptions(margin_m=0.005, via_pool=150))
    assert slow["calls"] >= 2 and np.array_equal(first.path, again.path)
    assert [w.kind for w in first.waypoints] == [w.kind for w in again.waypoints]
    assert first.cycle_time_s == again.cycle_time_s


# ---------------------------------------------------------------------------- UR10: ±360° joints, OMPL route planning

#: two poses of the UR10 cell's KPI design (deg): the straight move collides (so does home -> B) and no
#: structured via pose clears it; B's equivalent with wrist 1 at -188° is reached straight from A
UR10_A = [110.567, -69.385, 89.576, -34.028, -59.137, -72.239]
UR10_B = [69.601, -41.018, -147.856, 172.004, -102.254, -46.746]
#: a UR10 design pose whose wrist 2 (-226.5°) sits in a pocket between its -270° bound and the forearm:
#: no route leaves it; its 2π-equivalent (133.5°) is in the free space's main part
UR10_POCKET = [76.06, -149.554, 11.564, -90.812, -226.516, -1.974]


@pytest.fixture(scope="module")
def ur10():
    return load_cell("ur10")


def test_equivalents_keep_the_measured_tcp_and_clearances(ur10):
    q = np.radians([-23.213, -154.715, -115.824, 269.739, 119.397, 39.421])
    E = equivalents(q, ur10.q_lower, ur10.q_upper, ur10.robot.is_revolute)
    np.testing.assert_array_equal(E[0], q)
    assert len(E) == 4  # wrist 1 (269.7 -> -90.3) and wrist 2 (119.4 -> -240.6); wrist 3 (39.4) has none
    k = (E - q) / (2 * np.pi)
    np.testing.assert_allclose(k, np.rint(k), atol=1e-12)
    assert np.all((E >= ur10.q_lower) & (E <= ur10.q_upper))
    fc = FeasibilityChecker(ur10)
    T0, d0 = ur10.robot.oMtool(q), fc.pair_distances(q)
    for e in E[1:]:
        T = ur10.robot.oMtool(e)
        tcp0, tcp = T0.act(np.array([0, 0, 0.15])), T.act(np.array([0, 0, 0.15]))
        assert np.max(np.abs(tcp - tcp0)) < 1e-9 and np.max(np.abs(T.rotation - T0.rotation)) < 1e-9
        np.testing.assert_allclose(fc.pair_distances(e), d0, atol=1e-9)
    kr = load_cell("kr15")  # KR 15: a4/a6 ±350°, no other joint has room for a full turn
    assert len(equivalents(np.zeros(6), kr.q_lower, kr.q_upper, kr.robot.is_revolute)) == 1


def test_smallest_pair_distance_is_the_smallest_of_every_pair(ur10, kr15):
    """The move checks read only Coal's smallest pair distance: the minimum of every pair, in a cell with a
    non-convex mesh (the UR10 table) and without, clear and colliding configurations alike."""
    for cell in (ur10, kr15):
        fc = FeasibilityChecker(cell)
        X = cell.robot.random_q(np.random.default_rng(5), 300)
        exact = np.array([fc.pair_distances(q).min() for q in X])
        fast = np.array([fc.min_pair_distance(q) for q in X])
        assert (exact < 0).any() and (exact > 0.01).any()
        np.testing.assert_allclose(fast, exact, rtol=0, atol=1e-12)  # Coal's warm starts: equal to ~1e-16 m
    assert FeasibilityChecker(ur10).mesh_pairs  # the mesh branch was taken


def test_move_bound_call_is_the_smallest_pair_bound_and_the_cap_changes_nothing_below_it(ur10):
    """The move check's bound of a configuration (the smallest over the segment rows, without the pair table) is the
    smallest of its pair bounds, bit for bit, in a cell with soft pairs (the UR10's enclosing capsules of its table
    mesh) and half-spaces; with a cap the closest points are computed only where the balls come closer than it: every
    pair bound is at most the uncapped one (still a bound), the same below the cap and, for a cap > 0, at least the
    cap above it (a cap ≤ 0, which a move colliding without early stop gives, keeps the per-row balls: a soft pair's
    ball distance there may be ≤ 0, no bound). The move checks' cap just above the threshold that decides
    (``ball_cap``) bounds every configuration the former wide cap (0.05 m above it) bounds below the threshold as that
    one, bit for bit, and every other at or above it: a check evaluates exactly the configurations below its
    threshold, in the order of their bounds, so the same ones in the same order (a cap that is not positive stays
    wide).
    """
    from pin_kpi_oed.program.transitions import BALL_CAP_WIDE_M, ball_cap

    bound = TransitionChecker(ur10, 0.01).bound
    assert bound is not None and bound.soft_rows.size and bound.hard_rows.size and bound.H_pair.size
    X = ur10.robot.random_q(np.random.default_rng(2), 120)
    full = bound.pairs(X)
    assert (full.min(axis=1) < 0.05).any() and (full.min(axis=1) > 0.05).any()
    for cap in (None, -0.02, 0.0, 0.02, 0.1):
        capped = bound.pairs(X, cap)
        assert np.array_equal(bound(X, cap), capped.min(axis=1) - 1e-9)
        if cap is not None:
            below = full < cap
            assert below.any() and np.array_equal(capped[below], full[below]) and np.all(capped <= full)
            assert cap <= 0 or np.all(capped[~below] >= cap)
    for threshold in (-0.1, 0.0, 0.01, 0.05):
        wide, narrow = bound(X, threshold + BALL_CAP_WIDE_M), bound(X, ball_cap(threshold))
        below = wide < threshold
        assert np.array_equal(narrow[below], wide[below]) and np.all(narrow[~below] >= threshold)
        assert below.any() and (~below).any()
    assert ball_cap(0.01) < 0.01 + 1e-5 and ball_cap(-0.1) == -0.1 + BALL_CAP_WIDE_M


def test_ur10_colliding_move_is_planned_by_ompl_and_passes_the_dense_check(ur10):
    tc = TransitionChecker(ur10, 0.01)
    qa, qb = np.radians(UR10_A), np.radians(UR10_B)
    assert tc.clearance(qa) >= 0.01 and tc.clearance(qb) >= 0.01
    straight = tc.check(qa, qb, stop_early=False)
    assert not straight.clear and straight.min_clearance_m < 0  # a true collision, not just inside the margin
    vias = tc.structured_vias(qa, qb, ur10.q_work[0])
    assert tc.repair(qa, qb, vias, np.ones(6)) is None
    route = tc.plan_route(qa, qb, seed=0, max_checks=60_000)
    assert route is not None and len(route) >= 1
    path = np.vstack([qa, *route, qb])
    assert np.all((path >= ur10.q_lower) & (path <= ur10.q_upper))
    # independent re-check with a fresh checker at 0.25 deg steps
    fine = TransitionChecker(ur10, 0.01, step_rad=np.radians(0.25))
    check = fine.path_check(path)
    assert check.clear and check.min_clearance_m >= 0.01 - 1e-9


def test_ur10_route_is_the_same_in_one_process_or_two(ur10, tmp_path):
    """OMPL is seeded per call: the same move gives the same route after other plans and in a fresh process.

    The fresh process reads this process's cell (pickled: the same cell, without fitting the UR10's mesh capsules a
    second time, a second of CPU): what it checks is OMPL's state in a new interpreter, not the cell's reading. The
    plan before the second call is another move, found (OMPL drew its random numbers)."""
    import pickle
    import subprocess
    import sys

    qa, qb = np.radians(UR10_A), np.radians(UR10_B)
    first = TransitionChecker(ur10, 0.01).plan_route(qa, qb, seed=3, max_checks=60_000)
    assert first is not None and len(first) >= 1
    other = TransitionChecker(ur10, 0.01)
    before = other.plan_route(qb, qa, seed=7, max_checks=60_000)  # something else planned before
    assert before is not None and len(before) >= 1
    again = other.plan_route(qa, qb, seed=3, max_checks=60_000)
    assert len(again) == len(first) and all(np.array_equal(x, y) for x, y in zip(first, again))
    cell_file = tmp_path / "ur10.pickle"
    cell_file.write_bytes(pickle.dumps(ur10))
    code = ("import pickle, sys; import numpy as np; from pin_kpi_oed.program.transitions import TransitionChecker; "
            "cell = pickle.loads(open(sys.argv[1], 'rb').read()); "
            f"r = TransitionChecker(cell, 0.01).plan_route(np.radians({UR10_A}), np.radians({UR10_B}), "
            "seed=3, max_checks=60_000); print(np.array(r).tobytes().hex())")
    out = subprocess.run([sys.executable, "-c", code, str(cell_file)], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == np.array(first).tobytes().hex()
    other_seed = TransitionChecker(ur10, 0.01).plan_route(qa, qb, seed=4, max_checks=60_000)
    assert other_seed is not None and not (len(other_seed) == len(first)
                                           and all(np.array_equal(x, y) for x, y in zip(first, other_seed)))


def test_ur10_program_takes_the_pocket_poses_equivalent_and_exports_the_vias(ur10):
    """Equivalents avoid the pocket; with the listed values only, colliding moves get via points (exported)."""
    Q = np.radians([UR10_POCKET, UR10_A, UR10_B])
    prog = plan_program(ur10, Q, ProgramOptions(margin_m=0.01, time_limit_s=0.3, via_pool=100))
    assert prog.success and prog.n_colliding == 0 and sorted(prog.order) == [0, 1, 2]
    meas = {w.pose: w.q for w in prog.waypoints if w.kind == "measure"}
    assert meas[0][4] == pytest.approx(Q[0, 4] + 2 * np.pi)  # the pocket's wrist 2 taken a full turn round
    assert prog.n_turned >= 1 and "2pi-equivalent" in prog.summary()
    for i, q in meas.items():
        assert np.max(np.abs(ur10.robot.oMtool(q).translation - ur10.robot.oMtool(Q[i]).translation)) < 1e-9
    fine = TransitionChecker(ur10, 0.01, step_rad=np.radians(0.5))
    assert fine.path_check(prog.path).clear
    # the listed values only: A -> B and home -> B collide, the program goes through via points ...
    listed = plan_program(ur10, Q[1:], ProgramOptions(margin_m=0.01, time_limit_s=0.3, via_pool=100, equivalents=False))
    assert listed.success and fine.path_check(listed.path).clear
    assert listed.n_repaired >= 1 and any(w.kind == "via" for w in listed.waypoints)
    # ... and the exported program holds them
    info = ProgramInfo(cell=ur10.name, design="t", robot="ur10", joint_names=list(ur10.robot.joint_names),
                       revolute=np.ones(6, bool), cycle_time_s=listed.cycle_time_s)
    texts = write_program("urscript", listed.path, [w.kind for w in listed.waypoints],
                          [w.pose for w in listed.waypoints], info)
    back, measured = parse_program("urscript", texts, np.ones(6, bool))
    np.testing.assert_allclose(back, listed.path, atol=1e-6)
    assert sorted(measured) == [0, 1]
    # without the equivalents the pocket pose has no safe move at all
    stuck = plan_program(ur10, Q[:1], ProgramOptions(margin_m=0.01, time_limit_s=0.3, via_pool=100,
                                                     equivalents=False, plan_checks=1000))
    assert not stuck.success and stuck.n_colliding >= 1


#: a UR10 design pose (rad) with wrist 2 at -234.8°, folded against its bound: its 2π-equivalents with wrist 2
#: there lie in a pocket of the free space, those with wrist 2 at 125.2° reach home through a few via poses
UR10_FOLDED = [-0.48369823, -0.44938347, 2.45057794, -2.2208667, -4.09830123, -3.53655392]


def test_ur10_route_from_several_starts_leaves_from_a_free_equivalent(ur10):
    """One RRT-Connect problem from every 2π-equivalent of a pose: the route leaves from one outside the pocket
    and passes a finer independent check; from the pocket's equivalents alone no route is found."""
    reps = equivalents(np.array(UR10_FOLDED), ur10.q_lower, ur10.q_upper, ur10.robot.is_revolute)
    home = ur10.q_work[0]
    tc = TransitionChecker(ur10, 0.01)
    found = tc.plan_route_from(reps, home, seed=0, max_checks=3000)
    assert found is not None
    k, route = found
    assert reps[k][4] > 0 and len(route) >= 1  # wrist 2 at 125.2°: out of the pocket
    fine = TransitionChecker(ur10, 0.01, step_rad=np.radians(0.25))
    assert fine.path_check(np.vstack([reps[k], *route, home])).clear
    pocket = reps[reps[:, 4] < -np.pi]
    assert len(pocket) == 4 and tc.plan_route_from(pocket, home, seed=0, max_checks=3000) is None


def test_ur10_pose_whose_equivalents_all_miss_their_budget_is_rescued(ur10):
    """Each equivalent's own route home fails within its small budget (a sixteenth; no via pool): one problem from
    all of them with the full budget gives one equivalent its route home and its moves back; the others stay
    penalised."""
    from pin_kpi_oed.program.router import PENALTY_S, Router

    reps = equivalents(np.array(UR10_FOLDED), ur10.q_lower, ur10.q_upper, ur10.robot.is_revolute)
    nodes = np.vstack([ur10.q_work[0], reps])
    v = joint_speeds(ur10.robot)
    tc = TransitionChecker(ur10, 0.01)
    router = Router(nodes, [list(range(1, len(nodes)))], tc, v, time_matrix(nodes, v), seed=0, plan_checks=1600,
                    via_pool=1)
    assert not any(router.reach_home(i) for i in range(1, len(nodes)))  # every call failed on its own budget ...
    rescued = [i for i in range(1, len(nodes)) if router.home_route[i] is not None]
    assert len(rescued) == 1  # ... and the last one's failure started the rescue
    j = rescued[0]
    assert nodes[j][4] > 0 and router.cost[j, 0] == pytest.approx(move_time(nodes[j], nodes[0], v))
    assert all(router.cost[i, 0] == PENALTY_S for i in range(1, len(nodes)) if i != j)
    fine = TransitionChecker(ur10, 0.01, step_rad=np.radians(0.25))
    assert fine.path_check(np.vstack([nodes[j], *router.home_route[j], nodes[0]])).clear


#: ten poses of a UR10 KPI design (rad), UR10_FOLDED second: with a route-home budget of 100 checks per
#: equivalent, a via pool of 20 and three rounds, the program once ended with two colliding moves (the round
#: limit left the tour on an equivalent of the folded pose without a route home), at every 1e-9 rad change
UR10_TEN = [
    [-1.16457098, -0.00690381, 0.87020137, -4.03202327, -1.83410043, -4.51519816],
    UR10_FOLDED,
    [1.75663254, -1.51920194, 0.92908398, -0.04470306, -1.58238909, 1.52716684],
    [1.30814339, -1.28797202, -2.77451641, -1.95126074, 4.70789329, -1.58135575],
    [0.56317894, -0.72424407, 1.27269797, -0.74452413, 4.21350826, 4.15678191],
    [0.82416927, -0.52601222, 1.27246493, -0.80175219, -1.83286105, -1.94486025],
    [-1.26577243, -1.03924212, 1.53031901, 2.91317656, 4.70612781, 1.54715300],
    [-0.54818871, -0.84847114, 1.57574651, -0.86698734, 2.32504328, 2.28772818],
    [0.55982624, -0.17228357, 0.37931206, -2.84655843, 2.02405288, -1.76608686],
    [-0.67422932, -3.13779339, 1.69393026, 4.71066755, -1.79697397, 2.03713730],
]


@pytest.mark.parametrize("seed", [0, 1])
def test_ur10_program_stays_clear_when_the_design_moves_by_1e9_rad(ur10, seed):
    """A design changed by 1e-9 rad (what a rounding change in the kinematics does to an IPOPT design) still gets
    a program with every move clear in an independent check at 0.5°, on a tight planning budget."""
    Q = np.array(UR10_TEN) + np.random.default_rng(seed).uniform(-1e-9, 1e-9, (10, 6))
    prog = plan_program(ur10, Q, ProgramOptions(margin_m=0.01, plan_checks=1600, via_pool=20, max_rounds=3))
    assert prog.success and prog.n_colliding == 0 and sorted(prog.order) == list(range(10))
    fine = TransitionChecker(ur10, 0.01, step_rad=np.radians(0.5))
    path = prog.path
    assert all(fine.check(a, b, stop_early=False).clear for a, b in zip(path[:-1], path[1:]))
    meas = np.array([w.q for w in prog.waypoints if w.kind == "measure"])  # equivalents near home only
    assert np.all(np.abs(meas - ur10.q_work[0]) <= 1.5 * np.pi)


# ---------------------------------------------------------------------------- exports
from pin_kpi_oed.cli.app import main  # noqa: E402
from pin_kpi_oed.model.robot import load_robot  # noqa: E402
from pin_kpi_oed.program.export import FORMATS, ProgramInfo, parse_program, write_program  # noqa: E402


def _info(robot) -> ProgramInfo:
    return ProgramInfo(cell="test_cell", design="d.json (kpi)", robot=robot.name, joint_names=list(robot.joint_names),
                       revolute=np.asarray(robot.is_revolute, bool), cycle_time_s=12.5, date="2026-01-01T00:00:00Z")


@pytest.mark.parametrize("robot_name", ["kr15", "kr15_track"])
@pytest.mark.parametrize("fmt", FORMATS)
def test_every_format_round_trips_to_1e6_rad(robot_name, fmt):
    rb = load_robot(robot_name)
    rng = np.random.default_rng(7)
    Q = rb.random_q(rng, 9)
    kinds = ["home", "measure", "measure", "via", "measure", "measure", "via", "measure", "home"]
    poses = [-1, 4, 0, -1, 2, 3, -1, 1, -1]
    if fmt == "urscript" and robot_name == "kr15_track":
        with pytest.raises(Exception, match="6 revolute joints and no prismatic"):
            write_program(fmt, Q, kinds, poses, _info(rb))
        return
    texts = write_program(fmt, Q, kinds, poses, _info(rb))
    head = next(iter(texts.values()))
    for word in ("cell: test_cell", "design: d.json (kpi)", "units:", "date: 2026-01-01"):
        assert word in head
    back, measured = parse_program(fmt, texts, rb.is_revolute)
    assert back.shape == Q.shape
    np.testing.assert_allclose(back, Q, atol=1e-6, rtol=0)
    assert measured == [4, 0, 2, 3, 1]


@pytest.fixture(scope="module")
def small_design(tmp_path_factory):
    path = tmp_path_factory.mktemp("prog") / "d.json"
    assert main(["design", "--cell", "kr15", "--criteria", "random", "--measurements", "12", "--seed", "2",
                 "--quiet", "--json", str(path)]) == 0
    return path


def test_export_cli_writes_a_checked_program(small_design, tmp_path):
    out = tmp_path / "prog.src"
    js = tmp_path / "prog.json"
    assert main(["export", str(small_design), "--format", "krl", "--out", str(out), "--json", str(js),
                 "--quiet"]) == 0
    texts = {".src": out.read_text(), ".dat": out.with_suffix(".dat").read_text()}
    assert "DEF prog( )" in texts[".src"] and "DEFDAT prog PUBLIC" in texts[".dat"]
    import json

    doc = json.loads(js.read_text())
    Q, measured = parse_program("krl", texts, np.ones(6, bool))
    assert sorted(measured) == list(range(12)) and doc["n_colliding"] == 0
    np.testing.assert_allclose(Q, [w["q"] for w in doc["waypoints"]], atol=1e-6)


def test_export_html_that_fails_writes_no_program_and_the_page_holds_every_measurement_point(small_design, tmp_path,
                                                                                             capsys, monkeypatch):
    """The animation page is built before any file is written: when it fails (one line, exit 2), neither the program
    nor the JSON is left behind; when it succeeds both files are written, and the page's animation holds every
    measurement point: 12 increasing times, the last after the program's motion at the page's joint steps and frame
    rate. The page fails in its first step (the scene), so the failing run draws nothing; the animation is the one
    the successful run wrote (its inputs and times read as it was called)."""
    import pin_kpi_oed.viz.program_animation as anim
    import pin_kpi_oed.viz.scene as scene_module
    from pin_kpi_oed.errors import InputError

    def broken(*_a, **_k):
        raise InputError("the scene cannot be drawn")

    monkeypatch.setattr(scene_module, "build_scene", broken)
    out, page, js = tmp_path / "prog.script", tmp_path / "prog.html", tmp_path / "prog.json"
    assert main(["export", str(small_design), "--format", "urscript", "--out", str(out), "--html", str(page),
                 "--json", str(js), "--quiet"]) == 2
    assert "the scene cannot be drawn" in capsys.readouterr().err
    assert not out.exists() and not page.exists() and not js.exists()
    monkeypatch.undo()
    real, calls = anim.animate_program, []

    def recorded(scene, path, kinds, **kw):
        times = real(scene, path, kinds, **kw)
        calls.append((np.array(path), list(kinds), kw, times))
        return times

    monkeypatch.setattr(anim, "animate_program", recorded)
    assert main(["export", str(small_design), "--format", "urscript", "--out", str(out), "--html", str(page),
                 "--quiet"]) == 0
    assert out.read_text().startswith("# pin-kpi-oed") and "<html" in page.read_text()[:2000].lower()
    assert page.stat().st_size > 100_000
    [(path, kinds, kw, times)] = calls
    assert kw == {} and kinds.count("measure") == 12  # the page's defaults: 3 deg steps, 24 frames/s, hold 6
    assert len(times) == 12 and np.all(np.diff(times) > 0)
    # frames: hold 6 per pose + one per 3 deg of the largest joint move, so the last pose comes after
    # (sum over moves of ceil(max |dq| / 3 deg)) / fps seconds of motion
    moves = sum(max(1, math.ceil(np.max(np.abs(b - a)) / math.radians(3.0))) for a, b in zip(path[:-1], path[1:]))
    assert times[-1] < (moves + 6 * 12) / 24 and times[-1] > moves / 24 * 0.5


def test_export_shows_progress_on_a_terminal_only(small_design, tmp_path, capsys, monkeypatch):
    """Ordering and move checks take a minute on the UR10: a bar on stderr when forced / on a terminal, none in
    pipes."""
    monkeypatch.setenv("PIN_KPI_OED_PROGRESS", "1")
    assert main(["export", str(small_design), "--format", "csv", "--out", str(tmp_path / "a.csv"), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "program: order + check moves" in err and "checks=" in err
    monkeypatch.setenv("PIN_KPI_OED_PROGRESS", "0")
    assert main(["export", str(small_design), "--format", "csv", "--out", str(tmp_path / "b.csv"), "--quiet"]) == 0
    assert "program: order" not in capsys.readouterr().err
    assert (tmp_path / "a.csv").read_text().splitlines()[-3:] == (tmp_path / "b.csv").read_text().splitlines()[-3:]


def test_export_cli_bad_input_exit_2_nothing_written(small_design, tmp_path, capsys):
    out = tmp_path / "p.txt"
    assert main(["export", str(small_design), "--format", "fanuc", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "unknown format 'fanuc'" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()
    assert main(["export", str(small_design), "--format", "csv", "--out", str(tmp_path / "nodir" / "p.csv")]) == 2
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------- margins
from pin_kpi_oed.design.margins import with_margins  # noqa: E402
from pin_kpi_oed.errors import InputError  # noqa: E402


def test_with_margins_tightens_only_the_optimisers_cell(kr15):
    c = with_margins(kr15, 0.02, 1.5)
    assert c.clearance_m == pytest.approx(kr15.clearance_m + 0.02) and c.incidence_max_deg == pytest.approx(28.5)
    assert kr15.incidence_max_deg == 30.0 and with_margins(kr15, 0.0, 0.0) is kr15
    with pytest.raises(InputError, match="incidence_margin_deg"):
        with_margins(kr15, 0.0, 30.0)
    with pytest.raises(InputError, match="clearance_margin_m"):
        with_margins(kr15, -0.01, 0.0)


def test_design_margins_hold_in_the_true_check(tmp_path):
    import json

    path = tmp_path / "m.json"
    assert main(["design", "--cell", "kr15", "--criteria", "kpi", "--measurements", "12", "--starts", "1",
                 "--max-iter", "80", "--start", "random", "--clearance-margin", "0.03", "--incidence-margin", "2",
                 "--quiet", "--json", str(path)]) == 0  # IPOPT from the heuristic design: no 1,000-pose pool
    doc = json.loads(path.read_text())
    assert doc["clearance_margin_m"] == 0.03 and doc["incidence_margin_deg"] == 2.0
    assert doc["cell"]["clearance_m"] == 0.0 and doc["cell"]["incidence_max_deg"] == 30.0  # the true cell
    for d in doc["designs"]:
        Q = np.array(d["q_meas"])
        rep = FeasibilityChecker(load_cell("kr15")).check(Q)  # independent, untightened
        np.testing.assert_allclose(d["pose_clearance_m"], rep.clearance_m, atol=1e-9)
        assert rep.clearance_m.min() >= 0.03 - 1e-4 and rep.incidence_deg.max() <= 28.0 + 1e-3
        assert d["min_clearance_m"] == pytest.approx(rep.min_clearance_m)


# ---------------------------------------------------------------------------- user pool, sequential design
def _write_poses(path, names, Q):
    path.write_text(",".join(names) + "\n" + "\n".join(",".join(f"{x:.12f}" for x in q) for q in Q) + "\n")


def test_design_from_a_user_pool(kr15, tmp_path):
    import json

    rng = np.random.default_rng(4)
    Qf, _ = random_feasible(CollisionModel(kr15), 300, rng, 200_000)
    Qc = np.vstack([Qf, kr15.robot.random_q(rng, 100)])  # plus 100 unchecked ones (mostly infeasible)
    csv = tmp_path / "poses.csv"
    _write_poses(csv, kr15.robot.joint_names, Qc)
    out = tmp_path / "d.json"
    assert main(["design", "--cell", "kr15", "--pool", str(csv), "--criteria", "random,kpi", "--measurements", "15",
                 "--clearance-margin", "0", "--incidence-margin", "0", "--quiet", "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    rnd, kpi = doc["designs"]
    for d in doc["designs"]:
        Q = np.array(d["q_meas"])
        dist = np.min(np.abs(Q[:, None, :] - Qc[None]).max(axis=2), axis=1)
        assert dist.max() < 1e-9  # every selected pose is one of the user's
        assert FeasibilityChecker(kr15).check(Q).all_feasible
    assert kpi["trace_cs_m2"] < rnd["trace_cs_m2"]
    assert 0.5 < kpi["efficiency"] <= 1.0 + 1e-9  # certificate over the user's feasible candidates


def test_pool_and_given_bad_input_exit_2(kr15, tmp_path, capsys):
    csv = tmp_path / "bad.csv"
    _write_poses(csv, ["a1", "a2", "a3", "a4", "a5", "a6"], np.zeros((3, 6)))
    out = tmp_path / "d.json"
    for flag in ("--pool", "--given"):
        assert main(["design", "--cell", "kr15", flag, str(csv), "--quiet", "--json", str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and flag in err[0] and "bad.csv" in err[0]
    assert main(["design", "--cell", "kr15", "--target-sigma", "1e-6", "--quiet"]) == 2
    assert "--target-sigma needs --given" in capsys.readouterr().err
    assert not out.exists()


def test_sequential_design_beats_random_and_answers_how_many_more(kr15, tmp_path):
    """20 poses designed on top of 40 measured ones: tr C_s recomputed from scratch, below 60 random poses', and
    "how many more" until 0.8 times the 40 poses' σ, verified with one pose fewer. 40 IPOPT iterations and 500
    random feasible candidates for "how many more" keep every claim (the pool start is already far below random;
    the target needs a handful of poses)."""
    import json

    from pin_kpi_oed.design.optimize import DesignProblem
    from pin_kpi_oed.oed.objective import DesignCriterion

    base = DesignProblem(kr15)
    Q60, _ = base.random_design(60, seed=11)
    given = tmp_path / "measured.csv"
    _write_poses(given, kr15.robot.joint_names, Q60[:40])
    out = tmp_path / "seq.json"
    crit = DesignCriterion(base.model, base.base, "kpi", base.E)
    sigma40 = float(np.sqrt(crit.value(Q60[:40])))
    target = 0.8 * sigma40
    assert main(["design", "--cell", "kr15", "--given", str(given), "--criteria", "kpi", "--measurements", "20",
                 "--starts", "1", "--max-iter", "40", "--clearance-margin", "0", "--incidence-margin", "0",
                 "--target-sigma", str(target), "--pool-size", "500", "--quiet", "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    kpi = doc["designs"][-1]
    Qnew = np.array(kpi["q_meas"])
    # the 20 new poses on top of the 40 measured ones beat 60 random poses (tr C_s from scratch)
    assert crit.value(np.vstack([Q60[:40], Qnew])) == pytest.approx(kpi["trace_cs_m2"], rel=1e-9)
    assert kpi["trace_cs_m2"] < crit.value(Q60)
    assert np.trace(np.array(kpi["cov_s_m2"])) == pytest.approx(kpi["trace_cs_m2"], rel=1e-6)
    # "how many more": adding that many reaches the target, one fewer does not (t = 1 working configuration)
    u = doc["poses_until"]
    k = u["n_more"]
    Qa = np.array(u["q_added"])
    assert k == len(Qa) >= 1 and u["success"]
    assert np.sqrt(crit.value(np.vstack([Q60[:40], Qa]))) <= target * (1 + 1e-9)
    assert np.sqrt(crit.value(np.vstack([Q60[:40], Qa[:-1]]))) > target
    assert FeasibilityChecker(kr15).check(Qa).all_feasible


# ---------------------------------------------------------------------------- cells from meshes
from pin_kpi_oed.cell.meshes import mesh_vertices, capsule_of, fit_capsule, geometry_model  # noqa: E402
from pin_kpi_oed.cell.segments import point_segment_distance  # noqa: E402


def test_fit_capsule_encloses_and_is_tight_on_a_cylinder():
    rng = np.random.default_rng(1)
    phi, z = rng.random(4000) * 2 * np.pi, rng.random(4000)
    P = np.c_[0.1 * np.cos(phi), 0.1 * np.sin(phi), z]              # a cylinder surface r = 0.1, z in [0, 1]
    R = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    P = P @ R.T + [0.3, -0.2, 0.5]
    a, b, r = fit_capsule(P)
    assert np.all(point_segment_distance(P, a[None], b[None]) <= r + 1e-12)
    # within 4 %: the principal axis of 4,000 samples tilts by a few mrad
    assert r == pytest.approx(0.1, rel=0.04) and np.linalg.norm(b - a) == pytest.approx(1.0, abs=0.02)
    ab = (b - a) / np.linalg.norm(b - a)
    assert abs(ab @ R[:, 2]) == pytest.approx(1.0, abs=1e-3)


def test_ur10_capsules_enclose_its_collision_meshes():
    rb = load_robot("ur10")
    gm = geometry_model(rb)
    assert len(gm.geometryObjects) >= 7
    for go in gm.geometryObjects:
        a, b, r = capsule_of(rb, go)
        M = rb.model.frames[go.parentFrame].placement.inverse() * go.placement
        V = mesh_vertices(go) @ M.rotation.T + M.translation
        assert np.all(point_segment_distance(V, a[None], b[None]) <= r + 1e-9), go.name
    cell = load_cell("ur10")  # shipped, robot_capsules: urdf on mesh geometry
    assert len(cell.robot_capsules) == len(gm.geometryObjects)
    rep = FeasibilityChecker(cell).check(cell.q_work)
    assert rep.collision_free.all()


def test_design_header_states_the_cell_as_given(tmp_path, capsys):
    """The header's cell line is the cell file's (incidence limit 30 deg), the margins line the tightening the
    optimiser designed with: one incidence limit per meaning, not the tightened one under the cell's name."""
    assert main(["design", "--cell", "kr15", "--criteria", "random", "--measurements", "10", "--incidence-margin",
                 "2", "--json", str(tmp_path / "d.json")]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("cell kr15_fms") and "incidence <= 30 deg" in out[0]
    assert any(s.startswith("margins:") and "incidence 2 deg" in s and "incidence limit 30 deg" in s for s in out)
