r"""Simulated laser-tracker measurements from a "true" robot.

A truth is a raw parameter vector p* of a :class:`~pin_kpi_oed.model.tracker.TrackerModel`
(geometric errors of every joint placement, the tracker pose ``tracker_T_base·exp6(δ_t)``,
the reflector offset ``r0 + δ_r``), optionally with effects (``docs/ARCHITECTURE.md``,
"Effect interface") and their parameters θ*. A measurement at configuration q_i is

.. math::

    η_i = h\bigl(p^*, q_i + \textstyle\sum Δq(θ^*, q_i, aux)\bigr) + \sum Δy(θ^*, q_i, aux) + ε_i,
    \qquad ε_i \sim N(0, \operatorname{diag} σ_i^2)

with σ_i from the model's :class:`~pin_kpi_oed.model.noise.NoiseModel` (per-axis, or
a + b·range); a 6-D probe's orientation is ``R_meas = exp3(ε_rot) R_model`` with
ε_rot ~ N(0, σ_rot² I). Geometric errors are drawn from tolerances (normal, standard
deviation = tolerance). Every random draw takes a seed.

A truth is saved as a JSON document (``"format": "pin_kpi_oed.truth/1"``, :func:`truth_to_dict`): the nominal
set-up (robot, tool frame, tracker pose, reflector, TCP, noise), p* by parameter name, and the effects with
their θ*; :func:`load_truth` rebuilds the same simulated robot from it, to measure it again at other poses
or in another session (``simulate --truth FILE``).
"""

from __future__ import annotations

from dataclasses import asdict
from typing import Any
from collections.abc import Sequence

import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation

from pin_kpi_oed.model.tolerances import Tolerances
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.effects.library import predict_with_effects
from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.model.nests import NEST_COLUMN
from pin_kpi_oed.model.noise import NoiseModel
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.model.robot import Robot

__all__ = ["TRUTH_FORMAT", "Tolerances", "random_truth", "default_tracker_pose", "simulate", "truth_to_dict",
           "load_truth", "feasible_poses"]

#: Format name and version of a saved truth.
TRUTH_FORMAT = "pin_kpi_oed.truth/1"


def random_truth(model: TrackerModel, tol: Tolerances | None = None, seed: int = 0,
                 only: np.ndarray | Sequence[int] | None = None) -> np.ndarray:
    """Draw a true raw parameter vector p* ~ N(0, diag(tol²)).

    Args:
        model: the nominal measurement model.
        tol: tolerances (default :class:`Tolerances`).
        seed: seed of :func:`numpy.random.default_rng`.
        only: indices (or a boolean mask) of the parameters to perturb (e.g. the identifiable
            ones, ``analyse(model).base``); the others stay 0. Default: all.

    Returns:
        p*, shape (n_params,) (m, rad).
    """
    tol = tol or Tolerances()
    s = tol.sigma_vector(model)
    p = np.random.default_rng(seed).normal(0.0, 1.0, model.n_params) * s
    if only is not None:
        keep = np.zeros(model.n_params, bool)
        keep[np.asarray(only)] = True
        p = np.where(keep, p, 0.0)
    return p


def default_tracker_pose(robot: Robot, distance_m: float | None = None, yaw_rad: float = 2.6,
                         height_m: float = 0.3) -> pin.SE3:
    """A plausible tracker_T_base: the tracker stands ``distance_m`` (default reach + 1.5 m) from the base.

    The tracker's frame is rotated by ``yaw_rad`` about the vertical (its axes are arbitrary
    in practice) and slightly tilted; the returned pose is that of the robot base in the
    tracker frame (m, rad).
    """
    d = robot.reach() + 1.5 if distance_m is None else float(distance_m)
    base_T_tracker = pin.SE3(pin.rpy.rpyToMatrix(0.01, -0.02, yaw_rad), np.array([d, 0.4, height_m]))
    return base_T_tracker.inverse()


