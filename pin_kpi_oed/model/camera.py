r"""Measurement model of a camera seeing a calibration board: the board's corner pixels at one pose.

Two mountings (``mode``):

* **eye-in-hand**: the camera on the tool, the board fixed in the cell. A board corner b (board frame) is seen at

  .. math:: X = (T_{bt}(p, q)\, C(p))^{-1}\, B(p)^{-1}\, b,

  with C = tool_T_camera = C₀·exp6(δ_c) (the hand-eye transform, group ``camera``) and B = board_T_base =
  B₀·exp6(δ_b) (the robot base in the board frame, group ``board``: the device frame, as the tracker's pose is).
* **eye-to-hand**: the camera fixed in the cell, the board on the tool:

  .. math:: X = C(p)\, T_{bt}(p, q)\, B(p)\, b,

  with C = camera_T_base = C₀·exp6(δ_c) (the hand-eye transform, group ``camera``: the device frame) and
  B = tool_T_board = B₀·exp6(δ_b) (group ``board``).

T_bt(p, q) is the tool pose in the robot base with the joint placements M_j·exp6(δ_j) (the layout of
:mod:`pin_kpi_oed.model.parameters`, as for the laser tracker). The camera-frame point X (m) is projected by
OpenCV's pinhole model with its distortion (k1, k2, p1, p2, k3)::

    x' = X/Z, y' = Y/Z, r² = x'² + y'²,  radial = 1 + k1 r² + k2 r⁴ + k3 r⁶
    x'' = x' radial + 2 p1 x'y' + p2 (r² + 2x'²),   y'' = y' radial + p1 (r² + 2y'²) + 2 p2 x'y'
    u = fx x'' + cx,   v = fy y'' + cy                                                   (px)

A measurement is one image: the N corners' (u, v), ``nh = 2N`` rows ordered u₀, v₀, u₁, v₁, ... The intrinsics
(fx, fy, cx, cy in px; k1, k2, p1, p2, k3 dimensionless) are known by default; with ``estimate_intrinsics`` they
are the additive group ``intrinsics`` (give it a prior from a separate intrinsic calibration with
``layout.set_prior``).

Parameter Jacobian (tangent coordinates; the base class's right Jacobians of exp6 are applied after): a right
perturbation of joint j's placement moves the tool pose by the world twist ξ_j = Ad(A_j) δ_j, i.e. v₀ = R_A δv +
[t_A]× R_A δω, ω = R_A δω (A_j: the joint's frame before its motion); a base-frame point x moves by
[I, −[x]×] ξ. Eye-to-hand: ∂X/∂δ_j = R_C [I, −[x]×] G_j, ∂X/∂δ_c = R_C [I, −[x]×], ∂X/∂δ_b = R_C R_tool R_B
[I, −[b]×]. Eye-in-hand (W = T_bt C, the camera in the base, x = B⁻¹ b): ∂X/∂δ_j = −R_Wᵀ [I, −[x]×] G_j,
∂X/∂δ_c = −[I, −[X]×], ∂X/∂δ_b = −R_Wᵀ [I, −[x]×]. The pixels follow by the chain rule through the projection.

The KPI (eq. 12) is the TCP in the device frame: the board frame (eye-in-hand) or the camera frame (eye-to-hand);
a TCP in the robot base frame is not estimable, the device frame's pose being unknown.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.device import MeasurementModel
from pin_kpi_oed.model.kinematics import Kinematics, skew
from pin_kpi_oed.model.parameters import INTRINSIC_SUFFIXES, ParameterLayout
from pin_kpi_oed.model.robot import Robot

__all__ = ["CameraModel", "Intrinsics", "Board", "project", "CAMERA_MODES", "INTRINSIC_NAMES"]

#: the two mountings of a camera
CAMERA_MODES = ("eye_in_hand", "eye_to_hand")
#: the intrinsic parameters, in vector order (px, px, px, px, then dimensionless)
INTRINSIC_NAMES = INTRINSIC_SUFFIXES


@dataclass
class Intrinsics:
    """A camera's intrinsics in OpenCV's convention.

    Attributes:
        fx, fy: focal lengths (px); cx, cy: principal point (px).
        dist: distortion (k1, k2, p1, p2, k3), dimensionless.
        width, height: image size (px).

    Raises:
        InputError: a non-positive focal length or image size, or a distortion vector not of 5 values.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    dist: np.ndarray = field(default_factory=lambda: np.zeros(5))
    width: int = 1280
    height: int = 1024

    def __post_init__(self) -> None:
        self.dist = np.asarray(self.dist, float).ravel()
        if self.dist.shape != (5,):
            raise InputError(f"camera distortion: 5 values (k1, k2, p1, p2, k3), got {self.dist.size}")
        if not (self.fx > 0 and self.fy > 0 and self.width > 0 and self.height > 0):
            raise InputError(f"camera intrinsics: focal lengths and image size must be positive, got fx={self.fx}, "
                             f"fy={self.fy}, size {self.width}x{self.height}")

    def vector(self) -> np.ndarray:
        """(fx, fy, cx, cy, k1, k2, p1, p2, k3), (9,)."""
        return np.concatenate([[self.fx, self.fy, self.cx, self.cy], self.dist])

    def matrix(self) -> np.ndarray:
        """The camera matrix K, (3, 3) px."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])


@dataclass
class Board:
    """A chessboard's inner corners: ``rows`` × ``cols`` corners ``square_m`` apart, in the board's z = 0 plane.

    Raises:
        InputError: fewer than 2 rows or columns, or a square size not positive (m).
    """

    rows: int
    cols: int
    square_m: float

    def __post_init__(self) -> None:
        if self.rows < 2 or self.cols < 2 or not (np.isfinite(self.square_m) and self.square_m > 0):
            raise InputError(f"board: at least 2 x 2 corners and a positive square size in m, got {self.rows} x "
                             f"{self.cols}, square {self.square_m}")

    @property
    def n(self) -> int:
        """Number of corners."""
        return self.rows * self.cols

    def corners(self) -> np.ndarray:
        """Corner positions in the board frame, (N, 3) m; corner id = row · cols + col, x along a row."""
        r, c = np.divmod(np.arange(self.n), self.cols)
        return np.stack([c * self.square_m, r * self.square_m, np.zeros(self.n)], axis=1)


def project(X: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """OpenCV's pinhole projection with distortion (module docstring) and its derivatives.

    Args:
        X: camera-frame points, (..., 3) m, Z > 0.
        k: intrinsics (fx, fy, cx, cy, k1, k2, p1, p2, k3), (9,).

    Returns:
        uv (..., 2) px; ∂uv/∂X (..., 2, 3) px/m; ∂uv/∂k (..., 2, 9).
    """
    fx, fy, _, _, k1, k2, p1, p2, k3 = k
    Z = X[..., 2]
    x, y = X[..., 0] / Z, X[..., 1] / Z
    r2 = x * x + y * y
    rad = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
    drad = k1 + 2 * k2 * r2 + 3 * k3 * r2 ** 2  # ∂rad/∂r²
    xd = x * rad + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * rad + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    # ∂(x'', y'')/∂(x', y')
    dxx = rad + 2 * x * x * drad + 2 * p1 * y + 6 * p2 * x
    dxy = 2 * x * y * drad + 2 * p1 * x + 2 * p2 * y
    dyx = 2 * x * y * drad + 2 * p1 * x + 2 * p2 * y
    dyy = rad + 2 * y * y * drad + 6 * p1 * y + 2 * p2 * x
    D = np.stack([np.stack([fx * dxx, fx * dxy], -1), np.stack([fy * dyx, fy * dyy], -1)], -2)  # (..., 2, 2)
    N = np.zeros(X.shape[:-1] + (2, 3))  # ∂(x', y')/∂X
    N[..., 0, 0] = N[..., 1, 1] = 1.0 / Z
    N[..., 0, 2], N[..., 1, 2] = -x / Z, -y / Z
    uv = np.stack([fx * xd + k[2], fy * yd + k[3]], -1)
    dk = np.zeros(X.shape[:-1] + (2, 9))
    dk[..., 0, 0], dk[..., 1, 1] = xd, yd
    dk[..., 0, 2] = dk[..., 1, 3] = 1.0
    for i, rk in ((4, r2), (5, r2 ** 2), (8, r2 ** 3)):
        dk[..., 0, i], dk[..., 1, i] = fx * x * rk, fy * y * rk
    dk[..., 0, 6], dk[..., 1, 6] = fx * 2 * x * y, fy * (r2 + 2 * y * y)
    dk[..., 0, 7], dk[..., 1, 7] = fx * (r2 + 2 * x * x), fy * 2 * x * y
    return uv, D @ N, dk


def _lever(x: np.ndarray) -> np.ndarray:
    """[I, −[x]×]: how a point x moves under a twist (v at the origin, ω), (..., 3, 6)."""
    I3 = np.broadcast_to(np.eye(3), x.shape[:-1] + (3, 3))
    return np.concatenate([I3, -skew(x)], axis=-1)


@dataclass
class CameraModel(MeasurementModel):
    """A camera seeing a chessboard, eye-in-hand or eye-to-hand (module docstring); (u, v) in px.

    Attributes:
        robot: the serial arm.
        intrinsics: the camera's (nominal) intrinsics.
        board: the chessboard.
        mode: ``eye_in_hand`` or ``eye_to_hand``.
        camera_pose: nominal C₀: tool_T_camera (eye-in-hand) or camera_T_base (eye-to-hand).
        board_pose: nominal B₀: board_T_base (eye-in-hand) or tool_T_board (eye-to-hand).
        tcp_m: the KPI point in the tool frame (m).
        sigma_px: corner noise per image coordinate (px).
        estimate_intrinsics: the intrinsics are parameters (group ``intrinsics``).
        layout: the parameter layout.

    Raises:
        InputError: an unknown mode or a non-positive noise.
    """

    robot: Robot
    intrinsics: Intrinsics
    board: Board
    mode: str = "eye_in_hand"
    camera_pose: pin.SE3 = field(default_factory=pin.SE3.Identity)
    board_pose: pin.SE3 = field(default_factory=pin.SE3.Identity)
    tcp_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    sigma_px: float = 0.2
    estimate_intrinsics: bool = False
    layout: ParameterLayout | None = None

    def __post_init__(self) -> None:
        if self.mode not in CAMERA_MODES:
            raise InputError(f"camera mode '{self.mode}': one of {', '.join(CAMERA_MODES)}")
        if not (np.isfinite(self.sigma_px) and self.sigma_px > 0):
            raise InputError(f"camera noise sigma_px must be positive, got {self.sigma_px}")
        self.tcp_m = np.asarray(self.tcp_m, float).reshape(3)
        self._corners = self.board.corners()
        if self.layout is None:
            self.layout = self.make_layout()
        self.init_kinematics()

    # ------------------------------------------------------------------ the device's declaration
    def setup_spec(self) -> tuple[tuple[str, str], ...]:
        """``camera`` (pose), ``board`` (pose), + ``intrinsics`` when estimated."""
        spec = (("camera", "pose"), ("board", "pose"))
        return spec + (("intrinsics", "intrinsics"),) if self.estimate_intrinsics else spec

    @property
    def eye_in_hand(self) -> bool:
        """The camera is on the tool."""
        return self.mode == "eye_in_hand"

    @property
    def frame_group(self) -> str:
        """The fixed device frame: ``board`` (eye-in-hand) or ``camera`` (eye-to-hand)."""
        return "board" if self.eye_in_hand else "camera"

    @property
    def target_groups(self) -> tuple[str, ...]:
        """What rides on the tool: ``("camera",)`` (eye-in-hand) or ``("board",)`` (eye-to-hand)."""
        return ("camera",) if self.eye_in_hand else ("board",)

    @property
    def nh(self) -> int:
        """Rows per image: 2 per corner."""
        return 2 * self.board.n

    # ------------------------------------------------------------------ parameters
    def pose_of(self, group: str, p: np.ndarray) -> pin.SE3:
        """The ``camera`` or ``board`` pose at parameters ``p`` (C₀·exp6(δ) or B₀·exp6(δ))."""
        T0 = self.camera_pose if group == "camera" else self.board_pose
        return T0 * pin.exp6(np.asarray(p, float)[self.layout.group_slice(group)])

    def intrinsic_vector(self, p: np.ndarray) -> np.ndarray:
        """(fx, fy, cx, cy, k1, k2, p1, p2, k3) at parameters ``p``."""
        k = self.intrinsics.vector()
        if self.estimate_intrinsics:
            k = k + np.asarray(p, float)[self.layout.group_slice("intrinsics")]
        return k

    def sensor_pose(self, p: np.ndarray) -> pin.SE3:
        """The robot base in the device frame: board_T_base (eye-in-hand) or camera_T_base (eye-to-hand)."""
        return self.pose_of(self.frame_group, p)

    def hand_eye(self, p: np.ndarray) -> pin.SE3:
        """The hand-eye transform: tool_T_camera (eye-in-hand) or camera_T_base (eye-to-hand) at ``p``."""
        return self.pose_of("camera", p)

    # ------------------------------------------------------------------ geometry
    def _tool(self, p: np.ndarray, Q: np.ndarray) -> Kinematics:
        return self.kinematics(p, Q, np.zeros(3))

    def camera_points(self, p: np.ndarray, Q: np.ndarray) -> np.ndarray:
        """The board's corners in the camera frame, (m, N, 3) m."""
        kin = self._tool(p, Q)
        C, B = self.pose_of("camera", p), self.pose_of("board", p)
        if self.eye_in_hand:
            x = (self._corners - B.translation) @ B.rotation  # B⁻¹ b, base frame
            R_W = kin.R_tool @ C.rotation
            t_W = kin.R_tool @ C.translation + kin.p
            return np.einsum("mba,mnb->mna", R_W, x[None] - t_W[:, None])
        bt = self._corners @ B.rotation.T + B.translation
        x = np.einsum("mab,nb->mna", kin.R_tool, bt) + kin.p[:, None]
        return x @ C.rotation.T + C.translation

    def _point_jacobian(self, p: np.ndarray, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """X (m, N, 3) and ∂X/∂p at the tangent coordinates (m, N, 3, np) (module docstring)."""
        L = self.layout
        kin = self._tool(p, Q)
        m, n, N = kin.p.shape[0], L.n_joints, self.board.n
        G = np.zeros((m, 6, 6 * n))  # world twist of the tool per joint-placement parameter
        RA = np.moveaxis(kin.R_A, 1, 2).reshape(m, 3, 3 * n)  # (m, 3, 3n): [R_A,1 ... R_A,n] side by side
        tRA = np.moveaxis(skew(kin.t_A) @ kin.R_A, 1, 2).reshape(m, 3, 3 * n)
        G6 = G.reshape(m, 6, n, 6)
        G6[:, :3, :, :3] = RA.reshape(m, 3, n, 3)
        G6[:, :3, :, 3:] = tRA.reshape(m, 3, n, 3)
        G6[:, 3:, :, 3:] = RA.reshape(m, 3, n, 3)
        C, B = self.pose_of("camera", p), self.pose_of("board", p)
        J = np.zeros((m, N, 3, L.n))
        cs, bs = L.group_slice("camera"), L.group_slice("board")
        X = self.camera_points(p, Q)
        if self.eye_in_hand:
            x = (self._corners - B.translation) @ B.rotation
            RWt = np.swapaxes(kin.R_tool @ C.rotation, 1, 2)  # (m, 3, 3)
            Lx = RWt[:, None] @ _lever(x)[None]  # (m, N, 3, 6)
            J[..., :6 * n] = -Lx @ G[:, None]
            J[..., cs] = -_lever(X)
            J[..., bs] = -Lx
        else:
            bt = self._corners @ B.rotation.T + B.translation
            x = np.einsum("mab,nb->mna", kin.R_tool, bt) + kin.p[:, None]
            Lx = C.rotation @ _lever(x)
            J[..., :6 * n] = Lx @ G[:, None]
            J[..., cs] = Lx
            J[..., bs] = (C.rotation @ kin.R_tool @ B.rotation)[:, None] @ _lever(self._corners)[None]
        return X, J

    # ------------------------------------------------------------------ prediction
    def predict(self, p: np.ndarray, Q: np.ndarray) -> np.ndarray:
        """The corners' pixels at every configuration, (m, 2N) px (u₀, v₀, u₁, v₁, ...)."""
        X = self.camera_points(p, np.atleast_2d(np.asarray(Q, float)))
        return project(X, self.intrinsic_vector(p))[0].reshape(X.shape[0], -1)

    def jacobian(self, p: np.ndarray, Q: np.ndarray) -> np.ndarray:
        """∂h/∂p at any ``p`` (right Jacobians of exp6 included), (m, 2N, np) px per parameter unit."""
        p = np.asarray(p, float)
        X, JX = self._point_jacobian(p, np.atleast_2d(np.asarray(Q, float)))
        _, P, dk = project(X, self.intrinsic_vector(p))
        J = P @ JX  # (m, N, 2, np)
        if self.estimate_intrinsics:
            J[..., self.layout.group_slice("intrinsics")] = dk
        return self.at_parameters(J.reshape(X.shape[0], -1, self.n_params), p)

    def prediction_dq(self, p: np.ndarray, Q: np.ndarray) -> np.ndarray:
        """∂uv/∂q, (m, 2N, n) px per joint unit: a joint's world twist moves the camera or the board."""
        p = np.asarray(p, float)
        Q = np.atleast_2d(np.asarray(Q, float))
        kin = self._tool(p, Q)
        X = self.camera_points(p, Q)
        C, B = self.pose_of("camera", p), self.pose_of("board", p)
        if self.eye_in_hand:
            x = np.broadcast_to((self._corners - B.translation) @ B.rotation, X.shape)
            R = -np.swapaxes(kin.R_tool @ C.rotation, 1, 2)[:, None]  # (m, 1, 3, 3)
        else:
            bt = self._corners @ B.rotation.T + B.translation
            x = np.einsum("mab,nb->mna", kin.R_tool, bt) + kin.p[:, None]
            R = np.broadcast_to(C.rotation, (X.shape[0], 1, 3, 3))
        Xdq = R @ (_lever(x) @ kin.twist[:, None])  # (m, N, 3, n)
        P = project(X, self.intrinsic_vector(p))[1]
        return (P @ Xdq).reshape(X.shape[0], -1, Q.shape[1])

    def jacobian_dq(self, p: np.ndarray, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(uv (m, 2N), J (m, 2N, np), ∂J/∂q (m, 2N, np, n), ∂uv/∂q (m, 2N, n)).

        ∂J/∂q is by central differences of the exact J (step 1e-6 rad or m, relative error ~1e-8): the camera
        has no closed form of the second derivative yet; uv, J and ∂uv/∂q are exact.
        """
        p = np.asarray(p, float)
        Q = np.atleast_2d(np.asarray(Q, float))
        h = 1e-6
        dJ = np.zeros((Q.shape[0], self.nh, self.n_params, Q.shape[1]))
        for k in range(Q.shape[1]):
            dq = np.zeros(Q.shape[1])
            dq[k] = h
            dJ[..., k] = (self.jacobian(p, Q + dq) - self.jacobian(p, Q - dq)) / (2 * h)
        return self.predict(p, Q), self.jacobian(p, Q), dJ, self.prediction_dq(p, Q)

    def sigma(self, p: np.ndarray, Q: np.ndarray, Y: np.ndarray | None = None) -> np.ndarray:
        """σ of every pixel coordinate, (m, 2N) px."""
        return np.full((np.atleast_2d(Q).shape[0], self.nh), float(self.sigma_px))

    def kpi(self, p: np.ndarray, Q_work: np.ndarray) -> np.ndarray:
        """The TCP in the device frame (board frame eye-in-hand, camera frame eye-to-hand), (t, 3) m."""
        return self.sensor_point(p, Q_work, self.tcp_m).Y

    def kpi_jacobian(self, p: np.ndarray, Q_work: np.ndarray) -> np.ndarray:
        """E = ∂s/∂p of :meth:`kpi`, stacked over working configurations, (3t, np)."""
        p = np.asarray(p, float)
        return self.at_parameters(self.sensor_point(p, Q_work, self.tcp_m).J, p).reshape(-1, self.n_params)

    # ------------------------------------------------------------------ what the camera can see
    def in_view(self, p: np.ndarray, Q: np.ndarray, margin_px: float = 20.0, max_angle_rad: float = np.radians(60),
                depth_m: tuple[float, float] = (0.15, 2.0)) -> np.ndarray:
        """Whether the whole board is seen at each configuration, (m,) bool.

        Every corner in front of the camera within ``depth_m`` (m) and inside the image with ``margin_px`` (px) to
        its edges, and the angle between the board's normal and the ray to its centre at most ``max_angle_rad``.
        """
        X = self.camera_points(p, np.atleast_2d(np.asarray(Q, float)))
        ok = np.all((X[..., 2] > depth_m[0]) & (X[..., 2] < depth_m[1]), axis=1)
        Z = np.where(X[..., 2:] > 1e-6, X, np.nan)
        uv = project(Z, self.intrinsic_vector(p))[0]
        intr = self.intrinsics
        inside = ((uv[..., 0] >= margin_px) & (uv[..., 0] <= intr.width - margin_px)
                  & (uv[..., 1] >= margin_px) & (uv[..., 1] <= intr.height - margin_px))
        ok &= np.all(inside, axis=1)
        c = self.board.cols
        nrm = np.cross(X[:, c - 1] - X[:, 0], X[:, -1] - X[:, 0])
        ctr = X.mean(axis=1)
        cosang = np.abs(np.einsum("ma,ma->m", nrm, ctr)) / (np.linalg.norm(nrm, axis=1) * np.linalg.norm(ctr, axis=1))
        return ok & (cosang >= np.cos(max_angle_rad))

    def views(self, n: int, seed: int = 0, around: np.ndarray | None = None, spread_rad: float = 0.7,
              max_tries: int = 200) -> np.ndarray:
        """``n`` seeded configurations that see the whole board (:meth:`in_view` at the nominal parameters): a
        camera's excitation (random configurations over the joint limits mostly look away from the board).

        Args:
            n: how many; seed: the random draw's seed.
            around: configurations (k, n_joints) rad to perturb uniformly by ±``spread_rad`` (e.g. the working
                configurations); None: uniform within the joint limits.
            max_tries: batches of 20 n draws before giving up.

        Returns:
            (n, n_joints) rad.

        Raises:
            InputError: fewer than ``n`` configurations seeing the board after ``max_tries`` batches.
        """
        rng = np.random.default_rng(seed)
        lo, hi = self.robot.q_lower, self.robot.q_upper
        p0 = np.zeros(self.n_params)
        out: list[np.ndarray] = []
        for _ in range(max_tries):
            if around is None or len(around) == 0:
                Q = self.robot.random_q(rng, 20 * n)
            else:
                base = np.atleast_2d(around)[rng.integers(0, len(np.atleast_2d(around)), 20 * n)]
                Q = np.clip(base + rng.uniform(-spread_rad, spread_rad, base.shape), lo, hi)
            out.append(Q[self.in_view(p0, Q)])
            if sum(len(o) for o in out) >= n:
                return np.concatenate(out)[:n]
        raise InputError(f"camera: fewer than {n} configurations see the whole board (found "
                         f"{sum(len(o) for o in out)}): check the board's and the camera's poses")

    def identifiability_notes(self) -> list[str]:
        """What a camera cannot see, in plain words (the scale comes from the board's square size)."""
        frame = "board" if self.eye_in_hand else "camera"
        notes = [f"the scale comes from the board's square size ({self.board.square_m * 1e3:.3g} mm): an error of "
                 f"the printed size scales every identified length by the same factor",
                 f"the TCP is estimable in the {frame} frame only: the {frame}'s pose in the robot base is "
                 f"confounded with the first joint's placement"]
        if self.estimate_intrinsics:
            notes.append("the intrinsics are estimated with the geometry: give them the prior of a separate "
                         "intrinsic calibration, or vary the board's distance and tilt")
        return notes
