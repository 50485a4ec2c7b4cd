"""Cells from files: environment obstacles from a mesh / URDF file (enclosing capsules for the
optimiser, the meshes themselves in the independent check) and working configurations as TCP targets (IK)."""

from __future__ import annotations

import copy

import numpy as np
import pinocchio as pin
import pytest
import trimesh
import yaml

from pin_kpi_oed.cell.cell import CELL_DIR, cell_from_dict, load_cell, parse_cell_text
from pin_kpi_oed.cell.feasibility import FeasibilityChecker
from pin_kpi_oed.cell.meshes import fit_capsules
from pin_kpi_oed.cell.working_targets import solve_tcp_target
from pin_kpi_oed.errors import InputError


def _shipped(name: str) -> dict:
    """A shipped cell file as a fresh dict (the package's parse, libyaml's: the same values as PyYAML's own,
    ``tests/test_collision.py``; a text parsed before is copied)."""
    path = CELL_DIR / f"{name}.yaml"
    return parse_cell_text(path.read_text(), path)


def _kr15_dict() -> dict:
    d = _shipped("kr15")
    d["robot"] = str(CELL_DIR.parents[2] / "urdf" / "kr15.urdf")
    return d


def _inside_some(points: np.ndarray, caps) -> np.ndarray:
    """Per point: largest margin by which it is inside one of the capsules (>= 0 inside), m."""
    best = np.full(len(points), -np.inf)
    for c in caps:
        a, b, r = (c.a, c.b, c.radius) if hasattr(c, "a") else c
        d = b - a
        L2 = float(d @ d)
        t = np.clip((points - a) @ d / L2, 0.0, 1.0) if L2 > 0 else np.zeros(len(points))
        best = np.maximum(best, r - np.linalg.norm(points - (a + t[:, None] * d), axis=1))
    return best


def _l_mesh() -> trimesh.Trimesh:
    """A non-convex L-shaped bracket, 0.4 m × 0.4 m × 0.1 m."""
    return trimesh.util.concatenate([
        trimesh.creation.box([0.4, 0.1, 0.1]),
        trimesh.creation.box([0.1, 0.4, 0.1], transform=trimesh.transformations.translation_matrix([-0.15, 0.15, 0]))])


def _link6_world(cell, q) -> np.ndarray:
    rb = cell.robot
    pin.framesForwardKinematics(rb.model, rb.data, q)
    return (cell.W_T_base * rb.data.oMf[rb.model.getFrameId("link_6")]).translation.copy()


def test_fit_capsules_split_a_plate_and_enclose_its_surface():
    plate = trimesh.creation.box([1.2, 0.8, 0.04])
    caps = fit_capsules(plate.vertices, plate.faces, 0.1)
    assert 1 < len(caps) <= 16 and max(r for _, _, r in caps) <= 0.1
    surface = np.vstack([plate.sample(5000, seed=3), plate.vertices])
    assert _inside_some(surface, caps).min() >= -1e-9  # every surface point (not only vertices) inside


def test_mesh_obstacle_capsules_enclose_it_and_the_check_sees_the_mesh(tmp_path):
    mesh = _l_mesh()
    mesh.export(tmp_path / "bracket.stl")
    d = _kr15_dict()
    q = load_cell("kr15").q_work[0]
    centre = _link6_world(load_cell("kr15"), q)  # the bracket around the wrist at the working configuration
    d["environment"] = [{"name": "bracket", "mesh": "bracket.stl",
                         "pose": {"xyz_m": centre.tolist(), "rpy_deg": [0.0, 90.0, 30.0]}, "max_radius_m": 0.06}]
    cell = cell_from_dict(d, str(tmp_path / "cell.yaml"), tmp_path)
    env = cell.environment[0]
    assert [s.convex for s in env.solids] == [False]  # an L is not convex: a BVH mesh in the check
    caps = [c for c in cell.obstacles if c.name.startswith("bracket_")]
    assert caps and caps == env.capsules and max(c.radius for c in caps) <= 0.06
    M = env.W_T_obj
    V = np.asarray(mesh.vertices) @ M.rotation.T + M.translation  # the file's vertices, placed independently
    assert _inside_some(V, caps).min() >= -1e-9  # every mesh vertex inside the optimiser's capsules
    chk = FeasibilityChecker(cell)
    assert not any(n.startswith("bracket_") for n in chk.beam_names)  # the check has the mesh, not the capsules
    rep = chk.check(q[None])
    assert not rep.collision_free[0] and "bracket" in rep.worst[0] and rep.clearance_m[0] < 0
    # far away (3 m above the robot) the same pose is clear of it
    d["environment"][0]["pose"]["xyz_m"] = [0.0, 0.0, 6.0]
    far = FeasibilityChecker(cell_from_dict(d, str(tmp_path / "cell.yaml"), tmp_path)).check(q[None])
    assert far.collision_free[0] and "bracket" not in far.worst[0]


