"""A toy measurement device added from outside the package through the MeasurementModel interface.

A calibrated camera sees a marker on the tool and reports its pinhole image coordinates
(u, v) = f (X/Z, Y/Z) (px), X = camera_T_base(p) · oMtool(p, q) · marker(p). Set-up groups:
``camera`` (pose) and ``marker`` (point). It goes through the package's identifiability analysis,
covariance and design criterion unchanged; a mono camera cannot see scale, which the analysis
must find (one rank less than the laser tracker on the same robot). The package's
``identify`` is not used: it registers and re-parameterises a laser tracker's pose.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin
import pytest

from pin_kpi_oed.errors import IdentifiabilityError, InputError
from pin_kpi_oed.model.device import MeasurementModel
from pin_kpi_oed.model.parameters import ParameterLayout
from pin_kpi_oed.model.robot import Robot, load_robot
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.oed import covariance as cov
from pin_kpi_oed.oed import identifiability as idf
from pin_kpi_oed.oed.objective import DesignCriterion


@dataclass
class CameraModel(MeasurementModel):
    """Pinhole camera measuring a marker on the tool: (u, v) in px, nh = 2."""

    robot: Robot
    camera_T_base: pin.SE3 = field(default_factory=pin.SE3.Identity)
    marker_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    tcp_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    focal_px: float = 2000.0
    sigma_px: float = 0.05
    layout: ParameterLayout | None = None

    def __post_init__(self) -> None:
        self.marker_m = np.asarray(self.marker_m, float)
        if self.layout is None:
            self.layout = self.make_layout()
        self.init_kinematics()

    def setup_spec(self):
        return (("camera", "pose"), ("marker", "point"))

    frame_group = "camera"
    target_groups = ("marker",)
    nh = 2

    def sensor_pose(self, p):
        return self.camera_T_base * pin.exp6(np.asarray(p)[self.layout.group_slice("camera")])

    def marker(self, p):
        return self.marker_m + np.asarray(p)[self.layout.group_slice("marker")]

    def _proj(self, X):
        """Image coordinates (m, 2) and their Jacobian w.r.t. the camera-frame point, (m, 2, 3)."""
        f, Z = self.focal_px, X[:, 2]
        uv = f * X[:, :2] / Z[:, None]
        P = np.zeros((X.shape[0], 2, 3))
        P[:, 0, 0] = P[:, 1, 1] = f / Z
        P[:, :, 2] = -uv / Z[:, None]
        return uv, P

    def _dproj(self, X, Xdq):
        """∂P/∂q (m, 2, 3, n) from the camera-frame point's derivative Xdq (m, 3, n)."""
        f, Z = self.focal_px, X[:, 2]
        dZ = Xdq[:, 2, :]  # (m, n)
        dP = np.zeros((X.shape[0], 2, 3, Xdq.shape[2]))
        dP[:, 0, 0] = dP[:, 1, 1] = -f * dZ / Z[:, None] ** 2
        for a in range(2):  # P[a, 2] = -f X_a / Z²
            dP[:, a, 2] = -f * (Xdq[:, a, :] / Z[:, None] ** 2 - 2 * X[:, a, None] * dZ / Z[:, None] ** 3)
        return dP

    def predict(self, p, Q):
        return self._proj(self.sensor_point(p, Q, self.marker(p), "marker").Y)[0]

    def jacobian(self, p, Q):
        sp = self.sensor_point(p, Q, self.marker(p), "marker")
        return self._proj(sp.Y)[1] @ sp.J @ self.right_jacobian(p)

    def jacobian_dq(self, p, Q):
        sp = self.sensor_point(p, Q, self.marker(p), "marker", with_dq=True)
        uv, P = self._proj(sp.Y)
        dP = self._dproj(sp.Y, sp.Ydq)
        Jr = self.right_jacobian(p)
        J = P @ sp.J @ Jr
        dJ = np.einsum("mabk,mbp->mapk", dP, sp.J) + np.einsum("mab,mbpk->mapk", P, sp.dJ)
        dJ = np.einsum("mapk,pr->mark", dJ, Jr)
        return uv, J, dJ, P @ sp.Ydq

    def sigma(self, p, Q, Y=None):
        return np.full((np.atleast_2d(Q).shape[0], 2), self.sigma_px)

    def kpi(self, p, Q_work):
        return self.sensor_point(p, Q_work, self.tcp_m).Y

    def kpi_jacobian(self, p, Q_work):
        return (self.sensor_point(p, Q_work, self.tcp_m).J @ self.right_jacobian(p)).reshape(-1, self.n_params)


