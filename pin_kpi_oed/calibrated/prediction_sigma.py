r"""The standard deviation of measured − predicted: the one σ every command that predicts reports.

For a row q of station s (tracker rotation R_s), the covariance of measured − predicted in the tracker frame is

.. math::  C(q) = R_s\,\bigl(V_δ(q) + W + E(q)\,C_p\,E(q)^\top\bigr)\,R_s^\top
           \;[+\ \mathrm{diag}(σ_{\mathrm{noise}}^2)],

* V_δ: the discrepancy's posterior variance (a Gaussian process) — zero for a white or noise-only model;
* W: the white level (tracker noise and repeatability; for a white discrepancy the residual level corrected for the
  fitted parameters, :func:`~pin_kpi_oed.discrepancy.gp.white_level`); the noise model's σ for a noise-only model;
* E C_p Eᵀ: the parametric part's error, E the base-frame Jacobian of the prediction w.r.t. the robot parameters
  and, for a station ``identify`` fitted, its own set-up; for a station registered later, the robot's Jacobian after
  its re-fitted set-up absorbed what it can (:func:`_registered`), C_p their covariance —

  - noise-only model: the fit's covariance (``parameters.covariance`` of the model file) of the robot parameters
    and, for a station ``identify`` fitted, its own set-up (:func:`robot_parameter_covariance`), at every row,
    multiplied by the fit's reduced χ² when above 1 (residuals beyond the stated noise);
  - white discrepancy: the least-squares covariance under the white level, at every row; with joint-angle errors
    (few poses, :mod:`pin_kpi_oed.discrepancy.joint_angle`) their covariance τ² J_q J_qᵀ, the parameters' covariance
    under them and the cross term of what the fit absorbed (``JointAngleTerm.covariance``), per row never below the
    white level's own covariance in any direction (:func:`_white_excess`);
  - Gaussian process: the universal-kriging term (E − K_WQ Σ⁻¹F) C (E − K_WQ Σ⁻¹F)ᵀ on rows outside the
    coverage, the least-squares term E C_ls Eᵀ inside it
    (:meth:`~pin_kpi_oed.discrepancy.gp.Discrepancy.parametric_covariance`);
  - at a point of the tool off the fitted reflector (:func:`point_covariance`) of a 6-D fit, a discrepancy without
    joint-angle errors: the noise-only model's term, the fit's covariance, at every row. The discrepancy's
    covariances are the reflector positions' alone, which leave the flange's tilt about a reflector on the flange
    axis nearly free; the fit's orientation rows determine it (:func:`_orientation_informed`).

The tool's orientation (6-D models, :func:`orientation_sigma`): the covariance of the measured − predicted
orientation (rotation vector, tracker frame of the station) is

.. math::  C_ω(q) = f\,Ω(q)\,C_p\,Ω(q)^\top + \mathrm{diag}(w_ω^2),

Ω the orientation rows of the station's Jacobian over the fit's parameters (as E above, the probe's orientation
included; a station registered later takes the robot's unprojected, which errs on the large side), C_p the fit's
covariance, f = max(1, reduced χ²) when it was not scaled, w_ω the fit's orientation residual level per axis
(``fit.residual_sigma_rad``, corrected for the fitted parameters; else the stated orientation noise): the
discrepancy is a position term, so what the geometry leaves of the orientation is counted as white. A point at a
length L along the tool axis z (the tool frame's z in the tracker frame) moves by L·ω × z; its 3-D σ is
L·√tr([z]ₓ C_ω [z]ₓᵀ) (rotations about the axis do not move it).

Rows outside the training's joint-space coverage (:class:`~pin_kpi_oed.discrepancy.coverage.JointCoverage`: the
combination of the angles counts) are flagged; every σ of a station is multiplied by its ``sigma_scale``.
"""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from pin_kpi_oed.calibrated.shared_tables import discrepancy_at, outside_coverage, posterior_covariance_at, remembered
from pin_kpi_oed.model.kinematics import skew
from pin_kpi_oed.discrepancy.sandwich import row_sandwich

#: the length along the tool axis at which ``predict`` and ``compensate`` state the orientation's effect (m):
#: "orientation at 200 mm", as a cell's ``orientation_length_m`` defaults to
DEFAULT_TOOL_LENGTH_M = 0.2

__all__ = ["DEFAULT_TOOL_LENGTH_M", "SigmaPoint", "predictive_covariance", "predictive_sigma", "point_covariance",
           "orientation_sigma", "robot_parameter_covariance", "sigma_contents", "sigma_at", "with_registered_station",
           "station_sigma_factor"]


