"""Working configurations given as Cartesian TCP targets, solved by inverse kinematics.

A cell file may give its working configurations (the KPI poses q_work of eq. 19) as TCP targets in
the cell frame instead of joint values (SI units)::

    working_targets:
      - {xyz_m: [0.9, 0.0, 1.25]}                              # TCP position only
      - {xyz_m: [0.9, 0.3, 1.25], rpy_deg: [180, 0, 0]}        # and the tool frame's orientation
      - {xyz_m: [...], seed_deg: [0, -100, 110, -100, -90, 0]} # start the search here

The TCP is the cell's ``tcp_m`` point of the tool frame; ``rpy`` is the tool frame's orientation in
the cell frame (roll-pitch-yaw, as ``base`` and ``tracker``). :func:`solve_tcp_target` runs damped
least squares on Pinocchio's frame Jacobian (``pin.computeFrameJacobian``, LOCAL_WORLD_ALIGNED, the
TCP point's rows ``J_v − [r]× J_ω``) with steps through ``pin.integrate``, each iterate projected on
the joint bounds, from the given seed, then the explicit working configurations, the bounds'
middle and seeded random starts; the first solution within ``tol`` that the cell check accepts
(every capsule pair clear of the required clearance, in the optimiser's capsules:
:class:`~pin_kpi_oed.cell.feasibility.FeasibilityChecker`; the beam may be blocked, as for every working
configuration) is kept.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from collections.abc import Callable

import numpy as np
import pinocchio as pin

from pin_kpi_oed.cell.cell_checks import skip_hint
from pin_kpi_oed.cell.feasibility import FeasibilityChecker
from pin_kpi_oed.cell.fields import read_angles, read_vec
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.results import Result

#: position tolerance of a solved target (m) and orientation tolerance (rad)
IK_TOL_M = 1e-6
IK_TOL_RAD = 1e-6


@dataclass
class IkResult(Result):
    """Outcome of :func:`solve_tcp_target` (a :class:`~pin_kpi_oed.results.Result`: ``success`` within tolerance,
    within the bounds and accepted by the check; ``status`` ``solved``, ``refused`` (reached, refused by the check:
    ``message`` says why) or ``unreachable``; ``nit`` the starts tried).

    Attributes:
        q: the solution (n,) rad / m, or the best iterate when ``success`` is False.
        residual_m: TCP position error (m); residual_rad: orientation error (rad, 0 if free).
    """

    q: np.ndarray
    residual_m: float
    residual_rad: float


#: the largest entry of a vector: ``ndarray.max``'s reduction without its wrapper
_largest = np.maximum.reduce


@functools.lru_cache(maxsize=8)
def _damping(damping: float) -> dict[int, np.ndarray]:
    """λ²I of the damped step for 3 and 6 rows (read-only, made once per λ)."""
    out = {k: damping ** 2 * np.eye(k) for k in (3, 6)}
    for a in out.values():
        a.flags.writeable = False
    return out


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _descend(robot, q: np.ndarray, p_t: np.ndarray, R_t: np.ndarray | None, tcp: np.ndarray,
             max_iter: int, damping: float) -> tuple[np.ndarray, float, float]:
    """Damped least squares from q; returns (q, position error (m), orientation error (rad)).

    Written for the cost of its small NumPy calls (a cube's plan runs thousands of iterations): the norms as
    ``sqrt(e·e)`` (what ``np.linalg.norm`` computes for a vector), the damping's diagonal made once per λ, the
    largest step by ``np.maximum.reduce`` (``ndarray.max``'s reduction, without its wrapper), the tool frame placed
    by the frame Jacobian's own forward pass (no second forward kinematics): the same numbers as the plain calls
    (``tests/test_ik_descent.py`` keeps them as the reference).
    """
    model, data, fid = robot.model, robot.model.createData(), robot.tool_frame_id
    lo, hi = robot.q_lower, robot.q_upper
    q = np.clip(np.asarray(q, float), lo, hi)
    ep = er = np.inf
    damp = _damping(damping)
    for _ in range(max_iter):
        # the frame Jacobian's forward pass places the tool frame as forward kinematics does (the same products)
        J6 = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL_WORLD_ALIGNED)
        M = data.oMf[fid]
        r = M.rotation @ tcp
        e_pos = p_t - (M.translation + r)
        J = J6[:3] - _skew(r) @ J6[3:]
        e = e_pos
        ep = math.sqrt(e_pos.dot(e_pos))
        er = 0.0
        if R_t is not None:
            e_rot = pin.log3(R_t @ M.rotation.T)
            er = math.sqrt(e_rot.dot(e_rot))
            J = np.concatenate([J, J6[3:]])
            e = np.concatenate([e_pos, e_rot])
        if ep < 1e-3 * IK_TOL_M and er < 1e-3 * IK_TOL_RAD:
            break
        dq = J.T @ np.linalg.solve(J @ J.T + damp[J.shape[0]], e)
        big = float(_largest(np.abs(dq)))
        if big > 0.3:
            dq *= 0.3 / big
        q_new = np.clip(pin.integrate(model, q, dq), lo, hi)
        if _largest(np.abs(q_new - q)) < 1e-14:
            break
        q = q_new
    return q, ep, er


def track_target(robot, W_T_base: pin.SE3, tcp_m: np.ndarray, xyz_W: np.ndarray, R_W: np.ndarray | None,
                 q_start: np.ndarray, max_iter: int = 60, damping: float = 1e-3) -> tuple[np.ndarray, float, float]:
    """Damped least squares from one start only (no restarts): a path follower's warm-started step.

    Args:
        robot, W_T_base, tcp_m, xyz_W, R_W: as :func:`solve_tcp_target`.
        q_start: the start, typically the previous sample's solution (rad / m).
        max_iter: iterations; damping: the damping λ of (JJᵀ + λ²I).

    Returns:
        (q, position error (m), orientation error (rad, 0 if free)).
    """
    base_T_W = W_T_base.inverse()
    p_t = base_T_W.act(np.asarray(xyz_W, float))
    R_t = None if R_W is None else base_T_W.rotation @ np.asarray(R_W, float)
    return _descend(robot, q_start, p_t, R_t, np.asarray(tcp_m, float), max_iter, damping)


def solve_tcp_target(robot, W_T_base: pin.SE3, tcp_m: np.ndarray, xyz_W: np.ndarray, R_W: np.ndarray | None = None,
                     seeds: list[np.ndarray] | None = None, accept: Callable[[np.ndarray], str] | None = None,
                     n_random: int = 24, seed: int = 0, max_iter: int = 300, damping: float = 1e-3) -> IkResult:
    """Joint values putting the TCP at a cell-frame target (optionally with the tool's orientation).

    Args:
        robot: the robot (its bounds are the cell's).
        W_T_base: robot base in the cell frame.
        tcp_m: TCP in the tool frame (m).
        xyz_W: target TCP position in the cell frame (m).
        R_W: target tool-frame orientation in the cell frame (3×3), or None (position only).
        seeds: starts tried first (rad / m).
        accept: ``q -> ""`` when the cell check accepts q, else the reason (None: accept all).
        n_random: random starts after the seeds; seed: their random seed.
        max_iter: iterations per start; damping: the damping λ of (JJᵀ + λ²I).

    Returns:
        The :class:`IkResult` (the first accepted solution, else the smallest residual found).
    """
    base_T_W = W_T_base.inverse()
    p_t = base_T_W.act(np.asarray(xyz_W, float))
    R_t = None if R_W is None else base_T_W.rotation @ np.asarray(R_W, float)
    tcp = np.asarray(tcp_m, float)
    rng = np.random.default_rng(seed)
    starts = [np.asarray(s, float) for s in (seeds or [])] + [0.5 * (robot.q_lower + robot.q_upper)]
    starts += list(robot.random_q(rng, n_random))
    refused: IkResult | None = None  # reached but refused by the check
    closest: IkResult | None = None  # not reached: the smallest residual
    for k, q0 in enumerate(starts):
        q, ep, er = _descend(robot, q0, p_t, R_t, tcp, max_iter, damping)
        if ep <= IK_TOL_M and er <= IK_TOL_RAD:
            reason = accept(q) if accept is not None else ""
            if not reason:
                return IkResult(q, ep, er, success=True, status="solved", nit=k + 1)
            refused = refused or IkResult(q, ep, er, status="refused", message=reason)
        elif closest is None or ep + er < closest.residual_m + closest.residual_rad:
            closest = IkResult(q, ep, er, status="unreachable")
    best = refused if refused is not None else closest
    best.nit = len(starts)
    return best


#: random configurations (seeded) in which an obstacle that collides in every one is the cell's fault, not a target's
N_ALWAYS = 64


def blocked_in_all(chk: FeasibilityChecker, Q: np.ndarray, clearance_m: float) -> bool:
    """Whether a pair or a beam target is closer than ``clearance_m`` (by more than 1e-9 m) in every configuration
    of ``Q``: configuration by configuration, stopping at the first after which no column was close in all so far
    (a cell without such a fault: after a few of them, not all).

    Args:
        chk: the checker (its :meth:`~pin_kpi_oed.cell.feasibility.FeasibilityChecker.distances` columns).
        Q: configurations (m, n) rad.
        clearance_m: the required clearance of the pairs (m; the beam's columns are taken as they are).

    Returns:
        The verdict of the full (m, columns) distance matrix: some column below −1e-9 m in every row.
    """
    alive: np.ndarray | None = None
    for q in Q:
        d = chk.distances(q[None])[0]
        d[:chk.n_pairs] -= clearance_m
        close = d < -1e-9
        alive = close if alive is None else alive & close
        if not alive.any():
            return False
    return alive is not None


def _check_always_blocked(chk: FeasibilityChecker, cell, pre: str) -> None:
    """Refuse an obstacle that collides with a robot capsule, or blocks the beam, in each of :data:`N_ALWAYS` random
    configurations within the bounds (it overlaps the robot's base, or hides the tracker): no target is to blame.

    Raises:
        InputError: naming the obstacle, the robot capsule (or the beam) and the fix.
    """
    Q = np.random.default_rng(0).uniform(cell.q_lower, cell.q_upper, (N_ALWAYS, cell.robot.nq))
    if not blocked_in_all(chk, Q, cell.clearance_m):
        return
    D = chk.distances(Q)
    D[:, :chk.n_pairs] -= cell.clearance_m
    ncols = chk.n_pairs + len(chk.beam_names)
    always = [k for k in range(min(ncols, D.shape[1])) if np.all(D[:, k] < -1e-9)]
    k = always[0]
    a, b = chk.names[k].split("|", 1)
    worst = float(np.max(D[:, k])) * 1e3
    env = next((e.name for e in cell.environment if b in {c.name for c in e.capsules}), None)
    fitted = (f" (an enclosing capsule the optimiser uses for '{env}'; a smaller max_radius_m of '{env}' fits it "
              "tighter)" if env else "")
    robot_names = {chk.gm.geometryObjects[i].name for i in chk.robot_ids}
    if a != "beam" and b in robot_names:  # two of the robot's own capsules: no obstacle to move
        raise InputError(f"{pre}the robot's links '{a}' and '{b}' collide with each other in every one of {N_ALWAYS} "
                         f"random configurations (at best {worst:.0f} mm, clearance_m {cell.clearance_m * 1e3:g} mm "
                         f"included): {skip_hint([(a, b)])}")
    if a == "beam":
        where = "[" + ", ".join(f"{x:.3f}" for x in cell.W_T_tracker.translation) + "]"
        raise InputError(f"{pre}obstacle '{b}'{fitted} blocks the laser beam in every one of {N_ALWAYS} random "
                         f"configurations (at best {worst:.0f} mm): it hides the tracker at {where} m (cell frame); "
                         "move the tracker or the obstacle")
    raise InputError(f"{pre}obstacle '{b}'{fitted} overlaps the robot: '{a}' collides with it in every one of "
                     f"{N_ALWAYS} random "
                     f"configurations (at best {worst:.0f} mm, clearance_m {cell.clearance_m * 1e3:g} mm included): "
                     f"move the obstacle, or if it is the robot's own pedestal list [{a}, {b}] under skip_pairs")


def solve_working_targets(cell, targets: list, source: str = "") -> np.ndarray:
    """Working configurations (k, n) rad of the cell file's ``working_targets`` (see the module docstring).

    Args:
        cell: the cell read so far (robot, bounds, base, TCP, capsules, obstacles; its q_work are
            tried as starts).
        targets: the ``working_targets`` entries.
        source: the cell file (for messages).

    Returns:
        One configuration per target, in order.

    Raises:
        InputError: a malformed target, or one with no collision-free solution within the bounds,
            naming the target index and the residual (mm, deg).
    """
    import dataclasses


    from pin_kpi_oed.cell.collision import CollisionModel

    pre = f"{source}: " if source else ""
    robot = cell.robot
    # the cell's own faults first, said as such (not as a target no solution reaches): the tracker inside an
    # obstacle, a fixed robot capsule in one, an obstacle the robot hits or the beam crosses in every configuration
    CollisionModel(cell, collision=False)
    # the optimiser's model (environment files as their enclosing capsules): what the design checks q_work in
    chk = FeasibilityChecker(dataclasses.replace(cell, environment=[]))
    _check_always_blocked(chk, cell, pre)

    def accept(q: np.ndarray) -> str:
        # collision-free by the required clearance; the beam may be blocked: a working configuration is where the
        # robot works, not where it is measured (the cell's summary names the hidden ones)
        d = chk.distances(q[None])[0][:chk.n_pairs] - cell.clearance_m
        k = int(np.argmin(d)) if d.size else -1
        if k < 0 or d[k] >= -1e-9:
            return ""
        hint = f"; {skip_hint([chk.pair_names[k]])}" if k < chk.n_pairs else ""
        return f"{chk.names[k]} at {d[k] * 1e3:.1f} mm{hint}"

    out: list[np.ndarray] = []
    for i, t in enumerate(targets):
        w = f"{pre}working_targets[{i}]"
        if not isinstance(t, dict) or "xyz_m" not in t:
            raise InputError(f"{w}: expected a mapping with xyz_m (and optional rpy_rad/rpy_deg, seed_rad/seed_deg)")
        xyz = read_vec(t["xyz_m"], 3, f"{w}.xyz_m")
        rpy = read_angles(t, "rpy", 3, w, required=False)
        seed_q = read_angles(t, "seed", robot.nq, w, required=False)
        seeds = ([seed_q] if seed_q is not None else []) + list(np.atleast_2d(cell.q_work)) + out
        res = solve_tcp_target(robot, cell.W_T_base, cell.tcp_m, xyz, None if rpy is None else
                               pin.rpy.rpyToMatrix(*rpy), seeds=seeds, accept=accept, seed=i)
        if not res.success:
            what = (f"every solution within the joint bounds collides ({res.message})"
                    if res.message else "unreachable within the joint bounds")
            raise InputError(f"{w}: {what}; best residual {res.residual_m * 1e3:.3f} mm"
                             + (f", {np.degrees(res.residual_rad):.3f} deg" if rpy is not None else "")
                             + f" from {res.nit} starts")
        out.append(res.q)
    return np.array(out).reshape(len(out), robot.nq)
