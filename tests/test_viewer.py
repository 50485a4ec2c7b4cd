"""Meshcat preview: the design-file reader, the scene's objects, the CLI, and a real
render of the static page in headless Chromium.

The design JSON is built here (``make_design``) from ``load_robot('kr15')``, random configurations
and the test's own C_s formula (``cs_oracle``), so these tests do not depend on the design optimiser.
"""

from __future__ import annotations

import copy
import json
import re
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from pin_kpi_oed.cell.cell import capsules_from_urdf, load_cell
from pin_kpi_oed.cell.collision import INCID, CollisionModel
from pin_kpi_oed.design.design_file import load_design
from pin_kpi_oed.design.stand_in import stand_in_design
from pin_kpi_oed.errors import InputError, PinKpiOedError
from pin_kpi_oed.model.noise import NoiseModel
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.model.robot import load_robot
from pin_kpi_oed.oed.covariance import kpi_covariance
from pin_kpi_oed.oed.identifiability import analyse
from pin_kpi_oed.viz.ellipsoids import confidence_ellipsoid, fmt_factor, nice_factor
from pin_kpi_oed.viz.render import find_browser, render_png
from pin_kpi_oed.viz.robot_geometry import slug
from pin_kpi_oed.viz.scene import SceneOptions, build_scene
from pin_kpi_oed.viz.style import DESIGN_COLOURS

CRITERIA = ("random", "param", "kpi")


# ----------------------------------------------------------------------------- fixture generator
def cs_oracle(model: TrackerModel, Q: np.ndarray, q_work: np.ndarray) -> np.ndarray:
    """C_s = E (FᵀF + P)⁻¹ Eᵀ (eq. 19) assembled here from the model's Jacobians and prior."""
    b = analyse(model).base
    p0 = np.zeros(model.n_params)
    F = model.weighted_jacobian(p0, Q)[:, :, b].reshape(-1, b.size)
    E = model.kpi_jacobian(p0, q_work)[:, b]
    prior = model.layout.prior_sigma[b]
    return kpi_covariance(F, E, prior if np.isfinite(prior).any() else None)


def make_design(m: int = 16, seed: int = 0, cov_for: tuple[str, ...] = ("random", "kpi")) -> dict:
    """A design JSON (dict) as ``design --json`` writes it, from random KR 15 configurations.

    ``random``: one random set; ``param`` / ``kpi``: the best of a few random sets by tr(C_p) / tr(C_s).
    ``cov_s_m2`` is written only for the criteria in ``cov_for`` (the viewer recomputes the others).
    """
    rb = load_robot("kr15")
    W_T_tracker = pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, np.radians(120.0)), np.array([2.6, -2.2, 1.3]))
    W_T_base = pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.5]))
    tracker_T_base = W_T_tracker.inverse() * W_T_base
    noise = NoiseModel(sigma_xyz_m=(1e-6, 1e-6, 1e-6))
    model = TrackerModel(rb, tracker_T_base=tracker_T_base, reflector_m=np.array([0.06, 0.0, 0.12]),
                         tcp_m=np.array([0.0, 0.0, 0.2]), noise=noise)
    q_work = np.radians([[0.0, -41.0, 14.0, 0.0, 114.0, 0.0]])
    rng = np.random.default_rng(seed)
    sets = [rb.random_q(rng, m) for _ in range(6)]
    Cs = [cs_oracle(model, S, q_work) for S in sets]
    b = analyse(model).base
    Fs = [model.weighted_jacobian(np.zeros(model.n_params), S)[:, :, b].reshape(-1, b.size) for S in sets]
    trp = [np.trace(np.linalg.inv(F.T @ F)) for F in Fs]
    pick = {"random": 0, "param": int(np.argmin(trp)), "kpi": int(np.argmin([np.trace(C) for C in Cs]))}
    designs = []
    for crit in CRITERIA:
        i = pick[crit]
        e = {"criterion": crit, "q_meas": sets[i].tolist(), "trace_cs_m2": float(np.trace(Cs[i])),
             "min_clearance_m": 0.01, "max_incidence_deg": 29.0, "status": "test fixture"}
        if crit in cov_for:
            e["cov_s_m2"] = Cs[i].tolist()
        designs.append(e)
    caps = capsules_from_urdf(rb)
    return {
        "robot": {"name": "kr15", "urdf_path": rb.urdf_path, "tool_frame": "tool0"},
        "tracker_T_base": tracker_T_base.homogeneous.tolist(),
        "reflector_m": [0.06, 0.0, 0.12],
        "tcp_m": [0.0, 0.0, 0.2],
        "noise": noise.to_dict(),
        "q_work": q_work.tolist(),
        "capsules": [{"name": c.link, "link": c.link, "a_m": c.a.tolist(), "b_m": c.b.tolist(),
                      "radius_m": c.radius} for c in caps],
        "obstacles": [{"name": "car_body", "a_m": [1.3, -1.6, 0.6], "b_m": [1.3, 1.6, 0.6], "radius_m": 0.5},
                      {"name": "pedestal", "a_m": [0, 0, 0], "b_m": [0, 0, 0.22], "radius_m": 0.28}],
        "half_spaces": [{"name": "wall", "normal": [1.0, 0.0, 0.0], "offset_m": -0.45},
                        {"name": "floor", "normal": [0.0, 0.0, 1.0], "offset_m": 0.0}],
        "cell": {"W_T_base": W_T_base.homogeneous.tolist(), "skip_pairs": [["link_2", "link_4"],
                                                                           ["link_4", "link_6"]]},
        "designs": designs,
    }


@pytest.fixture(scope="module")
def design_dict() -> dict:
    return make_design()