def robot_parameter_covariance(cm: Any, label: str | None = None, probe: bool = False
                               ) -> tuple[list[str], list[str], np.ndarray | None]:
    """The fit's parameters a prediction of station ``label`` depends on, from a model's ``parameters``: (names in
    the fit, the station layout's names of the same parameters, their covariance), or ([], [], None).

    The robot parameters always; the station's own set-up (tracker pose, reflector) too when ``identify`` fitted it
    with the robot (their errors are correlated and partly cancel). A station registered later gets the robot's
    alone; its Jacobian is then projected (:func:`_registered`). ``probe``: a 6-D station's set-up includes the
    probe's orientation (what the measured orientation depends on besides the robot).
    """
    from pin_kpi_oed.model.parameters import STATION_SEP
    from pin_kpi_oed.model.parameters import ParameterLayout

    par = cm.parameters or {}
    names, C = list(par.get("names") or []), par.get("covariance")
    if C is None or not names:
        return [], [], None
    C = np.asarray(C, float)
    L = ParameterLayout(list(cm.robot.joint_names), pose6d=probe)
    robot = set(L.names[:6 * cm.robot.nq])
    own = label is not None and cm.setups[label].fitted_by == "identify"
    setup = set(L.names[6 * cm.robot.nq:]) if own else set()
    idx, generic = [], []
    for i, n in enumerate(names):
        g = n.replace(f"{STATION_SEP}{label}.", ".", 1) if own and STATION_SEP in n else n
        if i < len(C) and (n in robot or (g in setup and (STATION_SEP not in n or g != n))):
            idx.append(i)
            generic.append(g)
    if not idx:
        return [], [], None
    return [names[i] for i in idx], generic, C[np.ix_(idx, idx)]


def _jacobian_model(cm: Any, label: str, point: Any = None) -> tuple[Any, np.ndarray]:
    """Station ``label``'s measurement model for the σ's Jacobians: a station registered later with the reflector of
    the calibration (the first station ``identify`` fitted). Rows with a nearly constant flange axis barely
    determine the reflector, which a registration then trades against the tracker translation (on the UR10's
    Series D, 60 rows: 169 mm off along the flange axis), leaving the predictions unchanged but not the lever arms
    of the robot's rotation errors. With a :class:`SigmaPoint`, the model of that point of the tool instead."""
    model, p = cm.station_model(label)
    if point is not None:
        model.reflector_m = np.array(point.tcp_m, float)
    elif cm.setups[label].fitted_by != "identify":
        ref = next((st for st in cm.setups.values() if st.fitted_by == "identify"), None)
        if ref is not None:
            model.reflector_m = np.array(ref.reflector_m, float)
    return model, p


def _point_jacobian(cm: Any, label: str, Q: np.ndarray, cols: list[int], point: Any) -> np.ndarray:
    """Base-frame Jacobian (m, 3, k) of station ``label``'s predictions (of ``point``'s, :class:`SigmaPoint`, when
    given) w.r.t. the layout columns ``cols``. At a point of the tool the fitted reflector offset moves nothing (its
    columns are zero), and in the robot base frame neither does the tracker pose."""
    model, p = _jacobian_model(cm, label, point)
    Q = np.ascontiguousarray(np.atleast_2d(np.asarray(Q, float)))

    def compute() -> np.ndarray:
        J = model.base_jacobian(p, Q, cols)
        if point is not None:
            L = model.layout
            still = set() if point.follows_reflector else set(range(L.reflector.start, L.reflector.stop))
            if point.frame == "base":
                still |= set(range(L.tracker.start, L.tracker.stop))
            J[:, :, [k for k, c in enumerate(cols) if c in still]] = 0.0
        return J

    parts = (p, model.tracker_T_base.homogeneous, model.reflector_m, model.probe_R, model.nests_m, model.tcp_m, Q)
    return remembered(("point_jacobian", id(cm.robot), model.pose6d, Q.shape, tuple(cols), point)
                      + tuple(np.asarray(a, float).tobytes() for a in parts), compute)


def _robot_jacobian(cm: Any, label: str, Q: np.ndarray, names: list[str], point: Any = None) -> np.ndarray:
    """Base-frame Jacobian (m, 3, k) of station ``label``'s predictions (of ``point``'s when given) w.r.t. the
    parameters ``names`` (layout names)."""
    if not names:
        return np.zeros((len(Q), 3, 0))
    model, _ = _jacobian_model(cm, label)
    return _point_jacobian(cm, label, Q, [model.layout.names.index(n) for n in names], point)


