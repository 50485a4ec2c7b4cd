r"""The σ at the tool point: the one number every command states for the TCP of a calibrated model.

A calibration measures a reflector; the user asks about the TCP, another point of the tool. At configurations q the
covariance of the TCP's error (true − predicted, in the station's tracker frame or the robot base frame) is

.. math::  C_{\mathrm{TCP}}(q) = C_{\mathrm{model}}(q) + G(q)\,Σ_N\,G(q)^\top

* C_model: what ``predict`` states at the reflector, evaluated at the TCP
  (:func:`~pin_kpi_oed.calibrated.prediction_sigma.point_covariance`): the discrepancy's posterior and white level,
  the parametric part's error through the TCP's own Jacobian (the fitted reflector offset does not move the TCP; in
  the base frame the tracker pose does not either; off the reflector of a 6-D fit with the fit's covariance, which
  its orientation rows determine, not the discrepancy's of the positions alone), the station's σ factor;
* G Σ_N Gᵀ: the joint-placement parameters no reflector measurement determines, held at nominal under their
  tolerance prior Σ_N, absorbed by the fit as A = M⁻¹F_BᵀF_N (stored by ``identify`` in the model file,
  ``geometry.parameters.held``; :class:`~pin_kpi_oed.oed.held.HeldTerm`), G = E_B A − E_N at the TCP. Zero at the
  fitted reflector in the tracker frame; in the base frame joint 1's placement, held for the tracker pose, counts.
  A model file written before the absorption was stored gets the structural one
  (:func:`~pin_kpi_oed.oed.covariance.held_absorption` on seeded configurations: the same for an exact dependency).
* a camera calibration whose images showed joint-angle errors the geometry lacks (the model file's
  ``fit.joint_angle_sigma_rad``, s per joint, written by ``identify`` when a K-fold check on the images kept it:
  :mod:`~pin_kpi_oed.identification.camera_joint_noise`) adds J_q(q) diag(s²) J_q(q)ᵀ, J_q the TCP's joint
  Jacobian (:func:`joint_angle_covariance`); its parameters' covariance is then already the one under that error.

:func:`tcp_sigma` computes it; ``identify`` (its printed "predicted TCP std"), ``predict --at tcp``
(``CalibratedModel.predict_tcp``), ``compensate``, ``check``, ``monitor`` and ``report`` all call it, so the same
model and configurations give the same σ everywhere.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pin_kpi_oed.calibrated.prediction_sigma import SigmaPoint, point_covariance
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.parameters import STATION_SEP
from pin_kpi_oed.model.tolerances import Tolerances, held_columns
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.oed.covariance import held_absorption
from pin_kpi_oed.oed.held import HeldTerm, held_advice

__all__ = ["TcpSigma", "tcp_sigma", "held_map", "joint_angle_covariance"]


@dataclass
class TcpSigma:
    """The TCP's predicted position and the covariance of its error at configurations (SI units).

    Attributes:
        tcp_m: the point in the tool frame, (3,) m.
        frame: ``cell`` (the station's tracker frame) or ``base`` (the robot base frame).
        station: the station whose set-up is used.
        position_m: the calibrated model's TCP, (m, 3) m, in ``frame``.
        covariance_m2: the TCP error's covariance, model and held parameters, (m, 3, 3) m².
        held_m2: the held parameters' part of it, (m, 3, 3) m².
        extrapolation: rows outside the training's joint-space coverage, (m,).
        held_names: the held parameters; held_contrib_m: each one's RMS 3-D σ at the TCP over the rows, (k,) m.
    """

    tcp_m: np.ndarray
    frame: str
    station: str
    position_m: np.ndarray
    covariance_m2: np.ndarray
    held_m2: np.ndarray
    extrapolation: np.ndarray
    held_names: list[str] = field(default_factory=list)
    held_contrib_m: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def sigma_m(self) -> np.ndarray:
        """The 3-D σ per row, sqrt(tr C), (m,) m."""
        return np.sqrt(np.maximum(np.einsum("maa->m", self.covariance_m2), 0.0))

    @property
    def held_sigma_m(self) -> np.ndarray:
        """The held parameters' 3-D σ per row, (m,) m."""
        return np.sqrt(np.maximum(np.einsum("maa->m", self.held_m2), 0.0))

    @property
    def rms_m(self) -> float:
        """sqrt(mean tr C) over the rows (m): the TCP's σ over the configurations, one number."""
        return float(np.sqrt(np.mean(self.sigma_m ** 2))) if len(self.sigma_m) else 0.0

    @property
    def held_share(self) -> float:
        """Share of Σ tr C the held parameters make (0..1)."""
        tot = float(np.einsum("maa->", self.covariance_m2))
        return float(np.einsum("maa->", self.held_m2)) / tot if tot > 0 else 0.0

    def advice(self) -> str:
        """Which part of the TCP's σ no reflector measurement removes and what does (:func:`held_advice`), or ""."""
        if not self.held_names:
            return ""
        return held_advice(self.held_names, self.held_contrib_m, self.rms_m)


def tcp_sigma(cm: Any, Q: np.ndarray, tcp_m: np.ndarray | None = None, *, station: str | None = None,
              aux: Any = None, frame: str = "cell", tolerances: Tolerances | None = None, seed: int = 0,
              n_fit: int = 60) -> TcpSigma:
    """The TCP's position and the covariance of its error at configurations Q (module docstring).

    Args:
        cm: the :class:`~pin_kpi_oed.calibrated.model_file.CalibratedModel`.
        Q: configurations (m, n) rad / m.
        tcp_m: the point in the tool frame (m); default the model's ``tcp_m``.
        station: the station whose set-up is used (default the model's).
        aux: the rows' auxiliary data (temperature, payload, time) for the effects, or None.
        frame: ``cell`` (the station's tracker frame) or ``base`` (the robot base frame).
        tolerances: the held parameters' prior (default: the one the fit stored, else
            :class:`~pin_kpi_oed.model.tolerances.Tolerances`).
        seed, n_fit: the seeded configurations a model file without a stored absorption has it solved on.

    Returns:
        The :class:`TcpSigma`.

    Raises:
        InputError: configurations outside the limits or of the wrong shape, an unknown station or frame.
    """
    Q = cm.robot.check_q(np.atleast_2d(np.asarray(Q, float)), "Q (configurations at the TCP)")
    label = cm.station(station)
    tcp = np.asarray(cm.tcp_m if tcp_m is None else tcp_m, float).reshape(3)
    follows = np.allclose(tcp, cm.setups[label].reflector_m, rtol=0.0, atol=1e-12)
    point = SigmaPoint((float(tcp[0]), float(tcp[1]), float(tcp[2])), frame, follows)
    Y, C, extra = point_covariance(cm, Q, aux, label, np.array([label] * len(Q), dtype=object), point)
    Cj = joint_angle_covariance(cm, label, tcp, Q, frame)
    if Cj is not None:
        C = C + Cj
    G, term = held_map(cm, label, tcp, Q, seed, n_fit, tolerances, frame)
    if term is None:
        return TcpSigma(tcp, frame, label, Y, C, np.zeros_like(C), extra)
    Ch = term.covariance(G)
    return TcpSigma(tcp, frame, label, Y, C + Ch, Ch, extra, list(term.names), term.contributions(G))


def joint_angle_covariance(cm: Any, station: str | None, tcp_m: np.ndarray, Q: np.ndarray,
                           frame: str = "cell") -> np.ndarray | None:
    """J_q diag(s²) J_qᵀ (m, 3, 3) m² of the point ``tcp_m`` (tool frame, m) at configurations Q (rad): the joint-angle
    errors s (rad per joint) a camera calibration's images showed (``fit.joint_angle_sigma_rad``), in the station's
    frame (``cell``) or the base frame (``base``); None when the model has none.

    Raises:
        InputError: ``fit.joint_angle_sigma_rad`` is not one finite number >= 0 per joint.
    """
    s = (cm.fit or {}).get("joint_angle_sigma_rad") if isinstance(cm.fit, dict) else None
    if s is None:
        return None
    try:
        s = np.asarray(s, float).reshape(-1)
    except (TypeError, ValueError):
        s = np.array([np.nan])
    if s.size != cm.robot.nq or not np.all(np.isfinite(s)) or np.any(s < 0):
        raise InputError(f"model file: field fit.joint_angle_sigma_rad must be {cm.robot.nq} finite numbers >= 0 "
                         f"(rad, one per joint), got {(cm.fit or {}).get('joint_angle_sigma_rad')!r}")
    model_r, p = cm.station_model(station)
    model_c = TrackerModel(cm.robot, tracker_T_base=model_r.tracker_T_base, reflector_m=np.asarray(tcp_m, float),
                           noise=cm.noise, layout=model_r.layout)
    J = model_c.prediction_dq(p, np.atleast_2d(np.asarray(Q, float)))  # the station's frame
    if frame == "base":
        J = np.einsum("ba,mbn->man", model_r.tracker_pose(p).rotation, J)
    return np.einsum("maj,j,mbj->mab", J, s ** 2, J)


def held_map(cm: Any, station: str | None, tcp_m: np.ndarray, Q: np.ndarray, seed: int = 0, n_fit: int = 60,
             tolerances: Tolerances | None = None, frame: str = "cell") -> tuple[np.ndarray, HeldTerm | None]:
    """(G (m, 3, k) in m per parameter unit, the :class:`HeldTerm`): the displacement of the point ``tcp_m`` (tool
    frame) per unit of each held joint-placement parameter at configurations Q (module docstring). An empty G and
    None at the fitted reflector in the tracker frame, or when the model does not list its identified parameters.

    Args:
        cm: the calibrated model; station: its station (None: the default); tcp_m: the point (m); Q: (m, n) rad;
        seed, n_fit: the configurations of a structural absorption (model files without a stored one);
        tolerances: the held parameters' prior (default the stored one); frame: ``cell`` or ``base``.
    """
    Q = np.atleast_2d(np.asarray(Q, float))
    names = list((cm.parameters or {}).get("names") or [])
    model_r, p = cm.station_model(station)
    c = np.asarray(tcp_m, float).reshape(3)
    L = model_r.layout
    model_c = TrackerModel(cm.robot, tracker_T_base=model_r.tracker_T_base, reflector_m=c, noise=cm.noise, layout=L)
    term = _stored_term(cm, names) if names else None
    if term is None and names:
        term = _structural_term(cm, model_r, p, names, seed, n_fit)
    at_reflector = frame != "base" and np.allclose(c, model_r.reflector_m, rtol=0.0, atol=1e-12)
    if term is None or not term.k or at_reflector:
        return np.zeros((len(Q), 3, 0)), None
    if tolerances is not None:
        term = term.with_sigma(tolerances.sigma_vector(model_c)[[L.names.index(n) for n in term.names]])
    Jc = model_c.jacobian(p, Q)[:, :3, :]
    Jc[:, :, L.reflector] = 0.0  # the point does not follow the fitted reflector offset
    if frame == "base":  # the tracker pose does not move a point in the base frame
        Jc = np.einsum("ba,mbp->map", model_r.tracker_pose(p).rotation, Jc)
        Jc[:, :, L.tracker] = 0.0
    E_B = np.zeros((len(Q), 3, len(term.rows)))
    own = _own_label(term.rows, cm.station(station))
    for i, n in enumerate(term.rows):
        k = _station_column(L, n, own)
        if k is not None:
            E_B[:, :, i] = Jc[:, :, k]
    E_N = Jc[:, :, [L.names.index(n) for n in term.names]]
    return term.gain(E_B, E_N), term


def _own_label(rows: list[str], label: str) -> str | None:
    """The fitted station whose set-up rows stand for station ``label``'s: itself when the fit had it, else the
    first fitted one (a station registered later re-fits its own set-up, which absorbs the held parameters as the
    fitted one did); None for a one-station fit (unprefixed names)."""
    labels = [n.partition(STATION_SEP)[2].split(".", 1)[0] for n in rows if STATION_SEP in n]
    return None if not labels else (label if label in labels else labels[0])


def _station_column(L: Any, name: str, own: str | None) -> int | None:
    """The station layout's column of a fit parameter name: a robot parameter, or a set-up parameter (a
    several-station fit's ``tracker@own.tx`` read as ``tracker.tx``; another station's: None); None for effect
    parameters."""
    g = name
    if STATION_SEP in name:
        head, _, rest = name.partition(STATION_SEP)
        lab, _, comp = rest.partition(".")
        if lab != own:
            return None
        g = f"{head}.{comp}"
    return L.names.index(g) if g in L.names else None


def _stored_term(cm: Any, names: list[str]) -> HeldTerm | None:
    """The model file's stored absorption (``geometry.parameters.held``), or None."""
    d = (cm.parameters or {}).get("held")
    if not d:
        return None
    return d if isinstance(d, HeldTerm) else HeldTerm.from_dict(d, names)


def _structural_term(cm: Any, model_r: TrackerModel, p: np.ndarray, names: list[str], seed: int,
                     n_fit: int) -> HeldTerm | None:
    """The absorption of a model file without a stored one: :func:`held_absorption` on ``n_fit`` seeded
    configurations over the identified robot parameters and the station's set-up (exact for a structural
    dependency), the default tolerances."""
    L = model_r.layout
    ident = [n for n in names if n in L.names[:6 * cm.robot.nq]]
    held = held_columns(model_r, ident)
    if not held.size:
        return None
    b = [L.names.index(n) for n in ident] + list(range(L.tracker.start, L.tracker.stop)) + list(
        range(L.reflector.start, L.reflector.stop))
    Qfit = cm.robot.random_q(np.random.default_rng(seed), n_fit)
    F = model_r.jacobian(p, Qfit)[:, :3, :].reshape(-1, L.n)
    A = held_absorption(F[:, b], F[:, held])
    return HeldTerm([L.names[i] for i in held], Tolerances().sigma_vector(model_r)[held], [L.names[i] for i in b], A)
