"""Simulated camera measurements: the board's corner pixels of a true robot that is not the package's model.

The truth (:func:`camera_truth`): every joint placement off by the tolerances (N(0, σ²) per translation and
rotation), the hand-eye transform and the board's (or the camera's) pose off their nominal values, with
``intrinsics`` σ the camera's intrinsics off their nominal ones (a model that estimates them), and, with
``effects``, joint-angle errors the camera model lacks (a gear harmonic, joint compliance, ...: the effects'
``joint_offset``, added to the commanded joints before the true kinematics). The pixels
(:func:`simulate_corners`) are the truth's projection with N(0, σ_px²) noise per coordinate (seeded); a corner
outside the image or behind the camera is not detected (NaN), as a detector would miss it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pin_kpi_oed.effects.compose import sum_joint_offsets
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.camera import CameraModel

__all__ = ["CameraTolerances", "camera_truth", "simulate_corners", "simulate_detections", "LOSS_CAUSES",
           "lost_corners_text", "true_tcp"]


@dataclass(frozen=True)
class CameraTolerances:
    """σ of the true set-up's deviations from the nominal one (m, rad).

    Attributes:
        joint_translation_m, joint_rotation_rad: every joint placement's.
        hand_eye_translation_m, hand_eye_rotation_rad: the camera on the tool (eye-in-hand) or in the cell.
        board_translation_m, board_rotation_rad: the board in the cell (eye-in-hand) or on the tool.
        intrinsics: σ of the true intrinsics' offsets from the nominal ones in the model's order (fx, fy, cx, cy
            px, then k1, k2, p1, p2, k3 dimensionless; fewer values: the rest 0); empty: the intrinsics are known.
    """

    joint_translation_m: float = 5e-4
    joint_rotation_rad: float = 1e-3
    hand_eye_translation_m: float = 2e-3
    hand_eye_rotation_rad: float = 1e-2
    board_translation_m: float = 5e-3
    board_rotation_rad: float = 2e-2
    intrinsics: tuple[float, ...] = ()

    def sigma_vector(self, model: CameraModel) -> np.ndarray:
        """σ of every raw parameter of ``model`` (m, rad; the intrinsics' offsets px or dimensionless).

        Raises:
            InputError: more than 9 or negative or non-finite intrinsic σ, or intrinsic σ for a model that does not
                estimate its intrinsics (it has no parameters for them).
        """
        L = model.layout
        s = np.zeros(L.n)
        n = L.n_joints
        J = s[:6 * n].reshape(n, 6)
        J[:, :3], J[:, 3:] = self.joint_translation_m, self.joint_rotation_rad
        for group, t, r in (("camera", self.hand_eye_translation_m, self.hand_eye_rotation_rad),
                            ("board", self.board_translation_m, self.board_rotation_rad)):
            g = L.group_slice(group)
            s[g.start:g.start + 3], s[g.start + 3:g.stop] = t, r
        k = np.asarray(self.intrinsics, float)
        if k.size > 9 or not np.all(np.isfinite(k)) or np.any(k < 0):
            raise InputError(f"camera tolerances: intrinsics takes up to 9 finite sigma >= 0 (fx, fy, cx, cy px, "
                             f"then distortion), got {list(self.intrinsics)}")
        if np.any(k > 0):
            if not model.estimate_intrinsics:
                raise InputError("camera tolerances: true intrinsics off nominal need a model that estimates them "
                                 "(estimate_intrinsics, the cell's intrinsics_sigma)")
            g = L.group_slice("intrinsics")
            s[g.start:g.start + k.size] = k
        return s


def camera_truth(model: CameraModel, tol: CameraTolerances | None = None, seed: int = 0) -> np.ndarray:
    """A true raw parameter vector p* ~ N(0, diag(σ²)) of :class:`CameraTolerances` (seeded), (n_params,) m, rad
    (px and dimensionless for the intrinsics)."""
    s = (tol or CameraTolerances()).sigma_vector(model)
    return np.random.default_rng(seed).normal(0.0, 1.0, s.size) * s


def simulate_corners(model: CameraModel, Q: np.ndarray, truth_p: np.ndarray, effects: list | None = None,
                     seed: int = 0) -> np.ndarray:
    """The detected corners' pixels of the true robot at configurations Q (module docstring).

    Args:
        model: the nominal camera model (its ``sigma_px`` is the noise); Q: commanded joints (m, n) rad.
        truth_p: the true raw parameters; effects: [(effect, θ*)] the model lacks (joint offsets only).
        seed: the noise's seed.

    Returns:
        (m, 2N) px, NaN for a corner not detected.
    """
    return simulate_detections(model, Q, truth_p, effects, seed)[0]


#: Why the simulation loses a corner (:func:`simulate_detections`), in the order a corner is counted under.
LOSS_CAUSES = ("behind the camera", "outside the image")


def simulate_detections(model: CameraModel, Q: np.ndarray, truth_p: np.ndarray, effects: list | None = None,
                        seed: int = 0) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """:func:`simulate_corners` with the count of the corners lost per cause.

    Args:
        model: the nominal camera model (its ``sigma_px`` is the noise); Q: commanded joints (m, n) rad.
        truth_p: the true raw parameters; effects: [(effect, θ*)] the model lacks (joint offsets only).
        seed: the noise's seed.

    Returns:
        ((m, 2N) px, NaN for a corner not detected; cause of :data:`LOSS_CAUSES` -> corners lost to it per
        configuration, (m,) int, each lost corner counted once, under the first cause that holds). The simulation
        loses corners to these causes only: not to a grazing viewing angle, nor to an obstacle between the camera
        and the board.
    """
    Q = np.atleast_2d(np.asarray(Q, float))
    Qt = Q + sum_joint_offsets(effects, Q)[0] if effects else Q
    X = model.camera_points(truth_p, Qt)
    uv = model.predict(truth_p, Qt)
    uv = uv + np.random.default_rng(seed).normal(0.0, model.sigma_px, uv.shape)
    k = model.intrinsics
    pix = uv.reshape(len(Q), -1, 2)
    behind = X[..., 2] <= 0
    outside = ~behind & ((pix[..., 0] < 0) | (pix[..., 0] > k.width - 1) | (pix[..., 1] < 0)
                         | (pix[..., 1] > k.height - 1))
    pix[behind | outside] = np.nan
    return pix.reshape(len(Q), -1), dict(zip(LOSS_CAUSES, (behind.sum(axis=1), outside.sum(axis=1))))


def lost_corners_text(lost: dict[str, int], designed: bool) -> str:
    """Why corners of the written images were not detected: a count per cause ("" when none was lost).

    Args:
        lost: cause -> corners lost to it (:func:`~pin_kpi_oed.simulation.camera_sim.simulate_detections`);
        designed: the poses are a design's (checked to see every corner inside its image margin at nominal).

    Returns:
        "; corners lost: ..." naming each cause's count, why a design's corners go, and the causes not simulated.
    """
    if not sum(lost.values()):
        return ""
    why = (": the truth's joint, hand-eye and board errors move corners the design saw inside its image margin "
           "at the nominal model" if designed else "")
    counts = ", ".join(f"{n} {cause}" for cause, n in lost.items() if n)
    return (f"; corners lost: {counts}{why} (none to the viewing angle or to occlusion: the simulation does not "
            "model either)")


def true_tcp(model: CameraModel, Q: np.ndarray, truth_p: np.ndarray, effects: list | None = None) -> np.ndarray:
    """The true TCP in the device frame (board frame eye-in-hand, camera frame eye-to-hand) at commanded joints,
    (m, 3) m: what a calibration's TCP prediction is compared with."""
    Q = np.atleast_2d(np.asarray(Q, float))
    Qt = Q + sum_joint_offsets(effects, Q)[0] if effects else Q
    return model.kpi(truth_p, Qt)
