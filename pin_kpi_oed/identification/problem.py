r"""The identification problem: stations, their parameter layout, and the weighted residual with its Jacobian.

Several set-ups in one calibration
----------------------------------
A *station* is one placement of the laser tracker (a measurement session, a series): its rows
share one tracker pose ``tracker_T_base,s`` and — if the user says so — one reflector offset.
The robot is the same in every station, so its parameters (joint placements, effects θ) are
shared. With S stations the raw parameter vector of the calibration is

.. math::

    P = \bigl(δ_{\mathrm{robot}} \;(6 n),\;
        [δ_{t,s}\;(6)\; [,\, δ_{r,s}\;(3)\,[,\, ω_{p,s}\;(3)]]]_{s=1..S},\;
        [δ_r\;(3)\,[,\, ω_p\;(3)]]_{\text{shared}}\bigr)

(per-station reflector and probe with ``reflector_per_station``, else shared; ω_p for 6-D probes
only). Names: with one station exactly those of :class:`~pin_kpi_oed.model.parameters.ParameterLayout`
(``joint_a2.tx``, ``tracker.rz``, ``reflector.x``); with several, a station's set-up parameters
carry its label, ``tracker@B.tx``, ``reflector@B.x``. Every station is measured through its own
working :class:`~pin_kpi_oed.model.tracker.TrackerModel` (nominal tracker pose = that
station's registration, the set-up errors small); station s sees the raw vector
``p_s = P[index[s]]`` in its model's layout.

Identifiability with several stations: a direction of the raw parameters is unobservable jointly
iff it is unobservable in every station. The geometric null directions of one station (joint 1's
placement ↔ tracker pose, the last joint ↔ reflector, translations along / rotations about an
axis ↔ the next placement) need only that station's own set-up or robot parameters, so they stay
null jointly: the structural identifiable set is the one-station set (:func:`pin_kpi_oed.oed.
identifiability.analyse`) with every station's set-up kept (:meth:`StationLayout.lift`). What the
*data* of one station leave undetermined (a narrow coverage of joint space) may be determined by
the others; this is checked on the stacked Jacobian of all stations, never per station.

Residual (eqs. 5–6)
-------------------
x = (P_B, θ): the identifiable parameters followed by the effect parameters. Measurement i of
station s:

.. math::

    f_i^{\mathrm{pos}} = Σ_i^{-1}\bigl(h_s(p_s, q_i + ΣΔq_i(θ)) + ΣΔy_i(θ) − η_i\bigr),\qquad
    f_i^{\mathrm{rot}} = \log_3(R_{\mathrm{model},i} R_{\mathrm{meas},i}^\top)/σ_{\mathrm{rot}},

composed by :func:`pin_kpi_oed.effects.library.predict_with_effects` (the one composition of
effects), then one prior row per base parameter with a finite prior σ. Jacobian: station s's
:meth:`TrackerModel.jacobian` columns scattered into P's columns; effects
``R_T [v_k + ω_k × p]_k ∂Δq/∂θ + ∂Δy/∂θ`` (positions) and ``R_T [ω_k]_k ∂Δq/∂θ``
(orientation, times J_l⁻¹(φ) like every orientation row).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any
from collections.abc import Sequence

import numpy as np
from scipy.spatial.transform import Rotation

from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.model.nests import nest_column
from pin_kpi_oed.effects.library import predict_with_effects, sum_joint_offsets, sum_tool_offsets
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.model.kinematics import skew
from pin_kpi_oed.model.measured_joints import align_data
from pin_kpi_oed.model.parameters import STATION_SEP, ParameterLayout
from pin_kpi_oed.oed.identifiability import Identifiability

__all__ = ["StationLayout", "StationSet", "ResidualModel", "align_data", "effect_param_names", "log3", "jl_inv",
           "predict"]



# --------------------------------------------------------------------------- #
# Small SO(3) helpers (batched)
# --------------------------------------------------------------------------- #
def log3(R: np.ndarray) -> np.ndarray:
    """Batched rotation vectors of rotation matrices, (m, 3, 3) -> (m, 3) rad."""
    return Rotation.from_matrix(R).as_rotvec()


def jl_inv(phi: np.ndarray) -> np.ndarray:
    r"""Batched inverse left Jacobian of SO(3), (m, 3) -> (m, 3, 3).

    J_l⁻¹(φ) = I − ½[φ]× + (1/θ² − (1 + cos θ)/(2 θ sin θ)) [φ]×², θ = |φ|
    (= J_r⁻¹(φ)ᵀ; ``pin.Jlog3(R)`` is J_r⁻¹(log R)).
    """
    th = np.linalg.norm(phi, axis=1)
    K = skew(phi)
    small = th < 1e-4
    ths = np.where(small, 1.0, th)
    c = np.where(small, 1.0 / 12.0 + th ** 2 / 720.0,
                 1.0 / ths ** 2 - (1.0 + np.cos(ths)) / (2.0 * ths * np.sin(ths)))
    return np.eye(3) - 0.5 * K + c[:, None, None] * (K @ K)


def predict(model: Any, p: np.ndarray, Q: np.ndarray, effects: Sequence[Any] = (),
            thetas: Sequence[np.ndarray] = (), aux: MeasurementSet | None = None) -> np.ndarray:
    """Model response with effects: ``Y = h(p, Q + ΣΔq) + ΣΔy`` (tracker frame).

    A thin form of :func:`pin_kpi_oed.effects.library.predict_with_effects` (the one composition).

    Args:
        model: the measurement model (a :class:`~pin_kpi_oed.model.tracker.TrackerModel`).
        p: its raw parameter vector (m, rad).
        Q: configurations, (m, nq) rad (m for prismatic joints).
        effects: effect objects; ``thetas`` their parameters, one array per effect.
        aux: auxiliary data the effects read (temperature, time, payload), or None.

    Returns:
        (m, 3) positions (m), or (m, 6) with the orientation rotation vector (rad) for a 6-D model.
    """
    Q = np.atleast_2d(np.asarray(Q, float))
    return predict_with_effects(model, p, Q, aux, list(zip(effects, thetas)))


def effect_param_names(effects: Sequence[Any], robot: Any) -> list[str]:
    """Names of the effect parameters θ, in vector order: ``<effect.name>.<param>``.

    A name the effect already prefixes with its own name is kept as is.

    Raises:
        InputError: two effects give the same parameter name.
    """
    out: list[str] = []
    for e in effects:
        for n in e.param_names(robot):
            out.append(n if str(n).startswith(f"{e.name}.") else f"{e.name}.{n}")
    if len(set(out)) != len(out):
        dup = sorted({n for n in out if out.count(n) > 1})
        raise InputError(f"effect parameter names are not unique: {dup} (give the effects distinct names)")
    return out


# --------------------------------------------------------------------------- #
# Layout of several stations
# --------------------------------------------------------------------------- #
@dataclass
class StationLayout:
    """Raw parameters of a calibration with one or more stations (see the module docstring).

    Attributes:
        station_layout: the raw layout of every station's :class:`TrackerModel`.
        labels: station labels, in order.
        reflector_per_station: each station has its own reflector (and probe) parameters.
        names: global parameter names, in vector order.
        generic: for each global parameter, its index in ``station_layout``.
        owner: station index owning the parameter, −1 for robot and shared parameters.
        index: per station, the global index of each of its model's raw parameters.
        fixed: parameters held at their value; prior_sigma: Gaussian prior σ (inf = none).
    """

    station_layout: ParameterLayout
    labels: list[str]
    reflector_per_station: bool
    names: list[str]
    generic: np.ndarray
    owner: np.ndarray
    index: list[np.ndarray]
    fixed: np.ndarray
    prior_sigma: np.ndarray

    @classmethod
    def build(cls, L: ParameterLayout, labels: Sequence[str], reflector_per_station: bool = False
              ) -> StationLayout:
        """Global layout of ``labels`` stations whose models use layout ``L`` (fixed/prior copied from ``L``)."""
        labels = [str(s) for s in labels]
        S = len(labels)
        nj = 6 * L.n_joints
        own = [L.tracker] + ([L.reflector, L.probe] if reflector_per_station else [])
        shared = [] if reflector_per_station else [L.reflector, L.probe]
        names: list[str] = []
        generic: list[int] = []
        owner: list[int] = []
        index = [np.full(L.n, -1, int) for _ in range(S)]

        def add(k: int, s: int, name: str) -> None:
            for t in (range(S) if s < 0 else [s]):
                index[t][k] = len(names)
            names.append(name)
            generic.append(k)
            owner.append(s)

        for k in range(nj):
            add(k, -1, L.names[k])
        for s, lab in enumerate(labels):
            for sl in own:
                for k in range(sl.start, sl.stop):
                    n = L.names[k]
                    add(k, s, n if S == 1 else n.replace(".", f"{STATION_SEP}{lab}.", 1))
        for sl in shared:
            for k in range(sl.start, sl.stop):
                add(k, -1, L.names[k])
        g = np.array(generic, int)
        return cls(L, labels, bool(reflector_per_station), names, g, np.array(owner, int), index,
                   L.fixed[g].copy(), L.prior_sigma[g].copy())

    @property
    def n(self) -> int:
        """Number of global raw parameters."""
        return len(self.names)

    @property
    def n_stations(self) -> int:
        """Number of stations S."""
        return len(self.labels)

    def is_setup(self) -> np.ndarray:
        """Mask of measurement-set-up parameters (tracker, reflector, probe of any station)."""
        return self.station_layout.is_setup()[self.generic]

    def owned_by(self, s: int) -> np.ndarray:
        """Mask of the parameters station ``s`` owns alone (its tracker pose, its own reflector/probe)."""
        return self.owner == s

    def lift(self, ident: Identifiability) -> Identifiability:
        """The one-station identifiability analysis extended to every station (module docstring).

        Args:
            ident: analysis of one station's model (indices into ``station_layout``).

        Returns:
            The analysis over the global parameters: a parameter is identifiable iff its
            one-station counterpart is; dropped set-up parameters are named per station.
        """
        if self.n_stations == 1 and self.n == self.station_layout.n:
            return ident
        keep = set(np.asarray(ident.base, int).tolist())
        base = np.array([g for g in range(self.n) if int(self.generic[g]) in keep], int)
        by_name = {d["name"]: d for d in ident.dropped}
        dropped = []
        for g, k in enumerate(self.generic):
            d = by_name.get(self.station_layout.names[int(k)])
            if d is not None:
                dropped.append({**d, "name": self.names[g]})
        n_free = int(np.sum(~self.fixed))
        return Identifiability(list(self.names), base, int(base.size), self.n, n_free, dropped,
                               list(ident.notes), None)


class StationSet:
    """The working measurement models of a calibration: one :class:`TrackerModel` per station.

    Every model shares the robot (and the layout ``layout.station_layout``); its nominal
    tracker pose (and reflector, probe orientation) is that station's start or fitted set-up.

    Attributes:
        models: one model per station, in the order of ``layout.labels``.
        layout: the global :class:`StationLayout`.
    """

    def __init__(self, models: Sequence[TrackerModel], layout: StationLayout):
        if len(models) != layout.n_stations:
            raise InputError(f"{len(models)} station models for {layout.n_stations} station labels")
        self.models = list(models)
        self.layout = layout

    @classmethod
    def single(cls, model: TrackerModel, label: str = "") -> StationSet:
        """One station measured through ``model`` (global layout = the model's layout)."""
        return cls([model], StationLayout.build(model.layout, [label]))

    @property
    def labels(self) -> list[str]:
        """Station labels."""
        return self.layout.labels

    @property
    def robot(self) -> Any:
        """The robot shared by every station."""
        return self.models[0].robot

    @property
    def pose6d(self) -> bool:
        """Whether the measurements include the probe orientation."""
        return bool(self.models[0].pose6d)

    @property
    def nh(self) -> int:
        """Rows per measurement (3 or 6)."""
        return self.models[0].nh

    def station_p(self, P: np.ndarray, s: int) -> np.ndarray:
        """Raw parameter vector of station ``s``'s model from the global vector ``P``."""
        return np.asarray(P, float)[self.layout.index[s]]


# --------------------------------------------------------------------------- #
# Residual model
# --------------------------------------------------------------------------- #
class ResidualModel:
    r"""Weighted residual f(x) and its analytic Jacobian for :func:`scipy.optimize.least_squares`.

    x = (P_B, θ): the identifiable global raw parameters ``base`` followed by the parameters of
    the estimated effects. Rows: per measurement the position rows (and the orientation rows of
    a 6-D model), then one prior row per base parameter with a finite prior σ.

    Attributes:
        stations: the :class:`StationSet` (a single :class:`TrackerModel` is wrapped as one station).
        rows: per station, the indices of its measurements.
        Q: configurations in the robot's joint order, (m, n) rad.
        Y: measured positions (tracker frames), (m, 3) m.
        R_meas: measured orientations (m, 3, 3), or None.
        sigma: position σ per row, (m, 3) m; ``sigma_rot`` orientation σ (rad).
        base: indices of the estimated global raw parameters.
        p_ref: global raw parameter vector supplying the values of the others.
        effects: estimated effect objects; ``k`` their total number of parameters.
        held: ``[(effect, θ), ...]`` effects applied with fixed parameters (not estimated).
        theta0: start values of the estimated θ (concatenated; default zeros).
        names: names of x.
        prior_idx, prior_sigma: the unknowns with a Gaussian prior x_i ~ N(0, σ_i²) and their σ: the
            base parameters with a finite layout prior, then the effect parameters given a finite
            ``effect_prior_sigma`` (one row x_i / σ_i each, after the measurement rows).
        mask: measurement rows in use (outliers may be removed).
    """

    def __init__(self, stations: StationSet | TrackerModel, data: MeasurementSet, base: np.ndarray,
                 effects: Sequence[Any] = (), sigma: np.ndarray | None = None, p_ref: np.ndarray | None = None,
                 Q: np.ndarray | None = None, held: Sequence[tuple[Any, np.ndarray]] = (),
                 effect_prior_sigma: np.ndarray | float | None = None,
                 theta0: Sequence[np.ndarray] | None = None):
        if isinstance(stations, TrackerModel):
            stations = StationSet.single(stations)
        self.stations = stations
        self.layout = stations.layout
        model = stations.models[0]
        self.data = data
        self.Q = align_data(model.robot, data) if Q is None else np.asarray(Q, float)
        self.Y = np.asarray(data.position_m, float)
        self.m = self.Q.shape[0]
        self.nh = stations.nh
        if stations.pose6d and data.rotvec_rad is None:
            raise InputError(f"{data.source or 'data'}: a 6-D model needs rx, ry, rz columns")
        self.R_meas = Rotation.from_rotvec(data.rotvec_rad).as_matrix() if stations.pose6d else None
        self.rows = self._station_rows(data)
        whole = len(self.rows) == 1  # one station: every row, no copies
        self.aux = [data if whole else data.subset(r) for r in self.rows]
        self._take = [slice(None) if whole else r for r in self.rows]
        self._Qs = [self.Q[t] for t in self._take]
        nest = nest_column(data, model.n_nests)
        # each station's model measuring its rows at their nests (the same layout: the same parameters)
        self._models = [m_s if nest is None else m_s.at_nests(nest[t])
                        for m_s, t in zip(stations.models, self._take)]
        self.sigma = model.noise.sigma(self.Y) if sigma is None else np.broadcast_to(sigma, (self.m, 3)).copy()
        self.sigma_rot = float(model.noise.sigma_rot_rad)
        self.base = np.asarray(base, int)
        self.nb = self.base.size
        self.p_ref = np.zeros(self.layout.n) if p_ref is None else np.asarray(p_ref, float).copy()
        if self.p_ref.shape != (self.layout.n,):
            raise InputError(f"p_ref must have {self.layout.n} entries, got shape {self.p_ref.shape}")
        self.effects = list(effects)
        self.held = [(e, np.asarray(t, float)) for e, t in held]
        self.sizes = [len(e.param_names(model.robot)) for e in self.effects]
        self.k = int(sum(self.sizes))
        self.names = [self.layout.names[i] for i in self.base] + effect_param_names(self.effects, model.robot)
        ps = self.layout.prior_sigma[self.base]
        pe = np.full(self.k, np.inf)
        if effect_prior_sigma is not None:
            pe = np.broadcast_to(np.asarray(effect_prior_sigma, float), (self.k,)).copy()
            if np.any(~(pe > 0)):
                raise InputError(f"effect prior σ must be positive (inf = none), got {effect_prior_sigma}")
        allp = np.concatenate([ps, pe])
        self.prior_idx = np.flatnonzero(np.isfinite(allp))
        self.prior_sigma = allp[self.prior_idx]
        self.theta0 = np.zeros(self.k)
        if theta0 is not None:
            t0 = np.concatenate([np.asarray(t, float).ravel() for t in theta0]) if len(theta0) else np.zeros(0)
            if t0.shape != (self.k,):
                raise InputError(f"theta0: {t0.size} start values for {self.k} effect parameters")
            self.theta0 = t0
        self.W = np.hstack([1.0 / self.sigma] + ([np.full((self.m, 3), 1.0 / self.sigma_rot)] if self.nh == 6 else []))
        self.mask = np.ones(self.m, bool)
        # column map of each station: its model's raw parameter k -> column of x (or −1)
        pos = np.full(self.layout.n, -1, int)
        pos[self.base] = np.arange(self.nb)
        self.x_columns = [pos[idx] for idx in self.layout.index]
        self._check_effect_shapes()

    def _station_rows(self, data: MeasurementSet) -> list[np.ndarray]:
        labels = self.layout.labels
        if len(labels) == 1:
            return [np.arange(self.m)]
        if data.station is None:
            raise InputError(f"{data.source or 'data'}: {len(labels)} stations ({', '.join(labels)}) but the data "
                             "have no 'station' column")
        unknown = sorted(set(data.station.tolist()) - set(labels))
        if unknown:
            raise InputError(f"{data.source or 'data'}: column 'station': unknown station(s) {', '.join(unknown)} "
                             f"(stations: {', '.join(labels)})")
        return [np.flatnonzero(data.station == lab) for lab in labels]

    def _check_effect_shapes(self) -> None:
        if not (self.effects or self.held):
            return
        m, n = self.Q.shape
        for e, th in self.held + list(zip(self.effects, [np.zeros(k) for k in self.sizes])):
            k = np.asarray(th).size
            Qs = self._Qs[0]
            a, da = e.joint_offset(th, Qs, self.aux[0])
            b, db = e.tool_offset(th, Qs, self.aux[0], self.stations.models[0],
                                  self.stations.station_p(self.p_ref, 0))
            mr = Qs.shape[0]
            if np.shape(a) != (mr, n) or np.shape(da) != (mr, n, k):
                raise InputError(f"effect '{e.name}': joint_offset returned shapes {np.shape(a)}, {np.shape(da)}, "
                                 f"expected {(mr, n)}, {(mr, n, k)}")
            if np.shape(b) != (mr, 3) or np.shape(db) != (mr, 3, k):
                raise InputError(f"effect '{e.name}': tool_offset returned shapes {np.shape(b)}, {np.shape(db)}, "
                                 f"expected {(mr, 3)}, {(mr, 3, k)}")

    # ------------------------------------------------------------------ unknowns
    @property
    def nx(self) -> int:
        """Number of unknowns."""
        return self.nb + self.k

    @property
    def n_rows(self) -> int:
        """Number of residual rows (measurements in use and priors)."""
        return int(self.mask.sum()) * self.nh + self.prior_idx.size

    def unpack(self, x: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
        """Global raw parameter vector and per-effect θ from x."""
        x = np.asarray(x, float)
        P = self.p_ref.copy()
        P[self.base] = x[:self.nb]
        th, k0 = [], self.nb
        for k in self.sizes:
            th.append(x[k0:k0 + k].copy())
            k0 += k
        return P, th

    def x0(self) -> np.ndarray:
        """Start: the reference values of the base parameters and θ = ``theta0`` (default 0)."""
        return np.concatenate([self.p_ref[self.base], self.theta0])

    def _pairs(self, th: list[np.ndarray]) -> list[tuple[Any, np.ndarray]]:
        return self.held + list(zip(self.effects, th))

    # ------------------------------------------------------------------ residuals
    def evaluate(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """Unweighted residuals model − measured: positions (m, 3) m and orientations (m, 3) rad or None."""
        P, th = self.unpack(x)
        pairs = self._pairs(th)
        rpos = np.empty((self.m, 3))
        rrot = np.empty((self.m, 3)) if self.nh == 6 else None
        for s, rows in enumerate(self._take):
            model, p = self._models[s], self.stations.station_p(P, s)
            Qs = self._Qs[s]
            Y = predict_with_effects(model, p, Qs, self.aux[s], pairs) if pairs else model.predict(p, Qs)
            rpos[rows] = Y[:, :3] - self.Y[rows]
            if rrot is not None:
                R_model = Rotation.from_rotvec(Y[:, 3:]).as_matrix()
                rrot[rows] = log3(R_model @ np.swapaxes(self.R_meas[rows], 1, 2))
        if rrot is not None:  # the Jacobian at the same x reads them (a least-squares step asks for both)
            self._last_rrot = (np.asarray(x, float).tobytes(), rrot.copy())
        return rpos, rrot

    def _rotation_residuals(self, x: np.ndarray) -> np.ndarray:
        """The orientation residuals of :meth:`evaluate` at x, (m, 3) rad: those of the last evaluation when it was
        at the same x (the same numbers), else evaluated."""
        last = getattr(self, "_last_rrot", None)
        if last is not None and last[0] == np.asarray(x, float).tobytes():
            return last[1]
        rrot = self.evaluate(x)[1]
        assert rrot is not None
        return rrot

    def residual(self, x: np.ndarray) -> np.ndarray:
        """Weighted residual vector f(x) (rows: measurements in use, then priors)."""
        f = self.weighted_rows(x)[self.mask].ravel()
        if self.prior_idx.size:
            f = np.concatenate([f, np.asarray(x)[self.prior_idx] / self.prior_sigma])
        return f

    def weighted_rows(self, x: np.ndarray) -> np.ndarray:
        """Weighted residuals of every measurement, (m, nh) (ignores the mask and priors)."""
        rpos, rrot = self.evaluate(x)
        r = rpos if rrot is None else np.hstack([rpos, rrot])
        return r * self.W

    # ------------------------------------------------------------------ Jacobian
    def _effect_columns(self, model: TrackerModel, p: np.ndarray, s: int, Qe: np.ndarray, dq_ders: list,
                        dy_ders: list) -> np.ndarray:
        """(ms, nh, k): ∂(model response)/∂θ of the estimated effects at station s."""
        ms, n = Qe.shape
        nh_ = self.nh
        if not self.k:
            return np.zeros((ms, nh_, self.k))
        dQt = np.concatenate([np.asarray(d, float).reshape(ms, n, -1) for d in dq_ders], axis=2)
        dYt = np.concatenate([np.asarray(d, float).reshape(ms, 3, -1) for d in dy_ders], axis=2)
        RT = model.tracker_pose(p).rotation
        kin = model.kinematics(p, Qe, model.points(p))
        v, w = kin.twist[:, :3, :], kin.twist[:, 3:, :]
        pdot = v + np.cross(w, kin.p[:, :, None], axis=1)  # ṗ = v + ω × p (np.cross: its result's layout kept)
        pos = np.einsum("ab,mbn->man", RT, pdot) @ dQt
        pos += dYt  # in place: no third array of the rows' size (thousands of rows, hundreds of terms)
        if nh_ == 3:
            return pos
        out = np.empty((ms, nh_, self.k))
        out[:, :3] = pos
        out[:, 3:] = np.einsum("ab,mbn->man", RT, w) @ dQt
        return out

    def _device_jacobian(self, s: int, model: TrackerModel, p: np.ndarray, Qe: np.ndarray) -> np.ndarray:
        """Station s's device Jacobian dh/dp at (p, Qe), (ms, nh, np), read-only: the last one of the station again
        when p and Qe are the same (the fit's last step, its covariance and the held parameters' absorption ask for
        it at the same solution)."""
        key = (p.tobytes(), Qe.shape, Qe.tobytes())
        cache = self.__dict__.setdefault("_last_jh", {})
        last = cache.get(s)
        if last is not None and last[0] == key:
            return last[1]
        Jh = model.jacobian(p, Qe)
        Jh.flags.writeable = False
        cache[s] = (key, Jh)
        return Jh

    def jacobian_full(self, x: np.ndarray) -> np.ndarray:
        """Weighted Jacobian of every measurement, (m, nh, nx)."""
        P, th = self.unpack(x)
        pairs = self._pairs(th)
        nh_ = self.nh
        J = np.zeros((self.m, nh_, self.nx))
        n_held = len(self.held)
        for s, rows in enumerate(self._take):
            model, p = self._models[s], self.stations.station_p(P, s)
            Qs = self._Qs[s]
            if pairs:
                dQ, dq_ders = sum_joint_offsets(pairs, Qs, self.aux[s])
                Qe = Qs + dQ
            else:
                dq_ders, Qe = [], Qs
            Jh = self._device_jacobian(s, model, p, Qe)
            cols = self.x_columns[s]
            use = cols >= 0
            Js = J if isinstance(rows, slice) else np.zeros((Qs.shape[0], nh_, self.nx))
            Js[:, :, cols[use]] = Jh[:, :, use]
            if self.k:
                _, dy_ders = sum_tool_offsets(pairs, Qs, self.aux[s], model, p)
                Js[:, :, self.nb:] = self._effect_columns(model, p, s, Qe, dq_ders[n_held:], dy_ders[n_held:])
            if Js is not J:
                J[rows] = Js
        if nh_ == 6:
            J[:, 3:, :] = jl_inv(self._rotation_residuals(x)) @ J[:, 3:, :]
        J *= self.W[:, :, None]  # in place: the same products, no second array of the Jacobian's size
        return J

    def held_jacobian(self, x: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Weighted Jacobian of every measurement w.r.t. joint-placement parameters the fit holds (raw indices
        ``cols`` < 6 n), (m, nh, k): the rows of :meth:`jacobian_full` for parameters that are not unknowns."""
        P, th = self.unpack(x)
        pairs = self._pairs(th)
        cols = np.asarray(cols, int)
        J = np.zeros((self.m, self.nh, cols.size))
        for s, rows in enumerate(self._take):
            model, p = self._models[s], self.stations.station_p(P, s)
            Qs = self._Qs[s]
            Qe = Qs + sum_joint_offsets(pairs, Qs, self.aux[s])[0] if pairs else Qs
            J[rows] = self._device_jacobian(s, model, p, Qe)[:, :, cols]
        if self.nh == 6:
            J[:, 3:, :] = jl_inv(self._rotation_residuals(x)) @ J[:, 3:, :]
        return J * self.W[:, :, None]

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        """∂f/∂x, (rows, nx)."""
        Jf = self.jacobian_full(x)
        # every row in use (no outlier taken out): the rows as they are, without copying them
        J = Jf.reshape(-1, self.nx) if self.mask.all() else Jf[self.mask].reshape(-1, self.nx)
        if self.prior_idx.size:
            Pm = np.zeros((self.prior_idx.size, self.nx))
            Pm[np.arange(self.prior_idx.size), self.prior_idx] = 1.0 / self.prior_sigma
            J = np.vstack([J, Pm])
        return J