def test_urdf_obstacle_boxes_and_cylinders_and_skip_by_name(tmp_path):
    (tmp_path / "table.urdf").write_text(
        '<robot name="table"><link name="world"/><link name="top">'
        '<collision><origin xyz="0 0 0.72"/><geometry><box size="1.2 0.8 0.04"/></geometry></collision>'
        '<collision><origin xyz="0.55 0.35 0.35"/><geometry><cylinder radius="0.03" length="0.7"/></geometry>'
        '</collision></link><joint name="j" type="fixed"><parent link="world"/><child link="top"/></joint></robot>')
    d = _kr15_dict()
    d["environment"] = [{"name": "table", "urdf": "table.urdf", "pose": {"xyz_m": [0.0, 1.6, 0.0]}}]
    d["skip_pairs"].append(["base_link", "table"])
    cell = cell_from_dict(d, str(tmp_path / "cell.yaml"), tmp_path)
    env = cell.environment[0]
    assert sorted(s.convex for s in env.solids) == [True, True]
    corners = np.array([[sx * 0.6, 1.6 + sy * 0.4, 0.72 + sz * 0.02] for sx in (-1, 1) for sy in (-1, 1)
                        for sz in (-1, 1)])
    ang = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    rim = np.array([[0.55 + 0.03 * np.cos(a), 1.95 + 0.03 * np.sin(a), z] for a in ang for z in (0.0, 0.7)])
    assert _inside_some(np.vstack([corners, rim]), env.capsules).min() >= -1e-9
    assert ("base_link", "table") in cell.skip_pairs and ("base_link", "table_0") in cell.skip_pairs
    chk = FeasibilityChecker(cell)
    assert not any(a == "base_link" and "table" in b for a, b in chk.pair_names)
    assert any(a == "link_3" and b.startswith("table_top") for a, b in chk.pair_names)


@pytest.mark.parametrize("entry, needle", [
    ({"name": "x", "mesh": "missing.stl"}, "environment[0].mesh: no such file"),
    ({"name": "x", "mesh": "bad.stl"}, "environment[0].mesh: cannot read the mesh"),
    ({"name": "x", "urdf": "bad.stl"}, "environment[0].urdf: cannot read the URDF"),
    ({"name": "x", "mesh": "bad.stl", "urdf": "t.urdf"}, "environment[0]: give exactly one of"),
    ({"name": "x", "stl": "bad.stl"}, "environment[0]: unknown field(s) stl"),
])
def test_bad_environment_file_is_one_line_naming_file_and_key(tmp_path, entry, needle):
    (tmp_path / "bad.stl").write_text("not a mesh\n")
    d = _kr15_dict()
    d["environment"] = [entry]
    with pytest.raises(InputError) as e:
        cell_from_dict(d, str(tmp_path / "cell.yaml"), tmp_path)
    msg = str(e.value)
    assert needle in msg and "\n" not in msg and "cell.yaml" in msg