def _joint_jacobian(cm: Any, label: str, Q: np.ndarray, point: Any = None) -> np.ndarray:
    """∂y/∂q (m, 3, d) m/rad of station ``label``'s predictions (of ``point``'s when given), robot base frame."""
    model, p = _jacobian_model(cm, label, point)
    return np.einsum("ba,mbj->maj", model.tracker_pose(p).rotation, model.prediction_dq(p, np.atleast_2d(Q)))


def _setup_jacobian(cm: Any, label: str, Q: np.ndarray, point: Any = None) -> np.ndarray:
    """Base-frame Jacobian (m, 3, 9) of station ``label``'s predictions (of ``point``'s when given) w.r.t. its
    set-up (tracker pose, reflector)."""
    L = _jacobian_model(cm, label)[0].layout
    cols = list(range(L.tracker.start, L.tracker.stop)) + list(range(L.reflector.start, L.reflector.stop))
    return _point_jacobian(cm, label, Q, cols, point)


def _registered(cm: Any, label: str, Q: np.ndarray, E: np.ndarray, names: list[str], point: Any = None
                ) -> np.ndarray:
    """The robot Jacobian E (m, 3, R) over ``names`` of a station registered later, after its set-up absorbed what
    it can: Ẽ = E − G(q) (G_Zᵀ G_Z)⁻¹ G_Zᵀ J_Z (the re-registration formula of :mod:`pin_kpi_oed.oed.reregistration`)
    with Z the configurations the registration fitted the set-up on (:attr:`Setup.registered_q_rad`): the robot's
    error there is what the set-up absorbed, so the error left at q is E Δp less the set-up's answer to it. With the
    robot's marginal covariance alone the set-up's share counts as error (35 poses of the UR10's Series B scored on C
    after registration: standardised RMS 0.50); with the calibration's own configurations as the stand-in for Z,
    what the set-up absorbs in the other session's joint ranges is missed (the same case 0.33-0.48; 0.79-1.10 on the
    registration rows). A model file written before the rows were recorded uses the stand-in; without either, E
    (conservative). With a :class:`SigmaPoint`, E and the set-up's move at q are the point's, the rows Z the
    reflector's (what the registration measured)."""
    Z = _registration_rows(cm, label)
    if Z is None or not names:
        return E
    Gz = _setup_jacobian(cm, label, Z).reshape(-1, 9)
    Jz = _robot_jacobian(cm, label, Z, names).reshape(-1, len(names))
    norms = np.linalg.norm(Gz, axis=0)
    norms[norms == 0] = 1.0
    # set-up directions Z barely determines (relative singular value below 1 %) are left out, not amplified
    B, *_ = np.linalg.lstsq(Gz / norms, Jz, rcond=1e-2)
    return E - np.einsum("mak,kr->mar", _setup_jacobian(cm, label, Q, point) / norms, B)


def _registration_rows(cm: Any, label: str) -> np.ndarray | None:
    """The configurations a registered station's set-up was fitted on (the stand-in of :func:`_registered` for
    older model files), or None."""
    Z = cm.setups[label].registered_q_rad
    if Z is None or len(Z) < 3:
        cov = _coverage(cm)
        Z = None if cov is None else cov.Z
    return None if Z is None or len(Z) < 3 else Z


def _registration_map(cm: Any, label: str, Q: np.ndarray, Z: np.ndarray, point: Any = None) -> np.ndarray:
    """A (m, 3, 3k): the move of the set-up fitted on Z at each q per unit residual at Z's rows (base frame), the
    map of :func:`_registered` (Ẽ = E − A J_Z)."""
    Gz = _setup_jacobian(cm, label, Z).reshape(-1, 9)
    norms = np.linalg.norm(Gz, axis=0)
    norms[norms == 0] = 1.0
    return np.einsum("mak,kn->man", _setup_jacobian(cm, label, Q, point) / norms,
                     np.linalg.pinv(Gz / norms, rcond=1e-2))