@pytest.fixture(scope="module")
def design_path(tmp_path_factory, design_dict) -> Path:
    p = tmp_path_factory.mktemp("design") / "design.json"
    p.write_text(json.dumps(design_dict))
    return p


@pytest.fixture(scope="module")
def scene(design_path):
    return build_scene(load_design(design_path))


# ----------------------------------------------------------------------------- the scene's objects
def test_scene_holds_the_expected_objects(scene):
    rec = scene.recorder
    df = scene.design
    paths = set(rec.object_paths())
    # cell: half-spaces, obstacles, tracker, beam
    for p in ("cell/half_spaces/floor", "cell/half_spaces/wall", "cell/obstacles/car_body", "cell/obstacles/pedestal",
              "tracker/head", "tracker/body", "beam"):
        assert f"/meshcat/{p}" in paths, p
    # robot through Pinocchio's MeshcatVisualizer: the URDF's 7 cylinders + the reflector; 7 capsules
    from pinocchio.visualize import MeshcatVisualizer

    assert isinstance(scene.viz, MeshcatVisualizer)
    visuals = sorted(p for p in paths if p.startswith("/meshcat/robot/visuals/"))
    assert len(visuals) == 8 and "/meshcat/robot/visuals/reflector" in visuals
    assert rec.object_dict("/meshcat/robot/visuals/link_2_0")["object"]["geometries"][0]["type"] == "CylinderGeometry"
    caps = [p for p in paths if p.startswith("/meshcat/robot/collisions/")]
    assert len(caps) == len(df.capsules) == 7
    # capsules: present but hidden (a toggle in the viewer); visuals shown
    assert rec.properties("/meshcat/robot/collisions") == {"visible": False}
    assert rec.properties("/meshcat/robot/visuals") == {"visible": True}
    # ghosts: none by default for designs of more than 8 poses; a marker per pose instead,
    # the last design's shown
    assert not any(p.startswith("/meshcat/ghosts/") for p in paths)
    for d in df.designs:
        mk = rec.object_dict(f"/meshcat/markers/{slug(d.criterion)}")["object"]
        ext = mk["geometries"][0]["data"]["attributes"]["position"]["array"]  # a Float32Array (msgpack ext)
        pos = np.frombuffer(ext.data, np.float32).reshape(-1, 3)
        np.testing.assert_allclose(pos, df.reflector_world(d.q_meas), atol=1e-5)
        assert rec.properties(f"/meshcat/markers/{slug(d.criterion)}") == {"visible": d.criterion == "kpi"}
    # ellipsoids: one per design at the working configuration, in the design's colour, 95 %, magnified
    assert [e.design for e in scene.ellipsoids] == list(CRITERIA)
    colours = set()
    for e in scene.ellipsoids:
        obj = rec.object_dict(e.path)
        colour = obj["object"]["materials"][0]["color"]
        assert colour == DESIGN_COLOURS[e.design] == scene.colours[e.design]
        colours.add(colour)
        geom_scale = np.diag(np.array(obj["object"]["object"]["matrix"]).reshape(4, 4))[:3]
        np.testing.assert_allclose(np.sort(geom_scale), np.sort(e.radii_m * scene.scale), rtol=1e-9)
        d = df.design(e.design)
        r_ref, _ = confidence_ellipsoid(d.cov_s_m2[:3, :3], 0.95)  # rotation does not change the radii
        np.testing.assert_allclose(np.sort(e.radii_m), np.sort(r_ref), rtol=1e-9)
        np.testing.assert_allclose(np.sort(e.radii_m / np.sqrt(np.linalg.eigvalsh(d.cov_s_m2[:3, :3]))),
                                   np.sqrt(7.8147279) * np.ones(3), rtol=1e-6)
    assert len(colours) == 3 and 0xF57821 not in colours
    # side by side, centred on the nominal TCP, far enough apart not to overlap
    c = np.array([e.centre_world for e in scene.ellipsoids])
    np.testing.assert_allclose(c.mean(axis=0), df.tcp_world()[0], atol=1e-9)
    rmax = max(e.radii_m.max() for e in scene.ellipsoids) * scene.scale
    assert np.min(np.linalg.norm(np.diff(c, axis=0), axis=1)) > 2 * rmax
    # magnification: a 1-2-5 number making the largest ellipsoid a few cm (visible)
    assert 0.02 < rmax < 0.5 and re.fullmatch(r"[125]0*", str(int(scene.scale)))
    assert {"/meshcat/ellipsoids/tcp/w0", "/meshcat/ellipsoids/label/w0"} <= paths
    # the animation steps through every measurement configuration, design after design
    anims = [c for c in rec.commands if c["type"] == "set_animation"]
    assert len(anims) == 1 and anims[0]["options"]["play"] is False
    clips = {a["path"]: a["clip"] for a in anims[0]["animations"]}
    n_poses = sum(d.q_meas.shape[0] for d in df.designs)
    assert scene.animation_poses[0] == ("random", 0) and len(scene.animation_poses) == n_poses
    for p in ("/meshcat/robot/visuals/link_6_0", caps[0], "/meshcat/beam"):
        keys = {t["name"]: t["keys"] for t in clips[p]["tracks"]}
        assert len(keys[".position"]) == 2 * n_poses
    assert ".scale" in {t["name"] for t in clips["/meshcat/beam"]["tracks"]}