def test_cli_exit_2_on_a_missing_environment_file(tmp_path, capsys):
    from pin_kpi_oed.cli.app import main

    d = _kr15_dict()
    d["environment"] = [{"name": "fixture", "mesh": "nowhere.stl"}]
    (tmp_path / "cell.yaml").write_text(yaml.safe_dump(d))
    assert main(["design", "--cell", str(tmp_path / "cell.yaml"), "--criteria", "random", "--measurements", "10"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "environment[0].mesh" in err[0] and "nowhere.stl" in err[0]


# ---------------------------------------------------------------------- working targets (IK)
@pytest.mark.parametrize("name", ["kr15", "ur10"])
def test_target_from_fk_is_solved_within_limits(name):
    cell = load_cell(name)
    rng = np.random.default_rng(5)
    q_true = cell.q_work[0] + rng.uniform(-0.2, 0.2, cell.robot.nq)
    M = cell.W_T_base * cell.robot.oMtool(q_true)
    p = M.act(cell.tcp_m)
    for R in (None, M.rotation):
        res = solve_tcp_target(cell.robot, cell.W_T_base, cell.tcp_m, p, R, seeds=[cell.q_work[0]])
        assert res.success
        M2 = cell.W_T_base * cell.robot.oMtool(res.q)
        assert np.linalg.norm(M2.act(cell.tcp_m) - p) <= 1e-6
        assert np.all(res.q >= cell.q_lower) and np.all(res.q <= cell.q_upper)
        if R is not None:
            assert np.linalg.norm(pin.log3(M2.rotation.T @ R)) <= 1e-6


def test_working_targets_in_the_cell_file_and_unreachable_target():
    d = _kr15_dict()
    cell0 = load_cell("kr15")
    M = cell0.W_T_base * cell0.robot.oMtool(cell0.q_work[0])
    d["working_targets"] = [{"xyz_m": M.act(cell0.tcp_m).tolist(),
                             "rpy_rad": pin.rpy.matrixToRpy(M.rotation).tolist()}]
    cell = cell_from_dict(d, "kr15.yaml", CELL_DIR)
    assert cell.q_work.shape == (2, 6)  # the joint-space working configuration, then the solved target
    M2 = cell.W_T_base * cell.robot.oMtool(cell.q_work[1])
    assert np.linalg.norm(M2.act(cell.tcp_m) - M.act(cell0.tcp_m)) <= 1e-6
    d.pop("working_configurations_deg")
    d["working_targets"].append({"xyz_m": [6.0, 0.0, 1.0]})
    with pytest.raises(InputError) as e:
        cell_from_dict(d, "kr15.yaml", CELL_DIR)
    msg = str(e.value)
    assert "working_targets[1]" in msg and "residual" in msg and "mm" in msg and "\n" not in msg


def test_shipped_ur10_cell_is_built_from_files_and_designs(tmp_path):
    import json

    from pin_kpi_oed.cli.app import main

    cell = load_cell("ur10")
    env = cell.environment[0]
    assert env.kind == "urdf" and len(env.solids) == 6 and sum(not s.convex for s in env.solids) == 1  # the STL
    assert not any(c.name == "workpiece" for c in cell.obstacles)  # no hand-written environment capsule left
    d = _shipped("ur10")
    assert "working_configurations_deg" not in d and len(d["working_targets"]) == cell.q_work.shape[0] == 2
    for t, q in zip(d["working_targets"], cell.q_work):
        M = cell.W_T_base * cell.robot.oMtool(q)
        assert np.linalg.norm(M.act(cell.tcp_m) - np.array(t["xyz_m"])) <= 1e-6
        assert np.linalg.norm(pin.log3(M.rotation.T @ pin.rpy.rpyToMatrix(*np.radians(t["rpy_deg"])))) <= 1e-6
    for s in env.solids:  # the optimiser's capsules enclose every vertex of the table and the workpiece
        assert _inside_some(s.vertices, env.capsules).min() >= -1e-9
    assert FeasibilityChecker(cell).check(cell.q_work).collision_free.all()
    out = tmp_path / "d.json"
    # one Ipopt start (the default is two): the claim is that what design returns in this cell is collision-free and
    # feasible and keeps the environment, whichever start it comes from
    assert main(["design", "--cell", "ur10", "--criteria", "random,kpi", "--measurements", "14", "--starts", "1",
                 "--json", str(out)]) == 0
    res = json.loads(out.read_text())
    assert all(e["check"]["n_colliding"] == 0 and e["check"]["all_feasible"] for e in res["designs"])
    assert res["cell"]["environment"][0]["name"] == "table"
    # the design file keeps the environment: view / export check the same solids as design did
    from pin_kpi_oed.design.design_file import load_design

    df = load_design(out)
    Q = df.design("kpi").q_meas
    np.testing.assert_allclose(FeasibilityChecker(df.cell).distances(Q), FeasibilityChecker(cell).distances(Q),
                               atol=1e-12)
    res["cell"]["environment"][0]["path"] = str(tmp_path / "moved.urdf")  # the file is gone: capsules, a note
    moved = load_design(res)
    assert any("environment 'table' checked as its capsules" in n for n in moved.notes)
    assert "table_0" in FeasibilityChecker(moved.cell).beam_names
    # the viewer draws the files' geometry, the optimiser's capsules hidden under their own toggle
    from pin_kpi_oed.viz.scene import SceneOptions, build_scene

    rec = build_scene(df, SceneOptions(ghosts=False, animate=False)).recorder
    paths = rec.object_paths()
    assert sum(p.startswith("/meshcat/cell/environment/") for p in paths) == 6
    assert sum(p.startswith("/meshcat/cell/environment_capsules/") for p in paths) == len(env.capsules)
    assert rec.properties("/meshcat/cell/environment_capsules") == {"visible": False}


def test_beam_through_a_non_convex_mesh_is_blocked(tmp_path):
    """The laser beam crossing a non-convex (BVH) mesh makes the pose invisible, the mesh named."""
    _l_mesh().export(tmp_path / "bracket.stl")
    cell0 = load_cell("kr15")
    q = cell0.q_work[0]
    refl = (cell0.W_T_base * cell0.robot.oMtool(q)).act(cell0.reflector_m)
    mid = 0.5 * (refl + cell0.W_T_tracker.translation)
    d = _kr15_dict()
    d["environment"] = [{"name": "bracket", "mesh": "bracket.stl", "pose": {"xyz_m": mid.tolist()}}]
    chk = FeasibilityChecker(cell_from_dict(d, str(tmp_path / "cell.yaml"), tmp_path))
    dist = chk.distances(q[None])[0]
    k = chk.names.index("beam|bracket")
    assert dist[k] < 0
    rep = chk.check(q[None])
    assert not rep.visible[0] and rep.worst[0] == "beam|bracket"


def test_mesh_penetration_fixes_coals_zero_distance_in_a_degenerate_contact():
    """Coal's capsule-BVH distance is ~0 (not negative) for a capsule crossing a plate whose end sits on the far
    face; coal.collide finds the intersection and the check's fix-up makes the distance negative."""
    from types import SimpleNamespace

    import coal

    from pin_kpi_oed.cell.feasibility import mesh_penetration

    plate = trimesh.creation.box([1.0, 1.0, 0.1])
    bvh = coal.BVHModelOBBRSS()
    bvh.beginModel(len(plate.faces), len(plate.vertices))
    bvh.addVertices(np.asarray(plate.vertices, float))
    bvh.addTriangles(np.asarray(plate.faces, np.int32))
    bvh.endModel()
    cap = coal.Capsule(0.05, 0.4)  # from z = -0.05 (on the bottom face) through the top face
    M_cap, M_plate = pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.2])), pin.SE3.Identity()
    d0 = coal.distance(cap, coal.Transform3s(M_cap.rotation, M_cap.translation), bvh, coal.Transform3s(),
                       coal.DistanceRequest(), coal.DistanceResult())
    assert d0 > -1e-9  # Coal alone: no penetration seen
    gm = SimpleNamespace(geometryObjects=[SimpleNamespace(geometry=cap), SimpleNamespace(geometry=bvh)])
    chk = SimpleNamespace(pairs=[(0, 1)], mesh_pairs=[0], gm=gm, gd=SimpleNamespace(oMg=[M_cap, M_plate]))
    d = mesh_penetration(chk, np.array([d0]))
    assert d[0] <= -1e-6
    far = SimpleNamespace(pairs=[(0, 1)], mesh_pairs=[0], gm=gm,
                          gd=SimpleNamespace(oMg=[pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.5])), M_plate]))
    assert mesh_penetration(far, np.array([0.2]))[0] == 0.2  # clear pairs untouched