def _camera(**kw) -> CameraModel:
    """The camera 2.8 m in front of the KR 15, its optical axis (z) pointing back at the robot (-x)."""
    base_T_cam = pin.SE3(pin.rpy.rpyToMatrix(0.0, -np.pi / 2, 0.0) @ pin.rpy.rpyToMatrix(0.0, 0.0, -np.pi / 2),
                         np.array([2.8, 0.2, 0.9]))
    return CameraModel(load_robot("kr15"), camera_T_base=base_T_cam.inverse(), marker_m=np.array([0.05, 0.03, 0.08]),
                       tcp_m=np.array([0.0, 0.0, 0.2]), **kw)


def _poses(model, n, seed):
    """Random configurations whose marker is in front of the camera (Z > 0.5 m)."""
    rng = np.random.default_rng(seed)
    Q = model.robot.random_q(rng, 20 * n)
    Z = model.sensor_point(np.zeros(model.n_params), Q, model.marker_m).Y[:, 2]
    return Q[Z > 0.5][:n]


def _fd_jacobian(model, p, Q, h=1e-6):
    """∂h/∂p by central differences of ``predict`` (independent of the analytic Jacobian)."""
    J = np.zeros((Q.shape[0], model.nh, model.n_params))
    for i in range(model.n_params):
        dp = np.zeros(model.n_params)
        dp[i] = h
        J[:, :, i] = (model.predict(p + dp, Q) - model.predict(p - dp, Q)) / (2 * h)
    return J


def test_camera_is_a_measurement_model_with_its_own_groups():
    cam = _camera()
    assert isinstance(cam, MeasurementModel)
    assert cam.setup_groups == ("camera", "marker")
    assert cam.layout.names[-9:] == ["camera.tx", "camera.ty", "camera.tz", "camera.rx", "camera.ry", "camera.rz",
                                     "marker.x", "marker.y", "marker.z"]
    assert cam.layout.is_setup().sum() == 9 and not any(n.startswith("tracker") for n in cam.layout.names)


def test_camera_derivatives_match_finite_differences():
    cam = _camera()
    rng = np.random.default_rng(0)
    p = rng.normal(scale=1e-3, size=cam.n_params)  # away from nominal: the right Jacobians count
    Q = _poses(cam, 4, 1)
    J = cam.jacobian(p, Q)
    assert np.abs(J - _fd_jacobian(cam, p, Q)).max() < 1e-6 * np.abs(J).max()
    Y, J2, dJ, Ydq = cam.jacobian_dq(p, Q)
    F, dF = cam.weighted_jacobian_dq(p, Q)  # the base class's, σ independent of q
    assert np.abs(J2 - J).max() < 1e-12 * np.abs(J).max()
    h = 1e-6
    for k in range(cam.robot.nq):
        dq = np.zeros(cam.robot.nq)
        dq[k] = h
        dJ_fd = (cam.jacobian(p, Q + dq) - cam.jacobian(p, Q - dq)) / (2 * h)
        dY_fd = (cam.predict(p, Q + dq) - cam.predict(p, Q - dq)) / (2 * h)
        assert np.abs(dJ[..., k] - dJ_fd).max() < 1e-6 * np.abs(dJ).max()
        assert np.abs(dF[..., k] - dJ_fd / cam.sigma_px).max() < 1e-6 * np.abs(dF).max()
        assert np.abs(Ydq[..., k] - dY_fd).max() < 1e-6 * np.abs(Ydq).max()
        assert np.abs(cam.prediction_dq(p, Q)[..., k] - dY_fd).max() < 1e-6 * np.abs(Ydq).max()


def _scale_direction(model) -> np.ndarray:
    """p of a uniform scaling of every length (joint translations, tool offset via the marker, camera distance)."""
    L, rb = model.layout, model.robot
    d = np.zeros(model.n_params)
    for k, jid in enumerate(rb.joint_ids):
        M = rb.model.jointPlacements[jid]
        d[L.joint_slice(k).start:L.joint_slice(k).start + 3] = M.rotation.T @ M.translation
    Mt = rb.model.frames[rb.tool_frame_id].placement
    d[L.group_slice("marker")] = model.marker_m + Mt.rotation.T @ Mt.translation
    T0 = model.camera_T_base
    d[L.group_slice("camera").start:L.group_slice("camera").start + 3] = T0.rotation.T @ T0.translation
    return d


