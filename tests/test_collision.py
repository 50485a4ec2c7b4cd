"""Cells and collision constraints: loader, exact gradients (FD, in penetration too), Coal agreement,
the independent dense check, pruning, aggregation, and named errors for bad cells."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest
import yaml

from pin_kpi_oed.cell.cell import CELL_DIR, cell_from_dict, load_cell, parse_cell_text
from pin_kpi_oed.cell.aggregate import AggregatedConstraints
from pin_kpi_oed.cell.collision import INCID, CollisionModel
from pin_kpi_oed.cell.sampling import random_feasible
from pin_kpi_oed.cell.segments import point_segment_distance, segment_closest
from pin_kpi_oed.cell.feasibility import FeasibilityChecker, coal_capsule
from pin_kpi_oed.errors import InfeasibleError, InputError, PinKpiOedError


def _cell_dict(name: str = "kr15") -> dict:
    """A shipped cell file as a fresh dict (the package's parse: libyaml's, which parses every shipped cell file as
    PyYAML's own does, ``test_cell_files_parse_alike_with_libyaml_and_pyyaml``; a text parsed before is copied)."""
    path = CELL_DIR / f"{name}.yaml"
    return parse_cell_text(path.read_text(), path)


@pytest.fixture(scope="module")
def kr15():
    return load_cell("kr15")


@pytest.fixture(scope="module")
def coll15(kr15):
    return CollisionModel(kr15)


@pytest.fixture(scope="module")
def coll15_all(kr15):
    return CollisionModel(kr15, prune=False)


def _mixed_configs(coll: CollisionModel, n: int, seed: int) -> np.ndarray:
    """Random configurations, at least half of them with a penetrating capsule pair (d < 0, segments apart)."""
    rng = np.random.default_rng(seed)
    Q = coll.robot.random_q(rng, 4000)
    g = coll.evaluate(Q, with_grad=False)
    pair_rows = np.flatnonzero(coll.info.kind == 0)
    pen = np.flatnonzero((g[:, pair_rows] < -0.01).any(axis=1))
    free = np.flatnonzero(~(g[:, pair_rows] < 0).any(axis=1))
    assert pen.size >= n // 2 and free.size >= n - n // 2
    return np.vstack([Q[pen[: n // 2]], Q[free[: n - n // 2]]])


# ---------------------------------------------------------------------------------------------- kernels
def test_segment_closest_matches_brute_force_and_coal():
    import coal

    rng = np.random.default_rng(1)
    A1, B1, A2, B2 = (rng.normal(size=(200, 3)) for _ in range(4))
    B2[:20] = A2[:20] + 0.7 * (B1[:20] - A1[:20])  # parallel segments
    B1[20:30] = A1[20:30]  # degenerate (point) segments
    s, t, w1, w2 = segment_closest(A1, B1, A2, B2)
    d = np.linalg.norm(w2 - w1, axis=1)
    u = np.linspace(0, 1, 4001)
    P1 = A1[:, None] + u[None, :, None] * (B1 - A1)[:, None]  # points along segment 1, exact distance to 2
    brute = point_segment_distance(P1, A2[:, None], B2[:, None]).min(axis=1)
    assert np.all(d <= brute + 1e-12) and np.all(brute - d < 1e-5)
    assert np.all((s >= 0) & (s <= 1) & (t >= 0) & (t <= 1))
    req = coal.DistanceRequest()
    for i in range(30, 60):  # signed capsule distance, also in penetration
        r1, r2 = 0.3, 0.4
        c1, T1 = coal_capsule(A1[i], B1[i], r1)
        c2, T2 = coal_capsule(A2[i], B2[i], r2)
        res = coal.DistanceResult()
        assert coal.distance(c1, T1, c2, T2, req, res) == pytest.approx(d[i] - r1 - r2, abs=1e-9)


# ---------------------------------------------------------------------------------------------- cells
def test_shipped_cells_load_and_serialise():
    for name in ("kr15", "kr300", "kr500"):
        cell = load_cell(name)
        d = cell.to_dict()
        json.dumps(d)  # plain numbers only
        assert d["robot"]["tool_frame"] == "tool0" and len(d["robot_capsules"]) == 7
        assert {h["name"] for h in d["obstacles"]["half_spaces"]} == {"wall", "floor"}
        assert any(o["name"] == "car_body" for o in d["obstacles"]["capsules"])
        assert cell.q_work.shape == (1, 6) and cell.incidence_max_deg == 30.0
        T = np.array(d["tracker_T_base"])
        assert np.allclose(T[:3, :3].T @ T[:3, :3], np.eye(3))
        # reflector off the A6 axis (TCP estimable)
        assert np.hypot(cell.reflector_m[0], cell.reflector_m[1]) > 0.03


def test_capsules_from_urdf_are_the_collision_cylinders(kr15):
    caps = {c.name: c for c in kr15.robot_capsules}
    assert caps["link_2"].radius == pytest.approx(0.13)
    assert np.allclose(caps["link_2"].a, [0, 0, 0]) and np.allclose(caps["link_2"].b, [0.65, 0, 0])
    assert np.linalg.norm(caps["link_1"].b - caps["link_1"].a) == pytest.approx(np.hypot(0.3, 0.675))


def test_cell_from_path_with_relative_urdf(tmp_path):
    d = _cell_dict()
    d["robot"] = "../../../urdf/kr15.urdf"
    sub = tmp_path / "a" / "b" / "c"
    sub.mkdir(parents=True)
    (tmp_path / "urdf").mkdir()
    (tmp_path / "urdf" / "kr15.urdf").write_text((CELL_DIR.parents[2] / "urdf" / "kr15.urdf").read_text())
    path = sub / "cell.yaml"
    path.write_text(yaml.safe_dump(d))
    cell = load_cell(path)
    assert cell.robot.urdf_path.endswith("kr15.urdf") and cell.robot.nq == 6


# ---------------------------------------------------------------------------------------------- gradients
def _fd_check(coll, Q, h=1e-6):
    g, G = coll.evaluate(Q)
    for k in range(Q.shape[1]):
        Qp, Qm = Q.copy(), Q.copy()
        Qp[:, k] += h
        Qm[:, k] -= h
        fd = (coll.evaluate(Qp, with_grad=False) - coll.evaluate(Qm, with_grad=False)) / (2 * h)
        err = np.abs(fd - G[:, :, k])
        assert err.max() < 2e-6, (k, np.unravel_index(err.argmax(), err.shape), err.max())
    return g


@pytest.mark.parametrize("name", ["kr15", "kr300"])
def test_every_constraint_gradient_matches_finite_differences(name):
    cell = load_cell(name)
    coll = CollisionModel(cell, prune=False)
    Q = _mixed_configs(coll, 16, seed=3)
    g = _fd_check(coll, Q)
    assert (g[:, coll.info.kind == 0] < -0.01).any()  # penetration rows were checked
    names = coll.info.names
    assert any(n.startswith("beam|") for n in names) and any("@" in n for n in names) and "incidence" in names


def test_sparsity_pattern_is_exact(coll15_all):
    """Entries outside a row's declared joints are zero: each row depends on one configuration's joints."""
    Q = coll15_all.robot.random_q(np.random.default_rng(5), 20)
    _, G = coll15_all.evaluate(Q)
    mask = np.zeros((coll15_all.n_rows, coll15_all.n), bool)
    mask[coll15_all.jac_rows, coll15_all.jac_cols] = True
    assert np.abs(G[:, ~mask]).max() < 1e-12


def test_coal_backend_agrees_with_closed_form(coll15_all):
    Q = _mixed_configs(coll15_all, 6, seed=7)
    g1, G1 = coll15_all.evaluate(Q)
    g2, G2 = coll15_all.evaluate(Q, backend="coal")
    assert np.abs(g1 - g2).max() < 1e-9
    assert np.abs(G1 - G2).max() < 1e-7


def test_aggregated_constraints(coll15):
    Q = _mixed_configs(coll15, 10, seed=11)
    ks = AggregatedConstraints(coll15, "ks", 2e-3)
    g = coll15.evaluate(Q, with_grad=False)
    dist = coll15.info.kind != INCID
    c = ks.evaluate(Q, with_grad=False)
    dmin = g[:, dist].min(axis=1)
    assert np.all(c[:, 0] <= dmin + 1e-15) and np.all(c[:, 0] >= dmin - 2e-3 * np.log(dist.sum()) - 1e-15)
    assert np.allclose(c[:, 1], g[:, ~dist][:, 0])
    _fd_check(ks, Q)
    mn = AggregatedConstraints(coll15, "min")
    assert np.allclose(mn.evaluate(Q, with_grad=False)[:, 0], dmin)
    with pytest.raises(InputError):
        AggregatedConstraints(coll15, "softmax")


def test_pruned_rows_never_active(kr15, coll15, coll15_all):
    pruned = [i for i, n in enumerate(coll15_all.info.names) if n not in set(coll15.info.names)]
    assert pruned, "the KR 15 cell has rows that can never be active"
    Q = kr15.robot.random_q(np.random.default_rng(2), 20000)
    g = coll15_all.evaluate(Q, with_grad=False)
    assert g[:, pruned].min() > 0


def test_prune_bounds_beyond_joint_1_are_the_per_capsule_per_obstacle_sweep():
    """In the UR10 cell (twenty obstacles), each capsule beyond joint 1 is bounded by the joint-2 origin's distance
    to each obstacle over the sweep of joint 1, less the obstacle's radius, the capsule's reach R_k and the chord
    error, computed capsule by capsule and obstacle by obstacle: the same numbers bit for bit."""
    coll = CollisionModel(load_cell("ur10"))
    b = coll._prune_bounds()["obst"]
    lo, hi = coll.robot.q_lower[0], coll.robot.q_upper[0]
    q1 = np.append(np.arange(lo, hi, np.radians(0.25)), hi)
    Q = np.zeros((q1.size, coll.n))
    Q[:, 0] = q1
    fr = coll.fk.frames(Q)
    o2 = fr.t[:, 1] + fr.R[:, 1] @ coll.fk.placements[1].translation
    err = np.linalg.norm(np.cross(o2[0] - fr.t[0, 1], fr.R[0, 1] @ coll.fk.ang[0])) * np.radians(0.25) / 2
    nr, far = coll.n_robot, [a for a in range(coll.n_robot) if coll.seg_joint[a] >= 2]
    assert len(far) >= 4 and b.shape[1] >= 10
    for a in far:
        Rk = sum(np.linalg.norm(coll.fk.placements[j].translation) for j in range(2, coll.seg_joint[a]))
        Rk += max(np.linalg.norm(coll.A_loc[a]), np.linalg.norm(coll.B_loc[a])) + coll.radius[a]
        want = [(point_segment_distance(o2, coll.A_loc[nr + o], coll.B_loc[nr + o]) - coll.radius[nr + o] - Rk
                 - err).min() for o in range(b.shape[1])]
        assert np.array_equal(b[a], want)


# ---------------------------------------------------------------------------------------------- independent check
def test_independent_check_agrees_with_coal_and_fast_path(kr15, coll15_all):
    Q = _mixed_configs(coll15_all, 20, seed=13)
    rep = FeasibilityChecker(kr15).check(Q)
    g = coll15_all.evaluate(Q, with_grad=False)
    dist = coll15_all.info.kind != INCID
    fast_min = g[:, dist].min(axis=1)
    # the checker also covers the fixed base capsule (constant, >= 40 mm here): same minimum otherwise
    both = fast_min < 0.03
    assert both.sum() >= 10
    assert np.allclose(rep.clearance_m[both], fast_min[both], atol=1e-8)
    inc = np.degrees(np.arccos(np.clip(g[:, ~dist][:, 0] + coll15_all.cos_max, -1, 1)))
    assert np.allclose(rep.incidence_deg, inc, atol=1e-8)
    ok_fast = coll15_all.feasible(Q)
    assert np.array_equal(rep.feasible, ok_fast)
    assert 0 < rep.share_colliding < 1 and not rep.all_feasible
    assert rep.violations() and json.dumps(rep.to_dict())


def test_every_checked_distance_agrees_with_the_constraint_rows(kr15, coll15_all):
    """Pair by pair (not only the minimum): the checker's Coal distances equal the optimiser's closed-form
    rows (a half-space row per capsule end point: the capsule's distance is the smaller one)."""
    Q = _mixed_configs(coll15_all, 6, seed=17)
    chk = FeasibilityChecker(kr15)
    D = chk.distances(Q)
    g = coll15_all.evaluate(Q, with_grad=False) + kr15.clearance_m
    rows: dict[str, list[int]] = {}
    for r, name in enumerate(coll15_all.info.names):
        key = name.removeprefix("robot:").replace("@", "|").split(":")[0]
        rows.setdefault(key, []).append(r)
    fixed = {c.name for c in kr15.robot_capsules if c.link == "base_link"}
    # the beam's rows against a half-space cover its reflector end; its tracker end is checked once
    tracker = {f"beam|{h.name}": h.normal @ kr15.W_T_tracker.translation - h.offset - kr15.beam_radius_m
               for h in kr15.half_spaces}
    for k, name in enumerate(chk.names):
        if name not in rows:  # fixed capsule vs obstacle: checked once when the constraints are built
            assert name.split("|")[0] in fixed, name
            continue
        ref = np.minimum(g[:, rows[name]].min(axis=1), tracker.get(name, np.inf))
        np.testing.assert_allclose(D[:, k], ref, atol=1e-8, err_msg=name)
    assert set(rows) - {"incidence"} <= set(chk.names) and (D < 0).any()


def test_random_design_is_feasible_by_the_independent_check(kr15, coll15):
    Q, ns = random_feasible(coll15, 30, np.random.default_rng(0), 100000)
    assert Q.shape == (30, 6) and ns >= 30
    rep = FeasibilityChecker(kr15).check(Q)
    assert rep.all_feasible and rep.min_clearance_m >= 0 and rep.max_incidence_deg <= 30.0


# ---------------------------------------------------------------------------------------------- bad input
def test_unknown_link_name_is_named():
    d = _cell_dict()
    d["robot_capsules"] = [{"name": "arm", "link": "link_9", "a_m": [0, 0, 0], "b_m": [1, 0, 0], "radius_m": 0.1}]
    with pytest.raises(InputError, match="link_9"):
        cell_from_dict(d, "bad.yaml")
    d = _cell_dict()
    d["skip_pairs"].append(["link_2", "lnk_5"])
    with pytest.raises(InputError, match="lnk_5"):
        cell_from_dict(d, "bad.yaml")
    d = _cell_dict()
    d["beam"]["skip"] = ["carbody"]
    with pytest.raises(InputError, match="carbody"):
        cell_from_dict(d, "bad.yaml")


def test_tracker_inside_obstacle_is_named():
    d = _cell_dict()
    d["tracker"]["xyz_m"] = [1.3, 0.0, 0.6]
    with pytest.raises(InputError, match="inside obstacle 'car_body'"):
        CollisionModel(cell_from_dict(d, "bad.yaml"))


def test_working_configuration_in_collision_is_named(coll15):
    rng = np.random.default_rng(4)
    Q = coll15.robot.random_q(rng, 500)
    g = coll15.evaluate(Q, with_grad=False)
    robot_rows = [i for i, n in enumerate(coll15.info.names) if n.startswith("robot:")]
    q_bad = Q[np.flatnonzero(g[:, robot_rows].min(axis=1) < -0.05)[0]]
    d = _cell_dict()
    d["working_configurations_deg"] = [np.degrees(q_bad).tolist()]
    with pytest.raises(InputError, match=r"working configuration\(s\) in collision: 0 \(robot:"):
        CollisionModel(cell_from_dict(d, "bad.yaml"))


def test_working_configuration_out_of_sight_is_accepted_and_named(kr15, coll15):
    """A working configuration whose beam is blocked is where the robot works, not where it is measured: the cell is
    accepted, the summary names it and what blocks the beam."""
    refl = coll15._endpoints(kr15.q_work)[1][0, coll15.beam]  # reflector at the working configuration
    W_refl = kr15.W_T_base.act(refl)
    mid = 0.5 * (W_refl + kr15.W_T_tracker.translation)
    d = _cell_dict()
    d["obstacles"]["capsules"].append({"name": "screen", "a_m": mid.tolist(), "b_m": mid.tolist(), "radius_m": 0.2})
    cell = cell_from_dict(d, "hidden.yaml")
    assert cell.hidden_work == {} and "out of the tracker's sight" not in cell.summary()
    CollisionModel(cell)
    assert list(cell.hidden_work) == [0] and cell.hidden_work[0] == "screen"
    assert "working configuration(s) 0 (beam blocked by screen) out of the tracker's sight" in cell.summary()


def test_no_feasible_random_pose_is_reported():
    d = _cell_dict()
    d["incidence_max_deg"] = 0.2
    d["max_random_tries"] = 3000
    cell = cell_from_dict(d, "tight.yaml")
    coll = CollisionModel(cell)
    with pytest.raises(InfeasibleError, match="no feasible random pose found.*3000 tries"):
        random_feasible(coll, 10, np.random.default_rng(0), cell.max_random_tries)


@pytest.mark.parametrize("edit, match", [
    (lambda d: d.pop("tracker"), "tracker"),
    (lambda d: d.update(colour="red"), "colour"),
    (lambda d: d.update(reflector_m=[0, 0]), "reflector_m"),
    (lambda d: d["obstacles"]["half_spaces"].append({"name": "x", "normal": [0, 0, 0], "offset_m": 0}), "normal"),
    (lambda d: d.update(working_configurations_deg=[[0, 0, 0, 0, 0, 400]]), "outside its limits"),
    (lambda d: d.update(joint_bounds={"lower_deg": [0] * 6, "upper_deg": [0] * 6}), "empty"),
])
def test_bad_fields_are_named(edit, match):
    d = copy.deepcopy(_cell_dict())
    edit(d)
    with pytest.raises(PinKpiOedError, match=match):
        cell_from_dict(d, "bad.yaml")


def test_missing_and_invalid_files(tmp_path):
    with pytest.raises(InputError, match="no such cell file"):
        load_cell(tmp_path / "nope.yaml")
    p = tmp_path / "bad.yaml"
    p.write_text("robot: [unclosed\n")
    with pytest.raises(InputError, match="invalid YAML"):
        load_cell(p)
    p.write_text("robot: kr15: x\n")  # libyaml words it "not allowed in this context"
    with pytest.raises(InputError, match=r"invalid YAML \(mapping values are not allowed here\)"):
        load_cell(p)


def test_cell_files_parse_alike_with_libyaml_and_pyyaml():
    """load_cell parses with libyaml where PyYAML has it: every cell file of the package, the examples and the
    benchmarks gives the values of PyYAML's own parser, and the cell built from it is the same."""
    assert yaml.__with_libyaml__, "PyYAML without libyaml: nothing to compare (load_cell uses PyYAML's parser)"
    root = CELL_DIR.parents[2]
    files = sorted(CELL_DIR.glob("*.yaml")) + sorted((root / "examples").glob("*cell*.yaml")) \
        + sorted((root / "benchmarks" / "data").glob("*cell*.yaml"))
    assert len(files) >= 10
    for f in files:
        text = f.read_text()
        assert yaml.load(text, Loader=yaml.CSafeLoader) == yaml.safe_load(text), f.name
    d = yaml.safe_load((CELL_DIR / "kr15.yaml").read_text())
    assert load_cell("kr15").to_dict() == cell_from_dict(d, str(CELL_DIR / "kr15.yaml"), CELL_DIR).to_dict()


def test_geometry_backend_equals_closed_form(coll15_all):
    """One pin.computeDistances per configuration on a GeometryModel of the segments (Coal capsules, the beam
    re-shaped per pose) gives the closed form's values and gradients, in penetration too."""
    Q = _mixed_configs(coll15_all, 12, seed=3)
    g1, G1 = coll15_all.evaluate(Q)
    g2, G2 = coll15_all.evaluate(Q, backend="geometry")
    assert (g1 < 0).any()
    assert np.abs(g1 - g2).max() < 1e-9
    assert np.abs(G1 - G2).max() < 1e-9
    assert np.array_equal(coll15_all.evaluate(Q, with_grad=False, backend="geometry"), g2)


def test_geometry_backend_band_and_aggregate(coll15):
    """With a band only the near pairs get gradients (exact ones); the KS aggregate is unchanged."""
    Q = _mixed_configs(coll15, 10, seed=4)
    g1, G1 = coll15.evaluate(Q)
    band = 0.05
    g2, G2 = coll15.evaluate(Q, backend="geometry", band=band)
    assert np.abs(g1 - g2).max() < 1e-9
    pair = coll15.info.kind == 0
    gp = g1[:, pair]
    near = gp <= gp.min(axis=1, keepdims=True) + band + 1e-12
    assert 0 < near.sum() < near.size
    np.testing.assert_allclose(G2[:, pair][near], G1[:, pair][near], atol=1e-9)
    assert np.all(G2[:, pair][~near] == 0.0)
    for mode in ("ks", "min"):
        a1 = AggregatedConstraints(coll15, mode, 2e-3).evaluate(Q)
        a2 = AggregatedConstraints(coll15, mode, 2e-3, backend="geometry").evaluate(Q)
        np.testing.assert_allclose(a2[0], a1[0], atol=1e-9)
        np.testing.assert_allclose(a2[1], a1[1], atol=1e-8)
    with pytest.raises(InputError, match="backend"):
        AggregatedConstraints(coll15, "ks", backend="fcl")


def test_beam_frames_map_z_onto_the_beam():
    from pin_kpi_oed.cell.coal_distances import beam_frames

    a = np.array([1.0, 2.0, 0.5])
    B = np.array([[3.0, 2.0, 0.5], [1.0, 2.0, -3.0], [1.0, 2.0, 4.0], [0.2, -1.0, 2.0]])
    R, c, h = beam_frames(a, B)
    for i in range(len(B)):
        assert np.allclose(R[i].T @ R[i], np.eye(3), atol=1e-12) and np.linalg.det(R[i]) == pytest.approx(1.0)
        assert np.allclose(c[i] + h[i] * R[i][:, 2], B[i]) and np.allclose(c[i] - h[i] * R[i][:, 2], a)


def test_every_overlap_is_listed_at_once_with_the_skip_pairs_hint(coll15):
    """A working configuration with several colliding pairs: one message names every pair and the skip_pairs entry."""
    rng = np.random.default_rng(4)
    Q = coll15.robot.random_q(rng, 2000)
    g = coll15.evaluate(Q, with_grad=False)
    robot_rows = np.array([i for i, n in enumerate(coll15.info.names) if n.startswith("robot:")])
    n_bad = np.sum(g[:, robot_rows] < -0.01, axis=1)
    i = int(np.flatnonzero(n_bad >= 2)[0])
    bad = [coll15.info.names[r].removeprefix("robot:") for r in robot_rows[g[i, robot_rows] < -0.01]]
    d = _cell_dict()
    d["working_configurations_deg"] = [np.degrees(Q[i]).tolist()]
    with pytest.raises(InputError) as err:
        CollisionModel(cell_from_dict(d, "bad.yaml"))
    msg = str(err.value)
    # grouped by cause: the cause and its fix named once, the configuration once with every pair
    assert "\n" not in msg and msg.count("in collision") == 1 and len(bad) >= 2
    assert msg.count("list them under skip_pairs") == 1
    assert msg.count("working configuration(s) in collision: 0 (") == 1
    hint = msg.split("skip_pairs: [", 1)[1]
    for pair in bad:
        a, b = pair.split("|")
        assert f"{pair}, " in msg.replace("robot:", "") and f"[{a}, {b}]" in hint


def test_working_target_out_of_sight_is_solved_and_named(kr15, coll15):
    """A working target whose only solutions leave the beam blocked is solved all the same (a working configuration
    need not be in the tracker's sight) and named as hidden; before, the target solver refused it."""
    import pinocchio as pin

    refl = coll15._endpoints(kr15.q_work)[1][0, coll15.beam]
    W_refl = kr15.W_T_base.act(refl)
    mid = 0.5 * (W_refl + kr15.W_T_tracker.translation)
    d = _cell_dict()
    d["obstacles"]["capsules"].append({"name": "screen", "a_m": mid.tolist(), "b_m": mid.tolist(), "radius_m": 0.2})
    M = kr15.W_T_base * kr15.robot.oMtool(kr15.q_work[0])
    d.pop("working_configurations_deg", None)
    d["working_targets"] = [{"xyz_m": M.act(kr15.tcp_m).tolist(), "rpy_rad": pin.rpy.matrixToRpy(M.rotation).tolist(),
                             "seed_rad": np.asarray(kr15.q_work[0]).tolist()}]
    cell = cell_from_dict(d, "hidden_target.yaml")
    M2 = cell.W_T_base * cell.robot.oMtool(cell.q_work[0])
    assert np.linalg.norm(M2.act(cell.tcp_m) - M.act(kr15.tcp_m)) <= 1e-6
    CollisionModel(cell)
    assert list(cell.hidden_work) == [0] and "out of the tracker's sight" in cell.summary()


def test_beam_distances_are_coals_at_every_pose_whatever_the_order(kr15):
    """The checker's beam columns (fixed targets' placements kept from its first pose) are Coal's distance of the
    beam capsule to each target at that pose's placements, computed from scratch, in any order of poses."""
    import coal

    chk = FeasibilityChecker(kr15)
    Q = np.random.default_rng(3).uniform(kr15.q_lower, kr15.q_upper, (4, kr15.robot.nq))
    fresh = FeasibilityChecker(kr15)
    for q in (Q[2], Q[0], Q[3], Q[1], Q[2]):
        d = chk.distances(q[None])[0]
        fresh.pair_distances(q)
        refl = fresh.data.oMf[fresh.tool_id].act(fresh.reflector)
        beam, Tb = coal_capsule(fresh.tracker, refl, kr15.beam_radius_m)
        want = [coal.distance(beam, Tb, fresh.gm.geometryObjects[g].geometry,
                              coal.Transform3s(fresh.gd.oMg[g].rotation, fresh.gd.oMg[g].translation),
                              coal.DistanceRequest(), coal.DistanceResult()) for g in fresh.beam_targets]
        assert len(want) > 5 and np.array_equal(d[chk.n_pairs:], want)
        assert np.array_equal(d[:chk.n_pairs], fresh.pair_distances(q))


def test_a_model_without_collision_rows_has_the_same_rows_pruned_or_not(kr15):
    """Pruning drops only robot–obstacle and robot–half-space rows: without collision rows (the working targets'
    check of the cell's own faults, a design with ``collision=False``) pruned and unpruned rows are the same."""
    pruned, full = CollisionModel(kr15, collision=False), CollisionModel(kr15, collision=False, prune=False)
    assert pruned.names == full.names == ["incidence"]
    assert np.array_equal(pruned.pairs, full.pairs) and np.array_equal(pruned.half, full.half)


def test_pair_distances_read_each_poses_own_results(kr15):
    """The checker keeps references into Coal's result vector; at every pose, in any order, they read that pose's
    results: the same numbers as Coal's distance of each pair computed from scratch at the pose's placements, and
    the smallest of them is :meth:`min_pair_distance`."""
    import coal

    chk = FeasibilityChecker(kr15)
    Q = np.random.default_rng(5).uniform(kr15.q_lower, kr15.q_upper, (3, kr15.robot.nq))
    go = chk.gm.geometryObjects
    for q in (Q[1], Q[0], Q[2], Q[1]):
        d = chk.pair_distances(q)
        oMg = chk.gd.oMg
        want = [coal.distance(go[i].geometry, coal.Transform3s(oMg[i].rotation, oMg[i].translation),
                              go[k].geometry, coal.Transform3s(oMg[k].rotation, oMg[k].translation),
                              coal.DistanceRequest(), coal.DistanceResult()) for i, k in chk.pairs]
        assert len(want) > 10 and np.allclose(d, want, rtol=0, atol=1e-12)
        assert chk.min_pair_distance(q) == d.min()


def test_a_cell_text_parsed_before_is_a_fresh_copy_and_a_changed_text_is_parsed_again(tmp_path):
    """load_cell keeps each cell file's parse by its text: a text read again gives a copy equal to a fresh parse
    (changing it changes no later load), and a file rewritten at once with the same size (its stamp may not change)
    is parsed anew, its new values read; an alias's shared list is copied whole."""

    text = (CELL_DIR / "kr15.yaml").read_text()
    first = parse_cell_text(text, tmp_path / "a.yaml")
    again = parse_cell_text(text, tmp_path / "b.yaml")
    assert again == first == yaml.safe_load(text) and again is not first
    again["tracker"]["xyz_m"][0] = 99.0
    again["measurements"] = 1
    assert parse_cell_text(text, tmp_path / "c.yaml") == yaml.safe_load(text)
    p = tmp_path / "cell.yaml"
    p.write_text(text)
    c1 = load_cell(p)
    p.write_text(text.replace("clearance_m: 0.0 ", "clearance_m: 0.2 "))
    assert load_cell(p).clearance_m == 0.2 != c1.clearance_m
    shared = "a: &x [1.0, 2.0]\nb: *x\n"
    assert parse_cell_text(shared, p) == parse_cell_text(shared, p) == {"a": [1.0, 2.0], "b": [1.0, 2.0]}


def test_pair_gradient_is_bit_for_bit_the_witness_point_formula(coll15_all):
    """The pair rows' gradient (formed in place in :meth:`CollisionModel.evaluate`) is, bit for bit, the
    witness-point formula written out with temporaries: u (nᵀv + ωᵀ(P × n)) · mask summed over the four end points
    (the in-place form reorders no operation, so the designs do not change)."""
    from pin_kpi_oed.cell.collision import PAIR
    from pin_kpi_oed.cell.segments import cross

    coll = coll15_all
    Q = coll.robot.random_q(np.random.default_rng(7), 400)  # enough poses that a reordered sum changes some bit
    _, G = coll.evaluate(Q)
    EA, EB = coll.endpoints(Q)[:2]
    fr = coll.fk.frames(Q, twists=True)
    V, W = fr.V, fr.W
    i1, i2 = coll.pairs[:, 0], coll.pairs[:, 1]
    s, t, w1, w2 = segment_closest(EA[:, i1], EB[:, i1], EA[:, i2], EB[:, i2])
    diff = w2 - w1
    dseg = np.sqrt(np.einsum("mpa,mpa->mp", diff, diff))
    nrm = diff / np.where(dseg > 0, dseg, 1.0)[..., None]
    VT, WT = np.swapaxes(V, 1, 2), np.swapaxes(W, 1, 2)
    nv = nrm @ VT
    mA, mB = coll._masks()

    def side(P, u, mask):
        return u[..., None] * (nv + cross(P, nrm) @ WT) * mask[None]

    ref = (side(EA[:, i2], 1.0 - t, mA[i2]) + side(EB[:, i2], t, mB[i2])
           - side(EA[:, i1], 1.0 - s, mA[i1]) - side(EB[:, i1], s, mB[i1]))
    pair_rows = np.flatnonzero(coll.info.kind == PAIR)
    assert pair_rows.size == len(coll.pairs) and np.any(ref != 0.0)
    assert np.array_equal(G[:, pair_rows], ref)
