r"""Compensation ("program filtering"): joint values that put the real TCP on the target.

The controller keeps its nominal kinematics. To make the real robot reach a Cartesian target,
it must be told other joint values: those for which the **calibrated** model (geometry δ and
effects θ of a :class:`~pin_kpi_oed.calibrated.model_file.CalibratedModel`) puts the TCP on
the target. For target i (position t_i, optionally orientation R_i):

1. nominal solution q⁰_i: inverse kinematics on the nominal robot (what the controller would
   command), from the target's start configuration (a joint hint in the file), else from the
   robot's neutral pose and then from seeded random starts;
2. compensated solution q_i: inverse kinematics on the calibrated model started from q⁰_i::

       F(q) = [ T_f · oMtool_δ(q + ΣΔq(θ, q)) · c + ΣΔy(θ, q) ,   R_T · R_tool_δ(q + ΣΔq) ]

   with T_f the target frame (``cell``: the station's tracker frame, T_f = tracker_T_base of
   the station; ``base``: the robot base frame, T_f = I) and c the TCP point in the tool frame
   (default: the station's reflector, the point the calibration measured). The position of F is
   computed by :func:`~pin_kpi_oed.effects.library.predict_with_effects`, the same function the
   fit and :meth:`CalibratedModel.predict` use.
3. predicted correction: ``|F(q⁰_i) − t_i|`` (m), how far the calibrated model says the nominal
   solution misses the target, i.e. how far compensation moves the TCP.

Both IK problems are solved by damped Gauss–Newton (Levenberg–Marquardt steps
``Δq = Jᵀ(JJᵀ + λ²I)⁻¹ e``, steps limited to ``max_step_rad``, joint limits enforced by
clipping). J is Pinocchio's frame Jacobian (``LOCAL_WORLD_ALIGNED``) of the calibrated (resp.
nominal) model, shifted to the TCP point and rotated into the target frame; orientation rows
are scaled by ``length_m`` (m/rad). The effects' dependence on q (∂ΔQ/∂q, ∂Δy/∂q, of the order
of 10⁻⁴) is left out of J but not out of the residual, so the iteration converges to the exact
solution of the calibrated model (linearly, at a rate of that order). A position-only target
leaves the orientation free: the minimum-norm steps stay close to the nominal solution.

The nominal IK starts from the target's joint hint, else from the model's working configuration nearest
the target, else from the neutral configuration (:mod:`pin_kpi_oed.compensation.checks`): the
solution stays on that branch, also on a redundant arm. The TCP c is given in the robot's tool frame
(``CalibratedModel.robot.tool_frame``; the model's ``tcp_m`` when a cell or a measurement header stated it). The σ at
a TCP away from the fitted reflector includes what one reflector cannot see there
(:mod:`pin_kpi_oed.compensation.tool_offset`).

Status per target: ``ok``; ``unreachable`` (the nominal or the calibrated IK ends farther from
the target than ``reach_tol_m`` / ``reach_tol_rad``: outside the workspace, at a joint limit, or
at a singularity where the calibrated pose needs a large joint motion — ``inv_cond`` tells which);
``off_branch`` (the nominal IK left the branch of the hint / working configuration, or compensation moved
a joint by more than ``max_branch_step_rad``); ``joint_limit`` (a joint of the compensated configuration at
its limit); ``collision`` (with ``cell``: the compensated configuration collides in the cell's independent
check); ``near_singular`` (reached, but the inverse condition number σ_min/σ_max of the scaled Jacobian
is below ``singular_ratio``: small TCP corrections there need large joint motions); ``extrapolated`` (every check
passed, but the compensated configuration lies outside the calibration's joint-space coverage,
:class:`~pin_kpi_oed.discrepancy.coverage.JointCoverage`: the model was not measured near it, the correction there is
an extrapolation and its σ the widened one ``predict`` gives for the same configuration); ``tcp_unmeasured`` (every
check passed, but more than half the TCP's σ² is the joint-placement parameters no measurement determined,
:mod:`pin_kpi_oed.compensation.tool_offset`: the compensation is right at the measured part and unknown at the TCP
by that much; the result's status says so, "ok at the measured part; ...: measure the TCP"). Only ``ok`` is safe to
send as it is.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pinocchio as pin

from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.data.targets import TargetSet
from pin_kpi_oed.effects.library import predict_with_effects, sum_joint_offsets
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.compensation.checks import (branch_step, collision_rows, joint_limit_rows,
                                                          nearest_to_reference, rotation_errors, start_configurations)
from pin_kpi_oed.compensation.result import write_compensation
from pin_kpi_oed.compensation.result import (HELD_SHARE_MAX, SENDABLE, STATUSES, CompensationResult,
                                            held_status_line)
from pin_kpi_oed.calibrated.model_file import CalibratedModel
from pin_kpi_oed.calibrated.prediction_sigma import DEFAULT_TOOL_LENGTH_M
from pin_kpi_oed.calibrated.tcp_sigma import TcpSigma, tcp_sigma
from pin_kpi_oed.model.kinematics import skew
from pin_kpi_oed.model.parameters import ParameterLayout
from pin_kpi_oed.model.tracker import TrackerModel

__all__ = ["FRAMES", "STATUSES", "SENDABLE", "CompensationOptions", "PoseModel", "CompensationResult", "compensate",
           "compensate_program", "write_compensation", "forward", "check_tcp_stated"]

#: Frames a target can be given in.
FRAMES = ("cell", "base")


@dataclass
class CompensationOptions:
    """Knobs of :func:`compensate` (SI units).

    Attributes:
        frame: ``cell`` (tracker frame of the station) or ``base`` (robot base frame).
        station: the station whose set-up defines the cell frame and default TCP (default: the
            model's default station).
        tcp_m: TCP point in the tool frame (m); default the model's TCP (a model that states none is refused).
        length_m: weight of the orientation rows (m per rad) in the IK norm and the condition number.
        max_iter: iterations per IK start.
        tol_m, tol_rad: convergence of the IK (position m, orientation rad).
        reach_tol_m, reach_tol_rad: a final residual beyond these is ``unreachable``.
        max_step_rad: largest joint step per iteration (rad or m).
        damping: λ of the damped steps (m).
        singular_ratio: inverse condition number below which a solution is ``near_singular``.
        restarts: seeded random starts of the nominal IK when the first start fails.
        seed: seed of those starts.
        max_branch_step_rad: largest joint change (rad / m) compensation may make to the nominal solution; beyond
            it the compensated configuration is on another branch (``off_branch``).
        limit_margin: a compensated joint this close to its limit (rad / m) is ``joint_limit``.
        cell: the :class:`~pin_kpi_oed.cell.cell_model.Cell` whose independent check every compensated configuration
            must pass (``collision`` otherwise; its working configurations give the branch when the model has none);
            None: not checked.
        tool_length_m: a 6-D model's orientation σ is also stated as the σ of the point this far along the tool
            axis (m).
        tool_tolerances: the manufacturing tolerances of the joint placements the calibration could not determine,
            for the σ of a TCP away from the reflector (:mod:`pin_kpi_oed.compensation.tool_offset`); default the
            ones the fit stored (``identify``'s, the same σ it printed), else
            :class:`~pin_kpi_oed.model.tolerances.Tolerances` (0.5 mm, 1 mrad).
    """

    frame: str = "cell"
    station: str | None = None
    tcp_m: np.ndarray | None = None
    length_m: float = 0.5
    max_iter: int = 200
    tol_m: float = 1e-9
    tol_rad: float = 1e-9
    reach_tol_m: float = 1e-6
    reach_tol_rad: float = 1e-6
    max_step_rad: float = 0.3
    damping: float = 1e-6
    singular_ratio: float = 1e-2
    restarts: int = 10
    seed: int = 0
    max_branch_step_rad: float = 0.05
    limit_margin: float = 1e-6
    cell: Any = None
    tool_tolerances: Any = None
    tool_length_m: float = DEFAULT_TOOL_LENGTH_M

    def __post_init__(self) -> None:
        if self.frame not in FRAMES:
            raise InputError(f"frame must be one of {', '.join(FRAMES)}, got '{self.frame}'")
        for k in ("length_m", "tol_m", "tol_rad", "reach_tol_m", "reach_tol_rad", "max_step_rad", "singular_ratio",
                  "max_branch_step_rad", "limit_margin"):
            v = float(getattr(self, k))
            if not (np.isfinite(v) and v > 0):
                raise InputError(f"compensation option {k} must be a positive number, got {v!r}")
        if self.tcp_m is not None:
            self.tcp_m = np.asarray(self.tcp_m, float).reshape(3)
        if not (np.isfinite(self.tool_length_m) and self.tool_length_m >= 0):
            raise InputError(f"compensation option tool_length_m must be a length >= 0 (m), got {self.tool_length_m!r}")


class PoseModel:
    """TCP pose F(q) of a calibrated (or the nominal) robot in a target frame, and its Pinocchio Jacobian.

    Args:
        cm: the calibrated model.
        frame: ``cell`` or ``base`` (see the module docstring).
        station: station of the cell frame / default TCP.
        tcp_m: TCP in the tool frame (m); default the model's TCP when a cell or a measurement header stated it
            (``cm.tool_source``), else the station's reflector.
        nominal: use the nominal geometry and no effects (what the controller computes).
    """

    def __init__(self, cm: CalibratedModel, frame: str = "cell", station: str | None = None,
                 tcp_m: np.ndarray | None = None, nominal: bool = False):
        self.robot = cm.robot
        st = cm.setups[cm.station(station)]
        self.T = pin.SE3(st.tracker_T_base) if frame == "cell" else pin.SE3.Identity()
        default = cm.tcp_m if cm.tool_source else st.reflector_m
        self.tcp = np.asarray(default if tcp_m is None else tcp_m, float).reshape(3)
        L = ParameterLayout(list(self.robot.joint_names))
        self.tm = TrackerModel(self.robot, tracker_T_base=self.T, reflector_m=self.tcp, noise=cm.noise, layout=L)
        self.p = np.zeros(L.n)
        if not nominal:
            self.p[:6 * self.robot.nq] = cm.joint_p
        self.pairs = [] if nominal else list(zip(cm.effects, cm.thetas))
        self.discrepancy = None if nominal else cm.discrepancy
        self.model = self.tm.pinocchio_model(self.p)
        self.data = self.model.createData()
        self.fid = self.robot.tool_frame_id

    def joint_offsets(self, Q: np.ndarray, aux: Any) -> np.ndarray:
        """ΣΔq of the effects at Q, (m, n) rad."""
        return sum_joint_offsets(self.pairs, Q, aux)[0] if self.pairs else np.zeros_like(Q)

    def pose(self, Q: np.ndarray, aux: Any = None, rotations: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """TCP positions (m, 3) m and tool rotations (m, 3, 3) in the target frame at Q (rad); ``rotations``
        False: the positions alone (the rotations an empty (m, 0, 0) array), for a position-only IK's residuals."""
        Q = np.atleast_2d(np.asarray(Q, float))
        pos = predict_with_effects(self.tm, self.p, Q, aux, self.pairs)[:, :3]
        if self.discrepancy is not None:  # the robot's discrepancy (base frame) at the commanded joints
            pos = pos + self.discrepancy.predict(Q, return_var=False)[0] @ self.T.rotation.T
        if not rotations:
            return pos, np.empty((Q.shape[0], 0, 0))
        Qe = Q + self.joint_offsets(Q, aux)
        R = np.empty((Q.shape[0], 3, 3))
        for i, q in enumerate(Qe):
            pin.framesForwardKinematics(self.model, self.data, q)
            R[i] = self.T.rotation @ self.data.oMf[self.fid].rotation
        return pos, R

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        """(6, n) Jacobian of the TCP (linear velocity of the TCP point, angular velocity) in the target frame."""
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateFramePlacements(self.model, self.data)
        J = pin.getFrameJacobian(self.model, self.data, self.fid, pin.LOCAL_WORLD_ALIGNED)
        M = self.data.oMf[self.fid]
        r = M.rotation @ self.tcp
        Jv = J[:3] - skew(r) @ J[3:]
        return np.vstack([self.T.rotation @ Jv, self.T.rotation @ J[3:]])


@dataclass
class _IK:
    Q: np.ndarray
    err_m: np.ndarray
    err_rad: np.ndarray
    inv_cond: np.ndarray
    nit: int


def _wrap_clip(q: np.ndarray, lo: np.ndarray, hi: np.ndarray, revolute: np.ndarray) -> np.ndarray:
    """A revolute joint pushed past a limit is moved by ∓2π when that lands inside the limits; then clip."""
    q = q.copy()
    tau = 2.0 * np.pi
    up = revolute & (q > hi) & (q - tau >= lo)
    down = revolute & (q < lo) & (q + tau <= hi)
    q[up] -= tau
    q[down] += tau
    return np.clip(q, lo, hi)


def _solve_ik(pm: PoseModel, pos_t: np.ndarray, R_t: np.ndarray | None, Q0: np.ndarray, aux: Any,
              opt: CompensationOptions) -> _IK:
    """Levenberg–Marquardt IK of every row from Q0 (batched residuals, per-row Pinocchio Jacobians).

    Each row keeps its own damping λ_i (starting at ``opt.damping``): a step that lowers the
    row's weighted error is taken and λ_i divided by 3, otherwise it is rejected and λ_i
    multiplied by 5 — robust near singularities, Gauss–Newton (quadratic) elsewhere.
    """
    Q = np.array(Q0, float)
    lo, hi = pm.robot.q_lower, pm.robot.q_upper
    rows6 = R_t is not None
    nr = 6 if rows6 else 3
    rev = pm.robot.is_revolute
    w = np.r_[np.ones(3), np.full(3, opt.length_m)] if rows6 else np.ones(3)

    def errors(Qx: np.ndarray) -> np.ndarray:
        pos, R = pm.pose(Qx, aux, rotations=rows6)
        e = pos_t - pos
        return np.hstack([e, rotation_errors(R_t, R)]) if rows6 else e

    lam = np.full(len(Q), float(opt.damping))
    eye = np.eye(nr)
    E = errors(Q)
    nit = 0
    for nit in range(1, opt.max_iter + 1):  # noqa: B007 (the count is read after the loop)
        todo = (np.linalg.norm(E[:, :3], axis=1) > opt.tol_m)
        if rows6:
            todo |= np.linalg.norm(E[:, 3:], axis=1) > opt.tol_rad
        todo &= lam < 1e3
        if not todo.any():
            break
        Qe = Q + pm.joint_offsets(Q, aux)
        Qn = Q.copy()
        for i in map(int, np.flatnonzero(todo)):
            J = pm.jacobian(Qe[i])[:nr] * w[:, None]
            dq = J.T @ np.linalg.solve(J @ J.T + lam[i] ** 2 * eye, E[i] * w)
            s = np.abs(dq).max()
            if s > opt.max_step_rad:
                dq *= opt.max_step_rad / s
            Qn[i] = _wrap_clip(Q[i] + dq, lo, hi, rev)
        En = errors(Qn)
        better = todo & (np.linalg.norm(En * w, axis=1) < np.linalg.norm(E * w, axis=1))
        Q[better], E[better] = Qn[better], En[better]
        lam[better] = np.maximum(lam[better] / 3.0, opt.damping)
        lam[todo & ~better] *= 5.0
    err_m = np.linalg.norm(E[:, :3], axis=1)
    err_rad = np.linalg.norm(E[:, 3:], axis=1) if rows6 else np.zeros(len(Q))
    Qe = Q + pm.joint_offsets(Q, aux)
    inv_cond = np.empty(len(Q))
    for i, q in enumerate(Qe):
        sv = np.linalg.svd(pm.jacobian(q)[:nr] * w[:, None], compute_uv=False)
        inv_cond[i] = sv[-1] / sv[0] if sv[0] > 0 else 0.0
    return _IK(Q, err_m, err_rad, inv_cond, nit)


def _nominal_ik(pm0: PoseModel, pos_t: np.ndarray, R_t: np.ndarray | None, Q_start: np.ndarray, aux: Any,
                opt: CompensationOptions) -> tuple[_IK, np.ndarray]:
    """Nominal IK from Q_start, then from seeded random starts for the rows that did not converge.

    Returns:
        (the solutions, per row whether a random restart gave its solution).
    """
    ik = _solve_ik(pm0, pos_t, R_t, Q_start, aux, opt)
    restarted = np.zeros(len(Q_start), bool)
    rng = np.random.default_rng(opt.seed)
    for _ in range(opt.restarts):
        bad = (ik.err_m > opt.reach_tol_m) | (ik.err_rad > opt.reach_tol_rad)
        if not bad.any():
            break
        idx = np.flatnonzero(bad)
        sub_aux = aux.subset(idx) if isinstance(aux, MeasurementSet) else aux
        again = _solve_ik(pm0, pos_t[idx], None if R_t is None else R_t[idx], pm0.robot.random_q(rng, idx.size),
                          sub_aux, opt)
        better = again.err_m + opt.length_m * again.err_rad < ik.err_m[idx] + opt.length_m * ik.err_rad[idx]
        for k, i in enumerate(idx):
            if better[k]:
                ik.Q[i], ik.err_m[i], ik.err_rad[i], ik.inv_cond[i] = (again.Q[k], again.err_m[k], again.err_rad[k],
                                                                       again.inv_cond[k])
                restarted[i] = True
        ik.nit += again.nit
    return ik, restarted


def compensate(cm: CalibratedModel, targets: TargetSet, options: CompensationOptions | None = None
               ) -> CompensationResult:
    """Joint values that put the calibrated robot's TCP on Cartesian targets (module docstring, steps 1–3).

    Args:
        cm: the calibrated model (geometry + effects + set-up).
        targets: TCP positions (and orientations) in ``options.frame``; a joint hint per row
            (``targets.q``) starts the nominal IK there.
        options: :class:`CompensationOptions`.

    Returns:
        The :class:`CompensationResult` (``success``: every target reached).

    Raises:
        InputError: targets without positions, joint names that differ from the model's robot,
            an effect that needs a column (temperature, payload, time) the targets lack, no TCP (neither
            ``options.tcp_m`` nor one the model states).
    """
    opt = options or CompensationOptions()
    t0 = time.perf_counter()
    if targets.position_m is None:
        raise InputError(f"{targets.source or 'targets'}: no TCP positions (x, y, z) to compensate")
    check_tcp_stated(cm, opt)
    _check_joints(cm, targets)
    _check_effects(cm, targets.aux)
    pm = PoseModel(cm, opt.frame, opt.station, opt.tcp_m)
    pm0 = PoseModel(cm, opt.frame, opt.station, opt.tcp_m, nominal=True)
    pos_t = np.asarray(targets.position_m, float)
    R_t = None if targets.rotvec_rad is None else np.array([pin.exp3(v) for v in targets.rotvec_rad])
    q_work = cm.q_work if cm.q_work is not None or opt.cell is None or not np.size(opt.cell.q_work) else \
        cm.robot.check_q(opt.cell.q_work, "the cell's working configurations")
    start = start_configurations(pm0, q_work, targets.q, pos_t, R_t, targets.aux, opt.length_m)
    nom, restarted = _nominal_ik(pm0, pos_t, R_t, start.Q, targets.aux, opt)
    reached = (nom.err_m <= opt.reach_tol_m) & (nom.err_rad <= opt.reach_tol_rad) & ~restarted
    if reached.any():  # a redundant arm: the solution nearest the hint / working configuration
        w = np.r_[np.ones(3), np.full(3, opt.length_m)] if R_t is not None else np.ones(3)
        nom.Q[reached] = nearest_to_reference(pm0, nom.Q[reached], start.Q[reached], pos_t[reached],
                                              None if R_t is None else R_t[reached], w, opt.reach_tol_m)
    cal = _solve_ik(pm, pos_t, R_t, nom.Q, targets.aux, opt)
    left = restarted & np.array([k != "neutral" for k in start.kind])  # the hint's / working branch was left
    return _result(cm, targets, opt, pm, nom, cal, pos_t, t0, start.Q, start.kind, left)


def compensate_program(cm: CalibratedModel, program: TargetSet, options: CompensationOptions | None = None,
                       orientation: bool = True) -> CompensationResult:
    """Compensate a joint-space program: nominal FK → target → calibrated IK from the program's pose.

    The target of every program row is the TCP pose the nominal kinematics give for it (in the
    base frame: the controller's view), orientation included unless ``orientation`` is False.

    Continuity: every row's calibrated IK starts from its own program row and a row the correction moves by more
    than ``max_branch_step_rad`` is ``off_branch``, so consecutive sendable rows stay on the program's branch; the
    result's ``correction_jump_rad`` (the correction's change from the previous row) shows it, and its summary names
    where rows that are not ok (a singularity on the way) break the path.

    Args:
        cm: the calibrated model.
        program: the nominal program (``program.q``, rad / m).
        options: :class:`CompensationOptions` (``frame`` is ignored: the program lives in the base frame).
        orientation: also hold the tool orientation of each program pose.

    Returns:
        The :class:`CompensationResult` (``q_nominal`` = the program).

    Raises:
        InputError: a program without joint values, or with values outside the joint limits, no TCP (neither
            ``options.tcp_m`` nor one the model states).
    """
    opt = options or CompensationOptions()
    t0 = time.perf_counter()
    if program.q is None:
        raise InputError(f"{program.source or 'program'}: no joint columns")
    check_tcp_stated(cm, opt)
    _check_joints(cm, program)
    _check_effects(cm, program.aux)
    opt = CompensationOptions(**{**opt.__dict__, "frame": "base"})
    Q0 = cm.robot.check_q(program.q, program.source or "program")
    pm0 = PoseModel(cm, "base", opt.station, opt.tcp_m, nominal=True)
    pm = PoseModel(cm, "base", opt.station, opt.tcp_m)
    pos_t, R = pm0.pose(Q0, program.aux)
    R_t = R if orientation else None
    nom = _IK(Q0.copy(), np.zeros(len(Q0)), np.zeros(len(Q0)), np.ones(len(Q0)), 0)
    cal = _solve_ik(pm, pos_t, R_t, Q0, program.aux, opt)
    targets = TargetSet(program.names, pos_t, None, Q0, program.joint_names, program.aux, program.source)
    res = _result(cm, targets, opt, pm, nom, cal, pos_t, t0, Q0, ["program"] * len(Q0), np.zeros(len(Q0), bool))
    res.orientation = bool(orientation)
    res.correction_jump_rad = np.r_[0.0, np.abs(np.diff(cal.Q - Q0, axis=0)).max(axis=1)] if len(Q0) else np.zeros(0)
    return res


def check_tcp_stated(cm: CalibratedModel, opt: CompensationOptions, where: str = "the calibrated model") -> None:
    """Refuse to compensate without a TCP: neither ``opt.tcp_m`` nor a TCP the model states (``cm.tool_source``:
    a cell or a measurement header named it). The reflector is where the calibration measured, not the point the
    robot works with; taking it for the TCP puts the tool off the targets by the lever between the two.

    Raises:
        InputError: one line naming ``where`` and the two fixes.
    """
    if opt.tcp_m is not None or cm.tool_source:
        return
    refl = cm.setups[cm.station(opt.station)].reflector_m
    raise InputError(f"{where} states no TCP (identified without a cell or a data header stating tcp_m; only the "
                     f"reflector {np.round(refl, 6).tolist()} m was measured): give the TCP, tcp_m=[x, y, z] (m, in "
                     f"tool frame {cm.robot.tool_frame}), or identify with the cell (its tcp_m) so that the model "
                     "keeps it")


def _check_joints(cm: CalibratedModel, ts: TargetSet) -> None:
    if list(ts.joint_names) != list(cm.robot.joint_names):
        raise InputError(f"{ts.source or 'targets'}: joints {', '.join(ts.joint_names)} differ from the model's "
                         f"robot {cm.robot.name} ({', '.join(cm.robot.joint_names)})")


def _check_effects(cm: CalibratedModel, aux: MeasurementSet) -> None:
    for eff in cm.effects:
        col = eff.missing_column(aux) if hasattr(eff, "missing_column") else None
        if col:
            raise InputError(f"{aux.source or 'targets'}: the model's effect '{eff.name}' needs a '{col}' column "
                             f"the file lacks (its value at each target): add it, or compensate with a model "
                             f"without the effect (diagnose effects=[])")


def _result(cm: CalibratedModel, ts: TargetSet, opt: CompensationOptions, pm: PoseModel, nom: _IK, cal: _IK,
            pos_t: np.ndarray, t0: float, Q_start: np.ndarray, start: list[str], left_branch: np.ndarray
            ) -> CompensationResult:
    from pin_kpi_oed.discrepancy.lever_arm import lever_arm_m

    pos_nom, _ = pm.pose(nom.Q, ts.aux)
    correction = np.linalg.norm(pos_nom - pos_t, axis=1)
    step = branch_step(cal.Q, nom.Q)
    at_limit = joint_limit_rows(cm.robot, cal.Q, opt.limit_margin)
    colliding, pair = (collision_rows(opt.cell, cal.Q) if opt.cell is not None
                       else (np.zeros(len(ts), bool), [""] * len(ts)))
    at = _tcp_sigma(cm, cal.Q, ts.aux, opt, pm.tcp)
    unseen, extra = at.held_sigma_m, at.extrapolation
    rot, at_l = _orientation_sigma(cm, cal.Q, ts.aux, opt)
    held = unseen ** 2 > HELD_SHARE_MAX * at.sigma_m ** 2
    status = [_status(i, opt, nom, cal, bool(left_branch[i]), step[i] > opt.max_branch_step_rad, at_limit[i],
                      colliding[i], bool(extra[i]), bool(held[i])) for i in range(len(ts))]
    n_bad = sum(s not in ("ok", "tcp_unmeasured") for s in status)
    un = np.array([s == "tcp_unmeasured" for s in status], bool)
    text = "ok" if not un.any() else held_status_line(unseen[un], at.sigma_m[un])
    base_part = np.zeros(0)
    if opt.frame == "base":  # the part of the held σ that is the base frame's own placement, not the tool's
        tool = _tcp_sigma(cm, cal.Q, ts.aux, replace(opt, frame="cell"), pm.tcp).held_sigma_m
        base_part = np.sqrt(np.maximum(unseen ** 2 - tool ** 2, 0.0))
    return CompensationResult(
        success=n_bad == 0, status=text if n_bad == 0 else f"{n_bad} of {len(ts)} targets not ok",
        message="" if n_bad == 0 else "see the per-target status (" + " / ".join(STATUSES[1:]) + ")",
        nit=int(nom.nit + cal.nit), time_s=time.perf_counter() - t0, names=list(ts.names),
        joint_names=list(cm.robot.joint_names), q_nominal=nom.Q, q=cal.Q, correction_m=correction,
        residual_m=cal.err_m, residual_rad=cal.err_rad, inv_cond=cal.inv_cond, target_status=status,
        frame=opt.frame, station=cm.station(opt.station), tcp_m=pm.tcp, orientation=ts.rotvec_rad is not None,
        sigma_m=at.sigma_m, tcp_unobservable_m=unseen, base_unobservable_m=base_part, extrapolation=extra,
        tcp_from_reflector_m=lever_arm_m(pm.tcp, cm.setups[cm.station(opt.station)].reflector_m),
        tool_frame=cm.robot.tool_frame, start=list(start), q_start=np.asarray(Q_start, float),
        branch_step_rad=step, from_start_rad=branch_step(cal.Q, Q_start), collision_pair=pair,
        sigma_rot_rad=rot, tool_length_m=float(opt.tool_length_m), sigma_at_length_m=at_l, **_device_of(cm))


def _device_of(cm: CalibratedModel) -> dict:
    """The device the model was calibrated with: ``{device, camera_mode}`` (a camera's model has ``fit.device``)."""
    dev = (cm.fit or {}).get("device")
    if not isinstance(dev, dict):
        return {"device": "tracker", "camera_mode": ""}
    return {"device": "camera", "camera_mode": str(dev.get("mode", "eye_in_hand"))}


def _status(i: int, opt: CompensationOptions, nom: _IK, cal: _IK, left_branch: bool, big_step: bool,
            at_limit: bool, colliding: bool, outside: bool, held: bool = False) -> str:
    """The status of target i (module docstring): the first failed check. Near a singularity compensation needs
    large joint steps, so ``near_singular`` is named before a step too large for the branch; ``extrapolated`` (outside
    the calibration's joint-space coverage) comes after the others, ``tcp_unmeasured`` (``held``: the TCP's σ
    dominated by parameters no measurement determined) last: every other check passed."""
    if (nom.err_m[i] > opt.reach_tol_m or nom.err_rad[i] > opt.reach_tol_rad
            or cal.err_m[i] > opt.reach_tol_m or cal.err_rad[i] > opt.reach_tol_rad):
        return "unreachable"
    if left_branch:
        return "off_branch"
    if cal.inv_cond[i] < opt.singular_ratio:
        return "near_singular"
    if big_step:
        return "off_branch"
    if at_limit:
        return "joint_limit"
    if colliding:
        return "collision"
    if outside:
        return "extrapolated"
    return "tcp_unmeasured" if held else "ok"


def _tcp_sigma(cm: CalibratedModel, Q: np.ndarray, aux: Any, opt: CompensationOptions, tcp: np.ndarray) -> TcpSigma:
    """The TCP's σ at the compensated joints Q in the targets' frame:
    :func:`~pin_kpi_oed.calibrated.tcp_sigma.tcp_sigma` (one σ at the TCP for every command: the model's at the TCP
    and the joint-placement parameters it held at nominal under ``opt.tool_tolerances``)."""
    return tcp_sigma(cm, Q, tcp, station=opt.station, aux=aux if isinstance(aux, MeasurementSet) else None,
                     frame=opt.frame, tolerances=opt.tool_tolerances, seed=opt.seed)


def _orientation_sigma(cm: CalibratedModel, Q: np.ndarray, aux: Any, opt: CompensationOptions
                       ) -> tuple[np.ndarray, np.ndarray]:
    """(3-D σ of the orientation (rad), σ at ``opt.tool_length_m`` along the tool axis (m)) at Q of a 6-D model: of
    the frame the calibration measured (the probe's), which a tool rigidly mounted with it shares (its mounting
    relative to the probe is the nominal one, like a TCP away from the reflector); empty for a position-only model."""
    from pin_kpi_oed.calibrated.prediction_sigma import orientation_sigma

    if not cm.pose6d or not len(Q):
        return np.zeros(0), np.zeros(0)
    label = cm.station(opt.station)
    _, s, at_l = orientation_sigma(cm, Q, aux if isinstance(aux, MeasurementSet) else None, label,
                                   np.array([label] * len(Q), dtype=object), opt.tool_length_m)
    return np.linalg.norm(s, axis=1), at_l


def forward(cm: CalibratedModel, Q: np.ndarray, aux: Any = None, frame: str = "cell", station: str | None = None,
            tcp_m: np.ndarray | None = None) -> np.ndarray:
    """Where the calibrated model says the TCP goes for commanded joints Q: positions (m, 3) m in ``frame``."""
    return PoseModel(cm, frame, station, tcp_m).pose(np.atleast_2d(np.asarray(Q, float)), aux)[0]

