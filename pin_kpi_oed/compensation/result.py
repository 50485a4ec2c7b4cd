"""The result of a compensation and its file: the compensated joints of every target, what each check found and
the σ there (:mod:`pin_kpi_oed.compensation.compensator` computes it), and the compensation CSV a controller
receives (the compensated joints, rad / m, with the nominal joints, the correction, the residuals, the predicted
TCP σ and the status of every target; SI units)."""

from __future__ import annotations

import csv
import io
import os
from dataclasses import dataclass, field

import numpy as np

from pin_kpi_oed.data.atomic import atomic_write_text
from pin_kpi_oed.results import Result

__all__ = ["STATUSES", "SENDABLE", "HELD_SHARE_MAX", "CompensationResult", "write_compensation", "held_status_line"]

#: Status of a compensated target; only the first is safe to send as it is.
STATUSES = ("ok", "unreachable", "off_branch", "joint_limit", "collision", "near_singular", "extrapolated",
            "tcp_unmeasured")
#: The statuses whose compensated joints may be sent, with the caveat the status names (``extrapolated``: outside the
#: calibration's coverage; ``tcp_unmeasured``: ok at the measured part, the TCP's σ dominated by held parameters).
SENDABLE = ("ok", "extrapolated", "tcp_unmeasured")
#: A target whose TCP σ² is more than this share held parameters (G Σ_N Gᵀ) is ``tcp_unmeasured``, not ``ok``.
HELD_SHARE_MAX = 0.5


def held_status_line(held_m: np.ndarray, sigma_m: np.ndarray) -> str:
    """The status of a compensation whose targets passed every check but whose TCP σ is dominated by held
    parameters: "ok at the measured part; ... (x mm of y mm): measure the TCP".

    Args:
        held_m: the held parameters' 3-D σ at those targets (m); sigma_m: their TCP 3-D σ (m).

    Returns:
        The line (RMS over the targets, mm).
    """
    h = float(np.sqrt(np.mean(np.square(held_m))))
    t = float(np.sqrt(np.mean(np.square(sigma_m))))
    return (f"ok at the measured part; the TCP's sigma is dominated by parameters no measurement determined "
            f"({h * 1e3:.3g} mm of {t * 1e3:.3g} mm): measure the TCP")


