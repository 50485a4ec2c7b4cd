"""The robots :func:`~pin_kpi_oed.model.robot.load_robot` built in this process, kept by their file's bytes.

Loading a robot parses its URDF, builds the full Pinocchio model, reduces it to the chain and checks it (3–6 ms);
a copy of the built model costs ~0.1 ms. A study loads the same robot for its cell, its model file, its data's
header and each of its commands, so the last :data:`CACHE_SIZE` robots are kept, keyed on what the load reads: the
spec as given, the tool frame, the file's path and its bytes (a file rewritten in place is read again). Every
caller gets a copy of its own (Pinocchio model and data, joint lists, limits), so what one changes (a joint
placement, a limit) no other caller sees. A load with a UR kinematics file given is not kept.
"""

from __future__ import annotations

import copy
import dataclasses
import threading
from collections import OrderedDict
from pathlib import Path
from typing import Any

__all__ = ["CACHE_SIZE", "load_key", "cached", "keep", "clear", "size", "copy_robot"]

#: How many loaded robots are kept (the least recently asked leave first).
CACHE_SIZE = 8

_KEPT: OrderedDict[tuple, Any] = OrderedDict()
_LOCK = threading.Lock()


def load_key(spec: Any, tool_frame: str | None, path: Path) -> tuple | None:
    """The key of a load: (spec, tool frame, path, the file's bytes), or None when the file cannot be read (the
    load then says why).

    Args:
        spec: the robot spec as given to ``load_robot`` (a name or a URDF path).
        tool_frame: the tool frame asked for (None: the default).
        path: the file the spec resolves to (the URDF, or a UR type's kinematics file).

    Returns:
        The key, or None.
    """
    try:
        data = path.read_bytes()
    except OSError:
        return None
    return (str(spec), tool_frame, str(path), data)


def copy_robot(robot: Any) -> Any:
    """A copy of a :class:`~pin_kpi_oed.model.robot.Robot` that shares nothing mutable with it: the Pinocchio
    model copied (``pin.Model.copy``), new data for it, the joint lists, limits, notes and the UR kinematics copied.

    Args:
        robot: the robot.

    Returns:
        The copy.
    """
    model = robot.model.copy()
    kin = robot.kinematics
    if kin is not None:
        kin = dataclasses.replace(kin, values=kin.values.copy())
    return dataclasses.replace(
        robot, model=model, data=model.createData(), joint_ids=list(robot.joint_ids),
        joint_names=list(robot.joint_names), q_lower=robot.q_lower.copy(), q_upper=robot.q_upper.copy(),
        locked_joints=list(robot.locked_joints), revolute=copy.copy(robot.revolute), kinematics=kin,
        notes=list(robot.notes))


def cached(key: tuple | None) -> Any:
    """A copy of the robot kept under ``key`` (:func:`copy_robot`), or None (not kept, or no key)."""
    if key is None:
        return None
    with _LOCK:
        hit = _KEPT.get(key)
        if hit is None:
            return None
        _KEPT.move_to_end(key)
    return copy_robot(hit)


def keep(key: tuple | None, robot: Any) -> None:
    """Keep a copy of a freshly loaded robot under ``key`` (nothing without a key)."""
    if key is None:
        return
    kept = copy_robot(robot)
    with _LOCK:
        _KEPT[key] = kept
        _KEPT.move_to_end(key)
        while len(_KEPT) > CACHE_SIZE:
            _KEPT.popitem(last=False)


def clear() -> None:
    """Forget every kept robot (the next load of each parses its file)."""
    with _LOCK:
        _KEPT.clear()


def size() -> int:
    """How many robots are kept (at most :data:`CACHE_SIZE`)."""
    with _LOCK:
        return len(_KEPT)