def _joint_angle_covariance(cm: Any, d: Any, label: str, Q: np.ndarray, E: np.ndarray,
                            chunk: int = 500, point: Any = None) -> np.ndarray:
    """The joint-angle term's covariance (m, 3, 3) at station ``label``'s rows Q (base frame;
    :meth:`~pin_kpi_oed.discrepancy.joint_angle.JointAngleTerm.covariance`), with the registration's share at a
    station registered later; in chunks of rows (the registration map holds 9 k numbers per row)."""
    Jq = _joint_jacobian(cm, label, Q, point)
    if cm.setups[label].fitted_by == "identify" or label in d.param_stations:
        return d.joint_term.covariance(Q, Jq, E)
    Z = _registration_rows(cm, label)
    if Z is None:
        return d.joint_term.covariance(Q, Jq, E)
    JZ = _joint_jacobian(cm, label, Z)
    out = np.empty((len(Q), 3, 3))
    for a in range(0, len(Q), chunk):
        s = slice(a, a + chunk)
        out[s] = d.joint_term.covariance(Q[s], Jq[s], E[s], (_registration_map(cm, label, Q[s], Z, point), Z, JZ))
    return out


def _white_excess(Cb: np.ndarray, term: Any, E: np.ndarray) -> np.ndarray:
    """(m, 3, 3): what the white level's covariance W (diag(w²) + E C_w Eᵀ,
    :meth:`~pin_kpi_oed.discrepancy.joint_angle.JointAngleTerm.white_covariance`) holds beyond the joint-angle
    errors' Cb (m, 3, 3) per row: the positive part of W − Cb, so that Cb + it is at least both in every direction.
    The white level, corrected for the fitted parameters, is what the rows' residuals show at poses like them, which
    a joint-angle kernel of the wrong shape can under-state near the rows (where its cross term takes back what the
    fit absorbed); far from them the joint-angle errors carry the parameters' extrapolation."""
    W = term.white_covariance(E)
    if W is None:
        return np.zeros_like(Cb)
    lam, U = np.linalg.eigh(0.5 * (W - Cb + np.swapaxes(W - Cb, 1, 2)))
    return np.einsum("mak,mk,mbk->mab", U, np.maximum(lam, 0.0), U)


def _discrepancy_jacobian(cm: Any, d: Any, label: str, Q: np.ndarray, point: Any = None) -> np.ndarray:
    """Base-frame Jacobian of station ``label``'s predictions over the discrepancy's parameter columns: the robot's,
    then 9 per training station, (m, 3, R [+ 9 S]): a training station's own set-up columns filled (its set-up error
    is correlated with the robot's and partly cancels it); a station registered later: the robot's columns
    projected (:func:`_registered`), the set-up columns zero."""
    E = _robot_jacobian(cm, label, Q, list(d.param_names), point)
    own = label in d.param_stations and cm.setups[label].fitted_by == "identify"
    if not own:
        return _registered(cm, label, Q, E, list(d.param_names), point)
    s = d.param_stations.index(label)
    full = np.zeros((len(Q), 3, len(d.param_names) + 9 * len(d.param_stations)))
    full[:, :, :E.shape[2]] = E
    full[:, :, len(d.param_names) + 9 * s: len(d.param_names) + 9 * (s + 1)] = _setup_jacobian(cm, label, Q, point)
    return full


def _fit_parametric(cm: Any, label: str, Q: np.ndarray, point: Any = None) -> np.ndarray:
    """E C_p Eᵀ (m, 3, 3) m², robot base frame, with the fit's own covariance C_p (``parameters.covariance``, times
    :func:`_chi2_factor`) of the robot parameters and the station's set-up (:func:`robot_parameter_covariance`), E
    the Jacobian of station ``label``'s predictions (``point``'s when given) at Q (rad), projected for a station
    registered later (:func:`_registered`); zeros when the model holds no covariance."""
    _, names, Cp = robot_parameter_covariance(cm, label)
    if Cp is None:
        return np.zeros((len(Q), 3, 3))
    E = _robot_jacobian(cm, label, Q, names, point)
    if cm.setups[label].fitted_by != "identify":
        E = _registered(cm, label, Q, E, names, point)
    return row_sandwich(E, Cp * _chi2_factor(cm))


def _orientation_informed(cm: Any, d: Any, point: Any) -> bool:
    """Whether the parametric part at ``point`` takes the fit's covariance instead of the discrepancy's: a point of
    the tool off the fitted reflector, a fit with the probe's orientation rows (a 6-D model with a covariance), a
    discrepancy without a joint-angle term. The discrepancy's covariances are those of the reflector's positions
    alone; a reflector near the flange axis leaves in them the flange's tilt about the reflector nearly free (on the
    UR10's Series C half, 1,386 rows, σ 0.15-0.18 rad along wrist_2.rz, wrist_3.rx with wrist_3.tx, wrist_2.tz),
    which cancels at the reflector but not at a point 16 mm away (3.7 mm) or at the flange (21.6 mm); the
    orientation rows the fit had determine it (held-out on the other half through the measured orientation:
    standardised RMS 1.00 at both points with the fit's covariance, 0.10 with the discrepancy's)."""
    if point is None or point.follows_reflector or not cm.pose6d or d.joint_term is not None:
        return False
    return (cm.parameters or {}).get("covariance") is not None