def test_all_ghosts_on_request_and_screen_sized_labels(design_path):
    """--all-ghosts draws every pose of every design (the last design's shown); the ellipsoid labels are
    sprites of constant screen size, one line at LABEL_LINE_SCREEN of the page height at any zoom."""
    from pin_kpi_oed.viz.scene_parts import LABEL_LINE_SCREEN, MESHCAT_FOV_DEG

    sc = build_scene(load_design(design_path), SceneOptions(max_ghosts=None, animate=False))
    rec, df = sc.recorder, sc.design
    paths = set(rec.object_paths())
    for d in df.designs:
        ghosts = {p.split("/")[4] for p in paths if p.startswith(f"/meshcat/ghosts/{slug(d.criterion)}/")}
        assert len(ghosts) == d.q_meas.shape[0] == 16
        assert rec.properties(f"/meshcat/ghosts/{slug(d.criterion)}") == {"visible": d.criterion == "kpi"}
    few = build_scene(load_design(design_path, criteria=["kpi"]), SceneOptions(max_ghosts=16, animate=False))
    assert len({p for p in few.recorder.object_paths() if p.startswith("/meshcat/ghosts/kpi/")}) >= 16
    lab = rec.object_dict("/meshcat/ellipsoids/label/w0")["object"]
    assert lab["object"]["type"] == "Sprite"
    mat = lab["materials"][0]
    assert mat["type"] == "SpriteMaterial" and mat["sizeAttenuation"] is False and mat["depthTest"] is False
    import umsgpack

    T = np.array(umsgpack.unpackb(rec.node("/meshcat/ellipsoids/label/w0").transform)["matrix"]).reshape(4, 4).T
    sy = np.linalg.norm(T[:3, 1])
    n_lines = 1 + len(df.designs)
    # three.js: a sizeAttenuation=false sprite of height s covers s / (2 tan(fov/2)) of the page height
    per_line = sy / (2 * np.tan(np.radians(MESHCAT_FOV_DEG / 2))) / n_lines
    assert per_line == pytest.approx(LABEL_LINE_SCREEN) and per_line >= 0.02  # >= 18 px on a 900 px page
    assert np.linalg.norm(T[:3, 0]) > 2 * sy  # wider than high: the text is not squeezed
    # above the ellipsoids, never on them
    top = max(e.centre_world[2] + e.radii_m.max() * sc.scale for e in sc.ellipsoids)
    assert T[2, 3] > top


def test_robot_and_beam_placed_by_pinocchio(scene):
    """The robot's nodes carry Pinocchio's placements at q_work; the beam joins tracker and reflector."""
    import umsgpack

    df = scene.design
    rb = df.robot
    data = rb.model.createData()
    pin.framesForwardKinematics(rb.model, data, df.q_work[0])
    node = scene.recorder.node("/meshcat/robot/visuals/reflector")
    T = np.array(umsgpack.unpackb(node.transform)["matrix"]).reshape(4, 4).T
    refl_base = data.oMf[rb.tool_frame_id].act(df.model.reflector_m)
    np.testing.assert_allclose(T[:3, 3], refl_base, atol=1e-9)  # robot node frame = base frame
    Tr = np.array(umsgpack.unpackb(scene.recorder.node("/meshcat/robot").transform)["matrix"]).reshape(4, 4).T
    np.testing.assert_allclose(Tr, df.world_T_base.homogeneous, atol=1e-12)
    Tb = np.array(umsgpack.unpackb(scene.recorder.node("/meshcat/beam").transform)["matrix"]).reshape(4, 4).T
    a, b = df.world_T_tracker.translation, df.reflector_world(df.q_work[:1])[0]
    np.testing.assert_allclose(Tb[:3, 3], 0.5 * (a + b), atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(Tb[:3, 1]), np.linalg.norm(b - a), rtol=1e-9)


def test_static_html_is_self_contained(scene):
    page = scene.static_html()
    assert "new MeshCat.Viewer" in page and len(page) > 500_000  # meshcat's viewer inlined
    assert not re.search(r"<script[^>]+src=|<link[^>]+href=", page), "the page must not load anything"
    assert page.count("viewer.handle_command_bytearray") >= len(scene.recorder.object_paths())
    assert f"&times;{fmt_factor(scene.scale)}" in page  # the legend shows the magnification
    # the animation is sent after the objects it animates
    cmds = re.findall(r'data:application/octet-binary;base64,([A-Za-z0-9+/=]+)', page)
    import base64

    import umsgpack

    kinds = [umsgpack.unpackb(base64.b64decode(c))["type"] for c in cmds]
    assert kinds[-1] == "set_animation" and kinds.count("set_animation") == 1


def test_primitives_when_the_urdf_has_no_visuals(tmp_path, design_dict):
    """A URDF without visual geometry: the robot is drawn from its capsules."""
    text = Path(load_robot("kr15").urdf_path).read_text()
    bare = re.sub(r"<visual>.*?</visual>", "", text, flags=re.S)
    urdf = tmp_path / "bare.urdf"
    urdf.write_text(bare)
    d = copy.deepcopy(design_dict)
    d["designs"] = [e for e in d["designs"] if "cov_s_m2" in e]
    d["robot"] = {"urdf_path": str(urdf), "tool_frame": "tool0"}
    sc = build_scene(load_design(d), SceneOptions(ghosts=False, animate=False))
    vis = [p for p in sc.recorder.object_paths() if p.startswith("/meshcat/robot/visuals/")]
    assert len(vis) == 7 + 1  # one capsule per link + the reflector
    assert any("no visual geometry" in n for n in sc.design.notes)
    # and without capsules either: a stick figure
    d.pop("capsules")
    d["robot"] = {"urdf_path": str(urdf), "tool_frame": "tool0"}
    bare2 = re.sub(r"<collision>.*?</collision>", "", bare, flags=re.S)
    urdf.write_text(bare2)
    sc = build_scene(load_design(d), SceneOptions(ghosts=False, animate=False))
    assert any("/stick_" in p for p in sc.recorder.object_paths())