def simulate(model: TrackerModel, Q: np.ndarray, truth_p: np.ndarray | None = None,
             effects: Sequence[tuple[Any, np.ndarray]] = (), aux: MeasurementSet | dict | None = None,
             noise: NoiseModel | None = None, seed: int = 0, record_sigma: bool = True,
             outliers: tuple[float, float] | None = None, source: str = "simulated",
             nest: np.ndarray | Sequence[int] | None = None) -> MeasurementSet:
    """Simulate tracker measurements of a true robot at configurations ``Q``.

    Args:
        model: nominal measurement model (robot, tracker pose, reflector, noise; ``pose6d``
            adds probe orientations as rotation vectors).
        Q: configurations, (m, n) rad.
        truth_p: true raw parameters p* (default zeros: the nominal robot).
        effects: ``[(effect, theta), ...]`` unmodelled effects and their true parameters.
        aux: auxiliary columns the effects read: a :class:`MeasurementSet` (its temperature,
            payload, time, extra are copied) or a dict with keys ``temperature_c``,
            ``payload_kg``, ``time_s`` ((m,) arrays) and ``extra`` (dict).
        noise: noise model (default ``model.noise``).
        seed: seed of the noise (and outlier) draws.
        record_sigma: write the per-axis σ into ``sigma_m`` (the identification then uses it).
        outliers: ``(fraction, magnitude_m)``: that share of the measurements gets an extra
            error of the given size in a random direction; their rows are marked 1 in
            ``extra['is_outlier']``.
        source: the ``source`` label of the set.
        nest: the reflector nest of every row, (m,) int (:mod:`~pin_kpi_oed.model.nests`; written as the ``nest``
            column); None: every row at the model's reflector.

    Returns:
        The :class:`MeasurementSet` (SI units, tracker frame).

    Raises:
        InputError: wrong shapes, configurations outside the joint limits, bad aux columns.
    """
    robot = model.robot
    Q = robot.check_q(Q, "simulate: Q")
    m = Q.shape[0]
    p = np.zeros(model.n_params) if truth_p is None else np.asarray(truth_p, float)
    if p.shape != (model.n_params,):
        raise InputError(f"simulate: truth_p must have {model.n_params} entries, got shape {p.shape}")
    noise = noise or model.noise
    cols: dict[str, Any]
    if isinstance(aux, MeasurementSet):
        cols = {"temperature_c": aux.temperature_c, "payload_kg": aux.payload_kg, "time_s": aux.time_s,
                "extra": dict(aux.extra)}
    else:
        cols = dict(aux or {})
        unknown = set(cols) - {"temperature_c", "payload_kg", "time_s", "extra"}
        if unknown:
            raise InputError(f"simulate: unknown aux column(s) {sorted(unknown)} "
                             "(use temperature_c, payload_kg, time_s, extra)")
    ms = MeasurementSet(joint_names=list(robot.joint_names), q=Q, position_m=np.zeros((m, 3)),
                        temperature_c=cols.get("temperature_c"), payload_kg=cols.get("payload_kg"),
                        time_s=cols.get("time_s"), source=source, extra=dict(cols.get("extra") or {}))
    if nest is not None:
        model = model.at_nests(np.asarray(nest).reshape(m))
        ms.extra[NEST_COLUMN] = model.row_nest.astype(float)
    eff = [e for e, _ in effects]
    thetas = [np.asarray(t, float) for _, t in effects]
    Y = predict_with_effects(model, p, np.atleast_2d(np.asarray(Q, float)), ms, list(zip(eff, thetas)))
    rng = np.random.default_rng(seed)
    S = noise.sigma(Y[:, :3])
    pos = Y[:, :3] + rng.normal(size=(m, 3)) * S
    rotvec = None
    if model.pose6d:
        R = Rotation.from_rotvec(Y[:, 3:])
        rotvec = (Rotation.from_rotvec(rng.normal(size=(m, 3)) * noise.sigma_rot_rad) * R).as_rotvec()
    extra = dict(ms.extra)
    if outliers is not None:
        frac, mag = float(outliers[0]), float(outliers[1])
        if not (0 <= frac < 1 and mag >= 0):
            raise InputError(f"simulate: outliers must be (fraction in [0, 1), magnitude >= 0 m), got {outliers}")
        k = int(round(frac * m))
        idx = rng.choice(m, size=k, replace=False)
        d = rng.normal(size=(k, 3))
        pos[idx] += mag * d / np.linalg.norm(d, axis=1, keepdims=True)
        flag = np.zeros(m)
        flag[idx] = 1.0
        extra["is_outlier"] = flag
    return MeasurementSet(joint_names=list(robot.joint_names), q=Q, position_m=pos, rotvec_rad=rotvec,
                          sigma_m=S if record_sigma else None, temperature_c=ms.temperature_c,
                          payload_kg=ms.payload_kg, time_s=ms.time_s, source=source, extra=extra)