def _chi2_factor(cm: Any) -> float:
    """max(1, reduced χ²) of the fit when its covariance was not scaled by it already: a noise-only model whose
    residuals exceed the stated noise has a parameter covariance that much too small (the usual rescaling)."""
    fit = cm.fit or {}
    chi2 = fit.get("chi2_reduced")
    if fit.get("covariance_scaled") or chi2 is None or not np.isfinite(chi2):
        return 1.0
    return max(1.0, float(chi2))


def _coverage(cm: Any) -> Any:
    d = cm.discrepancy
    if d is not None and d.coverage is not None:
        return d.coverage
    return getattr(cm, "coverage", None)


def sigma_contents(cm: Any) -> str:
    """What a model's σ holds, in a few words: the parameters' covariance and noise always; a Gaussian-process
    discrepancy only when the model holds one (a white level is not one). Printed by ``predict``; the trust map's
    title (:func:`pin_kpi_oed.viz.trust_map.sigma_contents`). A camera calibration whose images showed joint-angle
    errors (``fit.joint_angle_sigma_rad``) says so: the TCP's σ carries them
    (:mod:`pin_kpi_oed.calibrated.tcp_sigma`)."""
    d = cm.discrepancy
    if d is None and isinstance(cm.fit, dict) and cm.fit.get("joint_angle_sigma_rad") is not None:
        return "parameters + the joint-angle errors the camera's images showed (in the TCP's sigma); no discrepancy"
    if d is None:
        return "parameters + noise; no discrepancy (noise-only model)"
    if d.kind == "white" and d.joint_term is not None:
        return "parameters + joint-angle errors and a white level from the residuals; no Gaussian process"
    if d.kind == "white":
        return "parameters + a white residual level; no correlated discrepancy"
    return f"parameters + Gaussian-process discrepancy ({d.kind}, {d.n_rows} rows) + white level"


@dataclass(frozen=True)
class SigmaPoint:
    """A point of the tool at which the σ is stated instead of the reflector's (:func:`point_covariance`).

    Attributes:
        tcp_m: the point in the tool frame, (3,) m.
        frame: ``cell`` (the station's tracker frame) or ``base`` (the robot base frame: the tracker pose moves
            nothing).
        follows_reflector: the point is the fitted reflector itself (its offset's error moves it).
    """

    tcp_m: tuple[float, float, float]
    frame: str = "cell"
    follows_reflector: bool = False


def _point_model(cm: Any, point: Any) -> Any:
    """A copy of the model whose stations' "reflector" is ``point``'s TCP: its predictions are the TCP's."""
    if point is None:
        return cm
    new = copy.copy(cm)
    new.setups = {lab: dataclasses.replace(st, reflector_m=np.array(point.tcp_m, float), nests_m=None)
                  for lab, st in cm.setups.items()}
    return new


