"""Simulated events for the calibration check: a calibrated robot, a change (a joint's offset, a bent tool, a moved
tracker, none), check rows measured on it, the verdict — and how often it is right.

Each event draws a robot (joint-placement errors), its calibration (the truth: the check tests the change, not the
calibration's own error), the event's change and the noisy check rows at the given poses (seeded). The verdict is
right when: no change → ``holds``; a moved tracker → ``holds`` or ``setup_moved`` (the robot did not change: no
false alarm); a joint offset → ``robot_changed`` naming that joint's offset (or its placement); a bent tool →
``robot_changed`` naming the tool.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.upkeep.check import check_calibration
from pin_kpi_oed.calibrated.model_file import CalibratedModel, Setup
from pin_kpi_oed.model.noise import NoiseModel

__all__ = ["EVENT_KINDS", "CheckEvent", "simulated_model", "simulate_event", "event_rates", "tcp_error_m",
           "recalibrate"]

EVENT_KINDS = ("none", "joint_offset", "tool", "tracker")


@dataclass
class CheckEvent:
    """One simulated event and its verdict.

    Attributes:
        kind: one of :data:`EVENT_KINDS`; joint: the changed joint (joint_offset), else "".
        verdict: the check's verdict; group: the group it named; right: whether the verdict is the right one.
        tcp_change_m: RMS displacement of the TCP at the working configurations by the robot's change (m, robot
            base frame); a change below the tolerance does not matter (``holds`` is right for it too).
        refit_error_m: RMS TCP error at the working configurations (tracker frame, m) of the verdict's re-fitted
            model against the changed robot (NaN unless the verdict re-fitted a group);
        recal_error_m: the same of a full re-calibration on ``Q_recal`` (NaN without).
    """

    kind: str
    joint: str
    verdict: str
    group: str
    right: bool
    tcp_change_m: float = 0.0
    result: object = field(default=None, repr=False)
    refit_error_m: float = float("nan")
    recal_error_m: float = float("nan")


def simulated_model(robot, q_work: np.ndarray, sigma_m: float, seed: int) -> CalibratedModel:
    """A calibrated model of ``robot`` with seeded joint-placement errors (0.1 mm, 0.2 mrad), a tracker 3 m away
    and a reflector 0.1 m beyond the tool frame, noise σ (m)."""
    rng = np.random.default_rng(seed)
    jp = np.concatenate([np.r_[rng.normal(0, 1e-4, 3), rng.normal(0, 2e-4, 3)] for _ in range(robot.nq)])
    T = pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, rng.uniform(-np.pi, np.pi)), np.array([2.5, 0.5, -0.3]))
    setup = Setup(T.homogeneous, np.array([0.05, 0.0, 0.1]))
    return CalibratedModel(robot, jp, setups={"A": setup}, noise=NoiseModel(sigma_xyz_m=(sigma_m,) * 3),
                           tcp_m=np.array([0.05, 0.0, 0.1]), default_station="A", q_work=q_work,
                           fit={"residual_sigma_m": [sigma_m] * 3})


def _truth(model: CalibratedModel, kind: str, rng: np.random.Generator, size: dict) -> tuple[CalibratedModel, str]:
    """The robot after the event (a copy of the model with the change)."""
    if kind == "joint_offset":
        j = int(rng.integers(1, model.robot.nq))          # the first joint's offset is a set-up change
        from pin_kpi_oed.upkeep.check import check_criterion  # noqa: F401  (the same axes)

        wm, _ = model.station_model()
        lin, ang = wm.joint_axes
        jp = model.joint_p.copy()
        jp[6 * j:6 * j + 6] += rng.choice([-1.0, 1.0]) * size["offset_rad"] * np.r_[lin[j], ang[j]]
        return dataclasses.replace(model, joint_p=jp), model.robot.joint_names[j]
    if kind == "tool":
        d = rng.normal(size=3)
        d *= size["tool_m"] / np.linalg.norm(d)
        setups = {k: dataclasses.replace(s, reflector_m=s.reflector_m + d) for k, s in model.setups.items()}
        return dataclasses.replace(model, setups=setups), ""
    if kind == "tracker":
        st = model.setups["A"]
        move = pin.exp6(np.r_[rng.normal(0, size["tracker_m"], 3), rng.normal(0, size["tracker_rad"], 3)])
        T = pin.SE3(st.tracker_T_base) * move
        return model.with_setup("A", dataclasses.replace(st, tracker_T_base=T.homogeneous)), ""
    return model, ""


def simulate_event(model: CalibratedModel, Q_check: np.ndarray, kind: str, seed: int, *, alpha: float = 0.05,
                   tolerance_m: float = 1e-4, size: dict | None = None, Q_recal: np.ndarray | None = None
                   ) -> CheckEvent:
    """One event: the change, the noisy check rows at ``Q_check`` (rad), the verdict.

    Args:
        size: the changes' sizes: ``offset_rad`` (5e-4), ``tool_m`` (5e-4), ``tracker_m`` (0.05), ``tracker_rad``
            (0.02).
        Q_recal: when given and the verdict re-fitted a group, also a full re-calibration (``identify``, every
            identifiable parameter and the set-up) on noisy rows of the changed robot at these poses, for the
            comparison of the TCP errors at the working configurations.
    """
    size = {"offset_rad": 5e-4, "tool_m": 5e-4, "tracker_m": 0.05, "tracker_rad": 0.02, **(size or {})}
    rng = np.random.default_rng(seed)
    truth, joint = _truth(model, kind, rng, size)
    sigma = np.asarray(model.noise.sigma_xyz_m)
    Y = truth.predict(Q_check, station="A") + rng.normal(size=(len(Q_check), 3)) * sigma
    data = MeasurementSet(list(model.robot.joint_names), Q_check, Y, source=f"simulated {kind} event")
    r = check_calibration(model, data, alpha=alpha, tolerance_m=tolerance_m, seed=seed)
    tcp = _tcp_change(model, truth) if kind in ("joint_offset", "tool") else 0.0
    if kind in ("joint_offset", "tool") and tcp < tolerance_m and r.verdict in ("holds", "setup_moved"):
        right = True
    elif kind == "none":
        right = r.verdict == "holds"
    elif kind == "tracker":
        right = r.verdict in ("holds", "setup_moved")
    elif kind == "tool":
        right = r.verdict == "robot_changed" and r.group == "tool"
    else:
        right = r.verdict == "robot_changed" and r.group.startswith(joint + " ")
    ev = CheckEvent(kind, joint, r.verdict, r.group, bool(right), tcp, r)
    if r.verdict == "robot_changed" and r.determined:
        ev.refit_error_m = tcp_error_m(r.model, truth, model)
        if Q_recal is not None:
            ev.recal_error_m = tcp_error_m(recalibrate(model, truth, Q_recal, seed), truth, model)
    return ev


def tcp_error_m(estimate: CalibratedModel, truth: CalibratedModel, ref: CalibratedModel) -> float:
    """RMS TCP error (m) at ``ref``'s working configurations of a model (its default station: registered on the
    changed robot's rows) against the changed robot, both in the tracker frame they were measured in; the TCP rides
    with each model's reflector (``ref``'s TCP offset from its reflector)."""
    pts = []
    for m in (estimate, truth):
        wm, p = m.station_model(None)
        wm.tcp_m = ref.tcp_m + (m.setups[m.station(None)].reflector_m - ref.setups[ref.station(None)].reflector_m)
        pts.append(wm.kpi(p, ref.q_work).reshape(-1, 3))
    return float(np.sqrt(np.mean(np.sum((pts[0] - pts[1]) ** 2, axis=1))))


def recalibrate(model: CalibratedModel, truth: CalibratedModel, Q: np.ndarray, seed: int) -> CalibratedModel:
    """A full re-calibration of the changed robot: noisy rows (the model's σ) at Q, ``identify`` from the nominal
    geometry (the set-up registered in closed form, every identifiable parameter fitted, no discrepancy)."""
    from pin_kpi_oed.identification.identify import identify
    from pin_kpi_oed.model.tracker import TrackerModel

    rng = np.random.default_rng(seed + 7)
    sigma = np.asarray(model.noise.sigma_xyz_m)
    Y = truth.predict(Q, station="A") + rng.normal(size=(len(Q), 3)) * sigma
    data = MeasurementSet(list(model.robot.joint_names), Q, Y, source="re-calibration")
    st = model.setups[model.station(None)]
    nominal = TrackerModel(model.robot, reflector_m=st.reflector_m, tcp_m=model.tcp_m, noise=model.noise)
    cm = identify(nominal, data, discrepancy="none").calibrated_model()
    cm.q_work = model.q_work
    return cm


def _tcp_change(model: CalibratedModel, truth: CalibratedModel) -> float:
    """RMS TCP displacement (m, robot base frame) between the model and the changed robot at the working
    configurations (the tool's change moves the TCP with the reflector)."""
    wm, p = model.station_model()
    wt, pt = truth.station_model()
    d_tool = truth.setups["A"].reflector_m - model.setups["A"].reflector_m
    wt.tcp_m = wt.tcp_m + d_tool
    R0, R1 = wm.tracker_pose(p).rotation, wt.tracker_pose(pt).rotation
    a = (wm.kpi(p, model.q_work) - wm.tracker_pose(p).translation) @ R0
    b = (wt.kpi(pt, model.q_work) - wt.tracker_pose(pt).translation) @ R1
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))))


def event_rates(events: list[CheckEvent]) -> dict:
    """Per kind: events, share right, share flagged (any verdict but holds / setup_moved), events whose change
    matters (TCP change at or above ``tolerance``: every event of a kind without a robot change counts)."""
    out = {}
    for kind in dict.fromkeys(e.kind for e in events):
        ev = [e for e in events if e.kind == kind]
        flagged = [e.verdict not in ("holds", "setup_moved") for e in ev]
        out[kind] = {"n": len(ev), "right": float(np.mean([e.right for e in ev])), "flagged": float(np.mean(flagged))}
    return out