# ----------------------------------------------------------------------------- the design reader
def test_missing_covariance_is_recomputed_with_the_prior(design_dict):
    """A design without cov_s_m2 gets the C_s of eq. 19 (the test's own assembly), prior included."""
    d = copy.deepcopy(design_dict)
    kpi = next(e for e in d["designs"] if e["criterion"] == "kpi")
    given = np.array(kpi.pop("cov_s_m2"))
    df = load_design(d)
    k = df.design("kpi")
    assert k.cov_source == "computed" and df.design("random").cov_source == "file"
    assert any("recomputed" in n for n in df.notes)
    np.testing.assert_allclose(k.cov_s_m2, given, rtol=1e-8)  # the file's C_s was made by cs_oracle
    # a prior in the file is used: C_s shrinks, and matches the oracle with that prior
    d["prior"] = {"joint_*.t*": 1e-6}
    dfp = load_design(d)
    assert dfp.design("kpi").cov_source == "computed"
    np.testing.assert_allclose(dfp.design("kpi").cov_s_m2, cs_oracle(dfp.model, k.q_meas, dfp.q_work), rtol=1e-8)
    assert np.trace(dfp.design("kpi").cov_s_m2) < 0.9 * np.trace(given)
    # cell-style fields: W_T_base from "cell", capsules in link frames, half-spaces, skip pairs
    np.testing.assert_allclose(df.world_T_base.translation, [0, 0, 0.5])
    assert [h.name for h in df.half_spaces] == ["wall", "floor"] and df.half_spaces[0].offset == -0.45
    assert ("link_2", "link_4") in df.cell.skip_pairs


def test_clearance_is_the_distance_of_the_solids():
    """Hand-computed: a ball on the tool and a ball in the cell; at the distances the check reports."""
    rb = load_robot("kr15")
    q = np.radians([[10.0, -50.0, 20.0, 0.0, 60.0, 0.0]])
    data = rb.model.createData()
    pin.framesForwardKinematics(rb.model, data, q[0])
    tool = data.oMf[rb.tool_frame_id].translation  # base = world
    centre = tool + np.array([0.3, -0.4, 0.0])  # 0.5 m from the tool
    d = {"robot": "kr15", "reflector_m": [0.0, 0.0, 0.0], "tracker_T_base": np.eye(4).tolist(), "q_work": q.tolist(),
         "capsules": [{"name": "tool_ball", "link": "tool0", "a": [0, 0, 0], "radius": 0.05}],
         "obstacles": [{"name": "ball", "center": centre.tolist(), "radius": 0.1}],
         "half_spaces": [{"name": "ground", "normal": [0, 0, 2], "offset": 2 * (tool[2] - 0.25)}],
         "beam": {"radius_m": 0.0}, "designs": [{"criterion": "one", "q_meas": q.tolist(),
                                                 "cov_s_m2": np.eye(3).tolist()}]}
    df = load_design(d)
    D = dict(zip(df.checker.names, df.checker.distances(q)[0]))
    assert D["tool_ball|ball"] == pytest.approx(0.5 - 0.05 - 0.1, abs=1e-9)
    assert D["tool_ball|ground"] == pytest.approx(0.25 - 0.05, abs=1e-9)
    # the beam runs from the tracker (the base origin) to the reflector (the tool origin): distance to the
    # ball's centre sampled densely along the segment
    s = np.linspace(0.0, 1.0, 200001)[:, None]
    ref = np.min(np.linalg.norm(s * tool - centre, axis=1)) - 0.1
    assert D["beam|ball"] == pytest.approx(ref, abs=1e-7)
    assert df.pose_clearance(q)[0] == pytest.approx(min(D.values()), abs=1e-12)


@pytest.fixture(scope="module")
def designed(tmp_path_factory):
    """A design JSON written by ``pin-kpi-oed design`` for the shipped KR 15 cell (heuristic design only)."""
    import argparse

    from pin_kpi_oed.cli import design as cli_design

    out = tmp_path_factory.mktemp("designed") / "design.json"
    ns = argparse.Namespace(cell="kr15", criteria="random", measurements=20, seed=0, json=str(out),
                            no_collision=False, starts=1, max_iter=10, quiet=True)
    assert cli_design.run(ns) == 0
    return out


def test_design_file_reproduces_the_cell_it_was_designed_in(designed):
    """The design file's cell is the optimiser's: same skip lists, and clearances equal to the design
    table's and to the optimiser's own (numpy, closed-form) constraint rows."""
    cell = load_cell("kr15")
    df = load_design(designed)
    assert not any("not checked" in n for n in df.notes)
    assert sorted(df.cell.skip_pairs) == sorted(cell.skip_pairs) and df.cell.beam_skip == cell.beam_skip
    assert df.cell.clearance_m == cell.clearance_m and df.incidence_limit_deg == cell.incidence_max_deg
    np.testing.assert_allclose(df.world_T_tracker.homogeneous, cell.W_T_tracker.homogeneous, atol=1e-12)
    d = df.design("random")
    clr = df.pose_clearance(d.q_meas)
    assert clr.min() == pytest.approx(d.info["min_clearance_m"], abs=1e-12)
    coll = CollisionModel(cell, prune=False)
    Q = cell.robot.random_q(np.random.default_rng(3), 300)
    g = coll.evaluate(Q, with_grad=False)[:, coll.info.kind != INCID].min(axis=1)
    clr = df.pose_clearance(Q)
    close = g < 0.03  # the fixed base capsule (constant, >= 40 mm) is in the check, not in the rows
    assert close.sum() > 50
    np.testing.assert_allclose(clr[close], g[close], atol=1e-8)


def test_pairs_colliding_at_every_working_configuration_are_skipped(design_dict):
    """Without skip lists, pairs that overlap at the working configuration are skipped and said so."""
    d = copy.deepcopy(design_dict)
    d["cell"].pop("skip_pairs")
    df = load_design(d)
    note = next(n for n in df.notes if "in collision at every working configuration" in n)
    assert "link_2|link_4" in note and ("link_2", "link_4") in df.cell.skip_pairs
    assert "link_2|link_4" not in df.checker.names
    # what is left is clear at the working configuration
    assert np.all(df.checker.distances(df.q_work) >= 0)