@dataclass(kw_only=True)
class CompensationResult(Result):
    """Compensated joint values of every target (SI units).

    Attributes:
        names: target labels.
        joint_names: the robot's joints (columns of ``q`` and ``q_nominal``).
        q_nominal: nominal IK solutions (what the controller would command for the target), (m, n).
        q: compensated joint values (send these), (m, n).
        correction_m: predicted TCP correction |F_cal(q_nominal) − target|, (m,) m.
        residual_m, residual_rad: calibrated-model distance of q's TCP from the target (m, rad).
        inv_cond: inverse condition number of the scaled Jacobian at q.
        status: per target ``ok`` / ``unreachable`` / ``near_singular`` / ... / ``tcp_unmeasured`` (every check
            passed but more than :data:`HELD_SHARE_MAX` of the TCP's σ² is the held parameters': no measurement
            determined the error there); ``status`` of the result: ``ok`` if every target is ok, the
            :func:`held_status_line` when the others are ``tcp_unmeasured``, else a count.
        frame: ``cell`` or ``base``; tcp_m: the TCP point (tool frame, m); station.
        sigma_m: predicted 3-D standard deviation of the TCP at q (m), the one σ at the TCP
            (:func:`~pin_kpi_oed.calibrated.tcp_sigma.tcp_sigma`, as ``predict --at tcp`` and ``identify`` state it):
            the model's discrepancy (posterior and white level; its noise model's σ without one), the
            parameters through the TCP's Jacobian and ``tcp_unobservable_m``, (m,). Learnt at the reflector: a TCP
            away from it adds the flange rotation's lever arm (:mod:`pin_kpi_oed.discrepancy.lever_arm`).
        tcp_from_reflector_m: the TCP's distance from the station's reflector (m).
        tool_frame: the tool frame ``tcp_m`` is given in.
        start: per target, where its branch came from (``hint``, ``working``, ``neutral``; ``program``).
        q_start: the start configurations (m, n).
        branch_step_rad: per target, the largest joint change of ``q`` from ``q_nominal`` (rad / m).
        from_start_rad: per target, the largest joint difference of ``q`` from ``q_start`` (rad / m).
        collision_pair: per target with a cell, the pair nearest to colliding at ``q`` ("" without a cell).
        tcp_unobservable_m: per target, the 3-D σ (m) at the TCP of what one reflector cannot see (joint-placement
            errors the fit could not determine, under the tolerances; 0 at the fitted reflector), included in
            ``sigma_m``.
        base_unobservable_m: targets in the base frame (``frame`` ``base``): per target, the part of
            ``tcp_unobservable_m`` (3-D σ, m, in quadrature) that is the base frame's own placement on the robot
            (joint 1's placement and what the tracker pose absorbs, held at their tolerance), which a reflector at
            the TCP does not remove and targets in the tracker frame leave out; empty in the tracker frame.
        extrapolation: per target, the compensated joints lie outside the calibration's joint-space coverage
            (:class:`~pin_kpi_oed.discrepancy.coverage.JointCoverage`): the model extrapolates there and its σ
            includes the parameters' extrapolation error, (m,) bool.
        sigma_rot_rad: a 6-D model's predicted 3-D σ of the orientation at q (rad), (m,): of the frame the
            calibration measured (the probe's; a tool rigidly mounted with it shares it, its mounting the nominal
            one); empty for a position-only model (:func:`~pin_kpi_oed.calibrated.prediction_sigma.
            orientation_sigma`).
        tool_length_m: the length along the tool axis of ``sigma_at_length_m`` (m).
        sigma_at_length_m: the 3-D σ of the point ``tool_length_m`` along the tool axis that the orientation error
            moves (m), (m,); empty for a position-only model.
        correction_jump_rad: a program's continuity: per row, the largest joint change of the correction q − q⁰
            from the previous row's (rad / m; 0 for the first row, empty for Cartesian targets). Compensation keeps
            the program's branch when it stays far below the program's own steps; the rows where it does not are
            not ``ok`` (a singularity, another branch).
        device: what the calibration measured with, ``tracker`` or ``camera`` (the model's ``fit.device``);
            camera_mode: ``eye_in_hand`` or ``eye_to_hand`` for a camera, else "". The messages name the device's
            frame and the mounted target it measured (reflector, board, camera).
    """

    names: list[str] = field(default_factory=list)
    joint_names: list[str] = field(default_factory=list)
    q_nominal: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    q: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    correction_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    residual_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    residual_rad: np.ndarray = field(default_factory=lambda: np.zeros(0))
    inv_cond: np.ndarray = field(default_factory=lambda: np.zeros(0))
    target_status: list[str] = field(default_factory=list)
    frame: str = "cell"
    station: str = ""
    tcp_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    orientation: bool = False
    sigma_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    tcp_from_reflector_m: float = 0.0
    tool_frame: str = ""
    start: list[str] = field(default_factory=list)
    q_start: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    branch_step_rad: np.ndarray = field(default_factory=lambda: np.zeros(0))
    from_start_rad: np.ndarray = field(default_factory=lambda: np.zeros(0))
    collision_pair: list[str] = field(default_factory=list)
    tcp_unobservable_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    base_unobservable_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    extrapolation: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    sigma_rot_rad: np.ndarray = field(default_factory=lambda: np.zeros(0))
    tool_length_m: float = 0.0
    sigma_at_length_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    correction_jump_rad: np.ndarray = field(default_factory=lambda: np.zeros(0))
    device: str = "tracker"
    camera_mode: str = ""

    @property
    def measured_text(self) -> str:
        """What the calibration measured on the tool: ``reflector``, ``board`` (eye-to-hand) or ``camera``."""
        if self.device != "camera":
            return "reflector"
        return "board" if self.camera_mode == "eye_to_hand" else "camera"

    def frame_text(self) -> str:
        """The targets' frame as the summary names it: the station's tracker frame, the camera's frame (eye-to-hand:
        the camera fixed in the cell), the board's frame (eye-in-hand: the board fixed in the cell), or ``base``."""
        if self.frame != "cell":
            return f"{self.frame} frame"
        if self.device != "camera":
            return f"tracker frame of station {self.station}"
        return self.device_frame_text()

    def device_frame_text(self) -> str:
        """The device's frame: ``the tracker frame``, ``the camera's frame`` (eye-to-hand) or ``the board's frame``
        (eye-in-hand)."""
        if self.device != "camera":
            return "the tracker frame"
        return "the camera's frame" if self.camera_mode == "eye_to_hand" else "the board's frame"

    def summary(self) -> str:
        """Counts, correction statistics (mm), and the targets that are not ok."""
        c = self.correction_m * 1e3
        ok = [s == "ok" for s in self.target_status]
        counts = ", ".join(f"{self.target_status.count(k)} {k.replace('_', ' ')}" for k in STATUSES[1:]
                           if k in self.target_status)
        lines = [f"compensated {len(self.names)} targets "
                 f"({'position + orientation' if self.orientation else 'position'}"
                 f", {self.frame_text()}): "
                 f"{sum(ok)} ok" + (f", {counts}" if counts else ""),
                 f"TCP {np.round(self.tcp_m * 1e3, 3).tolist()} mm in tool frame {self.tool_frame}"
                 + ("; branch from: " + ", ".join(f"{self.start.count(k)} {k}" for k in dict.fromkeys(self.start))
                    if self.start else "")
                 + (f"; largest joint change by compensation {np.max(self.branch_step_rad):.2e} rad"
                    if self.branch_step_rad.size else "")]
        if c.size:
            lines.append(f"predicted correction: mean {np.nanmean(c):.4f} mm, max {np.nanmax(c):.4f} mm; "
                         f"largest residual {np.nanmax(self.residual_m) * 1e3:.2e} mm")
        if self.sigma_m.size:
            lines.append(f"predicted TCP sigma (3-D) at the compensated joints: mean {np.mean(self.sigma_m) * 1e3:.4f} "
                         f"mm, max {np.max(self.sigma_m) * 1e3:.4f} mm")
            from pin_kpi_oed.discrepancy.lever_arm import LEVER_ARM_NOTE_M, lever_arm_line

            if self.device != "camera" and self.tcp_from_reflector_m >= LEVER_ARM_NOTE_M:  # a camera sees 6-D
                lines.append(lever_arm_line(self.tcp_from_reflector_m, "this sigma"))
            if self.sigma_rot_rad.size:
                lines.append(f"predicted orientation sigma (3-D, the measured probe's frame): mean "
                             f"{np.mean(self.sigma_rot_rad) * 1e3:.4f} mrad, max "
                             f"{np.max(self.sigma_rot_rad) * 1e3:.4f} mrad; at {self.tool_length_m * 1e3:g} mm "
                             "along the tool axis it moves the tool by sigma mean "
                             f"{np.mean(self.sigma_at_length_m) * 1e3:.4f} mm, max "
                             f"{np.max(self.sigma_at_length_m) * 1e3:.4f} mm")
            n_held = self.target_status.count("tcp_unmeasured")
            if n_held:
                lines.append(f"{n_held} of {len(self.names)} targets tcp unmeasured: every check passed, but more "
                             f"than {HELD_SHARE_MAX:.0%} of their TCP sigma^2 is from joint-placement parameters no "
                             f"measurement determined; the compensation is right at the measured {self.measured_text}"
                             ", not known at the TCP: measure the TCP ("
                             + ("a reflector nest at it, or " if self.device != "camera" else "")
                             + "a tool calibration)")
            if self.tcp_unobservable_m.size and np.max(self.tcp_unobservable_m) > 0:
                lines.append(self._unobservable_line())
        if np.any(self.extrapolation):
            far = [n for n, e in zip(self.names, self.extrapolation) if e]
            n_st = self.target_status.count("extrapolated")
            lines.append(f"{len(far)} of {len(self.names)} targets outside the calibration's joint-space coverage "
                         f"(extrapolation: {', '.join(far[:5])}{' ...' if len(far) > 5 else ''}"
                         f"{f'; {n_st} of them status extrapolated, not ok' if n_st else ''}): the model was not "
                         "measured near them, their correction is an extrapolation and their sigma the widened one "
                         "predict gives there (the parameters' extrapolation included); measure poses near them "
                         "(design --given with the calibration's poses adds them) and identify again")
        if self.correction_jump_rad.size > 1:
            lines.append(self._continuity_line())
        bad = [(n, s) for n, s in zip(self.names, self.target_status) if s != "ok"]
        for n, s in bad[:10]:
            lines.append(f"  target {n}: {s}")
        if len(bad) > 10:
            lines.append(f"  ... and {len(bad) - 10} more")
        return "\n".join(lines)

    def _unobservable_line(self) -> str:
        """What no reflector measurement determines at the TCP (largest over the targets, mm), split in the base
        frame into the tool's part (a reflector at the TCP removes it) and the base frame's own placement (no
        tracker measurement determines it)."""
        held = float(np.max(self.tcp_unobservable_m))
        camera = self.device == "camera"
        seer = "the camera's images" if camera else "the reflector"
        line = (f"of which {held * 1e3:.4f} mm (3-D, 1 sigma) {seer} cannot see at this TCP: joint-placement "
                "errors the calibration could not determine, from the manufacturing tolerances")
        fix = "the TCP measured (a tool calibration)" if camera else "a reflector at the TCP (or the TCP measured)"
        base = float(np.max(self.base_unobservable_m)) if self.base_unobservable_m.size else 0.0
        if base <= 0.05 * held:
            return line + f" (e.g. along and about the last joint axis); {fix} removes it"
        tool = float(np.max(np.sqrt(np.maximum(self.tcp_unobservable_m ** 2 - self.base_unobservable_m ** 2, 0.0))))
        where = self.device_frame_text()
        pose = where.replace(" frame", " pose") if camera else "the tracker pose"
        own = "camera" if camera else "tracker"
        return (line + f": {tool * 1e3:.4f} mm at the tool (along and about the last joint axis; {fix} removes it) "
                f"and {base * 1e3:.4f} mm the base frame's own placement on the robot (joint 1's placement and what "
                f"{pose} absorbs), which no {own} measurement determines: targets in {where} (--frame tracker) "
                "leave it out")

    def _continuity_line(self) -> str:
        """The program's continuity: the largest change of the correction between consecutive rows, over the rows
        that may be sent (ok and extrapolated) against the program's own largest joint step."""
        good = np.array([s in SENDABLE for s in self.target_status])
        pair = good[1:] & good[:-1]
        step = np.abs(np.diff(self.q_nominal, axis=0)).max(axis=1)
        jump = self.correction_jump_rad[1:]
        line = (f"continuity: the correction changes by at most {jump[pair].max() if pair.any() else 0.0:.2e} rad "
                f"between consecutive sendable rows (program steps up to {step.max():.2e} rad)")
        broken = np.flatnonzero(~pair)
        if broken.size:
            line += (f"; the program is broken at {broken.size} of {pair.size} steps by rows that are not ok (first "
                     f"between {self.names[broken[0]]} and {self.names[broken[0] + 1]}): do not send it as one path")
        return line

    def to_dict(self) -> dict:
        from pin_kpi_oed.data.atomic import to_jsonable

        return to_jsonable({**self.result_dict(), "names": self.names, "joint_names": self.joint_names,
                            "q": self.q, "q_nominal": self.q_nominal, "correction_m": self.correction_m,
                            "residual_m": self.residual_m, "residual_rad": self.residual_rad,
                            "inv_cond": self.inv_cond, "target_status": self.target_status, "frame": self.frame,
                            "station": self.station, "tcp_m": self.tcp_m, "orientation": self.orientation,
                            "sigma_m": self.sigma_m, "tcp_from_reflector_m": self.tcp_from_reflector_m,
                            "tool_frame": self.tool_frame, "start": self.start, "q_start": self.q_start,
                            "branch_step_rad": self.branch_step_rad, "from_start_rad": self.from_start_rad,
                            "collision_pair": self.collision_pair, "tcp_unobservable_m": self.tcp_unobservable_m,
                            "base_unobservable_m": self.base_unobservable_m,
                            "extrapolation": self.extrapolation, "sigma_rot_rad": self.sigma_rot_rad,
                            "tool_length_m": self.tool_length_m, "sigma_at_length_m": self.sigma_at_length_m,
                            "correction_jump_rad": self.correction_jump_rad, "device": self.device,
                            "camera_mode": self.camera_mode})