def test_identifiability_finds_that_a_camera_cannot_see_scale():
    cam = _camera()
    Q = _poses(cam, 200, 2)
    ident = idf.analyse(cam, Q=Q)
    tracker = TrackerModel(cam.robot, tracker_T_base=cam.camera_T_base, reflector_m=cam.marker_m)
    ident_t = idf.analyse(tracker, Q=Q)
    assert ident_t.rank == 27
    assert ident.n_raw == 45 and ident.rank == 26  # one less: the scale
    assert ident.setup_groups == ("camera", "marker")
    assert any("confounded with camera (convention" in line for line in ident.groups_text())
    # the scale direction moves no image coordinate and lies in the reported null space
    s = _scale_direction(cam)
    F = cam.weighted_jacobian(np.zeros(cam.n_params), Q).reshape(-1, cam.n_params)
    assert np.linalg.norm(F @ s) < 1e-9 * np.linalg.norm(F, 2) * np.linalg.norm(s)
    N = ident.null_space
    resid = s - N @ np.linalg.lstsq(N, s, rcond=None)[0]
    assert np.linalg.norm(resid) < 1e-6 * np.linalg.norm(s)
    # the extra lost direction: a link length held nominal, confounded with the camera pose and the other
    # lengths; by the convention (set-up parameters first) it fixes the scale, so the TCP stays estimable
    extra = [d for d in ident.dropped if d["name"] not in {e["name"] for e in ident_t.dropped}]
    assert len(extra) == 1 and extra[0]["convention"] and extra[0]["name"].split(".")[1] in ("tx", "ty", "tz")
    assert any(c.startswith("camera.") for c in extra[0]["confounded_with"])
    idf.check_kpi(ident, cam, cam.kpi_jacobian(np.zeros(cam.n_params), Q[:1]))
    # a TCP in the robot base frame is not estimable: the camera pose is unknown
    E_base = cam.camera_T_base.rotation.T @ cam.kpi_jacobian(np.zeros(cam.n_params), Q[:1])
    E_base[:, cam.layout.group_slice("camera")] = 0.0
    with pytest.raises(IdentifiabilityError, match="express the KPI in the camera frame"):
        idf.check_kpi(ident, cam, E_base)


def test_camera_covariance_and_design_criterion():
    """C_s = E C_p Eᵀ through the package equals E (FᵀF)⁻¹ Eᵀ built here from finite differences of
    ``predict``; the design criterion's gradient (base-class dF/dq) matches finite differences."""
    cam = _camera()
    Q = _poses(cam, 40, 3)
    ident = idf.analyse(cam, Q=_poses(cam, 200, 2))
    Qw = _poses(cam, 2, 4)
    p0 = np.zeros(cam.n_params)
    b = ident.base
    E = cam.kpi_jacobian(p0, Qw)[:, b]
    F = cam.weighted_jacobian(p0, Q).reshape(-1, cam.n_params)[:, b]
    Cs = cov.kpi_covariance(F, E)
    F_fd = (_fd_jacobian(cam, p0, Q) / cam.sigma_px).reshape(-1, cam.n_params)[:, b]
    Cs_fd = E @ np.linalg.inv(F_fd.T @ F_fd) @ E.T
    assert np.abs(Cs - Cs_fd).max() < 1e-4 * np.abs(Cs_fd).max()
    crit = DesignCriterion(cam, b, "kpi", E)
    v, g = crit.value_and_grad(Q)
    assert v == pytest.approx(np.trace(Cs_fd), rel=1e-4)
    h = 1e-4  # central differences: truncation ~1e-8 of max|g| here; at 1e-6 the rounding of the values is ~1e-6
    for i, k in [(0, 1), (5, 2), (17, 4)]:
        dQ = np.zeros_like(Q)
        dQ[i, k] = h
        fd = (crit.value(Q + dQ) - crit.value(Q - dQ)) / (2 * h)
        assert fd == pytest.approx(g[i, k], rel=1e-4, abs=1e-6 * np.abs(g).max())


def test_layout_groups_come_from_the_device():
    L = ParameterLayout(["j1", "j2"], setup=(("camera", "pose"), ("marker", "point"), ("lens", "rotation")))
    assert L.setup_groups == ("camera", "marker", "lens")
    assert L.group_slice("marker") == slice(18, 21) and L.group_kind("lens") == "rotation"
    assert L.group_slice("tracker") == slice(24, 24)  # absent group: empty
    with pytest.raises(InputError, match="matches no parameter.*camera.rz, marker.z"):
        L.select("tracker.*")
    with pytest.raises(InputError, match="unknown kind 'scalar'"):
        ParameterLayout(["j1"], setup=(("camera", "scalar"),))
    with pytest.raises(InputError, match="'j1': name already used"):
        ParameterLayout(["j1"], setup=(("j1", "pose"),))
    # the laser tracker's default layout is unchanged
    assert ParameterLayout(["j1"], pose6d=True).setup_groups == ("tracker", "reflector", "probe")