@pytest.mark.parametrize("mutate, message", [
    (lambda d: d.pop("robot"), "missing field 'robot'"),
    (lambda d: d["designs"][1].pop("q_meas"), "designs[1] (param): missing field 'q_meas'"),
    (lambda d: d["designs"][0].update(q_meas=[[0.0] * 5]), "designs[0].q_meas: 5 joint values"),
    (lambda d: d["capsules"][2].update(link="link_99"), "unknown link 'link_99'"),
    (lambda d: d["half_spaces"][0].update(normal=[0, 0, 0]), "half_spaces[0].normal: zero vector"),
    (lambda d: d.update(tracker_T_base=[[1, 0], [0, 1]]), "tracker_T_base"),
    (lambda d: d.update(designs=[]), "no designs"),
])
def test_bad_design_files_name_the_field(mutate, message, design_dict):
    d = copy.deepcopy(design_dict)
    mutate(d)
    with pytest.raises(PinKpiOedError) as exc:
        load_design(d)
    assert message in str(exc.value) and "\n" not in str(exc.value)


def test_unreadable_files(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        load_design(tmp_path / "missing.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(InputError, match="bad.json: not valid JSON"):
        load_design(bad)


def test_nice_factor_and_ellipsoid():
    assert nice_factor(41_000) == 50_000 and nice_factor(13_000) == 10_000
    assert nice_factor(1.6) == 2.0 and fmt_factor(20000) == "20 000"
    C = np.diag([4.0, 1.0, 9.0]) * 1e-12
    r, V = confidence_ellipsoid(C, 0.95)
    np.testing.assert_allclose(np.sort(r), np.sqrt(7.814727903) * np.array([1, 2, 3]) * 1e-6, rtol=1e-8)
    assert np.linalg.det(V) == pytest.approx(1.0)


# ----------------------------------------------------------------------------- CLI
def test_cli_view_writes_the_static_page(design_path, tmp_path, capsys):
    """``view --criteria --figures --pose``: the page shows the chosen designs, paused at the chosen pose, the printed
    tr(C_s) are the file's, the figures are written; bad files, folders and poses are refused with exit code 2;
    ``--all-ghosts`` draws every pose (the page grows by more than 2 kB a ghost). The page paused by ``--pose`` is the
    first command's page: one run of the command draws what two runs drew."""
    from pin_kpi_oed.cli.app import main

    out = tmp_path / "view.html"
    assert main(["view", str(design_path), "--html", str(out), "--no-open", "--criteria", "random,kpi",
                 "--figures", str(tmp_path), "--pose", "kpi:3"]) == 0
    page = out.read_text()
    assert "KPI (A on C_s)" in page and "heuristic" in page and "A on C_p" not in page
    assert "a.seek(" in page, "the page is not paused at the pose --pose names"
    text = capsys.readouterr().out
    df = load_design(design_path)
    for d in (df.design("random"), df.design("kpi")):  # tr(C_s) in mm^2, as `pin-kpi-oed design` prints it
        assert f"tr(C_s) = {d.trace_cs_m2 * 1e6:.4e} mm^2" in text
    from PIL import Image

    for name in ("design_ellipsoids.png", "design_designs.png", "design_poses.png"):
        assert f"wrote {tmp_path / name}" in text
        with Image.open(tmp_path / name) as im:
            assert im.format == "PNG" and im.size[0] > 500 and len(im.getcolors(1 << 16) or range(300)) > 20
    assert main(["view", str(tmp_path / "nope.json"), "--html", str(out), "--no-open"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nope.json: no such file" in err[0]
    assert main(["view", str(design_path), "--html", str(tmp_path / "no_dir" / "x.html"), "--no-open"]) == 2
    assert main(["view", str(design_path), "--html", str(out), "--no-open", "--pose", "kpi:99"]) == 2
    assert "no measurement configuration 99 of design 'kpi'" in capsys.readouterr().err
    size = out.stat().st_size  # 16 poses per design: no ghosts by default, all of them with --all-ghosts
    assert main(["view", str(design_path), "--html", str(out), "--no-open", "--criteria", "random,kpi",
                 "--all-ghosts"]) == 0
    assert out.stat().st_size > size + 32 * 2000, "--all-ghosts did not draw the 32 poses of the two designs"


def test_stand_in_design_is_visible_and_clear():
    """The stand-in's poses keep 2 cm from everything by the optimiser's own constraint rows (numpy, closed
    form) and face the tracker; its ``kpi`` C_s is the C_s of eq. 19 of its poses."""
    d = stand_in_design("kr15", m=12, seed=1, n_sets=3)
    df = load_design(d)
    assert [x.criterion for x in df.designs] == ["random", "kpi"] and df.designs[1].label == "best-of-random"
    coll = CollisionModel(df.cell, prune=False)
    for x in df.designs:
        g = coll.evaluate(x.q_meas, with_grad=False)
        assert g[:, coll.info.kind != INCID].min() > 0.02 - 1e-9
        assert np.all(g[:, coll.info.kind == INCID] >= 0)  # incidence within 30 deg
        np.testing.assert_allclose(x.cov_s_m2, cs_oracle(df.model, x.q_meas, df.q_work), rtol=1e-8)
    assert df.pose_clearance(df.q_work)[0] > 0  # the working configuration is clear of the car


# ----------------------------------------------------------------------------- headless Chromium
def load_rgb(png: Path) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(png).convert("RGB")).astype(int)


@pytest.mark.skipif(find_browser() is None, reason="no Chromium/Chrome browser on PATH or at /usr/bin/chromium "
                    "(Debian: apt-get install chromium; .ci/run installs it)")
def test_static_page_renders_robot_and_ellipsoids_in_chromium(design_path, tmp_path):
    """Render the static page four times (all; without the ellipsoids; without the robot; paused at a
    measurement configuration) and check that the pixels that change are where the scene's camera
    projects the ellipsoids and the robot, that each ellipsoid shows its design's colour, and that
    the animation moves the robot to the measurement configuration. The four pages are drawn by one
    browser launch: each in its own W × H frame of a 2 × 2 grid page (a frame is a window of that size
    to the page in it), cut apart from one screenshot. Frames of 512 × 384 px: the browser's software WebGL costs
    about a third less CPU than at 1024 × 768, and every pixel count and margin below is the one set for
    1024 × 768 scaled by the area (W²) or the width (W); the projections scale by themselves."""
    browser = find_browser()
    df = load_design(design_path)
    tcp = df.tcp_world()[0]
    base = df.world_T_base.translation
    target = 0.5 * (tcp + base + [0, 0, 0.6])
    sc = build_scene(df, SceneOptions(ghosts=False, camera=(target, target + np.array([2.2, 1.6, 1.2]))))
    W, H = 512, 384
    a = (W / 1024) ** 2  # pixel counts below are set for 1024 x 768 frames: an area scales with W²
    pages = {}
    pages["all"] = sc.static_html(legend=False)
    sc.set_visible("ellipsoids", False)
    pages["no_ellipsoids"] = sc.static_html(legend=False)
    sc.set_visible("ellipsoids", True)
    sc.set_visible("robot", False)
    pages["no_robot"] = sc.static_html(legend=False)
    sc.set_visible("robot", True)
    step = ("kpi", 5)  # the animation paused at the 6th pose of the KPI design
    pages["pose"] = sc.static_html(legend=False, pose=step)
    for k, page in pages.items():
        (tmp_path / f"{k}.html").write_text(page)

    grid = "".join(f'<iframe src="{k}.html" style="left:{W * (i % 2)}px;top:{H * (i // 2)}px"></iframe>'
                   for i, k in enumerate(pages))
    (tmp_path / "grid.html").write_text(
        "<!DOCTYPE html><html><head><style>html, body {margin: 0; padding: 0; overflow: hidden} "
        f"iframe {{border: 0; width: {W}px; height: {H}px; position: absolute}}</style></head>"
        f"<body>{grid}</body></html>")

    def shoot_all(timeout_ms: int) -> dict[str, np.ndarray | None]:
        """The four pages from one screenshot of the grid page (None each when no screenshot was written)."""
        try:
            img = load_rgb(render_png(tmp_path / "grid.html", tmp_path / "grid.png", 2 * W, 2 * H, timeout_ms,
                                      browser))
        except PinKpiOedError:  # no screenshot written
            return dict.fromkeys(pages)
        return {k: img[H * (i // 2):H * (i // 2 + 1), W * (i % 2):W * (i % 2 + 1)] for i, k in enumerate(pages)}

    def rendered(img: np.ndarray | None) -> bool:
        # the scene is drawn when the robot's orange is on screen or (robot hidden) the floor's grey is
        if img is None or img.shape[:2] != (H, W):
            return False
        orange = (img[..., 0] > 180) & (img[..., 1] > 60) & (img[..., 1] < 150) & (img[..., 2] < 80)
        grey = (np.abs(img - [184, 184, 176]).sum(-1) < 60)
        return orange.sum() > 300 * a or grey.sum() > 5000 * a

    rb = df.robot
    data = rb.model.createData()

    def pose_hits(D: np.ndarray, C: np.ndarray) -> list[bool]:
        """At the projected joint origins of the paused measurement configuration: does the robot differ from
        the page without the robot there (the page has stepped to the pose)?"""
        from scipy.ndimage import binary_dilation

        diff_p = binary_dilation(np.abs(D - C).sum(-1) > 40, iterations=round(6 * W / 1024))
        pin.framesForwardKinematics(rb.model, data, df.design(step[0]).q_meas[step[1]])
        pts_k = [(df.world_T_base * data.oMi[j]).translation for j in rb.joint_ids[1:]]
        pts_k.append((df.world_T_base * data.oMf[rb.tool_frame_id]).translation)
        return [bool(diff_p[int(y), int(x)]) for x, y in sc.project(np.array(pts_k), W, H) if 0 <= x < W and 0 <= y < H]

    def stepped(imgs: dict) -> bool:
        D, C = imgs.get("pose"), imgs.get("no_robot")
        if not (rendered(D) and rendered(C)):
            return False
        hits = pose_hits(D, C)
        return len(hits) >= 4 and np.mean(hits) >= 0.8

    imgs: dict[str, np.ndarray | None] = {}
    # the screenshot is taken once the page has loaded, at the latest after timeout_ms: the four pages load in one
    # browser (three times the 5 s one page had); a loaded machine may need longer for the first frame and the step
    for timeout_ms in (15000, 30000):
        imgs = shoot_all(timeout_ms)
        if all(rendered(imgs[k]) for k in pages) and stepped(imgs):
            break
    for k in pages:
        assert rendered(imgs[k]), f"{k}: Chromium did not render the scene (WebGL?)"
    A, B, C = imgs["all"], imgs["no_ellipsoids"], imgs["no_robot"]

    # --- ellipsoids: changed pixels around the projected centres, in the designs' colours
    diff_e = np.abs(A - B).sum(-1) > 40
    assert diff_e.sum() > 300 * a, "the ellipsoids are not visible"
    yy, xx = np.mgrid[0:H, 0:W]
    ys, xs = np.nonzero(diff_e)
    px = sc.project(np.array([e.centre_world for e in sc.ellipsoids] + [e.tcp_world for e in sc.ellipsoids]), W, H)
    f = (H / 2) / np.tan(np.radians(37.5))
    depth = [np.dot(e.centre_world - sc.camera_position, (sc.camera_target - sc.camera_position) /
                    np.linalg.norm(sc.camera_target - sc.camera_position)) for e in sc.ellipsoids]
    palette = {k: np.array([(c >> 16) & 255, (c >> 8) & 255, c & 255]) for k, c in sc.colours.items()}
    for i, e in enumerate(sc.ellipsoids):
        r_px = f * e.radii_m.max() * sc.scale / depth[i]
        cx, cy = px[i]
        assert 0 < cx < W and 0 < cy < H
        near = diff_e & ((xx - cx) ** 2 + (yy - cy) ** 2 <= (1.2 * r_px + 3) ** 2)
        assert near.sum() > 0.3 * np.pi * (0.5 * r_px) ** 2, f"{e.design}: ellipsoid not drawn at its place"
        # its colour: the shaded design colour (hue) is closer to its own than to the others'
        rgb = A[near].astype(float)
        rgb = rgb[rgb.max(axis=1) > 40]
        chroma = rgb / np.linalg.norm(rgb, axis=1, keepdims=True)
        dist = {k: np.median(np.linalg.norm(chroma - v / np.linalg.norm(v), axis=1)) for k, v in palette.items()}
        assert min(dist, key=dist.get) == e.design, (e.design, dist)
    # nothing changes far away from the ellipsoids (their label sits just above them)
    span = np.abs(px[:, 0] - px[:, 0].mean()).max() + 200 * W / 1024
    far = (np.abs(xs - px[:, 0].mean()) > span) | (ys > px[:, 1].max() + 150 * W / 1024)
    assert far.sum() < 0.02 * xs.size

    # --- robot: changed pixels cover the projected joint origins, orange dominates
    diff_r = np.abs(A - C).sum(-1) > 40
    assert diff_r.sum() > 3000 * a, "the robot is not visible"
    pin.framesForwardKinematics(rb.model, data, df.q_work[0])
    pts = [(df.world_T_base * data.oMi[j]).translation for j in rb.joint_ids[1:]]
    pts.append((df.world_T_base * data.oMf[rb.tool_frame_id]).translation)
    from scipy.ndimage import binary_dilation

    grown = binary_dilation(diff_r, iterations=round(6 * W / 1024))
    hits = [grown[int(round(y)), int(round(x))] for x, y in sc.project(np.array(pts), W, H)
            if 0 <= x < W and 0 <= y < H]
    assert len(hits) >= 5 and np.mean(hits) >= 0.8, hits
    rgb = A[diff_r]
    orange = (rgb[:, 0] > rgb[:, 1] + 40) & (rgb[:, 1] > rgb[:, 2] + 20)
    assert orange.mean() > 0.4

    # --- stepping: paused at a measurement configuration, the robot is drawn there (not at q_work)
    D = imgs["pose"]
    hits = pose_hits(D, C)
    assert len(hits) >= 4 and np.mean(hits) >= 0.8, hits
    moved = np.abs(D - A).sum(-1) > 40
    assert moved.sum() > 1000 * a, "the robot did not move to the measurement configuration"


def test_program_animation_passes_the_via_poses_and_draws_the_ordered_path():
    """export --html: the animation's frames include the transition paths (every via pose is passed),
    the ordered path is drawn (reflector trace through the vias), and ghosts only for a handful of poses."""
    from pin_kpi_oed.viz.program_animation import animate_program

    df = load_design(stand_in_design("kr15", m=10, seed=1, n_sets=2), criteria=["kpi"])
    for opts, n in ((SceneOptions(animate=False), 0), (SceneOptions(animate=False, max_ghosts=10), 10)):
        paths = build_scene(df, opts).recorder.object_paths()  # 10 poses: ghosted only on request
        assert len({p.split("/")[4] for p in paths if p.startswith("/meshcat/ghosts/kpi/")}) == n
    Q = df.design("kpi").q_meas
    home = df.q_work[0]
    via = 0.5 * (Q[1] + Q[2]) + np.radians([10.0, -5.0, 5.0, 0.0, 0.0, 0.0])
    path = np.array([home, Q[0], Q[1], via, Q[2], Q[3], home])
    kinds = ["home", "measure", "measure", "via", "measure", "measure", "home"]
    sc = build_scene(df, SceneOptions(ghosts=False, animate=False))
    times = animate_program(sc, path, kinds, step_deg=4.0, fps=10)
    assert len(times) == 4 and np.all(np.diff(times) > 0)
    rec = sc.recorder
    anim = [c for c in rec.commands if c["type"] == "set_animation"][-1]
    beam = next(a["clip"] for a in anim["animations"] if a["path"] == "/meshcat/beam")
    pos = np.array([k["value"] for t in beam["tracks"] if t["name"] == ".position" for k in t["keys"]])
    trk = df.world_T_tracker.translation
    refl = df.reflector_world(path)
    # a frame holds the robot exactly at the via pose (the beam node sits between tracker and reflector)
    assert np.min(np.linalg.norm(pos - 0.5 * (trk + refl[3]), axis=1)) < 1e-9
    # and the frames between Q[1] and the via are intermediate poses (<= 4 deg joint steps)
    n_steps = int(np.ceil(np.max(np.abs(via - Q[1])) / np.radians(4.0)))
    mid = 0.5 * (trk + df.reflector_world((Q[1] + (via - Q[1]) * (1 / n_steps))[None])[0])
    assert np.min(np.linalg.norm(pos - mid, axis=1)) < 1e-9
    # the ordered path: a line through the reflector at every target, the via drawn as its own dot
    line = rec.object_dict("/meshcat/program/path")["object"]
    trace = np.frombuffer(line["geometries"][0]["data"]["attributes"]["position"]["array"].data, np.float32)
    trace = trace.reshape(-1, 3)
    assert line["object"]["type"] == "Line" and len(trace) > len(path)
    for p in refl:
        assert np.min(np.linalg.norm(trace - p, axis=1)) < 1e-5
    vias = rec.object_dict("/meshcat/program/via")["object"]["geometries"][0]["data"]["attributes"]["position"]
    np.testing.assert_allclose(np.frombuffer(vias["array"].data, np.float32).reshape(-1, 3), refl[[3]], atol=1e-5)
    meas = rec.object_dict("/meshcat/program/measure")["object"]["geometries"][0]["data"]["attributes"]["position"]
    assert np.frombuffer(meas["array"].data, np.float32).size == 3 * 4


def test_animation_keyframe_has_a_scale_exactly_where_numpy_calls_it_not_one():
    """An animation keyframe carries a scale track where np.allclose(scale, 1.0) is false (the rule the keyframes
    were written by), tested in Python on the few numbers: at and around the tolerance, NaN, inf, shrunk meshes."""
    from meshcat.animation import AnimationClip

    from pin_kpi_oed.viz.scene_parts import anim_set

    class Node:
        current_frame = 3

        def __init__(self):
            self.clip = AnimationClip()

        def get_clip(self):
            return self.clip

    tol = 1e-8 + 1e-5
    scales = [np.ones(3), [1.0, 1.0 + 0.99 * tol, 1.0 - 0.99 * tol], [1.0, 1.0 + 1.01 * tol, 1.0], [1.0 - 2 * tol] * 3,
              [1.0, 1.0 + 1e-5 + 5e-9, 1.0], [1e-3] * 3, [1.0, np.nan, 1.0], [np.inf, 1.0, 1.0], [1.0, 2.0, 1.0],
              np.array([1.0, 1.0 + tol, 1.0])]
    M = pin.SE3(pin.rpy.rpyToMatrix(0.1, -0.2, 0.3), np.array([0.1, 0.2, 0.3]))
    for scale in scales:
        node = Node()
        anim_set(node, M, np.asarray(scale, float))
        tracks = node.clip.tracks
        assert ("scale" in tracks) == (not np.allclose(np.asarray(scale, float), 1.0)), scale
        assert tracks["position"].values == [[0.1, 0.2, 0.3]] and tracks["position"].frames == [3]
        if "scale" in tracks:
            np.testing.assert_array_equal(tracks["scale"].values, [np.asarray(scale, float)])


def test_cli_view_states_the_tcp_sigma_design_states(design_dict, tmp_path, capsys):
    """The TCP sigma view prints is the design's: sqrt((tr(C_s) + held) / t) with the file's held_trace_m2 (what no
    measurement of the reflector determines), the number design writes as tcp_sigma_m, and one line says so."""
    from pin_kpi_oed.cli.app import main

    doc = json.loads(json.dumps(design_dict))
    t = len(doc["q_work"]) if "q_work" in doc else len(doc["cell"]["q_work"])
    held = 0.25e-6  # 0.5 mm of a held flange offset, m^2
    for e in doc["designs"]:
        e["held_trace_m2"] = held
        e["tcp_sigma_m"] = float(np.sqrt((e["trace_cs_m2"] + held) / t))
    p = tmp_path / "held.json"
    p.write_text(json.dumps(doc))
    assert main(["view", str(p), "--html", str(tmp_path / "v.html"), "--no-open", "--criteria", "random,kpi"]) == 0
    text = capsys.readouterr().out
    for e in doc["designs"]:
        if e["criterion"] in ("random", "kpi"):
            assert f"TCP sigma = {e['tcp_sigma_m'] * 1e6:10.4f} um" in text, (e["tcp_sigma_m"], text)
    assert "sqrt((tr(C_s) + held) / t)" in text and "held 0.25 mm^2" in text


def test_capsules_attach_to_a_link_that_shares_its_fixed_joints_name(tmp_path):
    """A URDF whose fixed joint and child link have one name (example-robot-data's Z1: 'gripperStator') has two
    Pinocchio frames of that name: the capsule goes on the link's body frame, not a refusal by Pinocchio."""
    from pin_kpi_oed.cell.cell import CapsuleSpec
    from pin_kpi_oed.viz.robot_geometry import capsule_geometry

    limit = '<limit lower="-3" upper="3" effort="1" velocity="1"/>'
    (tmp_path / "twin.urdf").write_text(
        '<robot name="twin"><link name="base_link"/>'
        f'<joint name="j1" type="revolute"><parent link="base_link"/><child link="l1"/><origin xyz="0 0 0.1"/>'
        f'<axis xyz="0 0 1"/>{limit}</joint><link name="l1"/>'
        f'<joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.3"/>'
        f'<axis xyz="0 1 0"/>{limit}</joint><link name="l2"/>'
        '<joint name="gripper" type="fixed"><parent link="l2"/><child link="gripper"/><origin xyz="0.2 0 0"/>'
        '</joint><link name="gripper"/></robot>')
    rb = load_robot(str(tmp_path / "twin.urdf"), tool_frame="gripper")
    assert sum(f.name == "gripper" for f in rb.model.frames) == 2  # the ambiguity the fix resolves
    gm = capsule_geometry(rb.model, [CapsuleSpec("gripper", np.zeros(3), np.array([0.05, 0.0, 0.0]), 0.02,
                                                 "gripper")])
    fr = rb.model.frames[gm.geometryObjects[0].parentFrame]
    assert fr.name == "gripper" and fr.type == pin.FrameType.BODY