def truth_to_dict(model: TrackerModel, truth_p: np.ndarray, tol: Tolerances | None = None, seed: int | None = None,
                  effects: Sequence[tuple[Any, np.ndarray]] = ()) -> dict:
    """JSON-able description of a simulated truth (SI units), from which :func:`load_truth` rebuilds it.

    Raises:
        InputError: an effect that cannot be stored.
    """
    from pin_kpi_oed.data.atomic import to_jsonable
    from pin_kpi_oed.effects.spec import effect_spec
    from pin_kpi_oed.model.robot import portable_spec

    p = np.asarray(truth_p, float)
    return to_jsonable({
        "format": TRUTH_FORMAT,
        "robot": model.robot.name,
        "robot_spec": portable_spec(model.robot),
        "tool_frame": model.robot.tool_frame,
        "p_raw": {n: float(v) for n, v in zip(model.layout.names, p)},
        "tracker_T_base": model.tracker_pose(p).homogeneous,
        "reflector_m": model.reflector(p),
        "nominal": {"tracker_T_base": model.tracker_T_base.homogeneous, "reflector_m": model.reflector_m,
                    "tcp_m": model.tcp_m, "pose6d": bool(model.pose6d)},
        "joint_placements": [M.homogeneous for M in model.joint_placements(p)],
        "effects": [{**effect_spec(e), "theta": np.asarray(t, float)} for e, t in effects],
        "noise": model.noise.to_dict(),
        "tolerances": asdict(tol) if tol is not None else None,
        "seed": seed,
    })


def load_truth(path: str) -> tuple[TrackerModel, np.ndarray, list[tuple[Any, np.ndarray]]]:
    """The simulated robot of a truth file (:func:`truth_to_dict`): (nominal model, p*, [(effect, θ*), ...]).

    Raises:
        InputError: a missing or unreadable file, another format, a missing or malformed field (named).
    """
    import json
    from pathlib import Path

    from pin_kpi_oed.effects.spec import effect_from_spec
    from pin_kpi_oed.model.kinematics import se3_from_matrix
    from pin_kpi_oed.model.robot import load_robot

    try:
        d = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"truth_file {path}: cannot read the truth file ({exc})") from None
    if not isinstance(d, dict) or d.get("format") != TRUTH_FORMAT:
        raise InputError(f"truth_file {path}: not a truth file (field 'format' is "
                         f"{d.get('format') if isinstance(d, dict) else None!r}, expected '{TRUTH_FORMAT}'; "
                         "write one with simulate truth_file='FILE')")
    try:
        nom = d["nominal"]
        robot = load_robot(d["robot_spec"], d["tool_frame"])
        model = TrackerModel(robot, tracker_T_base=se3_from_matrix(nom["tracker_T_base"], f"{path}: tracker_T_base"),
                             reflector_m=np.asarray(nom["reflector_m"], float), tcp_m=np.asarray(nom["tcp_m"], float),
                             noise=NoiseModel.from_dict(d["noise"]), pose6d=bool(nom["pose6d"]))
        raw = d["p_raw"]
        missing = [n for n in model.layout.names if n not in raw]
        if missing:
            raise InputError(f"truth_file {path}: p_raw lacks {', '.join(missing[:3])}")
        p = np.array([float(raw[n]) for n in model.layout.names])
        effects = [(effect_from_spec(e, robot, f"truth_file {path}: effects[{i}]"), np.asarray(e["theta"], float))
                   for i, e in enumerate(d.get("effects") or [])]
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"truth_file {path}: missing or malformed field ({exc})") from None
    if not np.all(np.isfinite(p)):
        raise InputError(f"truth_file {path}: p_raw has values that are not finite")
    check_derived_fields(model, p, d, path)
    return model, p, effects


