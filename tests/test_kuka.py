"""Tests of the KUKA-like URDF generator (pin_kpi_oed.model.kuka) and the shipped URDFs.

Reference values are the tables of shared/reference/kuka_kinematics.md (mm, deg),
copied here on purpose so that a change in the generator is caught.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from scipy.optimize import minimize_scalar

from pin_kpi_oed.model import kuka
from pin_kpi_oed.model.notional_arms import notional_arm, notional_arms
from pin_kpi_oed.errors import InputError

URDF_DIR = Path(__file__).resolve().parents[1] / "urdf"

# md table: d1, a1, a2, a3, d4, d6, reach (mm)
MD_GEOMETRY_MM = {
    "kr15": (675, 300, 650, 150, 600, 140, 1568.5),
    "kr300": (675, 350, 1150, -41, 1000, 240, 2500.8),
    "kr500": (1045, 500, 1300, -55, 1025, 290, 2826.5),
}
# md table: (lower, upper) per axis, degrees (KR 15 uses the KR 16-2 row)
MD_LIMITS_DEG = {
    "kr15": ((-185, 185), (-155, 35), (-130, 154), (-350, 350), (-130, 130), (-350, 350)),
    "kr300": ((-185, 185), (-140, -5), (-120, 155), (-350, 350), (-122.5, 122.5), (-350, 350)),
    "kr500": ((-185, 185), (-130, 20), (-100, 144), (-350, 350), (-120, 120), (-350, 350)),
}
GEOMS = {"kr15": kuka.KR15, "kr300": kuka.KR300, "kr500": kuka.KR500}
ROBOTS = sorted(GEOMS)
HOME = np.deg2rad([0.0, -90.0, 90.0, 0.0, 0.0, 0.0])


def _md(robot: str) -> dict[str, float]:
    d1, a1, a2, a3, d4, d6, reach = (v / 1000.0 for v in MD_GEOMETRY_MM[robot])
    return dict(d1=d1, a1=a1, a2=a2, a3=a3, d4=d4, d6=d6, reach=reach)


@pytest.fixture(scope="module", params=ROBOTS)
def loaded(request):
    robot = request.param
    path = URDF_DIR / f"{robot}.urdf"
    model = pin.buildModelFromUrdf(str(path))
    geom_model = pin.buildGeomFromUrdf(model, str(path), pin.GeometryType.COLLISION)
    return robot, path, model, geom_model


def _fk(model: pin.Model, q: np.ndarray):
    data = model.createData()
    pin.framesForwardKinematics(model, data, np.asarray(q, dtype=float))
    return data


def _wrist_centre(model, data) -> np.ndarray:
    return data.oMi[model.getJointId("joint_a5")].translation.copy()


def _a6_axis_world(model, data) -> np.ndarray:
    # joint_a6 axis is -x of link_6 (ROS-I convention)
    return data.oMi[model.getJointId("joint_a6")].rotation @ np.array([-1.0, 0.0, 0.0])


# --- shipped files -----------------------------------------------------------------------------
def test_geometry_constants_match_md_table():
    for robot, geom in GEOMS.items():
        md = _md(robot)
        for key in ("d1", "a1", "a2", "a3", "d4", "d6"):
            assert getattr(geom, key) == pytest.approx(md[key], abs=1e-12), (robot, key)
        assert geom.reach_m == pytest.approx(md["reach"], abs=5e-5)  # md reach rounded to 0.1 mm


@pytest.mark.parametrize("robot", ROBOTS)
def test_shipped_urdf_is_generator_output(robot):
    assert (URDF_DIR / f"{robot}.urdf").read_text(encoding="utf-8") == kuka.urdf_text(GEOMS[robot])


@pytest.mark.parametrize("robot", ROBOTS)
def test_urdf_declares_stand_in_values(robot):
    text = kuka.urdf_text(GEOMS[robot])
    assert "stand-in" in text and "NOT KUKA data" in text
    assert "stand-in" in kuka.__doc__ and "not KUKA data" in kuka.__doc__


def test_joints_and_frames(loaded):
    robot, _, model, _ = loaded
    assert model.nq == model.nv == 6
    assert list(model.names)[1:] == [f"joint_a{i}" for i in range(1, 7)]
    for jid in range(1, 7):
        assert model.joints[jid].shortname() in {"JointModelRX", "JointModelRY", "JointModelRZ",
                                                  "JointModelRevoluteUnaligned"}
    assert model.existFrame("tool0")
    for link in kuka.LINK_NAMES:
        assert model.existFrame(link)
    fixed = model.frames[model.getFrameId("joint_a6-tool0")]
    assert fixed.type == pin.FrameType.FIXED_JOINT
    assert model.frames[model.getFrameId("tool0")].parentJoint == model.getJointId("joint_a6")


def test_collision_cylinders(loaded):
    robot, _, model, geom_model = loaded
    geom = GEOMS[robot]
    objs = {o.name.rsplit("_", 1)[0]: o for o in geom_model.geometryObjects}
    assert sorted(objs) == sorted(kuka.LINK_NAMES)
    for link, obj in objs.items():
        assert obj.geometry.__class__.__name__ == "Cylinder", link
        assert obj.geometry.radius == pytest.approx(geom.capsule_radii[link], abs=1e-12)
        assert 2.0 * obj.geometry.halfLength > 0.01, link
        assert model.frames[obj.parentFrame].name == link
    # base cylinder: about z, bottom on the floor
    base = objs["base_link"]
    assert np.allclose(base.placement.rotation[:, 2], [0, 0, 1])
    assert base.placement.translation[2] - base.geometry.halfLength == pytest.approx(0.0, abs=1e-12)
    # upper-arm cylinder axis spans A2 -> A3 exactly
    up = objs["link_2"]
    ends = [up.placement.act(np.array([0.0, 0.0, s * up.geometry.halfLength])) for s in (-1, 1)]
    assert np.allclose(sorted(e[0] for e in ends), [0.0, geom.a2], atol=1e-12)
    assert np.allclose([e[1:] for e in ends], 0.0, atol=1e-12)


def test_capsule_radii_follow_md_table():
    assert kuka.KR15.capsule_radii == {"base_link": 0.39, "link_1": 0.37, "link_2": 0.13, "link_3": 0.21,
                                       "link_4": 0.09, "link_5": 0.11, "link_6": 0.04}
    kr300 = {"base_link": 0.57, "link_1": 0.61, "link_2": 0.38, "link_3": 0.57,
             "link_4": 0.10, "link_5": 0.18, "link_6": 0.10}
    assert kuka.KR300.capsule_radii == kr300
    ratio = 2.8265 / 2.5008
    for link, r in kr300.items():
        assert kuka.KR500.capsule_radii[link] == pytest.approx(r * ratio, rel=1e-4)


def test_inertias_and_masses(loaded):
    robot, _, model, _ = loaded
    masses = [model.inertias[j].mass for j in range(1, 7)]
    assert sum(masses) == pytest.approx(GEOMS[robot].total_mass_kg, rel=1e-12)
    ratio = np.array(masses) / masses[0]
    assert np.allclose(ratio, np.array([94, 47, 35.25, 23.5, 23.5, 11.75]) / 94.0)
    for j in range(1, 7):
        eig = np.linalg.eigvalsh(model.inertias[j].inertia)
        assert np.all(eig > 0.0)
        assert eig[0] + eig[1] >= eig[2] - 1e-9  # triangle inequality of a physical body
    # gravity torques at HOME are finite and A2 carries the biggest static load
    data = model.createData()
    tau = pin.computeGeneralizedGravity(model, data, HOME)
    assert np.all(np.isfinite(tau))
    assert abs(tau[1]) >= abs(tau[2]) > 0.0


def test_joint_limits_equal_md_table(loaded):
    robot, _, model, _ = loaded
    lower = np.deg2rad([lim[0] for lim in MD_LIMITS_DEG[robot]])
    upper = np.deg2rad([lim[1] for lim in MD_LIMITS_DEG[robot]])
    assert np.allclose(model.lowerPositionLimit, lower, rtol=0.0, atol=1e-12)
    assert np.allclose(model.upperPositionLimit, upper, rtol=0.0, atol=1e-12)
    assert np.all(model.velocityLimit > 0.0) and np.all(model.effortLimit > 0.0)
    assert np.all(HOME >= model.lowerPositionLimit) and np.all(HOME <= model.upperPositionLimit)


# --- kinematics ----------------------------------------------------------------------------------
def test_zero_configuration(loaded):
    robot, _, model, _ = loaded
    md = _md(robot)
    data = _fk(model, np.zeros(6))
    a2_origin = data.oMi[model.getJointId("joint_a2")].translation
    assert np.allclose(a2_origin, [md["a1"], 0.0, md["d1"]], atol=1e-12)
    a3_origin = data.oMi[model.getJointId("joint_a3")].translation
    assert np.allclose(a3_origin, [md["a1"] + md["a2"], 0.0, md["d1"]], atol=1e-12)  # upper arm along +x
    wc = _wrist_centre(model, data)
    assert np.allclose(wc, [md["a1"] + md["a2"] + md["d4"], 0.0, md["d1"] + md["a3"]], atol=1e-12)
    tool0 = data.oMf[model.getFrameId("tool0")]
    flange = [md["a1"] + md["a2"] + md["d4"] + md["d6"], 0.0, md["d1"] + md["a3"]]
    assert np.allclose(tool0.translation, flange, atol=1e-12)
    # REP-199: z out of the flange (+x here), x = link_6 -z
    assert np.allclose(tool0.rotation, [[0, 0, 1], [0, 1, 0], [-1, 0, 0]], atol=1e-12)


def test_kr15_flange_at_zero_configuration():
    model = pin.buildModelFromUrdf(str(URDF_DIR / "kr15.urdf"))
    data = _fk(model, np.zeros(6))
    assert np.allclose(data.oMf[model.getFrameId("tool0")].translation, [1.690, 0.0, 0.825], atol=1e-12)


def test_joint_axes_directions(loaded):
    _, _, model, _ = loaded
    data = _fk(model, np.zeros(6))
    expected = {1: [0, 0, -1], 2: [0, 1, 0], 3: [0, 1, 0], 4: [-1, 0, 0], 5: [0, 1, 0], 6: [-1, 0, 0]}
    for jid, axis in expected.items():
        jdata = model.joints[jid]
        # motion subspace of a revolute joint: angular part in the joint frame
        S = np.asarray(jdata.createData().S)
        w_local = S[3:, 0] if S.ndim == 2 else S[3:]
        assert np.allclose(data.oMi[jid].rotation @ w_local, axis, atol=1e-12), jid
    # positive A2 lowers the upper arm tip (rotation about +y takes +x to -z)
    q = np.zeros(6)
    q[1] = 0.1
    d = _fk(model, q)
    assert d.oMi[model.getJointId("joint_a3")].translation[2] < data.oMi[model.getJointId("joint_a3")].translation[2]


def test_reach_matches_md_formula(loaded):
    robot, _, model, _ = loaded
    md = _md(robot)
    formula = md["a1"] + md["a2"] + math.hypot(md["a3"], md["d4"])
    assert formula == pytest.approx(md["reach"], abs=5e-5)

    a2_id = model.getJointId("joint_a2")

    def wc_from_a2_axis(a3_angle: float) -> float:
        q = np.zeros(6)
        q[2] = a3_angle
        data = _fk(model, q)
        d = _wrist_centre(model, data) - data.oMi[a2_id].translation
        return float(math.hypot(d[0], d[2]))  # distance from the A2 axis (along y)

    # maximise the wrist-centre distance from the A2 axis over A3
    best = max(np.linspace(-math.pi, math.pi, 73), key=wc_from_a2_axis)
    res = minimize_scalar(lambda t: -wc_from_a2_axis(t), bounds=(best - 0.1, best + 0.1), method="bounded",
                          options={"xatol": 1e-10})
    stretch = math.atan2(md["a3"], md["d4"])
    assert res.x == pytest.approx(stretch, abs=1e-4)
    assert -res.fun == pytest.approx(md["a2"] + math.hypot(md["a3"], md["d4"]), abs=1e-6)

    # A2 = 0 and the stretching A3: arm horizontal at the height of A2, wrist centre at the reach
    q = np.zeros(6)
    q[2] = stretch
    wc = _wrist_centre(model, _fk(model, q))
    assert wc[2] == pytest.approx(md["d1"], abs=1e-9)
    assert math.hypot(wc[0], wc[1]) == pytest.approx(formula, abs=1e-6)
    assert math.hypot(wc[0], wc[1]) == pytest.approx(GEOMS[robot].reach_m, abs=1e-6)


def test_home_pose(loaded):
    robot, _, model, _ = loaded
    md = _md(robot)
    data = _fk(model, HOME)
    a3_origin = data.oMi[model.getJointId("joint_a3")].translation
    assert np.allclose(a3_origin, [md["a1"], 0.0, md["d1"] + md["a2"]], atol=1e-12)  # upper arm vertical
    wc = _wrist_centre(model, data)
    assert np.allclose(wc, [md["a1"] + md["d4"], 0.0, md["d1"] + md["a2"] + md["a3"]], atol=1e-12)
    tool0 = data.oMf[model.getFrameId("tool0")]
    assert np.allclose(tool0.translation, wc + [md["d6"], 0.0, 0.0], atol=1e-12)
    assert np.allclose(tool0.rotation[:, 2], [1, 0, 0], atol=1e-12)  # flange faces forward
    assert np.allclose(tool0.rotation[:, 0], [0, 0, -1], atol=1e-12)
    # A5 = +90 deg from HOME: flange faces down
    q = HOME.copy()
    q[4] = math.pi / 2
    data = _fk(model, q)
    tool0 = data.oMf[model.getFrameId("tool0")]
    assert np.allclose(tool0.rotation[:, 2], [0, 0, -1], atol=1e-12)
    assert np.allclose(tool0.translation, wc - [0.0, 0.0, md["d6"]], atol=1e-12)


def test_tool0_z_along_a6_axis_away_from_wrist(loaded):
    robot, _, model, _ = loaded
    rng = np.random.default_rng(0)
    samples = [rng.uniform(model.lowerPositionLimit, model.upperPositionLimit) for _ in range(20)]
    for q in [HOME, np.zeros(6)] + samples:
        data = _fk(model, q)
        tool0 = data.oMf[model.getFrameId("tool0")]
        z = tool0.rotation[:, 2]
        wc = _wrist_centre(model, data)
        axis = _a6_axis_world(model, data)
        assert abs(abs(z @ axis) - 1.0) < 1e-12  # parallel to the A6 axis
        out = tool0.translation - wc
        assert np.linalg.norm(out) == pytest.approx(GEOMS[robot].d6, abs=1e-12)
        assert np.allclose(out, GEOMS[robot].d6 * z, atol=1e-12)  # flange on the A6 axis, z pointing away


# --- notional arms ---------------------------------------------------------------------------------
def test_notional_grid():
    arms = notional_arms()
    assert len(arms) == 90
    assert len({a.name for a in arms}) == 90
    assert len({(a.a2, a.d4) for a in arms}) == 90
    lambdas = sorted({a.a2 for a in arms})
    mus = sorted({a.d4 for a in arms})
    assert np.allclose(lambdas, np.arange(650, 1101, 50) / 1000.0, atol=1e-15) and len(lambdas) == 10
    assert np.allclose(mus, np.arange(600, 1001, 50) / 1000.0, atol=1e-15) and len(mus) == 9
    for a in arms:
        assert (a.d1, a.a1, a.a3, a.d6) == (kuka.KR15.d1, kuka.KR15.a1, kuka.KR15.a3, kuka.KR15.d6)
        assert a.q_lower == kuka.KR15.q_lower and a.q_upper == kuka.KR15.q_upper
        assert a.name == f"notional_a2_{round(a.a2 * 1000):04d}_d4_{round(a.d4 * 1000):04d}"


def test_notional_corner_is_kr15():
    corner = notional_arms()[0]
    assert corner.name == "notional_a2_0650_d4_0600"
    assert corner == notional_arm(0.650, 0.600)
    for f in ("d1", "a1", "a2", "a3", "d4", "d6", "q_lower", "q_upper", "capsule_radii", "total_mass_kg",
              "velocity_limits", "effort_limits"):
        assert getattr(corner, f) == getattr(kuka.KR15, f), f
    assert kuka.urdf_text(corner).replace(corner.name, kuka.KR15.name) == kuka.urdf_text(kuka.KR15)


def test_notional_urdfs_load_with_expected_reach():
    for arm in notional_arms():
        model = pin.buildModelFromXML(kuka.urdf_text(arm))
        q = np.zeros(6)
        q[2] = math.atan2(arm.a3, arm.d4)
        wc = _wrist_centre(model, _fk(model, q))
        assert math.hypot(wc[0], wc[1]) == pytest.approx(arm.a1 + arm.a2 + math.hypot(arm.a3, arm.d4), abs=1e-9)


@pytest.mark.parametrize("bad", [(0.0, 0.6), (-0.7, 0.6), (0.7, float("nan")), (float("inf"), 0.6)])
def test_notional_arm_rejects_bad_lengths(bad):
    with pytest.raises(InputError):
        notional_arm(*bad)


def test_geometry_validation():
    with pytest.raises(InputError):
        kuka.KukaGeometry(**{**kuka.KR15.__dict__, "q_lower": (0.0,) * 5})
    with pytest.raises(InputError):
        kuka.KukaGeometry(**{**kuka.KR15.__dict__, "capsule_radii": {"base_link": 0.1}})
    with pytest.raises(InputError):
        kuka.KukaGeometry(**{**kuka.KR15.__dict__, "d4": -1.0})
    with pytest.raises(InputError):
        kuka.KukaGeometry(**{**kuka.KR15.__dict__, "name": "bad name"})


# --- writing -----------------------------------------------------------------------------------------
def test_write_urdf_atomic(tmp_path):
    dest = tmp_path / "sub" / "arm.urdf"
    out = kuka.write_urdf(kuka.KR300, dest)
    assert out == dest
    assert dest.read_text(encoding="utf-8") == kuka.urdf_text(kuka.KR300)
    kuka.write_urdf(kuka.KR15, dest)  # overwrite in place
    assert dest.read_text(encoding="utf-8") == kuka.urdf_text(kuka.KR15)
    assert sorted(p.name for p in dest.parent.iterdir()) == ["arm.urdf"]  # no temporary file left
    model = pin.buildModelFromUrdf(str(dest))
    assert model.name == kuka.KR15.name


# --- linear track ----------------------------------------------------------------------------------------
def test_shipped_track_urdf_is_generator_output():
    assert (URDF_DIR / "kr15_track.urdf").read_text(encoding="utf-8") == kuka.urdf_text(kuka.KR15, kuka.KR15_TRACK)


def test_track_urdf_structure():
    path = URDF_DIR / "kr15_track.urdf"
    model = pin.buildModelFromUrdf(str(path))
    assert model.name == "kuka_kr15_2_track"
    jid = model.getJointId("joint_e1")
    assert jid == 1 and model.joints[jid].shortname() == "JointModelPY"
    assert model.names[int(model.parents[model.getJointId("joint_a1")])] == "joint_e1"
    assert (model.lowerPositionLimit[0], model.upperPositionLimit[0]) == (0.0, 6.4)
    assert np.allclose(model.jointPlacements[jid].translation, [0.0, 0.0, 0.7])
    geom = pin.buildGeomFromUrdf(model, str(path), pin.GeometryType.COLLISION)
    rail = next(g for g in geom.geometryObjects if model.frames[g.parentFrame].name == "track_rail")
    # the rail runs along y from -0.5 to 6.9 m, its axis 0.15 m above the rail frame
    ends = [rail.placement.act(np.array([0.0, 0.0, s * rail.geometry.halfLength])) for s in (-1, 1)]
    assert np.allclose(sorted(ends, key=lambda e: e[1]), [[0.0, -0.5, 0.15], [0.0, 6.9, 0.15]], atol=1e-12)
    base = model.inertias[jid]
    assert base.mass == kuka.KR15_TRACK.carriage_mass_kg


@pytest.mark.parametrize("field,value", [("upper_m", 0.0), ("velocity_m_s", 0.0), ("rail_radius_m", float("nan")),
                                         ("joint_name", "joint_a1"), ("overhang_m", -1.0)])
def test_track_validation(field, value):
    with pytest.raises(InputError, match=field):
        kuka.LinearTrack(**{field: value})
