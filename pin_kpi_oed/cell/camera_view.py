r"""What a camera must see at a measurement pose: the constraints g(q) ≥ 0 of a camera design, exact ∂g/∂q.

A camera (:class:`~pin_kpi_oed.model.camera.CameraModel`, eye-in-hand or eye-to-hand) measures a pose only when it
sees the whole board. For one configuration q, at the nominal parameters, with X_k the board's corners in the camera
frame, (u_k, v_k) their pixels, c the camera centre and the board's centre x₀ and normal n (its printed face, the
board frame's +z unless ``front_z`` is False) in the robot base frame:

* **image** (px): every corner ``margin_px`` inside the image, four rows per corner
  ``u_k − μ``, ``W − μ − u_k``, ``v_k − μ``, ``H − μ − v_k``;
* **depth** (m): the four outer corners' depths within the depth of field, ``Z_k − near`` and ``far − Z_k``;
* **angle** (cos): the viewing angle β between the board's normal and the ray from its centre to the camera,
  ``cos β − cos β_max`` with cos β = nᵀ(c − x₀)/‖c − x₀‖ (signed: a board seen from behind is not seen);
* **rays** (m): no robot link or obstacle between the camera and the board: the segments from c to the board's four
  outer corners and its centre, as thin capsules of radius ``ray_radius_m`` (like the tracker's laser beam), clear
  of every robot capsule and obstacle capsule, ``d(ray, capsule) − r_ray − r − clearance``. The capsules of the
  link that carries the camera (eye-in-hand) or the board (eye-to-hand) are not checked (the mount itself), nor
  names in ``ray_skip``. Half-spaces need no rows: both ends of a ray lie on their free side (the camera on the robot or
  in the cell, the board in the cell or on the robot, both checked), and a half-space is convex. An object inside
  the viewing pyramid that touches none of the five rays is not seen by these rows (the pyramid is not a capsule).

Derivatives. A point x carried by the robot's last joint moves by ∂x/∂q_j = v_j + ω_j × x ((v_j, ω_j) the joint's
world twist); the camera-frame corner X = R_cᵀ(x − t_c) then moves by ∂X/∂q_j = s R_cᵀ(v_j + ω_j × x), s = −1 when
the camera moves (eye-in-hand), +1 when the board moves (eye-to-hand); the pixels follow by the projection's
Jacobian (:func:`~pin_kpi_oed.model.camera.project`). The ray rows take the witness-point gradient of the capsule
constraints (:mod:`pin_kpi_oed.cell.collision`): ∂d/∂q = nᵀ(∂w₂/∂q − ∂w₁/∂q), ∂w = (1 − s)∂A + s∂B.

For the optimiser the rows of each kind are aggregated per configuration by the Kreisselmeier–Steinhauser function
(conservative: the aggregate ≥ 0 implies every row ≥ 0; :class:`~pin_kpi_oed.cell.aggregate.AggregatedConstraints`),
four rows per configuration. The function API is :func:`camera_constraints`; the independent check (OpenCV's
projection, Coal's distances) is :mod:`pin_kpi_oed.cell.camera_check`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pin_kpi_oed.cell.collision import CollisionModel
from pin_kpi_oed.cell.segments import cross, segment_closest
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.camera import CameraModel, project
from pin_kpi_oed.model.kinematics import Chain

__all__ = ["ViewLimits", "CameraView", "camera_constraints", "cell_view_limits", "cell_camera_view", "VIEW_KINDS"]

#: the kinds of rows, in the order of :meth:`CameraView.evaluate`, and their units
VIEW_KINDS = (("image", "px"), ("depth", "m"), ("angle", "cos"), ("rays", "m"))
#: rays per configuration: camera centre to the board's four outer corners and its centre
NRAYS = 5


@dataclass(frozen=True)
class ViewLimits:
    """What the camera needs to see the board (module docstring).

    Attributes:
        margin_px: every corner at least this far inside the image (px).
        max_angle_deg: largest viewing angle between the board's normal and the ray to the camera (deg).
        near_m, far_m: the depth of field: every outer corner's depth within [near, far] (m).
        ray_radius_m: radius of the rays' capsules (m).
        clearance_m: clearance of the rays from every capsule (m).
        ray_skip: capsule, link or obstacle names the rays are not checked against.
        front_z: the board's printed face is its frame's +z side (False: −z).
        ks_px, ks_m: Kreisselmeier–Steinhauser lengths of the aggregated image rows (px) and depth / ray rows (m).

    Raises:
        InputError: a negative margin, radius or clearance, an angle outside (0, 90) deg, or not 0 < near < far.
    """

    margin_px: float = 20.0
    max_angle_deg: float = 60.0
    near_m: float = 0.15
    far_m: float = 2.0
    ray_radius_m: float = 0.002
    clearance_m: float = 0.0
    ray_skip: tuple[str, ...] = ()
    front_z: bool = True
    ks_px: float = 1.0
    ks_m: float = 2e-3

    def __post_init__(self) -> None:
        if not (0.0 < self.max_angle_deg < 90.0):
            raise InputError(f"camera view: max_angle_deg must be in (0, 90) deg, got {self.max_angle_deg}")
        if not (0.0 < self.near_m < self.far_m):
            raise InputError(f"camera view: need 0 < near_m < far_m, got near_m={self.near_m}, far_m={self.far_m}")
        if min(self.margin_px, self.ray_radius_m, self.clearance_m) < 0:
            raise InputError(f"camera view: margin_px ({self.margin_px}), ray_radius_m ({self.ray_radius_m}) and "
                             f"clearance_m ({self.clearance_m}) must not be negative")

    @property
    def max_angle_rad(self) -> float:
        """The viewing-angle limit (rad)."""
        return float(np.radians(self.max_angle_deg))


class CameraView:
    """The camera's constraints of a design, batched over configurations (module docstring).

    Args:
        camera: the nominal camera model (intrinsics, board, mounting).
        limits: the :class:`ViewLimits`.
        coll: the cell's collision model (its robot and obstacle capsules are the rays' blockers), or None: no
            ray rows.

    Raises:
        InputError: the camera's robot is not the collision model's.
    """

    def __init__(self, camera: CameraModel, limits: ViewLimits | None = None, coll: CollisionModel | None = None):
        self.camera, self.limits, self.coll = camera, limits or ViewLimits(), coll
        self.robot = camera.robot
        self.n = self.robot.nq
        if coll is not None and coll.n != self.n:
            raise InputError(f"camera view: the camera's robot has {self.n} joints, the cell's {coll.n}")
        self.chain = Chain.from_robot(self.robot)
        self.p0 = np.zeros(camera.n_params)
        b = camera.board
        self.outer = np.array([0, b.cols - 1, b.n - b.cols, b.n - 1])
        self.corners = b.corners()
        self.centre = self.corners.mean(axis=0)
        self.blockers = self._blockers()
        self.kinds = self._row_kinds()

    def _blockers(self) -> np.ndarray:
        """Indices of the collision model's robot and obstacle segments the rays are checked against."""
        if self.coll is None:
            return np.zeros(0, int)
        c = self.coll
        keep = []
        for a in range(c.n_robot + c.n_obst):
            names = {c.seg_names[a], c.seg_link[a]} - {None}
            if a < c.n_robot and c.seg_joint[a] == self.n:
                continue  # the link carrying the camera or the board
            if names & set(self.limits.ray_skip):
                continue
            keep.append(a)
        return np.array(keep, int)

    def _row_kinds(self) -> np.ndarray:
        """Kind index (into :data:`VIEW_KINDS`) of every raw row."""
        N = self.camera.board.n
        return np.concatenate([np.zeros(4 * N, int), np.ones(8, int), [2],
                               np.full(NRAYS * self.blockers.size, 3, int)])

    @property
    def names(self) -> list[str]:
        """Names of the raw rows."""
        N = self.camera.board.n
        out = [f"image:corner{k}:{s}" for k in range(N) for s in ("u_min", "u_max", "v_min", "v_max")]
        out += [f"depth:corner{k}:{s}" for k in self.outer for s in ("near", "far")]
        out.append("angle")
        if self.coll is not None:
            out += [f"rays:{r}|{self.coll.seg_names[a]}" for r in ("c0", "c1", "c2", "c3", "centre")
                    for a in self.blockers]
        return out

    # ------------------------------------------------------------------ geometry
    def _frames(self, Q: np.ndarray) -> dict:
        """Camera pose, board corners, normal and centre in the base frame, and the joints' world twists."""
        cam = self.camera
        kin = self.chain.tool_point(Q, np.zeros(3))
        C, B = cam.pose_of("camera", self.p0), cam.pose_of("board", self.p0)
        m = Q.shape[0]
        sign = 1.0 if self.limits.front_z else -1.0
        if cam.eye_in_hand:  # C = tool_T_camera, B = board_T_base: the board fixed, the camera moving
            Rc = kin.R_tool @ C.rotation
            tc = kin.p + kin.R_tool @ C.translation
            xb = np.broadcast_to((self.corners - B.translation) @ B.rotation, (m, self.corners.shape[0], 3))
            nrm = np.broadcast_to(sign * B.rotation[2], (m, 3))
        else:  # C = camera_T_base, B = tool_T_board: the camera fixed, the board moving
            Rc = np.broadcast_to(C.rotation.T, (m, 3, 3))
            tc = np.broadcast_to(-C.rotation.T @ C.translation, (m, 3))
            bt = self.corners @ B.rotation.T + B.translation
            xb = np.einsum("mab,nb->mna", kin.R_tool, bt) + kin.p[:, None]
            nrm = sign * (kin.R_tool @ B.rotation[:, 2])
        V, W = np.swapaxes(kin.twist[:, :3], 1, 2), np.swapaxes(kin.twist[:, 3:], 1, 2)  # (m, n, 3)
        X = np.einsum("mba,mnb->mna", Rc, xb - tc[:, None])
        return {"Rc": Rc, "tc": tc, "xb": xb, "nrm": nrm, "V": V, "W": W, "X": X}

    def _ray_targets(self, xb: np.ndarray) -> np.ndarray:
        """The rays' ends on the board: the four outer corners and the centre, base frame, (m, 5, 3) m."""
        return np.concatenate([xb[:, self.outer], xb.mean(axis=1, keepdims=True)], axis=1)

    @staticmethod
    def _velocity(V: np.ndarray, W: np.ndarray, x: np.ndarray) -> np.ndarray:
        """∂x/∂q of points carried by the last joint: v_j + ω_j × x, (m, k, 3, n) for x (m, k, 3)."""
        return np.swapaxes(V[:, None] + cross(W[:, None], x[:, :, None]), 2, 3)

    @staticmethod
    def _corner_velocity(V: np.ndarray, W: np.ndarray, x: np.ndarray) -> np.ndarray:
        """:meth:`_velocity` (the same numbers: the same products and sums) laid out contiguous, each component
        written in place instead of stacked and transposed: the camera rotation's product over it (``evaluate``)
        runs twice as fast on it as on the transposed view, with the same sums in the same order."""
        m, k, n = x.shape[0], x.shape[1], V.shape[1]
        out = np.empty((m, k, 3, n))
        w = [W[:, None, :, i] for i in range(3)]  # (m, 1, n)
        y = [x[:, :, None, i] for i in range(3)]  # (m, k, 1)
        for i in range(3):
            a, b = (i + 1) % 3, (i + 2) % 3
            np.add(V[:, None, :, i], w[a] * y[b] - w[b] * y[a], out=out[:, :, i])
        return out

    # ------------------------------------------------------------------ rows
    def evaluate(self, Q: np.ndarray, with_grad: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """Every raw row g(Q) ≥ 0 (module docstring) and ∂g/∂q.

        Args:
            Q: configurations (m, n) rad (m for prismatic joints).
            with_grad: also return the gradients.

        Returns:
            g (m, rows) in px, m and cos (:attr:`kinds`, :attr:`names`); G (m, rows, n) or None.
        """
        Q = np.atleast_2d(np.asarray(Q, float))
        f = self._frames(Q)
        moving = -1.0 if self.camera.eye_in_hand else 1.0
        vel = self._corner_velocity(f["V"], f["W"], f["xb"])  # (m, N, 3, n) of the base-frame corners as if carried
        Xdq = moving * np.einsum("mba,mnbj->mnaj", f["Rc"], vel)
        parts = [self._image(f["X"], Xdq, with_grad), self._depth(f["X"], Xdq, with_grad),
                 self._angle(f, with_grad)]
        if self.blockers.size:
            parts.append(self._rays(Q, f, with_grad))
        g = np.concatenate([p[0] for p in parts], axis=1)
        return g, (np.concatenate([p[1] for p in parts], axis=1) if with_grad else None)

    def _image(self, X: np.ndarray, Xdq: np.ndarray, with_grad: bool) -> tuple[np.ndarray, np.ndarray | None]:
        cam, mu = self.camera, self.limits.margin_px
        Z = np.where(X[..., 2:] > 1e-6, X, np.array([0.0, 0.0, 1e-6]))  # behind the camera: the depth rows refuse
        uv, P, _ = project(Z, cam.intrinsic_vector(self.p0))
        W_, H_ = cam.intrinsics.width, cam.intrinsics.height
        g = np.stack([uv[..., 0] - mu, W_ - mu - uv[..., 0], uv[..., 1] - mu, H_ - mu - uv[..., 1]], -1)
        m = X.shape[0]
        if not with_grad:
            return g.reshape(m, -1), None
        duv = P @ Xdq  # (m, N, 2, n)
        G = np.stack([duv[:, :, 0], -duv[:, :, 0], duv[:, :, 1], -duv[:, :, 1]], 2)
        return g.reshape(m, -1), G.reshape(m, -1, self.n)

    def _depth(self, X: np.ndarray, Xdq: np.ndarray, with_grad: bool) -> tuple[np.ndarray, np.ndarray | None]:
        Z = X[:, self.outer, 2]
        g = np.stack([Z - self.limits.near_m, self.limits.far_m - Z], -1).reshape(X.shape[0], -1)
        if not with_grad:
            return g, None
        dZ = Xdq[:, self.outer, 2]  # (m, 4, n)
        return g, np.stack([dZ, -dZ], 2).reshape(X.shape[0], -1, self.n)

    def _angle(self, f: dict, with_grad: bool) -> tuple[np.ndarray, np.ndarray | None]:
        x0 = f["xb"].mean(axis=1)
        r = f["tc"] - x0
        L = np.linalg.norm(r, axis=1)
        rh = r / L[:, None]
        c = np.einsum("ma,ma->m", f["nrm"], rh)
        g = (c - np.cos(self.limits.max_angle_rad))[:, None]
        if not with_grad:
            return g, None
        V, W = f["V"], f["W"]
        proj = (f["nrm"] - c[:, None] * rh) / L[:, None]  # ∂cos/∂r
        if self.camera.eye_in_hand:  # the camera centre moves, the board is fixed
            dr = self._velocity(V, W, f["tc"][:, None])[:, 0]  # (m, 3, n)
            dc = np.einsum("ma,man->mn", proj, dr)
        else:  # the board (centre and normal) moves, the camera is fixed
            dr = -self._velocity(V, W, x0[:, None])[:, 0]
            dn = np.swapaxes(cross(W, f["nrm"][:, None]), 1, 2)  # (m, 3, n)
            dc = np.einsum("ma,man->mn", proj, dr) + np.einsum("man,ma->mn", dn, rh)
        return g, dc[:, None, :]

    def _rays(self, Q: np.ndarray, f: dict, with_grad: bool) -> tuple[np.ndarray, np.ndarray | None]:
        c = self.coll
        assert c is not None
        EA, EB, JA, JB = c.endpoints(Q, with_grad=with_grad)
        k = self.blockers
        m, nb = Q.shape[0], k.size
        R = NRAYS
        A1 = np.broadcast_to(f["tc"][:, None, None], (m, R, nb, 3))  # the camera centre
        targets = self._ray_targets(f["xb"])
        B1 = np.broadcast_to(targets[:, :, None], (m, R, nb, 3))  # the outer corners and the centre
        A2 = np.broadcast_to(EA[:, None, k], (m, R, nb, 3))
        B2 = np.broadcast_to(EB[:, None, k], (m, R, nb, 3))
        s, t, w1, w2 = segment_closest(A1, B1, A2, B2)
        diff = w2 - w1
        d = np.linalg.norm(diff, axis=-1)
        lim = self.limits
        g = (d - c.radius[k][None, None] - lim.ray_radius_m - lim.clearance_m).reshape(m, -1)
        if not with_grad:
            return g, None
        assert JA is not None and JB is not None
        nrm = diff / np.where(d > 0, d, 1.0)[..., None]
        dcam = self._velocity(f["V"], f["W"], f["tc"][:, None])[:, 0]  # (m, 3, n)
        if self.camera.eye_in_hand:
            dA1, dB1 = np.broadcast_to(dcam[:, None], (m, R, 3, self.n)), np.zeros((m, R, 3, self.n))
        else:
            dA1, dB1 = np.zeros((m, R, 3, self.n)), self._velocity(f["V"], f["W"], targets)  # (m, R, 3, n)
        dw1 = (1 - s)[..., None, None] * dA1[:, :, None] + s[..., None, None] * dB1[:, :, None]
        dw2 = (1 - t)[..., None, None] * JA[:, None, k] + t[..., None, None] * JB[:, None, k]
        G = np.einsum("mrba,mrban->mrbn", nrm, dw2 - dw1)
        return g, G.reshape(m, -1, self.n)

    # ------------------------------------------------------------------ aggregated rows
    def aggregate(self, Q: np.ndarray, with_grad: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """One Kreisselmeier–Steinhauser row per kind present (:data:`VIEW_KINDS`; the angle row as is), ≤ the
        smallest row of its kind (conservative), with its exact gradient; (m, k) and (m, k, n)."""
        g, G = self.evaluate(Q, with_grad)
        vals, grads = [], []
        for kind, (_, unit) in enumerate(VIEW_KINDS):
            idx = np.flatnonzero(self.kinds == kind)
            if idx.size == 0:
                continue
            gk = g[:, idx]
            ell = self.limits.ks_px if unit == "px" else self.limits.ks_m
            lo = gk.min(axis=1)
            e = np.exp(-(gk - lo[:, None]) / ell) if unit != "cos" else np.ones_like(gk)
            ssum = e.sum(axis=1)
            vals.append(lo - ell * np.log(ssum) if unit != "cos" else gk[:, 0])
            if with_grad:
                assert G is not None
                grads.append(np.einsum("mr,mrn->mn", e / ssum[:, None], G[:, idx]))
        ga = np.stack(vals, axis=1)
        return ga, (np.stack(grads, axis=1) if with_grad else None)

    @property
    def aggregate_units(self) -> list[str]:
        """Units of the aggregated rows (px, m, cos, m)."""
        return [u for k, (_, u) in enumerate(VIEW_KINDS) if np.any(self.kinds == k)]

    @property
    def aggregate_names(self) -> list[str]:
        """Names of the aggregated rows."""
        return [f"camera {n}" for k, (n, _) in enumerate(VIEW_KINDS) if np.any(self.kinds == k)]

    def feasible(self, Q: np.ndarray, tol: float = 0.0) -> np.ndarray:
        """Whether every raw row is ≥ −tol at each configuration, (m,) bool."""
        g, _ = self.evaluate(Q, with_grad=False)
        return np.all(g >= -tol, axis=1)


def camera_constraints(camera: CameraModel, Q: np.ndarray, limits: ViewLimits | None = None,
                       coll: CollisionModel | None = None) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """The camera's constraints at configurations Q: values, Jacobian and row names (module docstring).

    Args:
        camera: the nominal camera model.
        Q: configurations (m, n) rad (m for prismatic joints), or one (n,).
        limits: the :class:`ViewLimits` (margin px, angle deg, depth of field m, rays).
        coll: the cell's collision model (the rays' blockers), or None: no ray rows.

    Returns:
        (g (m, rows) in px / m / cos, each ≥ 0 when satisfied; ∂g/∂q (m, rows, n); the rows' names).
    """
    view = CameraView(camera, limits, coll)
    g, G = view.evaluate(np.atleast_2d(np.asarray(Q, float)))
    assert G is not None
    return g, G, view.names


def cell_view_limits(cell) -> ViewLimits:
    """The :class:`ViewLimits` a cell file's camera states (its ``camera.view`` block,
    :mod:`pin_kpi_oed.cell.camera_setup`: margin px, largest viewing angle rad, depth of field m; the defaults where
    it says nothing), the rays' clearance the cell's ``clearance_m``.

    Args:
        cell: a :class:`~pin_kpi_oed.cell.cell_model.Cell` with a camera.

    Returns:
        The view limits.

    Raises:
        InputError: the cell has no camera.
    """
    if getattr(cell, "camera", None) is None:
        raise InputError(f"cell {cell.source or cell.name}: has no camera (no view limits)")
    v = cell.camera.view
    return ViewLimits(margin_px=v["margin_px"], max_angle_deg=float(np.degrees(v["max_angle_rad"])),
                      near_m=v["near_m"], far_m=v["far_m"], clearance_m=float(cell.clearance_m))


def cell_camera_view(cell, coll: CollisionModel | None = None) -> CameraView:
    """The camera's constraints in a cell: its nominal camera model (:meth:`Cell.measurement_model`) and the cell
    file's view limits (:func:`cell_view_limits`).

    Args:
        cell: a :class:`~pin_kpi_oed.cell.cell_model.Cell` with a camera.
        coll: the cell's collision model (the rays' blockers), or None: no ray rows.

    Returns:
        The :class:`CameraView`.

    Raises:
        InputError: the cell has no camera.
    """
    limits = cell_view_limits(cell)
    return CameraView(cell.measurement_model(), limits, coll)


def camera_cell(robot, obstacles: list | None = None, half_spaces: list | None = None,
                skip_pairs: list[tuple[str, str]] | None = None, q_work: np.ndarray | None = None,
                clearance_m: float = 0.0, name: str = "camera_cell", capsules: list | None = None):
    """A work cell for a camera design built in code: the robot's capsules (fitted to its URDF's collision
    geometry unless given), obstacles and half-spaces in the robot base frame (the cell frame), no tracker.

    The cell model carries a laser tracker; here it is placed 100 m above the base and its beam is checked against
    nothing, so the collision model holds the capsule pairs and half-spaces alone.

    Args:
        robot: the :class:`~pin_kpi_oed.model.robot.Robot`.
        obstacles: :class:`~pin_kpi_oed.cell.cell_model.CapsuleSpec` obstacles (m, base frame).
        half_spaces: :class:`~pin_kpi_oed.cell.cell_model.HalfSpace` (base frame).
        skip_pairs: capsule / link / obstacle name pairs never checked against each other.
        q_work: working configurations (t, n) rad.
        clearance_m: required clearance of every capsule pair (m).
        name: the cell's name.
        capsules: robot capsules (link frames); default fitted to the URDF (:func:`capsules_from_urdf`).

    Returns:
        The :class:`~pin_kpi_oed.cell.cell_model.Cell`.
    """
    import pinocchio as pin

    from pin_kpi_oed.cell.cell import capsules_from_urdf
    from pin_kpi_oed.cell.cell_model import Cell
    from pin_kpi_oed.model.noise import NoiseModel

    caps = capsules if capsules is not None else capsules_from_urdf(robot)
    obst, halfs = list(obstacles or []), list(half_spaces or [])
    beam_skip = [c.name for c in caps] + [o.name for o in obst] + [h.name for h in halfs]
    qw = np.zeros((0, robot.nq)) if q_work is None else np.atleast_2d(np.asarray(q_work, float))
    return Cell(name=name, source="", robot=robot, W_T_base=pin.SE3.Identity(),
                W_T_tracker=pin.SE3(np.eye(3), np.array([0.0, 0.0, 100.0])), reflector_m=np.zeros(3),
                tcp_m=np.zeros(3), noise=NoiseModel(), q_lower=robot.q_lower.copy(), q_upper=robot.q_upper.copy(),
                robot_capsules=caps, obstacles=obst, half_spaces=halfs, skip_pairs=list(skip_pairs or []),
                beam_skip=beam_skip, clearance_m=clearance_m, q_work=qw)
