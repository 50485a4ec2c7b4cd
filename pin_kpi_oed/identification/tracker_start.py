r"""Step 2 of :func:`~pin_kpi_oed.identification.identify.identify`: every station's working model and start.

The tracker pose of every station is guessed in closed form by point-set registration
(Kabsch/Umeyama, no scale, :func:`register_points`) of the nominal forward kinematics onto the
station's measured points; for a 6-D probe the probe orientation is the chordal mean
``proj_SO3(Σ_i (R_T R_tool,i)ᵀ R_meas,i)`` (:func:`proj_so3`).
"""

from __future__ import annotations

from typing import Any
from collections.abc import Sequence

import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation

from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.effects.library import predict_with_effects
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.identification.fit_inputs import FitInputs
from pin_kpi_oed.identification.identify_options import IdentifyOptions
from pin_kpi_oed.identification.problem import StationLayout, StationSet
from pin_kpi_oed.model.parameters import ParameterLayout
from pin_kpi_oed.model.nests import nest_column
from pin_kpi_oed.model.tracker import TrackerModel

__all__ = ["register_points", "proj_so3", "working_layout", "start_stations"]


def proj_so3(M: np.ndarray) -> np.ndarray:
    """Closest rotation to a 3×3 matrix (SVD projection)."""
    U, _, Vt = np.linalg.svd(M)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
    return U @ D @ Vt


def register_points(X: np.ndarray, Y: np.ndarray, w: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    r"""Closed-form rigid registration (Kabsch/Umeyama, no scale): ``Y ≈ X Rᵀ + t``.

    Minimises Σ_i w_i |y_i − (R x_i + t)|² with the SVD of the weighted cross-covariance
    H = Σ w_i (x_i − x̄)(y_i − ȳ)ᵀ = U S Vᵀ: R = V diag(1, 1, det(V Uᵀ)) Uᵀ, t = ȳ − R x̄.

    Args:
        X: points in the source frame (robot base), (m, 3) m.
        Y: the same points in the target frame (tracker), (m, 3) m.
        w: optional non-negative weights, (m,).

    Returns:
        (R (3, 3), t (3,) m).

    Raises:
        InputError: fewer than 3 points, or points (nearly) collinear.
    """
    X = np.asarray(X, float)
    Y = np.asarray(Y, float)
    if X.shape[0] < 3:
        raise InputError(f"registration needs at least 3 points, got {X.shape[0]}")
    w = np.ones(len(X)) if w is None else np.asarray(w, float)
    w = w / w.sum()
    xm, ym = w @ X, w @ Y
    H = (X - xm).T @ ((Y - ym) * w[:, None])
    U, S, Vt = np.linalg.svd(H)
    if S[1] <= 1e-9 * max(S[0], 1e-300):
        raise InputError("the measured points are (nearly) collinear: the tracker pose cannot be registered; "
                         "use configurations spread over the workspace")
    d = np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0
    R = Vt.T @ np.diag([1.0, 1.0, d]) @ U.T
    return R, ym - R @ xm


def working_layout(model: TrackerModel, pose6d: bool, setup_only: bool) -> ParameterLayout:
    """The layout of a station's working model: ``model``'s fixed flags and priors; robot fixed if ``setup_only``."""
    L0 = model.layout
    L = ParameterLayout(list(model.robot.joint_names), pose6d=pose6d)
    for i, n in enumerate(L.names):
        if n in L0.names:
            k = L0.names.index(n)
            L.fixed[i] = L0.fixed[k]
            L.prior_sigma[i] = L0.prior_sigma[k]
    if setup_only:
        L.fixed = L.fixed | ~L.is_setup()
    return L


def start_stations(model: TrackerModel, data: MeasurementSet, inp: FitInputs, effects: Sequence[Any],
           opts: IdentifyOptions) -> tuple[StationSet, np.ndarray, list[np.ndarray]]:
    """Step 2: working models of every station, start values, registered tracker poses."""
    robot = model.robot
    L = working_layout(model, inp.pose6d, opts.setup_only)
    layout = StationLayout.build(L, inp.labels, opts.reflector_per_station)
    S = layout.n_stations
    p_user = np.zeros(model.n_params) if opts.p0 is None else np.asarray(opts.p0, float).reshape(model.n_params)
    tracker_known = bool(L.fixed[L.tracker].any() or np.isfinite(L.prior_sigma[L.tracker]).any())
    probe_known = bool(L.fixed[L.probe].any() or np.isfinite(L.prior_sigma[L.probe]).any())
    if S > 1 and tracker_known:
        raise InputError(f"{inp.src}: {S} stations ({', '.join(inp.labels)}) but tracker parameters are fixed or have "
                         "a prior: with several stations every tracker pose is registered from its own rows")
    P = np.zeros(layout.n)
    for g, k in enumerate(layout.generic):
        n = L.names[k]
        if n in model.layout.names and not n.startswith(("tracker.", "reflector.")):
            P[g] = p_user[model.layout.index(n)]
    T0 = model.tracker_pose(p_user)
    reflector0 = model.reflector(p_user)
    nests0 = model.nests_m - model.nests_m[0] + reflector0  # the nests move with the start's offset
    models = [TrackerModel(robot, tracker_T_base=T0, reflector_m=reflector0, tcp_m=model.tcp_m, noise=model.noise,
                           pose6d=inp.pose6d, probe_R=np.asarray(model.probe_R, float), layout=L, nests_m=nests0)
              for _ in range(S)]
    nest = nest_column(data, model.n_nests)
    stations = StationSet(models, layout)
    if opts.register and not tracker_known:
        th0 = list(opts.theta0) if opts.theta0 is not None else [np.zeros(len(e.param_names(robot))) for e in effects]
        pairs = list(opts.held_effects) + list(zip(effects, th0))
        M_probe = []
        for s, rows in enumerate(inp.rows):
            wm = models[s]
            wm.tracker_T_base = pin.SE3.Identity()
            p_s = stations.station_p(P, s)
            aux = data if rows.size == len(data) else data.subset(rows)
            wn = wm if nest is None else wm.at_nests(nest[rows])
            X = predict_with_effects(wn, p_s, inp.Q[rows], aux, pairs)[:, :3]  # base frame: tracker = identity
            w = None if inp.sigma is None else 1.0 / np.mean(inp.sigma[rows] ** 2, 1)
            R, t = register_points(X, data.position_m[rows], w)
            wm.tracker_T_base = pin.SE3(R, t)
            if inp.pose6d:
                kin = wm.kinematics(p_s, inp.Q[rows], wm.reflector(p_s))
                Rm = Rotation.from_rotvec(data.rotvec_rad[rows]).as_matrix()
                M_probe.append(np.einsum("mba,bc,mcd->ad", kin.R_tool, R.T, Rm))  # Σ (R_T R_tool)ᵀ R_meas
        if inp.pose6d and not probe_known:
            for s, wm in enumerate(models):
                wm.probe_R = proj_so3(M_probe[s] if opts.reflector_per_station else sum(M_probe))
            P[layout.is_setup() & (layout.generic >= L.probe.start) & (layout.generic < L.probe.stop)] = 0.0
    return stations, P, [m.tracker_T_base.homogeneous.copy() for m in models]
