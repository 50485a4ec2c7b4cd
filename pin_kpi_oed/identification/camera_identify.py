r"""A camera calibration as a calibrated model: the fit on the corners and the model file every command reads.

:func:`identify_camera` reads a camera measurement set (one row per detected corner), finds the identifiable
parameters on seeded configurations around the measured ones that see the board
(:meth:`~pin_kpi_oed.model.camera.CameraModel.views`, :func:`~pin_kpi_oed.oed.identifiability.analyse`), fits them
on the reprojection error (:func:`~pin_kpi_oed.identification.camera_fit.fit_camera`) and computes how the fit
absorbed the joint-placement parameters it holds at nominal (A = M⁻¹F_BᵀF_N on the fit's own pixel rows,
:func:`~pin_kpi_oed.oed.covariance.held_absorption`; their prior: the tolerances).

:meth:`CameraIdentification.calibrated_model` writes it in the calibrated model's vocabulary, so that
``predict --at tcp``, ``compensate``, ``report`` and the σ at the TCP (:mod:`pin_kpi_oed.calibrated.tcp_sigma`)
need nothing of their own for a camera:

* the robot's joint-placement errors as fitted;
* one station ``camera`` whose ``tracker_T_base`` is the fitted device frame (board_T_base eye-in-hand,
  camera_T_base eye-to-hand: the frame the camera's TCP is estimable in) and whose ``reflector_m`` is the fitted
  origin of the part on the tool (the camera or the board);
* the fit's parameters with the device frame's named as the station's set-up (``board.tx`` → ``tracker.tx``
  eye-in-hand): the TCP's σ through the model's Jacobian is E C_p Eᵀ over the robot and the device frame (the part
  on the tool does not move the TCP), plus the held term G Σ_N Gᵀ;
* the device itself (``fit.device``: mount, intrinsics, board, fitted poses, reprojection RMS in px), read back by
  :func:`camera_device`; a model that estimated intrinsics (the cell's ``intrinsics_sigma``) adds
  ``fitted_intrinsics`` (all nine by name, px and dimensionless) and ``intrinsics_std`` (the σ of the estimated
  ones, by name), and :func:`camera_model_of` takes the fitted intrinsics as its nominal ones. The model's noise
  is 1 nm: a camera does not measure the TCP, its pixel noise is in C_p.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pin_kpi_oed.calibrated.model_file import CalibratedModel, Setup
from pin_kpi_oed.data.corner_measurements import CornerSet
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.identification.camera_fit import CameraFit, fit_camera
from pin_kpi_oed.identification.camera_joint_noise import N_FOLDS, JointNoise, camera_joint_noise
from pin_kpi_oed.identification.identify_result import param_unit
from pin_kpi_oed.model.camera import INTRINSIC_NAMES, CameraModel, Intrinsics
from pin_kpi_oed.model.noise import NoiseModel
from pin_kpi_oed.model.tolerances import Tolerances
from pin_kpi_oed.oed.covariance import held_absorption
from pin_kpi_oed.oed.held import HeldTerm
from pin_kpi_oed.oed.identifiability import analyse

__all__ = ["CameraIdentification", "identify_camera", "camera_device", "camera_model_of", "STATION"]

#: the station label of a camera calibration
STATION = "camera"
#: the noise a camera model states for measured − predicted TCP positions (m): none measured, a negligible level
_NO_TCP_NOISE_M = 1e-9


@dataclass
class CameraIdentification:
    """A camera calibration (:func:`identify_camera`).

    Attributes:
        model: the nominal camera model; fit: the :class:`CameraFit`; labels: the images used.
        Q: their joint values (m, n) rad; uv: their corners (m, 2N) px (NaN: not detected).
        held: the joint-placement parameters held at nominal with their absorption, or None.
        source: the measurement file; device: the camera's description (the cell's ``camera``/``board``).
        joint: the joint-angle error level of the images and whether the σ carries it
            (:mod:`~pin_kpi_oed.identification.camera_joint_noise`), or None (not estimated).
    """

    model: CameraModel
    fit: CameraFit
    labels: list[str]
    Q: np.ndarray
    uv: np.ndarray
    held: HeldTerm | None
    source: str = ""
    device: dict = field(default_factory=dict)
    joint: JointNoise | None = None

    def stored_names(self) -> list[str]:
        """The fit's parameter names in the calibrated model's vocabulary (the device frame as ``tracker``)."""
        frame = self.model.frame_group
        return [f"tracker.{n.split('.', 1)[1]}" if n.split(".", 1)[0] == frame else n for n in self.fit.names]

    def fitted_intrinsics(self) -> tuple[dict[str, float], dict[str, float]]:
        """The intrinsics at the fit ({name: value}, all nine, px or dimensionless) and the σ of the estimated ones
        ({name: σ}; empty when the model holds every intrinsic at nominal)."""
        m, f = self.model, self.fit
        values = dict(zip(INTRINSIC_NAMES, m.intrinsic_vector(f.p).tolist()))
        std = np.sqrt(np.maximum(np.diag(f.covariance), 0.0))
        sig = {n.split(".", 1)[1]: float(s) for n, s in zip(f.names, std) if n.startswith("intrinsics.")}
        return values, sig

    def calibrated_model(self, q_work: np.ndarray | None = None, tool_source: str = "") -> CalibratedModel:
        """The calibration as a :class:`CalibratedModel` (module docstring)."""
        m, p = self.model, self.fit.p
        nj = 6 * m.robot.nq
        mounted = m.pose_of(m.target_groups[0], p)
        setup = Setup(m.sensor_pose(p).homogeneous, mounted.translation.copy(), n_rows=self.fit.n_rows,
                      fitted_by="identify", source=self.source)
        names = self.stored_names()
        jn = self.joint if self.joint is not None and self.joint.used else None
        cov = self.fit.covariance if jn is None else jn.covariance
        std = np.sqrt(np.maximum(np.diag(cov), 0.0))
        device = {**self.device, "mode": m.mode, "fitted_camera_pose": m.pose_of("camera", p).homogeneous.tolist(),
                  "fitted_board_pose": m.pose_of("board", p).homogeneous.tolist(), "rms_px": self.fit.rms_px,
                  "sigma_px": m.sigma_px}
        values, sig = self.fitted_intrinsics()
        if m.estimate_intrinsics:
            device.update(fitted_intrinsics=values, intrinsics_std=sig)
        fit = {"device": device, "n_measurements": self.fit.n_images, "n_rows": self.fit.n_rows,
               "rms_px": self.fit.rms_px, "chi2_reduced": self.fit.chi2_reduced,
               "covariance_scaled": jn is not None, "loss": "linear", "success": bool(self.fit.success),
               "status": self.fit.status, "nfev": int(self.fit.nfev), "time_s": float(self.fit.time_s)}
        if self.joint is not None:
            fit["joint_noise"] = self.joint.to_dict()
        if jn is not None:  # the σ at the TCP adds J_q diag(s²) J_qᵀ (calibrated.tcp_sigma)
            fit["joint_angle_sigma_rad"] = [float(v) for v in jn.sigma_rad]
        return CalibratedModel(
            robot=m.robot, joint_p=np.asarray(p[:nj], float).copy(), setups={STATION: setup},
            noise=NoiseModel(sigma_xyz_m=(_NO_TCP_NOISE_M,) * 3), tcp_m=m.tcp_m.copy(),
            parameters={"names": names, "values": p[self.fit.base], "std": std, "units": [param_unit(n) for n in names],
                        "covariance": cov,
                        **({"held": self.held.to_dict()} if self.held is not None else {})},
            fit=fit, default_station=STATION,
            history=[{"step": "identify", "device": "camera", "data": self.source, "n_images": self.fit.n_images,
                      "rms_px": self.fit.rms_px}],
            q_work=q_work, tool_source=tool_source)

    def summary(self) -> str:
        """Readable lines: images, corners, reprojection RMS, χ², identified and held parameters, the estimated
        intrinsics with their σ."""
        f = self.fit
        values, sig = self.fitted_intrinsics()
        unit = {n: " px" if n in ("fx", "fy", "cx", "cy") else "" for n in sig}
        intr = ("\nfitted intrinsics: " + ", ".join(f"{n} {values[n]:.6g}{unit[n]} (sigma {s:.2g}{unit[n]})"
                                                     for n, s in sig.items()) if sig else "")
        return (f"camera fit: {f.n_images} images, {f.n_rows // 2} corners, reprojection RMS {f.rms_px:.3f} px, "
                f"reduced chi2 {f.chi2_reduced:.2f}, {len(f.base)} parameters identified"
                + (f", {self.held.k} joint-placement parameters held at nominal (tolerance prior)"
                   if self.held is not None else "") + intr
                + (f"\n{self.joint.reason}" if self.joint is not None else ""))


def _aligned(cs: CornerSet, model: CameraModel, source: str) -> tuple[list[str], np.ndarray, np.ndarray]:
    labels, Q, uv = cs.arrays(model.board.n, source)
    robot = model.robot
    names = list(robot.joint_names)
    if sorted(cs.joint_names) != sorted(names):
        raise InputError(f"{source}: joint columns {', '.join(cs.joint_names)} are not the robot's "
                         f"({', '.join(names)})")
    Q = Q[:, [cs.joint_names.index(n) for n in names]]
    return labels, robot.check_q(Q, source), uv


def identify_camera(model: CameraModel, cs: CornerSet, *, source: str = "camera measurements", seed: int = 0,
                    loss: str = "linear", device: dict | None = None,
                    tolerances: Tolerances | None = None, joint_noise: bool = True) -> CameraIdentification:
    """Identify the robot, the hand-eye transform and the board from a camera measurement set (module docstring).

    Args:
        model: the nominal camera model (a cell's :meth:`~pin_kpi_oed.cell.cell_model.Cell.measurement_model`).
        cs: the detected corners; source: their file, for messages.
        seed: the seed of the identifiability analysis's configurations.
        loss: ``linear`` or a robust loss of :func:`fit_camera`.
        device: the camera's description to store (the cell's ``camera`` and ``board`` fields).
        tolerances: the held joint-placement parameters' prior (default :class:`Tolerances`).
        joint_noise: estimate the images' joint-angle error level and let the K-fold check on images decide
            whether the σ carries it (:mod:`~pin_kpi_oed.identification.camera_joint_noise`; seeded by ``seed``).

    Returns:
        The :class:`CameraIdentification`.

    Raises:
        InputError: joint columns not the robot's, joint values outside its limits, too few images.
        IdentifiabilityError: the images do not determine the parameters.
    """
    labels, Q, uv = _aligned(cs, model, source)
    if len(Q) < 3:
        raise InputError(f"{source}: {len(Q)} image(s) with the board; a camera calibration needs at least 3 (the "
                         "hand-eye transform alone needs two rotations about different axes)")
    ident = analyse(model, Q=model.views(60, seed=seed, around=Q), seed=seed)
    fit = fit_camera(model, Q, uv, ident.base, loss=loss)
    nj = 6 * model.robot.nq
    held_idx = np.array([i for i in range(nj) if i not in set(ident.base.tolist())], int)
    held = None
    if held_idx.size:
        rows = np.isfinite(uv).ravel()
        F = model.weighted_jacobian(fit.p, Q).reshape(-1, model.n_params)[rows]
        tol = tolerances or Tolerances()
        sig = np.where(np.arange(nj) % 6 < 3, tol.joint_translation_m, tol.joint_rotation_rad)[held_idx]
        A = held_absorption(F[:, fit.base], F[:, held_idx])
        stored = CameraIdentification(model, fit, labels, Q, uv, None).stored_names()
        held = HeldTerm([model.layout.names[i] for i in held_idx], sig, stored, A)
    joint = (camera_joint_noise(model, fit.p, fit.base, Q, uv, fit.chi2_reduced, seed=seed)
             if joint_noise and len(Q) >= 2 * N_FOLDS else None)
    return CameraIdentification(model, fit, labels, Q, uv, held, source, dict(device or {}), joint)


def camera_device(cm: Any) -> dict | None:
    """The camera a calibrated model was identified with (``fit.device``), or None for a tracker's model."""
    d = (getattr(cm, "fit", None) or {}).get("device")
    return d if isinstance(d, dict) else None