def _base_blocks(cm: Any, Q: np.ndarray, aux: Any, station: str | None, labels: np.ndarray, point: Any = None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(Y (m, 3) m tracker frame, the covariance of measured − predicted without the noise (m, 3, 3) m² in the robot
    base frame, the noise model's variance per tracker axis (m, 3) m² (noise-only models), extrapolation (m,)):
    the module docstring's terms before the rotation, the σ scale and the noise; at ``point``'s TCP when given."""
    m = len(Q)
    cov = _coverage(cm)
    extra = outside_coverage(cov, Q) if cov is not None else np.zeros(m, bool)
    d = cm.discrepancy
    if d is None:
        Y = _point_model(cm, point).predict_rows(Q, aux, station, False, None)
        noise2 = np.asarray(cm.noise.sigma(Y[:, :3]), float).reshape(m, 3) ** 2
        V = np.zeros((m, 3))
    else:
        delta, var = discrepancy_at(d, Q)               # one kernel evaluation for the mean and the variance
        Y = _point_model(cm, point).predict_rows(Q, aux, station, False, delta)
        noise2 = np.zeros((m, 3))
        V = var + d.noise_var_m2
    Cb = np.einsum("na,ab->nab", V, np.eye(3))
    for lab in dict.fromkeys(labels):
        rows = np.flatnonzero(labels == lab)
        if d is None or _orientation_informed(cm, d, point):
            Cb[rows] += _fit_parametric(cm, lab, Q[rows], point)
        elif d.param_cov is not None or d.param_cov_ls is not None:
            E = _discrepancy_jacobian(cm, d, lab, Q[rows], point)
            out = extra[rows]
            if d.kind == "white":
                C = d.parametric_covariance(Q[rows], E)
                if d.joint_term is not None:
                    C = C + Cb[rows] + _joint_angle_covariance(cm, d, lab, Q[rows], E, point=point)
                    Cb[rows] = C + _white_excess(C, d.joint_term, E)
                else:
                    Cb[rows] += C
            else:
                for mask, inside in ((out, False), (~out, True)):
                    if mask.any():
                        Cb[rows[mask]] += d.parametric_covariance(Q[rows][mask], E[mask], inside=inside)
    return Y, Cb, noise2, extra


def predictive_sigma(cm: Any, Q: np.ndarray, aux: Any, station: str | None, labels: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(Y (m, 3) m, σ (m, 3) m tracker frame, extrapolation (m,) bool) of a
    :class:`~pin_kpi_oed.calibrated.model_file.CalibratedModel` at checked configurations Q (module docstring).

    ``labels``: the station of each row (:meth:`CalibratedModel.row_stations`).
    """
    Y, Cb, noise2, extra = _base_blocks(cm, Q, aux, station, labels)
    scale = np.array([cm.setups[lab].sigma_scale for lab in labels], float)[:, None]
    sig = np.empty((len(Q), 3))
    for lab in dict.fromkeys(labels):
        rows = np.flatnonzero(labels == lab)
        R = cm.setups[lab].tracker_T_base[:3, :3]
        sig[rows] = np.sqrt(np.einsum("ia,nab,ib->ni", R, Cb[rows], R) + noise2[rows])
    return Y, scale * sig, extra


def point_covariance(cm: Any, Q: np.ndarray, aux: Any, station: str | None, labels: np.ndarray,
                     point: SigmaPoint) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(Y (m, 3) m, C (m, 3, 3) m², extrapolation (m,) bool): :func:`predictive_sigma`'s terms at a point of the tool
    (``point``: its TCP and frame) as full 3 × 3 covariances: the discrepancy's posterior and white level, the
    parametric part's error through the point's own Jacobian (the fitted reflector offset moves it not; in the base
    frame, neither does the tracker pose), the station's σ factor. The parameters held at nominal are not in it
    (:mod:`pin_kpi_oed.calibrated.tcp_sigma` adds them). The discrepancy is the reflector's, learnt there; its
    rotation part at a TCP away from the reflector is what :mod:`pin_kpi_oed.discrepancy.lever_arm` states.

    Raises:
        InputError: ``point.frame`` neither ``cell`` nor ``base``.
    """
    from pin_kpi_oed.errors import InputError

    if point.frame not in ("cell", "base"):
        raise InputError(f"frame {point.frame!r}: must be 'cell' (the tracker frame) or 'base'")
    Y, Cb, noise2, extra = _base_blocks(cm, Q, aux, station, labels, point)
    C = np.empty_like(Cb)
    for lab in dict.fromkeys(labels):
        rows = np.flatnonzero(labels == lab)
        st = cm.setups[lab]
        R = st.tracker_T_base[:3, :3]
        Ct = np.einsum("ia,nab,jb->nij", R, Cb[rows], R) + np.einsum("na,ab->nab", noise2[rows], np.eye(3))
        if point.frame == "base":
            Ct = np.einsum("ai,nab,bj->nij", R, Ct, R)
            Y[rows] = (Y[rows] - st.tracker_T_base[:3, 3]) @ R
        C[rows] = Ct * st.sigma_scale ** 2
    return Y, C, extra


def orientation_sigma(cm: Any, Q: np.ndarray, aux: Any, station: str | None, labels: np.ndarray,
                      length_m: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(ω (m, 3) rad, σ_ω (m, 3) rad, σ_L (m,) m) of a 6-D
    :class:`~pin_kpi_oed.calibrated.model_file.CalibratedModel` at checked configurations Q (module docstring):
    the predicted probe orientation (rotation vector, tracker frame), the σ per axis of measured − predicted
    orientation, and the 3-D σ of a point ``length_m`` along the tool axis that the orientation error moves.

    Raises:
        InputError: the model (or the rows' station) predicts positions only, or ``length_m`` is negative.
    """
    from pin_kpi_oed.errors import InputError

    if not cm.pose6d:
        raise InputError("the model predicts positions only (identified without orientations): no orientation "
                         "sigma; identify with the rx, ry, rz columns of a 6-DoF probe")
    if not (np.isfinite(length_m) and length_m >= 0):
        raise InputError(f"tool length {length_m!r} m: must be a length >= 0 (m)")
    m = len(Q)
    delta = cm.discrepancy.predict(Q, return_var=False)[0] if cm.discrepancy is not None else None
    W = cm.predict_rows(Q, aux, station, True, delta)[:, 3:6]
    level = (cm.fit or {}).get("residual_sigma_rad")
    w2 = (np.asarray(level, float).reshape(3) if level is not None else np.full(3, cm.noise.sigma_rot_rad)) ** 2
    sig, sig_l = np.empty((m, 3)), np.empty(m)
    for lab in dict.fromkeys(labels):
        rows = np.flatnonzero(labels == lab)
        model, p = _jacobian_model(cm, lab)
        if not model.pose6d:
            raise InputError(f"station '{lab}' was registered without orientations: no orientation sigma there")
        C = np.tile(np.diag(w2), (rows.size, 1, 1))
        _, names, Cp = robot_parameter_covariance(cm, lab, probe=True)
        if Cp is not None:
            cols = [model.layout.names.index(n) for n in names]
            Om = model.jacobian(p, Q[rows])[:, 3:6][:, :, cols]
            C += row_sandwich(Om, Cp * _chi2_factor(cm))
        kin = model.kinematics(p, Q[rows], model.reflector(p))
        z = np.einsum("ab,mb->ma", model.tracker_pose(p).rotation, kin.R_tool[:, :, 2])
        Z = skew(z)
        scale = cm.setups[lab].sigma_scale
        sig[rows] = scale * np.sqrt(np.einsum("maa->ma", C))
        sig_l[rows] = scale * length_m * np.sqrt(np.maximum(np.einsum("mab,mbc,mac->m", Z, C, Z), 0.0))
    return W, sig, sig_l


def predictive_covariance(cm: Any, Q: np.ndarray, aux: Any, label: str) -> tuple[np.ndarray, np.ndarray]:
    """(Y (m, 3) m, C (3m, 3m) m²): the joint covariance of measured − predicted over the rows of one station
    (tracker frame, row-major: index 3 i + a), the σ of :func:`predictive_sigma` with the rows' correlations: the
    discrepancy's posterior covariance between the rows (per axis S_a² k_post(q_i, q_j)), the white level on the
    diagonal, the parametric part's error shared by every row (:meth:`Discrepancy.parametric_factor`; a noise-only
    model: E C_p Eᵀ between rows), the joint-angle errors of a white discrepancy between the rows
    (:meth:`~pin_kpi_oed.discrepancy.joint_angle.JointAngleTerm.covariance_between`; at a station registered later
    without the registration's share) with each row's block raised to the white level's (:func:`_white_excess`),
    all rotated into the tracker frame and multiplied by the station's
    ``sigma_scale``². Its 3 × 3 diagonal blocks hold :func:`predictive_sigma`'s σ² on their diagonals.

    Args:
        cm: the calibrated model; Q: checked configurations (m, n) rad; aux: the rows' auxiliary data or None;
        label: the station of every row.
    """
    m = len(Q)
    st = cm.setups[label]
    R = st.tracker_T_base[:3, :3]
    d = cm.discrepancy
    Cb = np.zeros((m, 3, m, 3))
    if d is None:
        Y = cm.predict_rows(Q, aux, label, False, None)
        _, names, Cp = robot_parameter_covariance(cm, label)
        A = np.zeros((m, 3, 0))
        if Cp is not None:
            E = _robot_jacobian(cm, label, Q, names)
            if st.fitted_by != "identify":
                E = _registered(cm, label, Q, E, names)
            w, U = np.linalg.eigh(0.5 * (Cp + Cp.T) * _chi2_factor(cm))
            A = E @ (U * np.sqrt(np.maximum(w, 0.0)))
        noise2 = np.asarray(cm.noise.sigma(Y[:, :3]), float).reshape(m, 3) ** 2
    else:
        delta, _ = discrepancy_at(d, Q, False)
        Y = cm.predict_rows(Q, aux, label, False, delta)
        K = posterior_covariance_at(d, Q)
        for a in range(3):
            Cb[:, a, :, a] = K * d.scale_m[a] ** 2 + np.eye(m) * d.noise_var_m2[a]
        A = np.zeros((m, 3, 0))
        if d.param_cov is not None or d.param_cov_ls is not None:
            E = _discrepancy_jacobian(cm, d, label, Q)
            cov = _coverage(cm)
            out = outside_coverage(cov, Q) if cov is not None else np.zeros(m, bool)
            A = d.parametric_factor(Q, E, ~out if d.kind != "white" else np.zeros(m, bool))
            if d.kind == "white" and d.joint_term is not None:
                Cb += d.joint_term.covariance_between(Q, _joint_jacobian(cm, label, Q), E)
        noise2 = np.zeros((m, 3))
    Cb += np.einsum("iap,jbp->iajb", A, A)
    if d is not None and d.kind == "white" and d.joint_term is not None and d.param_cov is not None:
        i = np.arange(m)
        Cb[i, :, i, :] += _white_excess(Cb[i, :, i, :], d.joint_term, E)
    Ct = np.einsum("xa,iajb,yb->ixjy", R, Cb, R).reshape(3 * m, 3 * m)
    Ct[np.diag_indices(3 * m)] += noise2.reshape(-1)
    return Y, Ct * st.sigma_scale ** 2


def sigma_at(cm: Any, Q: np.ndarray, aux: Any = None, station: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(3-D σ (m,) m, outside the coverage (m,) bool) of a calibrated model's predictions at configurations Q (rad)
    of a station (default: the model's): ``predict``'s σ (:meth:`CalibratedModel.predict_with_sigma`, widened
    outside the coverage), the one every command that states a σ at configurations reports (``compensate``'s
    targets, ``design --model``'s working configurations)."""
    _, sig, extra = cm.predict_with_sigma(np.atleast_2d(np.asarray(Q, float)), aux, station=cm.station(station))
    return np.sqrt((sig ** 2).sum(axis=1)), np.asarray(extra, bool)


def with_registered_station(cm: Any, label: str, setup: Any, data: Any, Q: np.ndarray, n_unknowns: int,
                            step: dict) -> Any:
    """The model with a station a registration fitted, the default: its σ factor set from the registration rows
    (:func:`station_sigma_factor`, written into ``setup.sigma_scale``), the step in the model's history with the rows'
    standardised RMS and the factor.

    Args:
        cm: the :class:`~pin_kpi_oed.calibrated.model_file.CalibratedModel`; label: the station; setup: its fitted
            :class:`~pin_kpi_oed.calibrated.model_file.Setup`.
        data: the registration rows (x, y, z in m); Q: their configurations (m, n) rad.
        n_unknowns: the set-up's fitted unknowns; step: the history entry of the registration.

    Returns:
        The new model.
    """
    probe = cm.with_setup(label, setup, default=True)
    setup.sigma_scale, z_reg = station_sigma_factor(probe, data, Q, label, n_unknowns)
    return cm.with_setup(label, setup, default=True,
                         step={**step, "standardised_rms": z_reg, "sigma_scale": setup.sigma_scale})


def station_sigma_factor(cm: Any, data: Any, Q: np.ndarray, label: str, n_unknowns: int) -> tuple[float, float | None]:
    """The σ factor of a newly registered station: s = √(Σ z² / (3m − k)) over its m registration rows
    (z = residual / predicted σ per axis, k the set-up's unknowns), kept only when above 1.

    A session unlike the calibrated one (another day, set-up or temperature) shows in the registration rows'
    residuals before any other row is measured; scaling by s keeps the predicted σ honest there. The factor never
    shrinks σ: 60 rows of a session that happen to fit well are no evidence that the rest will.

    Args:
        cm: the model with the station; data: its registration rows (x, y, z in m); Q: their configurations (m, n)
            rad; label: the station; n_unknowns: the set-up's fitted unknowns k.

    Returns:
        (factor ≥ 1, the registration rows' standardised RMS, or None when 3m ≤ k).
    """
    dof = 3 * len(Q) - int(n_unknowns)
    if dof <= 0:
        return 1.0, None
    Y, sig, _ = cm.predict_with_sigma(Q, data, station=label)
    z2 = float(np.sum(((np.asarray(data.position_m, float) - Y[:, :3]) / sig) ** 2))
    if not np.isfinite(z2):
        return 1.0, None
    return max(1.0, float(np.sqrt(z2 / dof))), float(np.sqrt(z2 / (3 * len(Q))))
