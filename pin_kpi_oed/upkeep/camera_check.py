r"""Does a camera calibration still hold? New images of the board against the calibrated model.

For check images at configurations q_i with corners η_i, the calibrated camera model
(:func:`~pin_kpi_oed.identification.camera_identify.camera_model_of`: the robot, hand-eye transform and board as
fitted) gives the standardised residual r = (h(p̂, q) − η)/σ_px on every detected corner coordinate. On images the
calibration did not see, r is not white: the fitted parameters' error moves every corner of an image together, so
its covariance is S = I + F C_p Fᵀ + H Σ_N Hᵀ (F the σ-weighted Jacobian at the check's poses, C_p the model file's
parameter covariance, H = F_N − F_B A the held joint placements' effect left after the fit's absorption A, Σ_N their
tolerances; intrinsics the model estimated are not in F: their part is left out). Two χ² tests, each at the Šidák
level α₁ = 1 − (1 − α)^{1/2} so that the verdict's false-alarm rate is α, the statistics divided by the
calibration's own reduced χ² (at least 1: a fit whose residuals exceed σ_px says so). A calibration whose images
showed joint-angle errors (the model file's ``fit.joint_angle_sigma_rad`` s and ``fit.joint_noise``'s pixel level
ν, :mod:`~pin_kpi_oed.identification.camera_joint_noise`) adds their part B_i diag(s²) B_iᵀ / ν per image (B_i the
image's σ-weighted joint Jacobian; its stored C_p is already the covariance under that error, so C_p / ν) and divides
by ν instead:

1. T₀ = rᵀ S⁻¹ r on every row (n dof): consistent → ``holds``;
2. else the set-up re-fitted (hand-eye transform and board pose, 12 parameters, the robot held; the re-fit's
   residual r₁ then one generalised least-squares step in S's metric) and T₁ = r₁ᵀ S⁻¹ r₁ (n − 12 dof):
   consistent → ``setup_moved`` (the camera or the board moved: re-identify the set-up); else ``recalibrate``
   (the robot changed).

The exit codes are the tracker check's (:data:`~pin_kpi_oed.upkeep.check.EXIT_CODES`): 0 holds, 1 the set-up
moved, 3 re-calibrate. The TCP's displacement is not judged against a tolerance here (the tracker's check does);
the set-up's shift is stated.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.linalg import cho_factor, cho_solve
from scipy.stats import chi2

from pin_kpi_oed.data.corner_measurements import CornerSet
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.identification.camera_fit import fit_camera
from pin_kpi_oed.identification.camera_identify import camera_model_of
from pin_kpi_oed.results import Result

__all__ = ["CameraCheck", "check_camera", "prediction_covariance", "residual_level", "CAMERA_EXIT_CODES"]

#: exit code per verdict (the tracker check's :data:`~pin_kpi_oed.upkeep.check.EXIT_CODES`)
CAMERA_EXIT_CODES = {"holds": 0, "setup_moved": 1, "recalibrate": 3}


@dataclass(kw_only=True)
class CameraCheck(Result):
    """The verdict of :func:`check_camera` (a :class:`~pin_kpi_oed.results.Result`).

    Attributes:
        verdict: ``holds``, ``setup_moved`` or ``recalibrate``.
        chi2_fixed, dof_fixed, p_fixed: the test with everything as calibrated.
        chi2_refit, dof_refit, p_refit: the test with the set-up re-fitted (NaN when not needed).
        rms_px: RMS reprojection error as calibrated (px); scale: the calibration's residual level the statistics
            are divided by (:func:`residual_level`); alpha, alpha_each: the verdict's and each test's false-alarm
            rate.
        setup_shift_m: the re-fitted hand-eye transform's and board's translation change (m), (2,) or NaN.
        n_images: images used.
    """

    verdict: str
    chi2_fixed: float
    dof_fixed: int
    p_fixed: float
    chi2_refit: float
    dof_refit: int
    p_refit: float
    rms_px: float
    scale: float
    alpha: float
    alpha_each: float
    setup_shift_m: np.ndarray
    n_images: int

    @property
    def exit_code(self) -> int:
        """0 holds, 1 the set-up moved, 3 re-calibrate."""
        return CAMERA_EXIT_CODES[self.verdict]

    def summary(self) -> str:
        """Readable lines (px, mm)."""
        out = [f"camera check on {self.n_images} images: RMS {self.rms_px:.3f} px as calibrated, chi2 "
               f"{self.chi2_fixed:.1f} on {self.dof_fixed} dof (p {self.p_fixed:.3g}; each test at "
               f"{self.alpha_each:.3g}, the verdict's false-alarm rate {self.alpha:g}; scaled by the calibration's "
               f"residual level {self.scale:.2f})"]
        if np.isfinite(self.chi2_refit):
            out.append(f"set-up re-fitted: chi2 {self.chi2_refit:.1f} on {self.dof_refit} dof (p {self.p_refit:.3g}); "
                       f"the hand-eye transform moved {self.setup_shift_m[0] * 1e3:.3g} mm, the board "
                       f"{self.setup_shift_m[1] * 1e3:.3g} mm")
        out.append({"holds": "verdict: holds (the images agree with the calibration)",
                    "setup_moved": "verdict: setup_moved (the camera or the board moved: identify the set-up again; "
                                   "the robot agrees)",
                    "recalibrate": "verdict: recalibrate (a moved set-up does not explain the images: the robot "
                                   "changed)"}[self.verdict])
        return "\n".join(out)


def check_camera(cm: Any, cs: CornerSet, alpha: float = 0.05, source: str = "check images") -> CameraCheck:
    """The verdict on check images (module docstring).

    Args:
        cm: a calibrated camera model; cs: the check images' corners; alpha: the verdict's false-alarm rate.
        source: the file, for messages.

    Returns:
        The :class:`CameraCheck`.

    Raises:
        InputError: alpha outside (0, 1), joint columns not the robot's, fewer pixel rows than 13.
    """
    if not 0 < alpha < 1:
        raise InputError(f"check: alpha must lie in (0, 1), got {alpha}")
    model, p = camera_model_of(cm)
    _, Q, uv = cs.arrays(model.board.n, source)
    names = list(model.robot.joint_names)
    if sorted(cs.joint_names) != sorted(names):
        raise InputError(f"{source}: joint columns {', '.join(cs.joint_names)} are not the robot's "
                         f"({', '.join(names)})")
    Q = model.robot.check_q(Q[:, [cs.joint_names.index(n) for n in names]], source)
    rows = np.isfinite(uv)
    n = int(rows.sum())
    if n <= 12:
        raise InputError(f"{source}: {n // 2} corners; a camera check needs at least 7")
    scale = residual_level(cm)
    a1 = 1.0 - (1.0 - alpha) ** 0.5
    r = (model.predict(p, Q) - uv)[rows]
    L = model.layout
    setup = np.r_[np.arange(L.group_slice("camera").start, L.group_slice("camera").stop),
                  np.arange(L.group_slice("board").start, L.group_slice("board").stop)]
    F = model.weighted_jacobian(p, Q).reshape(-1, model.n_params)[rows.ravel()]
    B = (model.prediction_dq(p, Q) / model.sigma_px)[rows]
    img = np.broadcast_to(np.arange(len(Q))[:, None], rows.shape)[rows]
    chol = cho_factor(prediction_covariance(cm, model, F, B, img))
    T0 = float(r @ cho_solve(chol, r)) / model.sigma_px ** 2
    p0 = float(chi2.sf(T0 / scale, n))
    T1, p1, shift = np.nan, np.nan, np.full(2, np.nan)
    verdict = "holds"
    if p0 < a1:
        fit = fit_camera(model, Q, uv, setup, p_ref=p)
        r1 = (model.predict(fit.p, Q) - uv)[rows] / model.sigma_px
        Fs = model.weighted_jacobian(fit.p, Q).reshape(-1, model.n_params)[rows.ravel()][:, setup]
        SiF = cho_solve(chol, Fs)
        r1 = r1 - Fs @ np.linalg.lstsq(Fs.T @ SiF, SiF.T @ r1, rcond=None)[0]
        T1 = float(r1 @ cho_solve(chol, r1))
        p1 = float(chi2.sf(T1 / scale, n - setup.size))
        shift = np.array([np.linalg.norm(fit.p[L.group_slice(g)][:3]) for g in ("camera", "board")])
        verdict = "setup_moved" if p1 >= a1 else "recalibrate"
    return CameraCheck(verdict=verdict, chi2_fixed=T0, dof_fixed=n, p_fixed=p0, chi2_refit=float(T1),
                       dof_refit=n - 12, p_refit=float(p1), rms_px=float(np.sqrt(np.mean(r ** 2))), scale=scale,
                       alpha=alpha, alpha_each=a1, setup_shift_m=shift, n_images=len(Q), success=True,
                       status=verdict, message=verdict)


def residual_level(cm: Any) -> float:
    """The calibration's own residual level in σ_px² units: the joint-angle structure's pixel level ν when its
    images showed joint-angle errors (``fit.joint_noise``), else the reduced χ² (at least 1 each)."""
    fit = cm.fit or {}
    jn = fit.get("joint_noise") if fit.get("joint_angle_sigma_rad") is not None else None
    level = (jn or {}).get("noise_var_px2_units") if isinstance(jn, dict) else None
    if level is None:
        level = fit.get("chi2_reduced")
    try:
        level = float(level or 1.0)
    except (TypeError, ValueError):
        raise InputError(f"model file: fit: the residual level must be a number, got {level!r}") from None
    return max(1.0, level) if np.isfinite(level) else 1.0


def prediction_covariance(cm: Any, model: Any, F: np.ndarray, B: np.ndarray | None = None,
                          img: np.ndarray | None = None) -> np.ndarray:
    """S = I + F C_p Fᵀ + H Σ_N Hᵀ (+ the joint-angle errors' B_i diag(s²) B_iᵀ / ν per image): the covariance of the
    σ-weighted residuals of images the calibration did not see (module docstring).

    Args:
        cm: the calibrated camera model (its ``parameters``: names, covariance, held block; its ``fit``'s
            joint-angle level, if any).
        model: the camera model of :func:`camera_model_of` (its layout names the columns of F).
        F: the σ-weighted Jacobian of the check's detected rows, (n, model.n_params), dimensionless per parameter
            unit (m or rad).
        B: the same rows' σ-weighted joint Jacobian, (n, n_joints) per rad, and img: each row's image (n,); without
            them no joint-angle part is added.

    Returns:
        S, (n, n), in units of σ_px² times the calibration's residual level (:func:`residual_level`).
    """
    par = cm.parameters or {}
    frame = model.frame_group
    layout = list(model.layout.names)

    def column(name: str) -> int:
        raw = f"{frame}.{name.split('.', 1)[1]}" if name.startswith("tracker.") else name
        return layout.index(raw) if raw in layout else -1

    names = [str(x) for x in par.get("names") or []]
    cols = np.array([column(x) for x in names], int)
    S = np.eye(F.shape[0])
    C = np.asarray(par.get("covariance") if par.get("covariance") is not None else np.zeros((0, 0)), float)
    fit = cm.fit or {}
    if fit.get("covariance_scaled"):  # back to the stated noise: the statistics are divided by the level themselves
        C = C / residual_level(cm)
    if names and C.shape == (len(names), len(names)):
        keep = cols >= 0
        FB = F[:, cols[keep]]
        S += FB @ C[np.ix_(keep, keep)] @ FB.T
    held = par.get("held") or {}
    h_names = [str(x) for x in held.get("names") or []]
    A = np.asarray(held.get("absorption") if held.get("absorption") is not None else np.zeros((0, 0)), float)
    if h_names and A.shape == (len(names), len(h_names)) and all(x in layout for x in h_names):
        keep = cols >= 0
        H = F[:, [layout.index(x) for x in h_names]] - F[:, cols[keep]] @ A[keep]
        S += (H * np.asarray(held.get("sigma"), float) ** 2) @ H.T
    sj = fit.get("joint_angle_sigma_rad")
    if sj is not None and B is not None and img is not None:
        Bs = B * (np.asarray(sj, float) / np.sqrt(residual_level(cm)))[None, :]
        S += np.where(np.asarray(img)[:, None] == np.asarray(img)[None, :], Bs @ Bs.T, 0.0)
    return S