def camera_model_of(cm: Any) -> tuple[CameraModel, np.ndarray]:
    """The camera model a calibrated camera model was identified with, its fitted hand-eye transform and board pose
    as the nominal ones, and the raw parameters (the robot's fitted errors, set-up errors zero).

    Raises:
        InputError: the model is not a camera's (no ``fit.device``) or its device does not read back.
    """
    from pin_kpi_oed.cell.camera_setup import read_camera_setup
    from pin_kpi_oed.model.kinematics import se3_from_matrix

    dev = camera_device(cm)
    if dev is None:
        raise InputError("the model was not identified with a camera (its fit has no 'device')")
    setup = read_camera_setup({"camera": dev.get("camera"), "board": dev.get("board")}, "model file: fit.device")
    cam = se3_from_matrix(dev.get("fitted_camera_pose"), "model file: fit.device.fitted_camera_pose")
    brd = se3_from_matrix(dev.get("fitted_board_pose"), "model file: fit.device.fitted_board_pose")
    intr = setup.intrinsics
    fitted = dev.get("fitted_intrinsics")
    if fitted is not None:
        try:
            k = np.array([float(fitted[n]) for n in INTRINSIC_NAMES])
        except (TypeError, KeyError, ValueError):
            raise InputError(f"model file: fit.device.fitted_intrinsics: expected a number for each of "
                             f"{', '.join(INTRINSIC_NAMES)}, got {fitted!r}") from None
        if not np.all(np.isfinite(k)):
            raise InputError(f"model file: fit.device.fitted_intrinsics: a value is not finite ({fitted!r})")
        intr = Intrinsics(float(k[0]), float(k[1]), float(k[2]), float(k[3]), k[4:], intr.width, intr.height)
    model = CameraModel(cm.robot, intr, setup.board, mode=setup.mode, camera_pose=cam, board_pose=brd,
                        tcp_m=cm.tcp_m.copy(), sigma_px=setup.sigma_px)
    p = np.zeros(model.n_params)
    p[:cm.joint_p.size] = cm.joint_p
    return model, p