#: largest disagreement (m for translations, 1 for rotation entries) between a truth file's derived field and
#: the value its ``p_raw`` gives: the file's own rounding is far below it, a hand edit far above
DERIVED_TOL = 1e-9


def check_derived_fields(model: TrackerModel, p: np.ndarray, d: dict, path: str) -> None:
    """Refuse a truth file whose derived fields (``tracker_T_base``, ``reflector_m``, ``joint_placements``) are not
    the ones its ``p_raw`` gives: the true robot is ``p_raw`` (with ``nominal``), and an edit of a derived field
    alone would change nothing that is simulated.

    Args:
        model: the nominal model the file describes.
        p: its raw parameters p* (``p_raw``).
        d: the file's document.
        path: the file (for messages).

    Raises:
        InputError: a derived field malformed or disagreeing with ``p_raw`` (named, with the disagreement in m).
    """
    derived = {"tracker_T_base": [model.tracker_pose(p).homogeneous], "reflector_m": [model.reflector(p)],
               "joint_placements": [M.homogeneous for M in model.joint_placements(p)]}
    for field, want in derived.items():
        if field not in d:
            continue
        got = d[field] if field == "joint_placements" else [d[field]]
        try:
            arrays = [np.asarray(g, float) for g in got] if isinstance(got, list) else None
        except (TypeError, ValueError):
            arrays = None
        if arrays is None or len(arrays) != len(want) or any(a.shape != w.shape for a, w in zip(arrays, want)):
            raise InputError(f"truth_file {path}: field '{field}' is malformed (expected the values p_raw gives, "
                             f"shape {tuple(np.shape(want if len(want) > 1 else want[0]))})")
        for k, (a, w) in enumerate(zip(arrays, want)):
            gap = float(np.max(np.abs(a - w))) if np.all(np.isfinite(a)) else float("inf")
            if gap > DERIVED_TOL:
                name = f"{field}[{k}]" if field == "joint_placements" else field
                raise InputError(f"truth_file {path}: field '{name}' disagrees with p_raw (by {gap:.3g}); the true "
                                 "robot is p_raw with 'nominal': edit p_raw (the derived fields follow it) or "
                                 "delete the derived field")


def feasible_poses(cell: Any, n: int, seed: int) -> np.ndarray:
    """``n`` configurations drawn uniformly within the cell's joint bounds and kept when feasible in the cell:
    collision-free, the beam clear and the reflector in sight by the cell's own independent check.

    Args:
        cell: the :class:`~pin_kpi_oed.cell.cell_model.Cell`.
        n: number of configurations.
        seed: seed of the draws.

    Returns:
        (n, nq) configurations (rad / m).

    Raises:
        InfeasibleError: fewer than ``n`` feasible configurations within the cell's sampling budget.
    """
    from pin_kpi_oed.cell.collision import CollisionModel
    from pin_kpi_oed.cell.sampling import random_feasible
    from pin_kpi_oed.cell.feasibility import FeasibilityChecker
    from pin_kpi_oed.errors import InfeasibleError

    rng = np.random.default_rng(seed)
    coll, chk = CollisionModel(cell), FeasibilityChecker(cell)
    found: list[np.ndarray] = []
    for _ in range(5):
        want = n - len(found)
        if want <= 0:
            break
        Q, _ = random_feasible(coll, want + max(2, want // 5), rng, cell.max_random_tries)
        found.extend(Q[chk.check(Q).feasible])
    if len(found) < n:
        raise InfeasibleError(f"cell {cell.name}: only {len(found)} of {n} random configurations are feasible in the "
                              "cell's independent check; ask for fewer held-out poses")
    return np.asarray(found[:n])