def write_compensation(path: str | os.PathLike, res: CompensationResult) -> None:
    """Write the compensated joints as CSV, atomically (SI units).

    Columns: ``name``, the joint columns (compensated, rad / m: send these), ``<joint>_nominal``,
    ``correction_m``, ``residual_m``, ``residual_rad``, ``inv_cond``, ``sigma_m`` (predicted 3-D TCP σ, m),
    ``start`` (where the branch came from), ``branch_step_rad`` (largest joint change from the nominal solution),
    ``extrapolation`` (1: outside the calibration's joint-space coverage), ``status``; a 6-D model adds
    ``sigma_rot_rad`` (the tool orientation's 3-D σ, rad) and ``sigma_at_length_m`` (the σ it causes at the tool
    length, m); a program adds ``correction_jump_rad`` (the correction's change from the previous row, rad / m).
    """
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["name"] + res.joint_names + [f"{j}_nominal" for j in res.joint_names]
               + ["correction_m", "residual_m", "residual_rad", "inv_cond", "sigma_m", "start", "branch_step_rad",
                  "extrapolation", "status"]
               + (["sigma_rot_rad", "sigma_at_length_m"] if res.sigma_rot_rad.size else [])
               + (["correction_jump_rad"] if res.correction_jump_rad.size else []))
    for i, n in enumerate(res.names):
        w.writerow([n] + [repr(float(v)) for v in res.q[i]] + [repr(float(v)) for v in res.q_nominal[i]]
                   + [repr(float(res.correction_m[i])), repr(float(res.residual_m[i])),
                      repr(float(res.residual_rad[i])), repr(float(res.inv_cond[i])),
                      repr(float(res.sigma_m[i])) if res.sigma_m.size else "",
                      res.start[i] if res.start else "",
                      repr(float(res.branch_step_rad[i])) if res.branch_step_rad.size else "",
                      str(int(res.extrapolation[i])) if res.extrapolation.size else "", res.target_status[i]]
                   + ([repr(float(res.sigma_rot_rad[i])), repr(float(res.sigma_at_length_m[i]))]
                      if res.sigma_rot_rad.size else [])
                   + ([repr(float(res.correction_jump_rad[i]))] if res.correction_jump_rad.size else []))
    atomic_write_text(path, buf.getvalue())