# ---------------------------------------------------------------------- primitives (box, cylinder, sphere)
def _seg_box_distance(a: np.ndarray, b: np.ndarray, r: float, M: pin.SE3, half: np.ndarray) -> float:
    """Distance (m) of a capsule to a box, by dense sampling of the segment in the box frame (independent of Coal)."""
    t = np.linspace(0.0, 1.0, 20001)[:, None]
    P = (a + t * (b - a) - M.translation) @ M.rotation  # box frame
    out = np.linalg.norm(np.maximum(np.abs(P) - half, 0.0), axis=1)
    inside = np.all(np.abs(P) <= half, axis=1)
    depth = np.where(inside, -np.min(half - np.abs(P), axis=1), 0.0)
    return float(np.min(np.where(inside, depth, out))) - r


def _seg_point_distance(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> float:
    d = b - a
    t = np.clip((c - a) @ d / (d @ d), 0.0, 1.0)
    return float(np.linalg.norm(c - (a + t * d)))


def _robot_capsule_world(chk, cell, q, name):
    """(a, b, radius) of the robot capsule ``name`` in the cell frame at ``q``."""
    rb = cell.robot
    spec = next(c for c in cell.robot_capsules if c.name == name)
    pin.framesForwardKinematics(rb.model, rb.data, q)
    M = cell.W_T_base * rb.data.oMf[rb.model.getFrameId(spec.link)]
    return M.act(spec.a), M.act(spec.b), spec.radius


def test_box_cylinder_sphere_obstacles_one_coal_shape_exact_distances_and_enclosing_capsules(tmp_path):
    """A primitive is one Coal shape in the check (its distance to a robot capsule equals the analytic one) and
    its capsules enclose it: a 0.3 m cube is one capsule (through a URDF box: up to 16)."""
    cell0 = load_cell("kr15")
    q = cell0.q_work[0]
    wrist = _link6_world(cell0, q)
    d = _kr15_dict()
    R = pin.rpy.rpyToMatrix(0.3, -0.2, 0.7)
    d["environment"] = [
        {"name": "crate", "box": {"size_m": [0.3, 0.3, 0.3]},
         "pose": {"xyz_m": (wrist + [0.0, 0.0, 0.45]).tolist(), "rpy_deg": np.degrees([0.3, -0.2, 0.7]).tolist()}},
        {"name": "pillar", "cylinder": {"radius_m": 0.1, "length_m": 1.5}, "pose": {"xyz_m": [-0.2, 1.8, 0.75]}},
        {"name": "lamp", "sphere": {"radius_m": 0.2}, "pose": {"xyz_m": (wrist + [0.0, -0.5, 0.0]).tolist()}}]
    cell = cell_from_dict(d, str(tmp_path / "cell.yaml"), tmp_path)
    crate, pillar, lamp = cell.environment
    assert [len(e.solids) for e in cell.environment] == [1, 1, 1] and all(e.solids[0].convex for e in cell.environment)
    assert len(crate.capsules) == 1 and len(pillar.capsules) == 1 and len(lamp.capsules) == 1
    cube = trimesh.creation.box(extents=[0.3, 0.3, 0.3])
    surface = np.vstack([cube.sample(4000, seed=1), cube.vertices]) @ R.T + crate.W_T_obj.translation
    assert _inside_some(surface, crate.capsules).min() >= -1e-9
    cyl = trimesh.creation.cylinder(radius=0.1, height=1.5, sections=64)
    surf = np.vstack([cyl.sample(4000, seed=2), cyl.vertices]) + pillar.W_T_obj.translation
    assert _inside_some(surf, pillar.capsules).min() >= -1e-9
    assert pillar.capsules[0].radius == pytest.approx(0.1)
    chk = FeasibilityChecker(cell)
    dist = dict(zip(chk.names, chk.distances(q[None])[0]))
    wrist_caps = [c for c in cell.robot_capsules if c.link in ("link_5", "link_6")]
    assert wrist_caps
    for cap in wrist_caps:
        a, b, r = _robot_capsule_world(chk, cell, q, cap.name)
        key = next(k for k in dist if k.split("|")[0] == cap.name and k.split("|")[1] == "crate")
        exact = _seg_box_distance(a, b, r, crate.W_T_obj, np.array([0.15, 0.15, 0.15]))
        assert dist[key] == pytest.approx(exact, abs=2e-4)
        key = next(k for k in dist if k.split("|")[0] == cap.name and k.split("|")[1] == "lamp")
        assert dist[key] == pytest.approx(_seg_point_distance(a, b, lamp.W_T_obj.translation) - r - 0.2, abs=1e-7)


def test_primitive_obstacles_round_trip_through_the_design_file(tmp_path):
    from pin_kpi_oed.cell.environment import environment_from_dicts

    d = _kr15_dict()
    d["environment"] = [{"name": "crate", "box": {"size_m": [0.3, 0.2, 0.1]}, "pose": {"xyz_m": [0.0, 1.6, 0.05]}}]
    cell = cell_from_dict(d, str(tmp_path / "cell.yaml"), tmp_path)
    notes: list[str] = []
    back = environment_from_dicts([e.to_dict() for e in cell.environment], cell.obstacles, "d.json", notes)
    assert not notes and len(back) == 1 and back[0].kind == "box"
    assert np.allclose(back[0].solids[0].geometry.halfSide, [0.15, 0.1, 0.05])
    assert [c.name for c in back[0].capsules] == [c.name for c in cell.environment[0].capsules]


@pytest.mark.parametrize("entry, needle", [
    ({"name": "x", "box": {"size_m": [0.3, 0.3]}}, "box.size_m"),
    ({"name": "x", "box": {"size_m": [0.3, -0.3, 0.3]}}, "box.size_m"),
    ({"name": "x", "cylinder": {"radius_m": 0.1}}, "length_m"),
    ({"name": "x", "sphere": {"radius_m": 0}}, "radius_m"),
    ({"name": "x", "sphere": {"radius_m": 0.1}, "box": {"size_m": [1, 1, 1]}}, "give exactly one of"),
])
def test_bad_primitive_obstacle_is_one_line_naming_the_field(tmp_path, entry, needle):
    d = _kr15_dict()
    d["environment"] = [entry]
    with pytest.raises(InputError) as e:
        cell_from_dict(d, str(tmp_path / "cell.yaml"), tmp_path)
    assert needle in str(e.value) and "\n" not in str(e.value)


def _sphere_near(cell, q, name: str, gap: float, radius: float = 0.05) -> list[float]:
    """Centre of a sphere of ``radius`` ``gap`` m clear of the robot capsule ``name`` at ``q`` (cell frame), beside
    the capsule's middle along the cell's y axis."""
    a, b, r = _robot_capsule_world(None, cell, q, name)
    return ((a + b) / 2 + np.array([0.0, 1.0, 0.0]) * (r + radius + gap)).tolist()


def test_clearance_message_names_the_clearance_margin_option(tmp_path, capsys):
    from pin_kpi_oed.cli.app import main

    cell = load_cell("kr15")
    q = cell.q_work[0]
    cap = next(c.name for c in cell.robot_capsules if c.link == "link_5")  # the others are > 30 mm from it
    d = _kr15_dict()
    d["obstacles"]["capsules"].append({"name": "probe_stand", "a_m": _sphere_near(cell, q, cap, 0.010),
                                       "b_m": _sphere_near(cell, q, cap, 0.010), "radius_m": 0.05})
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(d))
    assert main(["design", "--cell", str(tmp_path / "c.yaml"), "--criteria", "random", "--measurements", "10"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "probe_stand" in err[0], err
    assert "--clearance-margin 20 mm" in err[0] and "--clearance-margin 0.009 admits it" in err[0], err[0]


def test_obstacle_on_the_base_and_tracker_in_an_obstacle_are_named_before_the_working_targets(tmp_path):
    """The UR10 cell (working targets solved by IK): an obstacle the shoulder hits at every configuration, or one
    around the tracker (a capsule or a box), is refused as the cell's fault, not as an unreachable working target."""
    base = _shipped("ur10")
    for f in ("ur10_table.urdf", "ur10_workpiece.stl"):
        (tmp_path / f).write_bytes((CELL_DIR / f).read_bytes())

    def refused(edit) -> str:
        d = copy.deepcopy(base)
        edit(d)
        with pytest.raises(InputError) as e:
            cell_from_dict(d, str(tmp_path / "cell.yaml"), tmp_path)
        assert "\n" not in str(e.value) and "working_targets" not in str(e.value), str(e.value)
        return str(e.value)

    msg = refused(lambda d: d["obstacles"]["capsules"].append(
        {"name": "crate", "a_m": [0.0, 0.0, 1.05], "b_m": [0.0, 0.0, 1.05], "radius_m": 0.08}))
    assert "obstacle 'crate' overlaps the robot: 'shoulder_link'" in msg and "every one of 64" in msg
    msg = refused(lambda d: d["obstacles"]["capsules"].append(
        {"name": "cover", "a_m": [0.3, -2.6, 1.2], "b_m": [0.3, -2.6, 1.4], "radius_m": 0.2}))
    assert "the tracker at [0.300, -2.600, 1.300] m (cell frame) is inside obstacle 'cover'" in msg
    msg = refused(lambda d: d["environment"].append(
        {"name": "hut", "box": {"size_m": [0.5, 0.5, 0.5]}, "pose": {"xyz_m": [0.3, -2.6, 1.3]}}))
    assert "is inside obstacle 'hut'" in msg
    # a plate above the tracker whose coarse enclosing capsule holds it: the optimiser's capsule is named, with the fix
    plate = {"name": "plate", "box": {"size_m": [0.6, 0.6, 0.02]}, "pose": {"xyz_m": [0.3, -2.6, 1.45]},
             "max_radius_m": 1.0}
    msg = refused(lambda d: d["environment"].append(plate))
    assert "obstacle 'plate_0' (an enclosing capsule the optimiser uses for 'plate'" in msg and "max_radius_m" in msg
    d = copy.deepcopy(base)
    d["environment"].append({**plate, "max_radius_m": 0.05})  # strips 5 cm thick: the tracker is clear of them
    cell = cell_from_dict(d, str(tmp_path / "cell.yaml"), tmp_path)
    assert len(cell.environment[-1].capsules) > 1


def test_the_always_blocked_test_stops_early_with_the_full_matrixs_verdict():
    """The working targets' check of the cell's own faults goes configuration by configuration and stops once no
    pair is close in all so far: at every clearance, from none close to many close in all 64 configurations, its
    verdict is that of the full (64, columns) distance matrix."""
    import dataclasses

    from pin_kpi_oed.cell.working_targets import N_ALWAYS, blocked_in_all

    cell = load_cell("ur10")
    chk = FeasibilityChecker(dataclasses.replace(cell, environment=[]))
    Q = np.random.default_rng(0).uniform(cell.q_lower, cell.q_upper, (N_ALWAYS, cell.robot.nq))
    D = chk.distances(Q)
    verdicts = []
    for clearance in (0.0, 0.05, 0.2, 0.4, 0.8, 1.6):
        full = D.copy()
        full[:, :chk.n_pairs] -= clearance
        want = bool(np.any(np.all(full < -1e-9, axis=0)))
        assert blocked_in_all(chk, Q, clearance) == want
        verdicts.append(want)
    assert verdicts[0] is False and verdicts[-1] is True  # both verdicts reached


def test_mesh_boxes_bound_the_mesh_pairs_and_the_smallest_distance_is_unchanged():
    """The boxes around the UR10 cell's workpiece mesh bound every mesh pair from below (Coal's capsule–box distance
    never above its capsule–mesh distance), and the smallest pair distance that leaves the far mesh pairs out is the
    one with every pair computed, on configurations near and far from the mesh, colliding or clear: equal but for the
    last digits Coal's warm-started GJK moves (a mesh pair computed at fewer configurations starts from older
    results; ~1e-17 m)."""
    cell = load_cell("ur10")
    fast, full = FeasibilityChecker(cell), FeasibilityChecker(cell)
    full.mesh_boxes = None  # every pair computed by Coal
    assert fast.mesh_boxes is not None and len(fast.mesh_pairs) == 8
    bgm, bgd, boxes = fast.mesh_boxes
    X = cell.robot.random_q(np.random.default_rng(0), 400)
    D = np.array([full.pair_distances(q) for q in X])
    near = X[np.isin(D.argmin(axis=1), full.mesh_pairs) & (D.min(axis=1) > 1e-6)]  # a mesh pair the smallest, clear
    assert len(near) >= 3
    X = np.vstack([X[:100], near, *(np.linspace(a, b, 20) for a, b in zip(near[:-1], near[1:]))])
    left_out = mesh_smallest = 0
    for q in X:
        d = full.pair_distances(q)
        pin.updateGeometryPlacements(full.model, full.data, bgm, bgd)
        pin.computeDistances(bgm, bgd)
        low = np.array([r.min_distance for r in boxes])
        assert np.all(low <= d[full.mesh_pairs] + 1e-9)
        left_out += int(np.sum(low > d.min() + 1e-4))
        mesh_smallest += int(d.min() > 1e-6 and int(np.argmin(d)) in full.mesh_pairs)
        assert abs(fast.min_pair_distance(q) - d.min()) <= 1e-12
    assert left_out > len(X) and mesh_smallest >= len(near)  # pairs left out; clear configurations a mesh decides
