"""The calibration check on simulated robots that are not the package's model: each robot has its own geometric
errors on every joint parameter and an unmodelled gear harmonic, is calibrated by the package (``identify`` on noisy
rows at designed poses, the discrepancy as ``identify`` decides), checked at the poses ``check design`` sizes for the
verdict, then changed — or not — and checked again.

Per robot (seeded): a UR10, a tracker where :func:`~pin_kpi_oed.simulation.simulator.default_tracker_pose` puts
it, a reflector 50 mm off the flange axis and 100 mm out (the TCP: the point the tolerance is about), 5 working
configurations; the truth draws every joint-placement parameter, the reflector and the tracker pose from
:class:`~pin_kpi_oed.model.tolerances.Tolerances` (0.5 mm, 1 mrad; the reflector 1 mm) and a gear harmonic of
every joint (orders 1 and 2, 50 µrad); the calibration measures it at ``n_cal`` D-optimal poses of a seeded pool
(tracker noise σ per axis). An event changes the truth by a size k × τ at the working TCPs (RMS over the working
configurations, linearised) and measures the check poses on it:

* ``none`` — nothing changes (fresh noise);
* ``joint_offset`` — one joint's offset (joints 2–6; the first is a set-up change);
* ``tool`` — the reflector (with the TCP) moves by k τ in a random direction;
* ``tracker`` — the tracker pose moves by a random twist that displaces the working TCPs by k τ;
* ``placement_tracker`` (:data:`COMBINED_KINDS`) — one joint's placement (joints 2–6, every parameter of it) moves
  in a random direction that displaces the working TCPs by k τ, and the tracker moves as in ``tracker``: a change of
  many columns whose re-fit needs the set-up re-registered on the check rows (the kind where a re-calibration is
  expected better).

The verdict is right when: no change (or a change below τ) → ``holds``; a joint offset or placement above τ (with the
tracker moved or not) → the robot changed (or re-calibrate) naming that joint (its offset or placement); the tool above
τ → naming the tool; the tracker above τ → ``setup_moved``. For every change shown above τ, the TCP error at the working
configurations (RMS 3-D, the true tracker frame) of the verdict's re-fitted model and of a re-calibration (``identify``
on fresh rows of the changed robot at the calibration's poses) are measured, to judge the verdict's choice between them.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["CHANGE_KINDS", "COMBINED_KINDS", "SimulatedRobot", "RobotEvent", "simulated_robot", "robot_event",
           "clopper_pearson"]

CHANGE_KINDS = ("none", "joint_offset", "tool", "tracker")
#: Changes of two parts at once (not in :data:`CHANGE_KINDS`, whose events the published figures are):
#: ``placement_tracker``, a joint's placement (all its parameters) changed and the tracker moved, each by k τ.
COMBINED_KINDS = ("placement_tracker",)
REFLECTOR_M = np.array([0.05, 0.0, 0.1])


@dataclass
class SimulatedRobot:
    """A simulated robot, its calibration and its check poses.

    Attributes:
        nominal: the nominal measurement model (tracker pose, reflector, noise); p: the true raw parameters;
        effects: the unmodelled effects ``[(effect, θ)]``; cm: the calibrated model (working configurations set);
        Q_cal: the calibration's poses (rad); Q_check: the check poses (``check design``, sized); qw: the working
            configurations (rad); seed: the robot's seed; sizing: the check design's ``poses_needed`` (0: not
            reached) and its verdict power.
    """

    nominal: Any
    p: np.ndarray
    effects: list
    cm: Any
    Q_cal: np.ndarray
    Q_check: np.ndarray
    qw: np.ndarray
    seed: int
    sizing: dict = field(default_factory=dict)


@dataclass
class RobotEvent:
    """One event and its verdict.

    Attributes:
        kind, joint: the change (:data:`CHANGE_KINDS`; the joint of a joint offset); factor: its size in units of the
            tolerance (asked); tcp_change_m: its true RMS displacement of the working TCPs (m).
        verdict, group, exit_code: the check's; change_tcp_m, change_tcp_sigma_m: what it estimated.
        right: whether the verdict is the right one (module docstring).
        alike: the other parts the verdict named ("X or Y"); sized: False when it could not size the change.
        groups: the four groups of least remaining χ² (the check's table: what the naming chose among).
        refit_error_m, recal_error_m: the true RMS TCP error at the working configurations of the verdict's
            re-fitted model and of a re-calibration (NaN unless a change was shown above τ);
        predicted_refit_m, predicted_recal_m: the verdict's expected TCP errors of each.
        calibration_error_m: the true RMS TCP error of the robot's calibration before the change (m): the part of
            its error a re-fit carries and a re-calibration draws afresh.
        recal_draws_m: the true TCP errors of re-calibrations on ``recal_draws`` fresh noisy draws of the rows (m;
            the first is ``recal_error_m``): the spread of the realisation a verdict cannot foresee.
        setup_held: the verdict's re-fit kept the model's set-up (False: re-registered on the check rows).
    """

    kind: str
    joint: str
    factor: float
    tcp_change_m: float
    verdict: str
    group: str
    exit_code: int
    right: bool
    change_tcp_m: float = float("nan")
    change_tcp_sigma_m: float = float("nan")
    refit_error_m: float = float("nan")
    recal_error_m: float = float("nan")
    predicted_refit_m: float = float("nan")
    predicted_recal_m: float = float("nan")
    time_s: float = 0.0
    alike: list = field(default_factory=list)
    sized: bool = True
    groups: list = field(default_factory=list)
    calibration_error_m: float = float("nan")
    recal_draws_m: list = field(default_factory=list)
    setup_held: bool = False


def simulated_robot(seed: int, *, n_cal: int = 60, noise_m: float = 2.5e-5, tolerance_m: float = 1e-4,
                    alpha: float = 0.05, m_check: int | None = None, m_max: int = 30) -> SimulatedRobot:
    """A robot that is not the model, calibrated by the package, with its check poses (module docstring).

    Args:
        seed: the robot's seed (truth, poses, noise).
        n_cal: calibration poses; noise_m: tracker noise σ per axis (m).
        tolerance_m, alpha: what the check is designed for.
        m_check: check poses (None: what ``check design`` sizes for the verdict, at least 10, at most ``m_max``).
    """
    from pin_kpi_oed.effects.joint_angle import GearHarmonic
    from pin_kpi_oed.identification.identify import identify
    from pin_kpi_oed.model.noise import NoiseModel
    from pin_kpi_oed.model.robot import load_robot
    from pin_kpi_oed.model.tolerances import Tolerances
    from pin_kpi_oed.model.tracker import TrackerModel
    from pin_kpi_oed.oed.identifiability import analyse
    from pin_kpi_oed.oed.objective import DesignCriterion
    from pin_kpi_oed.simulation.simulator import default_tracker_pose, random_truth, simulate
    from pin_kpi_oed.upkeep.check_design import design_check

    rb = load_robot("ur10")
    rng = np.random.default_rng(seed)
    noise = NoiseModel(sigma_xyz_m=(noise_m,) * 3)
    model = TrackerModel(rb, tracker_T_base=default_tracker_pose(rb), reflector_m=REFLECTOR_M, tcp_m=REFLECTOR_M,
                         noise=noise)
    qw = 0.5 * rng.uniform(rb.q_lower, rb.q_upper, size=(5, rb.nq))
    pool = rng.uniform(rb.q_lower, rb.q_upper, size=(400, rb.nq))
    base = analyse(model, pool[:100]).base
    Q_cal = pool[DesignCriterion(model, base, criterion="D").select(pool, n_cal, seed=seed).indices]
    p = random_truth(model, Tolerances(5e-4, 1e-3, reflector_m=1e-3), seed=seed)
    eff = GearHarmonic(rb)
    effects = [(eff, rng.normal(size=len(eff.param_names(rb))) * 5e-5)]
    train = simulate(model, Q_cal, p, effects, seed=seed + 1)
    nominal = TrackerModel(rb, reflector_m=REFLECTOR_M, tcp_m=REFLECTOR_M, noise=noise)
    cm = identify(nominal, train, Q_work=qw).calibrated_model()
    cm.q_work = qw
    d = design_check(cm, m=10, tolerance_m=tolerance_m, alpha=alpha, pool_size=200, seed=seed, n_random=1)
    need = d.poses_needed
    m = m_check or (min(max(need, 10), m_max) if need else m_max)
    if m != 10:
        d = design_check(cm, m=m, tolerance_m=tolerance_m, alpha=alpha, pool_size=200, seed=seed, n_random=1,
                         size=False)
    return SimulatedRobot(model, p, effects, cm, Q_cal, d.Q, qw, seed,
                          sizing={"poses_needed": need, "m": m, "verdict_power": min(d.verdict_power.values())})


def _true_tcp(robot: SimulatedRobot, p: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """The true TCP (the reflector: nominal offset + its true error) at Q in the true tracker frame, (k, 3) m."""
    from pin_kpi_oed.simulation.simulator import simulate
    from pin_kpi_oed.model.noise import NoiseModel

    quiet = NoiseModel(sigma_xyz_m=(1e-15,) * 3)
    return simulate(robot.nominal, Q, p, robot.effects, noise=quiet, seed=0).position_m


def _changed_truth(robot: SimulatedRobot, kind: str, factor: float, tol: float, rng: np.random.Generator
                   ) -> tuple[np.ndarray, str]:
    """The true parameters after a change of ``factor`` × τ at the working TCPs (linearised), and the joint."""
    wm = robot.nominal
    L = wm.layout
    p = robot.p.copy()
    E = wm.kpi_jacobian(p, robot.qw)
    t = len(robot.qw)

    def scaled(cols: np.ndarray, d: np.ndarray) -> np.ndarray:
        size = np.linalg.norm(E[:, cols] @ d) / np.sqrt(t)
        return d * (factor * tol / size)

    if kind == "joint_offset":
        j = int(rng.integers(1, wm.robot.nq))
        lin, ang = wm.joint_axes
        cols = np.arange(L.joint_slice(j).start, L.joint_slice(j).stop)
        p[cols] += rng.choice([-1.0, 1.0]) * scaled(cols, np.r_[lin[j], ang[j]])
        return p, wm.robot.joint_names[j]
    if kind == "tool":
        d = rng.normal(size=3)
        p[L.reflector] += d * (factor * tol / np.linalg.norm(d))
        return p, ""
    if kind == "tracker":
        cols = np.arange(L.tracker.start, L.tracker.stop)
        p[cols] += scaled(cols, np.r_[rng.normal(size=3), rng.normal(size=3) / 1.5])
        return p, ""
    if kind == "placement":
        j = int(rng.integers(1, wm.robot.nq))
        cols = np.arange(L.joint_slice(j).start, L.joint_slice(j).stop)
        p[cols] += scaled(cols, np.r_[rng.normal(size=3), rng.normal(size=3) / 1.5][:len(cols)])
        return p, wm.robot.joint_names[j]
    if kind == "placement_tracker":
        moved, joint = _changed_truth(robot, "placement", factor, tol, rng)
        both, _ = _changed_truth(dataclasses.replace(robot, p=moved), "tracker", factor, tol, rng)
        return both, joint
    return p, ""


def _right(kind: str, joint: str, verdict: str, group: str, big: bool, alike: tuple = ()) -> bool:
    """Whether the verdict is right (module docstring); a verdict naming "X or Y" (parts the check rows do not tell
    apart) is right when the truth is among them."""
    if kind == "none" or not big:
        return verdict == "holds"
    if kind == "tracker":
        return verdict == "setup_moved"
    named = verdict in ("robot_changed", "recalibrate")
    parts = [group.rsplit(" ", 1)[0] if group != "tool" else "tool", *alike]
    return named and bool(group) and (("tool" if kind == "tool" else joint) in parts)


def robot_event(robot: SimulatedRobot, kind: str, factor: float, seed: int, *, tolerance_m: float = 1e-4,
                alpha: float = 0.05, recalibrate: bool = True, recal_draws: int = 1) -> RobotEvent:
    """One event on a simulated robot (module docstring): the change, the check rows, the verdict, and for a change
    shown above τ the true TCP errors of the re-fit and of a re-calibration.

    Args:
        robot: the robot; kind: one of :data:`CHANGE_KINDS`; factor: the change's size in units of τ.
        seed: seed of the change's direction and of the rows' noise.
        recalibrate: also re-calibrate when a change is shown above τ (the expensive part).
        recal_draws: re-calibrations on this many seeded fresh draws of the rows' noise (the first is the event's).

    Returns:
        The event (:class:`RobotEvent`).
    """
    from pin_kpi_oed.identification.identify import identify
    from pin_kpi_oed.model.tracker import TrackerModel
    from pin_kpi_oed.simulation.simulator import simulate
    from pin_kpi_oed.upkeep.check import check_calibration

    t0 = time.perf_counter()
    rng = np.random.default_rng(seed)
    p, joint = _changed_truth(robot, kind, factor, tolerance_m, rng) if kind != "none" else (robot.p, "")
    before, after = _true_tcp(robot, robot.p, robot.qw), _true_tcp(robot, p, robot.qw)
    if kind == "tracker":        # the set-up's change: the working TCPs as the tracker sees them
        tcp_change = float(np.sqrt(np.mean(np.sum((after - before) ** 2, axis=1))))
    else:                        # the robot's change: the TCP in the robot's base frame (the tracker as before)
        tracker = robot.nominal.layout.tracker
        robot_only = p.copy()
        robot_only[tracker] = robot.p[tracker]
        T = robot.nominal.tracker_pose(robot.p)
        moved = _true_tcp(robot, robot_only, robot.qw)
        tcp_change = float(np.sqrt(np.mean(np.sum(((moved - before) @ T.rotation) ** 2, axis=1))))
    rows = simulate(robot.nominal, robot.Q_check, p, robot.effects, seed=seed + 11)
    r = check_calibration(robot.cm, rows, alpha=alpha, tolerance_m=tolerance_m, seed=seed)
    big = tcp_change >= tolerance_m
    ev = RobotEvent(kind, joint, factor, tcp_change, r.verdict, r.group, r.exit_code,
                    _right(kind, joint, r.verdict, r.group, big, tuple(r.alike)), r.change_tcp_m,
                    r.change_tcp_sigma_m, predicted_refit_m=r.refit_error_m, predicted_recal_m=r.recalibrate_error_m,
                    alike=list(r.alike), sized=r.sized,
                    groups=sorted(r.groups, key=lambda g: g["chi2_remaining"])[:4], setup_held=r.setup_held)
    if np.isfinite(r.refit_error_m) and r.model is not None and recalibrate:
        ev.refit_error_m = _tcp_error(r.model.predict(robot.qw), after)
        ev.calibration_error_m = _tcp_error(robot.cm.predict(robot.qw), before)
        nominal = TrackerModel(robot.nominal.robot, reflector_m=REFLECTOR_M, tcp_m=REFLECTOR_M,
                               noise=robot.nominal.noise)
        for j in range(max(recal_draws, 1)):
            data = simulate(robot.nominal, robot.Q_cal, p, robot.effects, seed=seed + 13 + 1_000_003 * j)
            recal = identify(nominal, data, Q_work=robot.qw).calibrated_model()
            ev.recal_draws_m.append(_tcp_error(recal.predict(robot.qw), after))
        ev.recal_error_m = ev.recal_draws_m[0]
    ev.time_s = time.perf_counter() - t0
    return ev


def _tcp_error(pred: np.ndarray, truth: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((pred - truth) ** 2, axis=1))))


def clopper_pearson(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """The exact (Clopper–Pearson) two-sided interval of a binomial share k / n at ``level``."""
    from scipy import stats

    if n == 0:
        return float("nan"), float("nan")
    a = 1.0 - level
    lo = 0.0 if k == 0 else float(stats.beta.ppf(a / 2, k, n - k + 1))
    hi = 1.0 if k == n else float(stats.beta.ppf(1 - a / 2, k + 1, n - k))
    return lo, hi
