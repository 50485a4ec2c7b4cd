"""The robots ``load_robot`` keeps (:mod:`pin_kpi_oed.model.robot_cache`): a kept robot is the one a fresh load
builds, every caller gets a copy of its own, a file rewritten in place is read again, and the cache stays bounded."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from pin_kpi_oed.model import robot_cache
from pin_kpi_oed.model.robot import URDF_DIR, load_robot


def _same(a, b) -> None:
    """Every field of two robots equal, and nothing mutable shared."""
    assert a.model == b.model and a.model is not b.model
    assert a.data is not b.data
    for f in ("urdf_path", "name", "tool_frame", "tool_frame_id", "joint_ids", "joint_names", "locked_joints",
              "urdf_text", "notes"):
        assert getattr(a, f) == getattr(b, f), f
    for f in ("q_lower", "q_upper", "revolute"):
        assert np.array_equal(getattr(a, f), getattr(b, f)) and getattr(a, f) is not getattr(b, f), f
    assert (a.kinematics is None) == (b.kinematics is None)
    if a.kinematics is not None:
        assert a.kinematics == b.kinematics and a.kinematics.values is not b.kinematics.values


@pytest.mark.parametrize("name", ["ur10", "kr15_track", "panda", "ur5e"])
def test_a_kept_robot_is_the_one_a_fresh_load_builds(name):
    robot_cache.clear()
    fresh = load_robot(name)
    assert robot_cache.size() == 1
    kept = load_robot(name)
    _same(fresh, kept)
    robot_cache.clear()
    _same(load_robot(name), kept)  # parsed again: the same robot
    q = kept.neutral()
    assert kept.oMtool(q).isApprox(fresh.oMtool(q), 0.0)


def test_each_caller_gets_a_copy_of_its_own():
    robot_cache.clear()
    a = load_robot("ur10")
    a.model.jointPlacements[2] = pin.SE3(np.eye(3), np.array([1.0, 2.0, 3.0]))
    a.q_lower[0] = -0.1
    a.joint_names[0] = "changed"
    b = load_robot("ur10")
    b.q_upper[1] = 0.2
    c = load_robot("ur10")
    assert not np.allclose(c.model.jointPlacements[2].translation, [1.0, 2.0, 3.0])
    assert c.q_lower[0] != -0.1 and c.q_upper[1] != 0.2 and c.joint_names[0] != "changed"
    robot_cache.clear()
    _same(load_robot("ur10"), c)


def test_a_file_rewritten_in_place_is_read_again(tmp_path):
    robot_cache.clear()
    path = tmp_path / "arm.urdf"
    text = (URDF_DIR / "kr15.urdf").read_text()
    path.write_text(text)
    first = load_robot(path)
    j = first.joint_ids[1]
    old = first.model.jointPlacements[j].translation.copy()
    import xml.etree.ElementTree as ET

    root = ET.fromstring(text)
    origin = root.findall("joint")[1].find("origin")
    xyz = [float(v) for v in origin.get("xyz").split()]
    origin.set("xyz", " ".join(str(v + 0.125) for v in xyz))
    path.write_text(ET.tostring(root, encoding="unicode"))
    second = load_robot(path)
    assert np.allclose(second.model.jointPlacements[j].translation, old + 0.125, atol=1e-12)
    assert robot_cache.size() == 2


def test_the_cache_is_bounded(tmp_path):
    robot_cache.clear()
    text = (URDF_DIR / "kr15.urdf").read_text()
    for i in range(robot_cache.CACHE_SIZE + 3):
        path = tmp_path / f"arm{i}.urdf"
        path.write_text(text)
        load_robot(path)
        assert robot_cache.size() == min(i + 1, robot_cache.CACHE_SIZE)
    robot_cache.clear()
    assert robot_cache.size() == 0
