r"""Parameter identification from measured data (paper eqs. 5–6), with effects and validation.

Identification removes the systematic error TCP(p, q) − TCP(p_true, q) ≠ 0 (eq. 2) as far as the
model can represent it; :func:`validate` measures what remains on held-out data.

Problem
-------
Given m measurements (q_i, η_i) of a :class:`~pin_kpi_oed.data.measurements.MeasurementSet`, find the
identifiable parameters x = (p_B, θ) minimising the weighted least-squares cost (eqs. 5–6)

.. math::

    \min_x \; \tfrac12 \sum_i \rho\bigl(\lVert f_i(x) \rVert^2\bigr)
      + \tfrac12 \sum_{k \in B} (p_k / \sigma^{\mathrm{prior}}_k)^2,

with the weighted residual of measurement i (position rows, then orientation rows for a 6-D probe)

.. math::

    f_i^{\mathrm{pos}} = \Sigma_i^{-1}\bigl(h(p, q_i + \Delta q_i(θ)) + \Delta y_i(θ) - η_i\bigr)
    \quad [\text{m}/\text{m}],\qquad
    f_i^{\mathrm{rot}} = \log_3\bigl(R_{\mathrm{model},i}\, R_{\mathrm{meas},i}^\top\bigr) / σ_{\mathrm{rot}}

(the result reports the opposite sign, measured − model, i.e. ``log3(R_meas R_modelᵀ)``).
``ρ`` is the identity (plain least squares, Levenberg–Marquardt, MINPACK via
:func:`scipy.optimize.least_squares` ``method='lm'``) or a robust loss (``soft_l1``,
``huber``, ``cauchy``; trust-region reflective), which bounds the pull of outliers.

* p_B: the identifiable raw parameters of :func:`pin_kpi_oed.oed.identifiability.analyse`
  (its convention: tracker, reflector and probe parameters are kept, the robot parameters
  confounded with them held nominal); the others stay at their given value.
* θ: parameters of optional *effects* (``docs/ARCHITECTURE.md``, "Effect interface"):
  joint-angle errors Δq(θ, Q, aux) and additive tracker-frame offsets Δy(θ, Q, aux).

Jacobian (analytic, exact at any x): with J_h = ∂h/∂p from
:meth:`~pin_kpi_oed.model.tracker.TrackerModel.jacobian` (right Jacobians of exp6 included),
(v_k, ω_k) the world twist of joint k and p the reflector in the base frame,

.. math::

    \frac{∂f^{\mathrm{pos}}}{∂p_B} = Σ^{-1} J_h^{\mathrm{pos}},\qquad
    \frac{∂f^{\mathrm{pos}}}{∂θ} = Σ^{-1}\bigl(R_T\,[v_k + ω_k × p]_k\, \tfrac{∂Δq}{∂θ}
        + \tfrac{∂Δy}{∂θ}\bigr),

    \frac{∂f^{\mathrm{rot}}}{∂(p_B, θ)} = σ_{\mathrm{rot}}^{-1}\, J_l^{-1}(φ)\,
        \bigl[J_h^{\mathrm{rot}},\; R_T [ω_k]_k \tfrac{∂Δq}{∂θ}\bigr],

where φ = log3(R_model R_measᵀ), J_l⁻¹ the inverse left Jacobian of SO(3) and
J_h^rot the spatial angular Jacobian of the model orientation. The p-dependence of an
effect's Δy (its ``model, p`` arguments) is neglected in the Jacobian (not in f).

Start
-----
The tracker pose is unknown in practice (the tracker stands anywhere). Before the
iterations it is guessed in closed form by point-set registration (Kabsch/Umeyama,
no scale) of the nominal forward kinematics x_i (base frame) onto the measured points
y_i (tracker frame)::

    H = Σ_i (x_i − x̄)(y_i − ȳ)ᵀ = U S Vᵀ,   R = V diag(1, 1, det(V Uᵀ)) Uᵀ,   t = ȳ − R x̄

and, for a 6-D probe, the probe orientation by the chordal mean
``R_probe = proj_SO3(Σ_i (R_T R_tool,i)ᵀ R_meas,i)``. The identification then runs on a
working :class:`~pin_kpi_oed.model.tracker.TrackerModel` whose nominal tracker pose is this
guess, so the tracker parameters stay small. ``IdentificationResult.model`` and ``.p`` are
that working model and its raw parameter vector: ``result.model.predict(result.p, Q)``
reproduces the fit (without effects).

Uncertainty
-----------
C = (FᵀF + P)⁻¹ over x with F = ∂f/∂x at the solution (inlier rows) and P the prior
(:func:`pin_kpi_oed.oed.covariance.param_covariance`); optionally scaled by the reduced χ²
when the weights are only relative (unknown σ). The predicted TCP uncertainty at working
configurations is ``C_s = E C_pp Eᵀ`` (eq. 25) with E = ds/dp_B, reported per
configuration as ``sqrt(trace C_s,i)`` (m).

Outliers: measurement i is flagged when ``‖f_i‖ > sqrt(χ²_{nh}(1 − α)) · s`` with s the
robust (MAD) scale of the weighted residual components, 1.4826 · median |f|. With a robust
loss the sequence is: plain least squares (start), robust fit (f_scale = 3 s unless given),
flag, then plain least squares on the inliers, re-flag, until the flags settle (≤ 3 rounds);
the estimate, its covariance and χ² are those of the final inlier fit (a robust loss alone
still leaves a bias of order f_scale per outlier). With the plain loss, outliers are only
flagged.

Units: SI (m, rad) everywhere; summaries print mm, µm and mrad and say so.
"""

from __future__ import annotations

import copy
import time
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np
import pinocchio as pin
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation
from scipy.stats import chi2 as _chi2

from pin_kpi_oed.oed.covariance import param_covariance
from pin_kpi_oed.errors import IdentifiabilityError, InputError, SolverError
from pin_kpi_oed.oed.identifiability import Identifiability, analyse
from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.model.kinematics import skew
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.model.parameters import ParameterLayout

__all__ = [
    "ROBUST_LOSSES",
    "IdentificationResult",
    "ResidualModel",
    "identify",
    "validate",
    "format_validation",
    "predict",
    "effect_terms",
    "effect_param_names",
    "register_points",
    "align_data",
]

#: Loss functions accepted by :func:`identify` (``linear`` = plain least squares).
ROBUST_LOSSES = ("linear", "soft_l1", "huber", "cauchy")

#: Number of seeded random configurations of the structural identifiability analysis.
N_EXCITATION = 60


# --------------------------------------------------------------------------- #
# Small SO(3) helpers (batched)
# --------------------------------------------------------------------------- #
def _log3(R: np.ndarray) -> np.ndarray:
    """Batched rotation vectors of rotation matrices, (m, 3, 3) -> (m, 3) rad."""
    return Rotation.from_matrix(R).as_rotvec()


def _jl_inv(phi: np.ndarray) -> np.ndarray:
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


def _proj_so3(M: np.ndarray) -> np.ndarray:
    """Closest rotation to a 3×3 matrix (SVD projection)."""
    U, _, Vt = np.linalg.svd(M)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
    return U @ D @ Vt


# --------------------------------------------------------------------------- #
# Effects
# --------------------------------------------------------------------------- #
def effect_param_names(effects: Sequence[Any], robot) -> list[str]:
    """Names of the effect parameters θ, in vector order: ``<effect.name>.<param>``.

    A name the effect already prefixes with its own name is kept as is.
    """
    out: list[str] = []
    for e in effects:
        for n in e.param_names(robot):
            out.append(n if str(n).startswith(f"{e.name}.") else f"{e.name}.{n}")
    if len(set(out)) != len(out):
        dup = sorted({n for n in out if out.count(n) > 1})
        raise InputError(f"effect parameter names are not unique: {dup} (give the effects distinct names)")
    return out


def _effect_sizes(effects: Sequence[Any], robot) -> list[int]:
    return [len(e.param_names(robot)) for e in effects]


def effect_terms(effects: Sequence[Any], thetas: Sequence[np.ndarray], Q: np.ndarray, aux: MeasurementSet | None,
                 model: TrackerModel, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Sum of the effects' joint and tool offsets and their θ-derivatives.

    Args:
        effects: objects of the Effect interface (``docs/ARCHITECTURE.md``).
        thetas: one parameter vector per effect.
        Q: configurations, (m, n) rad.
        aux: the measurement set (temperature, payload, time columns) passed to the effects.
        model: the measurement model (passed to ``tool_offset``).
        p: raw parameters (passed to ``tool_offset``).

    Returns:
        ``dQ`` (m, n) rad, ``dQ_dtheta`` (m, n, K), ``dY`` (m, 3) m (tracker frame),
        ``dY_dtheta`` (m, 3, K), K = total number of effect parameters.
    """
    m, n = Q.shape
    sizes = [np.asarray(t, float).size for t in thetas]
    K = int(sum(sizes))
    dQ = np.zeros((m, n))
    dQt = np.zeros((m, n, K))
    dY = np.zeros((m, 3))
    dYt = np.zeros((m, 3, K))
    k0 = 0
    for e, th, k in zip(effects, thetas, sizes):
        th = np.asarray(th, float).reshape(k)
        if hasattr(e, "joint_offset"):
            a, da = e.joint_offset(th, Q, aux)
            a = np.asarray(a, float)
            da = np.asarray(da, float)
            if a.shape != (m, n) or da.shape != (m, n, k):
                raise InputError(f"effect '{e.name}': joint_offset returned shapes {a.shape}, {da.shape}, "
                                 f"expected {(m, n)}, {(m, n, k)}")
            dQ += a
            dQt[:, :, k0:k0 + k] = da
        if hasattr(e, "tool_offset"):
            b, db = e.tool_offset(th, Q, aux, model, p)
            b = np.asarray(b, float)
            db = np.asarray(db, float)
            if b.shape != (m, 3) or db.shape != (m, 3, k):
                raise InputError(f"effect '{e.name}': tool_offset returned shapes {b.shape}, {db.shape}, "
                                 f"expected {(m, 3)}, {(m, 3, k)}")
            dY += b
            dYt[:, :, k0:k0 + k] = db
        k0 += k
    return dQ, dQt, dY, dYt


def predict(model: TrackerModel, p: np.ndarray, Q: np.ndarray, effects: Sequence[Any] = (),
            thetas: Sequence[np.ndarray] = (), aux: MeasurementSet | None = None) -> np.ndarray:
    """Model response with effects: ``Y = h(p, Q + ΣΔq) + ΣΔy`` (tracker frame).

    Returns:
        (m, 3) positions (m), or (m, 6) with the orientation rotation vector (rad) for a 6-D model.
    """
    Q = np.atleast_2d(np.asarray(Q, float))
    if effects:
        dQ, _, dY, _ = effect_terms(effects, thetas, Q, aux, model, p)
    else:
        dQ, dY = 0.0, 0.0
    Y = np.array(model.predict(p, Q + dQ), float)
    Y[:, :3] += dY
    return Y


# --------------------------------------------------------------------------- #
# Input checks and registration
# --------------------------------------------------------------------------- #
def align_data(robot, data: MeasurementSet) -> np.ndarray:
    """Joint values of ``data`` in the robot's joint order, checked (rad).

    Raises:
        InputError: missing joint columns, non-finite values, degrees instead of rad,
            values outside the joint limits, non-finite positions.
    """
    src = data.source or "measurement set"
    missing = [j for j in robot.joint_names if j not in data.joint_names]
    if missing:
        raise InputError(f"{src}: missing joint column(s) {', '.join(missing)} (rad); robot joints: "
                         f"{', '.join(robot.joint_names)}; data columns: {', '.join(data.joint_names)}")
    idx = [data.joint_names.index(j) for j in robot.joint_names]
    Q = np.asarray(data.q, float)[:, idx]
    for name, arr in (("joint values", Q), ("x, y, z", data.position_m), ("rx, ry, rz", data.rotvec_rad),
                      ("sigma", data.sigma_m)):
        if arr is None:
            continue
        bad = ~np.isfinite(arr)
        if bad.any():
            i = int(np.argwhere(bad)[0][0])
            raise InputError(f"{src}: {name} of measurement {i + 1} is not finite (NaN/inf)")
    robot.check_units(Q, src, first_row=1)
    if data.rotvec_rad is not None and np.any(np.linalg.norm(data.rotvec_rad, axis=1) > 2 * np.pi + 0.1):
        raise InputError(f"{src}: rotation vectors longer than 2π rad: looks like degrees; convert to rad")
    if data.sigma_m is not None and np.any(data.sigma_m <= 0):
        raise InputError(f"{src}: standard deviations must be > 0 m")
    return robot.check_q(Q, what=src)


def _check_duplicates(Q: np.ndarray, data: MeasurementSet) -> None:
    parts = [Q, data.position_m] + ([data.rotvec_rad] if data.rotvec_rad is not None else [])
    keys = np.ascontiguousarray(np.hstack(parts) + 0.0)
    _, first, inv, counts = np.unique(keys, axis=0, return_index=True, return_inverse=True, return_counts=True)
    if np.any(counts > 1):
        g = int(np.flatnonzero(counts > 1)[0])
        rows = np.flatnonzero(inv.ravel() == g) + 1
        raise InputError(f"{data.source or 'measurement set'}: duplicate measurements (same joint values and same "
                         f"measured values): rows {', '.join(map(str, rows[:5]))}; remove the copies")


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


def _check_units(robot, Y: np.ndarray, reflector: np.ndarray, src: str) -> None:
    """Reject positions whose spread the robot cannot produce (mm instead of m)."""
    reach = robot.reach() + float(np.linalg.norm(reflector))
    spread = float(np.median(np.linalg.norm(Y - np.median(Y, axis=0), axis=1)))
    if spread > 3.0 * reach:
        raise InputError(f"{src}: the measured points lie a median {spread:.4g} from their median point, but the "
                         f"robot reaches only {reach:.3g} m: positions look like mm; convert x, y, z to m")


# --------------------------------------------------------------------------- #
# Residual model
# --------------------------------------------------------------------------- #
class ResidualModel:
    r"""Weighted residual f(x) and its analytic Jacobian for :func:`scipy.optimize.least_squares`.

    x = (p_B, θ): the identifiable raw parameters ``base`` of ``model`` followed by the
    effect parameters. Rows: per measurement the position rows (and the orientation rows
    of a 6-D model), then one prior row per base parameter with a finite prior σ.

    Attributes:
        model: the measurement model (its ``pose6d`` decides the orientation rows).
        Q: configurations in the robot's joint order, (m, n) rad.
        Y: measured positions (tracker frame), (m, 3) m.
        R_meas: measured orientations (m, 3, 3), or None.
        sigma: position σ per row, (m, 3) m; ``sigma_rot`` orientation σ (rad).
        base: indices of the estimated raw parameters.
        p_ref: raw parameter vector supplying the values of the others.
        effects: effect objects; ``k`` their total number of parameters.
        names: names of x.
    """

    def __init__(self, model: TrackerModel, data: MeasurementSet, base: np.ndarray, effects: Sequence[Any] = (),
                 sigma: np.ndarray | None = None, p_ref: np.ndarray | None = None, Q: np.ndarray | None = None):
        self.model = model
        self.data = data
        self.Q = align_data(model.robot, data) if Q is None else Q
        self.Y = np.asarray(data.position_m, float)
        self.m = self.Q.shape[0]
        self.nh = model.nh
        self.R_meas = Rotation.from_rotvec(data.rotvec_rad).as_matrix() if model.pose6d else None
        if model.pose6d and data.rotvec_rad is None:
            raise InputError(f"{data.source or 'data'}: a 6-D model needs rx, ry, rz columns")
        self.sigma = model.noise.sigma(self.Y) if sigma is None else np.broadcast_to(sigma, (self.m, 3)).copy()
        self.sigma_rot = float(model.noise.sigma_rot_rad)
        self.base = np.asarray(base, int)
        self.nb = self.base.size
        self.p_ref = np.zeros(model.n_params) if p_ref is None else np.asarray(p_ref, float).copy()
        self.effects = list(effects)
        self.sizes = _effect_sizes(self.effects, model.robot)
        self.k = int(sum(self.sizes))
        self.names = [model.layout.names[i] for i in self.base] + effect_param_names(self.effects, model.robot)
        ps = model.layout.prior_sigma[self.base]
        self.prior_idx = np.flatnonzero(np.isfinite(ps))
        self.prior_sigma = ps[self.prior_idx]
        self.W = np.hstack([1.0 / self.sigma] + ([np.full((self.m, 3), 1.0 / self.sigma_rot)] if model.pose6d else []))
        self.mask = np.ones(self.m, bool)  # measurement rows in use (outliers may be removed)

    @property
    def nx(self) -> int:
        """Number of unknowns."""
        return self.nb + self.k

    @property
    def n_rows(self) -> int:
        """Number of residual rows (measurements and priors)."""
        return int(self.mask.sum()) * self.nh + self.prior_idx.size

    def unpack(self, x: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
        """Raw parameter vector and per-effect θ from x."""
        x = np.asarray(x, float)
        p = self.p_ref.copy()
        p[self.base] = x[:self.nb]
        th, k0 = [], self.nb
        for k in self.sizes:
            th.append(x[k0:k0 + k].copy())
            k0 += k
        return p, th

    def x0(self) -> np.ndarray:
        """Start: the reference values of the base parameters and θ = 0."""
        return np.concatenate([self.p_ref[self.base], np.zeros(self.k)])

    def _terms(self, p, th, Q):
        if self.effects:
            return effect_terms(self.effects, th, Q, self.data, self.model, p)
        return None

    def evaluate(self, x: np.ndarray, Q: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """Unweighted residuals model − measured: positions (m, 3) m and orientations (m, 3) rad or None."""
        p, th = self.unpack(x)
        Q = self.Q if Q is None else Q
        t = self._terms(p, th, Q)
        Qe = Q if t is None else Q + t[0]
        model = self.model
        kin = model.kinematics(p, Qe, model.reflector(p))
        T = model.tracker_pose(p)
        Yp = kin.p @ T.rotation.T + T.translation
        if t is not None:
            Yp = Yp + t[2]
        rpos = Yp - self.Y
        rrot = None
        if model.pose6d:
            R_probe = model.probe_R @ pin.exp3(p[model.layout.probe])
            R_model = T.rotation @ kin.R_tool @ R_probe
            rrot = _log3(R_model @ np.swapaxes(self.R_meas, 1, 2))
        return rpos, rrot

    def residual(self, x: np.ndarray) -> np.ndarray:
        """Weighted residual vector f(x) (rows: measurements in use, then priors)."""
        rpos, rrot = self.evaluate(x)
        r = rpos if rrot is None else np.hstack([rpos, rrot])
        f = (r * self.W)[self.mask].ravel()
        if self.prior_idx.size:
            f = np.concatenate([f, x[self.prior_idx] / self.prior_sigma])
        return f

    def weighted_rows(self, x: np.ndarray) -> np.ndarray:
        """Weighted residuals of every measurement, (m, nh) (ignores the mask and priors)."""
        rpos, rrot = self.evaluate(x)
        r = rpos if rrot is None else np.hstack([rpos, rrot])
        return r * self.W

    def jacobian_full(self, x: np.ndarray) -> np.ndarray:
        """Weighted Jacobian of every measurement, (m, nh, nx)."""
        p, th = self.unpack(x)
        model = self.model
        t = self._terms(p, th, self.Q)
        Qe = self.Q if t is None else self.Q + t[0]
        J = np.empty((self.m, self.nh, self.nx))
        J[:, :, :self.nb] = model.jacobian(p, Qe)[:, :, self.base]
        RT = model.tracker_pose(p).rotation
        if self.k:
            kin = model.kinematics(p, Qe, model.reflector(p))
            v, w = kin.twist[:, :3, :], kin.twist[:, 3:, :]
            pdot = v + np.cross(w, kin.p[:, :, None], axis=1)
            Ydq = np.einsum("ab,mbn->man", RT, pdot)
            J[:, :3, self.nb:] = Ydq @ t[1] + t[3]
            if model.pose6d:
                J[:, 3:, self.nb:] = np.einsum("ab,mbn->man", RT, w) @ t[1]
        if model.pose6d:
            _, rrot = self.evaluate(x)
            J[:, 3:, :] = _jl_inv(rrot) @ J[:, 3:, :]
        return J * self.W[:, :, None]

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        """∂f/∂x, (rows, nx)."""
        J = self.jacobian_full(x)[self.mask].reshape(-1, self.nx)
        if self.prior_idx.size:
            P = np.zeros((self.prior_idx.size, self.nx))
            P[np.arange(self.prior_idx.size), self.prior_idx] = 1.0 / self.prior_sigma
            J = np.vstack([J, P])
        return J


# --------------------------------------------------------------------------- #
# Result
# --------------------------------------------------------------------------- #
def _unit(name: str) -> str:
    suffix = name.rsplit(".", 1)[-1]
    if name.split(".")[0] in ("reflector",) or suffix in ("tx", "ty", "tz"):
        return "m"
    if suffix in ("rx", "ry", "rz"):
        return "rad"
    return ""


@dataclass
class IdentificationResult:
    """Outcome of :func:`identify`.

    Attributes:
        names: names of the estimated parameters (identifiable raw parameters, then effect θ).
        values: their estimates (m, rad; θ in the effect's units). Raw parameters are the
            right-perturbation errors of ``parameters.py``; the tracker ones are relative to
            ``tracker_T_base_init``, the reflector ones to the given nominal reflector.
        std: standard deviations (same units).
        covariance: covariance of the estimates, (k, k).
        correlation: correlation matrix, (k, k).
        p: full raw parameter vector of ``model`` (non-identifiable entries at their given value).
        theta: effect parameters, one array per effect.
        residuals_m: measured − model position per measurement, (m, 3) m (tracker frame).
        residuals_rad: log3(R_meas R_modelᵀ) per measurement (m, 3) rad, or None (position only).
        errors_m: position error norm per measurement, (m,) m.
        weighted_errors: ‖f_i‖ per measurement (dimensionless).
        outliers: indices of flagged measurements.
        tcp_std_m: predicted TCP standard deviation sqrt(trace C_s) per working configuration, (t,) m.
        converged: whether the solver stopped on a tolerance.
        status: :func:`scipy.optimize.least_squares` status; ``message`` its text.
        cost: final cost ½ Σ ρ(f²) (dimensionless).
        chi2_reduced: Σ f² / (rows − unknowns) over the measurements in use.
        iterations: number of Jacobian evaluations (LM iterations); ``nfev`` residual evaluations.
        tracker_T_base: fitted pose of the robot base in the tracker frame, 4×4 (m).
        tracker_T_base_init: registration guess (reference of the tracker parameters), 4×4 (m).
        reflector_m: fitted reflector offset in the tool frame, (3,) m.
        probe_R: fitted probe orientation in the tool frame (6-D only), 3×3.
        model: the working :class:`TrackerModel` (not serialised).
        effects: the effect objects (not serialised; names in ``to_dict``).
        identifiability: the analysis that chose the parameters.
        loss: loss function used; ``f_scale`` its scale (weighted units).
        covariance_scaled: covariance multiplied by ``chi2_reduced`` (relative weights only).
        sigma_source: where the weights came from (``data``, ``noise model``).
        time_s: wall-clock time of the identification (s).
    """

    names: list[str]
    values: np.ndarray
    std: np.ndarray
    covariance: np.ndarray
    correlation: np.ndarray
    p: np.ndarray
    theta: list[np.ndarray]
    residuals_m: np.ndarray
    residuals_rad: np.ndarray | None
    errors_m: np.ndarray
    weighted_errors: np.ndarray
    outliers: np.ndarray
    tcp_std_m: np.ndarray
    converged: bool
    status: int
    message: str
    cost: float
    chi2_reduced: float
    iterations: int
    nfev: int
    tracker_T_base: np.ndarray
    tracker_T_base_init: np.ndarray
    reflector_m: np.ndarray
    probe_R: np.ndarray | None
    model: TrackerModel = field(repr=False)
    effects: list = field(default_factory=list, repr=False)
    identifiability: Identifiability | None = field(default=None, repr=False)
    loss: str = "linear"
    f_scale: float = 1.0
    covariance_scaled: bool = False
    sigma_source: str = "noise model"
    time_s: float = 0.0

    @property
    def n_measurements(self) -> int:
        """Number of measurements used in the fit."""
        return int(self.errors_m.size)

    @property
    def rms_m(self) -> float:
        """RMS of the position error norms over the inliers (m)."""
        keep = np.ones(self.errors_m.size, bool)
        keep[self.outliers] = False
        return float(np.sqrt(np.mean(self.errors_m[keep] ** 2))) if keep.any() else float("nan")

    def parameter(self, name: str) -> tuple[float, float]:
        """(value, std) of an estimated parameter by name.

        Raises:
            InputError: the parameter was not estimated.
        """
        if name not in self.names:
            raise InputError(f"parameter '{name}' was not estimated (estimated: {', '.join(self.names[:4])}, ...)")
        i = self.names.index(name)
        return float(self.values[i]), float(self.std[i])

    def predict(self, Q: np.ndarray, aux: MeasurementSet | None = None) -> np.ndarray:
        """Predicted measurements at configurations ``Q`` (rad), (m, 3) m or (m, 6) (with effects)."""
        return predict(self.model, self.p, Q, self.effects, self.theta, aux)

    def to_dict(self) -> dict:
        """Plain JSON-able dict (SI units)."""
        L = self.model.layout
        return {
            "robot": self.model.robot.name,
            "urdf": self.model.robot.urdf_path,
            "tool_frame": self.model.robot.tool_frame,
            "n_measurements": self.n_measurements,
            "pose6d": bool(self.model.pose6d),
            "loss": self.loss,
            "f_scale": self.f_scale,
            "sigma_source": self.sigma_source,
            "converged": bool(self.converged),
            "status": int(self.status),
            "message": self.message,
            "cost": float(self.cost),
            "chi2_reduced": float(self.chi2_reduced),
            "iterations": int(self.iterations),
            "nfev": int(self.nfev),
            "time_s": float(self.time_s),
            "rms_m": self.rms_m,
            "parameters": [{"name": n, "value": float(v), "std": float(s), "unit": _unit(n)}
                           for n, v, s in zip(self.names, self.values, self.std)],
            "covariance": self.covariance,
            "covariance_scaled": bool(self.covariance_scaled),
            "correlation": self.correlation,
            "p_raw": {n: float(v) for n, v in zip(L.names, self.p)},
            "effects": {e.name: {n: float(v) for n, v in zip(effect_param_names([e], self.model.robot), th)}
                        for e, th in zip(self.effects, self.theta)},
            "tracker_T_base": self.tracker_T_base,
            "tracker_T_base_init": self.tracker_T_base_init,
            "reflector_m": self.reflector_m,
            "probe_R": self.probe_R,
            "joint_placements": [pin.SE3(M).homogeneous for M in self.model.joint_placements(self.p)],
            "residuals_m": self.residuals_m,
            "residuals_rad": self.residuals_rad,
            "errors_m": self.errors_m,
            "outliers": self.outliers,
            "tcp_std_m": self.tcp_std_m,
            "identifiability": self.identifiability.to_dict() if self.identifiability is not None else None,
        }

    def summary(self) -> str:
        """Readable multi-line summary (display units: mm, µm, mrad)."""
        e = self.errors_m * 1e3
        st = "converged" if self.converged else "NOT converged"
        out = [f"identification of {self.model.robot.name} ({self.n_measurements} measurements, "
               f"{'6-D' if self.model.pose6d else 'position'}, loss {self.loss}): {st} after "
               f"{self.iterations} iterations ({self.nfev} evaluations, {self.time_s * 1e3:.1f} ms)",
               f"  position residuals: RMS {self.rms_m * 1e3:.4f} mm, mean {e.mean():.4f} mm, max {e.max():.4f} mm; "
               f"reduced chi2 {self.chi2_reduced:.3g} (weights: {self.sigma_source}"
               f"{', covariance scaled by it' if self.covariance_scaled else ''})"]
        if self.residuals_rad is not None:
            a = np.linalg.norm(self.residuals_rad, axis=1) * 1e3
            out.append(f"  orientation residuals: RMS {np.sqrt(np.mean(a ** 2)):.4f} mrad, max {a.max():.4f} mrad")
        if self.outliers.size:
            rows = ", ".join(str(i + 1) for i in self.outliers[:10])
            out.append(f"  outliers flagged: {self.outliers.size} (rows {rows}{' ...' if self.outliers.size > 10 else ''})")
        T = self.tracker_T_base
        rpy = pin.rpy.matrixToRpy(T[:3, :3])
        out.append(f"  tracker_T_base: xyz {np.round(T[:3, 3], 6).tolist()} m, rpy {np.round(rpy, 6).tolist()} rad")
        out.append(f"  reflector in {self.model.robot.tool_frame}: {np.round(self.reflector_m * 1e3, 4).tolist()} mm")
        if self.tcp_std_m.size:
            out.append(f"  predicted TCP std at {self.tcp_std_m.size} working configurations: mean "
                       f"{self.tcp_std_m.mean() * 1e6:.2f} µm, max {self.tcp_std_m.max() * 1e6:.2f} µm")
        out.append(f"  {len(self.names)} estimated parameters (value ± std; mm or mrad):")
        for n, v, s in zip(self.names, self.values, self.std):
            u = _unit(n)
            f = 1e3 if u in ("m", "rad") else 1.0
            disp = {"m": "mm", "rad": "mrad"}.get(u, "")
            out.append(f"    {n:<28s} {v * f:+12.5f} ± {s * f:.5f} {disp}")
        C = self.correlation
        iu = np.triu_indices(len(self.names), 1)
        strong = [(abs(C[i, j]), i, j) for i, j in zip(*iu) if abs(C[i, j]) > 0.95]
        for c, i, j in sorted(strong, reverse=True)[:5]:
            out.append(f"  strongly correlated: {self.names[i]} / {self.names[j]} ({C[i, j]:+.3f})")
        return "\n".join(out)

    def __str__(self) -> str:
        return self.summary()


# --------------------------------------------------------------------------- #
# Identification
# --------------------------------------------------------------------------- #
_IDENT_CACHE: dict[tuple, Identifiability] = {}


def _structural_identifiability(model: TrackerModel, seed: int) -> Identifiability:
    """:func:`analyse` on a seeded random excitation, cached per robot geometry and set-up."""
    rb = model.robot
    key = (rb.urdf_path, rb.tool_frame, tuple(rb.joint_names),
           np.array([rb.model.jointPlacements[j].homogeneous for j in rb.joint_ids]).round(12).tobytes(),
           model.reflector_m.round(12).tobytes(), bool(model.pose6d), model.layout.fixed.tobytes(),
           repr(model.noise.to_dict()), seed)
    hit = _IDENT_CACHE.get(key)
    if hit is None:
        Qx = rb.random_q(np.random.default_rng(seed), N_EXCITATION)
        hit = analyse(model, Q=Qx)
        if len(_IDENT_CACHE) > 64:
            _IDENT_CACHE.clear()
        _IDENT_CACHE[key] = hit
    return copy.deepcopy(hit)  # callers may keep or modify their copy


def _working_layout(model: TrackerModel, pose6d: bool, setup_only: bool) -> ParameterLayout:
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


def _data_rank_check(F: np.ndarray, names: list[str], m: int, nh: int) -> None:
    """Raise if the data do not determine every unknown (pivoted QR of the scaled Jacobian)."""
    import scipy.linalg as sla

    norms = np.linalg.norm(F, axis=0)
    if np.any(norms == 0):
        k = int(np.flatnonzero(norms == 0)[0])
        raise IdentifiabilityError(f"the measurements do not move '{names[k]}': add configurations that do, "
                                   "or fix it as known")
    _, R, piv = sla.qr(F / norms, mode="economic", pivoting=True)
    d = np.abs(np.diag(R))
    bad = np.flatnonzero(d < 1e-8 * d[0])
    if bad.size:
        who = names[piv[bad[0]]]
        raise IdentifiabilityError(f"the {m} measurements do not determine '{who}' (and {bad.size - 1} more "
                                   f"direction(s)); the configurations are too similar: spread them over the "
                                   f"joint ranges, or fix the parameter as known")


def identify(model: TrackerModel, data: MeasurementSet, *, effects: Sequence[Any] = (),
             p0: np.ndarray | None = None, loss: str = "linear", f_scale: float | None = None,
             weights: str = "auto", register: bool = True, use_orientation: bool = True,
             setup_only: bool = False, scale_covariance: bool = False, Q_work: np.ndarray | None = None,
             ident: Identifiability | None = None, outlier_alpha: float = 1e-3,
             max_nfev: int | None = None, tol: float = 1e-10, max_median_error_m: float | None = None,
             raise_on_failure: bool = True, seed: int = 0) -> IdentificationResult:
    r"""Identify the robot's geometric parameters (and effect parameters θ) from measurements.

    Weighted nonlinear least squares (eqs. 5–6) over the identifiable parameters, by
    Levenberg–Marquardt with the analytic Jacobian (or trust-region reflective with a robust
    loss), from the nominal model and a closed-form registration of the tracker pose.

    Args:
        model: measurement model: robot, nominal reflector in the tool frame, noise (weights),
            TCP point, layout (``fixed`` parameters held at their value, ``prior_sigma``). Its
            ``tracker_T_base`` is only used when ``register`` is False or the tracker is fixed.
        data: the measurements (joint columns named as the robot's joints; SI units).
        effects: objects of the Effect interface (``docs/ARCHITECTURE.md``); their θ are
            identified jointly (start at 0).
        p0: raw parameters of ``model`` to start from / hold fixed entries at (default zeros).
        loss: ``linear`` (Levenberg–Marquardt), ``soft_l1``, ``huber`` or ``cauchy`` (robust,
            followed by a plain refit on the inliers; see the module docstring).
        f_scale: robust-loss scale in weighted units; default 3 × the MAD scale of a first
            plain least-squares fit.
        weights: ``auto`` (the data's sigma columns if present, else the noise model),
            ``data`` or ``noise``.
        register: guess the tracker pose (and probe orientation) by point-set registration; skipped
            for the tracker (probe) when one of its parameters is fixed or has a prior, so that
            these refer to ``model.tracker_T_base`` (``model.probe_R``).
        use_orientation: use the rx, ry, rz columns (6-D probe) when the data have them.
        setup_only: estimate the set-up parameters only (tracker, reflector, probe): the
            "nominal robot" baseline.
        scale_covariance: multiply the covariance by the reduced χ² (relative weights only).
        Q_work: working configurations of the TCP uncertainty (rad); default the data's.
        ident: a precomputed identifiability analysis of the working model (default: computed
            on ``N_EXCITATION`` seeded random configurations).
        outlier_alpha: false-alarm probability of the outlier flag.
        max_nfev: maximum number of residual evaluations (default 50 × unknowns).
        tol: ftol, xtol and gtol of the solver.
        max_median_error_m: fail if the median position error after the fit exceeds it
            (default 1 % of the robot's reach): the model cannot reach the data.
        raise_on_failure: raise :class:`SolverError` when the solver does not converge.
        seed: seed of the identifiability excitation.

    Returns:
        The :class:`IdentificationResult`.

    Raises:
        InputError: missing joint columns, NaN, degrees or mm instead of rad or m, duplicate
            rows, an unknown loss.
        IdentifiabilityError: fewer equations than unknowns, or the configurations do not
            determine a parameter.
        SolverError: no convergence, or the fitted model does not reach the data.
    """
    t_start = time.perf_counter()
    robot = model.robot
    src = data.source or "measurement set"
    if loss not in ROBUST_LOSSES:
        raise InputError(f"unknown loss '{loss}' (choose from {', '.join(ROBUST_LOSSES)})")
    if weights not in ("auto", "data", "noise"):
        raise InputError(f"weights must be auto, data or noise, got '{weights}'")
    Q = align_data(robot, data)
    _check_duplicates(Q, data)
    pose6d = bool(use_orientation and data.rotvec_rad is not None)
    L = _working_layout(model, pose6d, setup_only)
    if weights == "data" and data.sigma_m is None:
        raise InputError(f"{src}: weights='data' but the file has no sigma columns")
    use_data_sigma = data.sigma_m is not None and weights in ("auto", "data")
    sigma = np.asarray(data.sigma_m, float) if use_data_sigma else None
    sigma_source = "data" if use_data_sigma else "noise model"

    # ---- start values -------------------------------------------------------
    p_user = np.zeros(model.n_params) if p0 is None else np.asarray(p0, float).reshape(model.n_params)
    p_start = np.zeros(L.n)
    for i, n in enumerate(L.names):
        if n in model.layout.names and not n.startswith("tracker."):
            p_start[i] = p_user[model.layout.index(n)]
    T0 = model.tracker_pose(p_user)
    reflector0 = model.reflector(p_user)
    p_start[L.reflector] = 0.0
    _check_units(robot, data.position_m, reflector0, src)
    # a fixed tracker parameter or a prior on one means the user's nominal tracker pose is meaningful: keep it
    tracker_known = bool(L.fixed[L.tracker].any() or np.isfinite(L.prior_sigma[L.tracker]).any())
    probe_known = bool(L.fixed[L.probe].any() or np.isfinite(L.prior_sigma[L.probe]).any())
    probe_R0 = np.asarray(model.probe_R, float)
    wm = TrackerModel(robot, tracker_T_base=T0, reflector_m=reflector0, tcp_m=model.tcp_m, noise=model.noise,
                      pose6d=pose6d, probe_R=probe_R0, layout=L)
    if effects:
        dQ0, _, dY0, _ = effect_terms(effects, [np.zeros(k) for k in _effect_sizes(effects, robot)], Q, data, wm,
                                      p_start)
    else:
        dQ0, dY0 = 0.0, 0.0
    if register and not tracker_known:
        kin = wm.kinematics(p_start, Q + dQ0, wm.reflector(p_start))
        R, t = register_points(kin.p, data.position_m - dY0, None if sigma is None else 1.0 / np.mean(sigma ** 2, 1))
        wm.tracker_T_base = pin.SE3(R, t)
        if pose6d:
            Rm = Rotation.from_rotvec(data.rotvec_rad).as_matrix()
            M = np.einsum("mba,bc,mcd->ad", kin.R_tool, R.T, Rm)  # Σ (R_T R_tool)ᵀ R_meas
            if not probe_known:
                wm.probe_R = _proj_so3(M)
                p_start[L.probe] = 0.0
    T_init = wm.tracker_T_base.homogeneous.copy()

    # ---- identifiable parameters ---------------------------------------------
    if ident is None:
        ident = _structural_identifiability(wm, seed)
    base = np.asarray(ident.base, int)
    prob = ResidualModel(wm, data, base, effects, sigma=sigma, p_ref=p_start, Q=Q)
    n_eq = prob.m * prob.nh
    if n_eq < prob.nx:
        raise IdentifiabilityError(
            f"{src}: {prob.m} measurements give {n_eq} equations for {prob.nx} identifiable parameters "
            f"({prob.nb} geometric/set-up{f' + {prob.k} effect' if prob.k else ''}); measure at least "
            f"{int(np.ceil(prob.nx / prob.nh))} configurations (better 2–3× as many)")
    x0 = prob.x0()
    J0 = prob.jacobian_full(x0).reshape(-1, prob.nx)
    _data_rank_check(J0, prob.names, prob.m, prob.nh)

    # ---- solve ----------------------------------------------------------------
    nfev_max = max_nfev if max_nfev is not None else 50 * max(prob.nx, 1)
    method = "lm" if loss == "linear" else "trf"
    if prob.n_rows < prob.nx:
        method = "trf"

    def _solve(x_init, loss_, scale_, method_):
        try:
            return least_squares(prob.residual, x_init, jac=prob.jacobian, method=method_, loss=loss_,
                                 f_scale=scale_, x_scale="jac", ftol=tol, xtol=tol, gtol=tol, max_nfev=nfev_max)
        except (ValueError, np.linalg.LinAlgError) as exc:
            raise SolverError(f"identification failed: {str(exc).splitlines()[0]}") from None

    fs = 1.0
    pre_iter = pre_fev = 0
    if loss == "linear":
        sol = _solve(x0, "linear", 1.0, method)
    else:
        first = _solve(x0, "linear", 1.0, "lm" if prob.n_rows >= prob.nx else "trf")
        if f_scale is None:
            f_lin = prob.weighted_rows(first.x).ravel()
            fs = 3.0 * 1.4826 * float(np.median(np.abs(f_lin))) or 1.0
        else:
            fs = float(f_scale)
        sol = _solve(first.x, loss, fs, "trf")
        pre_iter, pre_fev = int(first.njev or 0), int(first.nfev)
    x = sol.x
    if not np.all(np.isfinite(x)):
        raise SolverError("identification diverged (non-finite parameters); check the robot, joint order and units")
    converged = bool(sol.status > 0)
    if not converged and raise_on_failure:
        raise SolverError(f"identification did not converge in {sol.nfev} evaluations (cost {sol.cost:.4g}): "
                          "check the joint order, units (m, rad) and the reflector offset, or raise max_nfev")
    rpos, _ = prob.evaluate(x)
    errors = np.linalg.norm(rpos, axis=1)
    limit = 0.01 * robot.reach() if max_median_error_m is None else float(max_median_error_m)
    if float(np.median(errors)) > limit:
        raise SolverError(f"the fitted model does not reach the data: median position error "
                          f"{np.median(errors) * 1e3:.4g} mm after {sol.njev or 0} iterations (limit {limit * 1e3:.3g} "
                          f"mm); check the robot model, tool frame, joint order/zero and units (m, rad)")

    # ---- outliers (robust loss: refit plain least squares on the inliers until the flags settle) --
    def _flag(x_):
        fw_ = prob.weighted_rows(x_)
        we_ = np.linalg.norm(fw_, axis=1)
        s_rob = 1.4826 * float(np.median(np.abs(fw_)))
        thr = float(np.sqrt(_chi2.ppf(1.0 - outlier_alpha, prob.nh))) * max(s_rob, 1e-300)
        return fw_, we_, np.flatnonzero(we_ > thr)

    fw, we, outliers = _flag(x)
    n_iter, n_fev = pre_iter + int(sol.njev or 0), pre_fev + int(sol.nfev)
    if loss != "linear":
        for _ in range(3):
            prob.mask = np.ones(prob.m, bool)
            prob.mask[outliers] = False
            if prob.n_rows < prob.nx:
                raise IdentifiabilityError(f"{src}: too few inliers ({int(prob.mask.sum())}) for {prob.nx} "
                                           "parameters")
            sol2 = _solve(x, "linear", 1.0, "lm")
            if sol2.status <= 0 and raise_on_failure:
                raise SolverError(f"the refit on the inliers did not converge in {sol2.nfev} evaluations")
            x = sol2.x
            n_iter += int(sol2.njev or 0)
            n_fev += int(sol2.nfev)
            fw, we, new_out = _flag(x)
            if np.array_equal(new_out, outliers):
                break
            outliers = new_out
        prob.mask = np.ones(prob.m, bool)
        prob.mask[outliers] = False
    rpos, rrot = prob.evaluate(x)
    errors = np.linalg.norm(rpos, axis=1)

    # ---- covariance ---------------------------------------------------------------
    F = prob.jacobian_full(x)[prob.mask].reshape(-1, prob.nx)
    n_rows = F.shape[0]
    chi2 = float(np.sum(fw[prob.mask] ** 2))
    dof = max(n_rows + prob.prior_idx.size - prob.nx, 1)
    chi2_red = chi2 / dof
    prior = np.full(prob.nx, np.inf)
    prior[prob.prior_idx] = prob.prior_sigma
    C = param_covariance(F, prior, prob.names)
    if scale_covariance:
        C = C * chi2_red
    std = np.sqrt(np.clip(np.diag(C), 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = C / np.outer(std, std)
    corr = np.where(np.isfinite(corr), corr, 0.0)

    # ---- predicted TCP uncertainty at the working configurations -------------------
    p_hat, th_hat = prob.unpack(x)
    Qw = Q if Q_work is None else robot.check_q(Q_work, "Q_work")
    E = wm.kpi_jacobian(p_hat, Qw)[:, base]
    Cpp = C[:prob.nb, :prob.nb]
    var = np.einsum("ij,jk,ik->i", E, Cpp, E).reshape(-1, 3).sum(axis=1)
    tcp_std = np.sqrt(np.clip(var, 0.0, None))

    T_fit = wm.tracker_pose(p_hat)
    probe_R = wm.probe_R @ pin.exp3(p_hat[L.probe]) if pose6d else None
    return IdentificationResult(
        names=prob.names, values=x.copy(), std=std, covariance=C, correlation=corr, p=p_hat, theta=th_hat,
        residuals_m=-rpos, residuals_rad=None if rrot is None else -rrot, errors_m=errors, weighted_errors=we,
        outliers=outliers, tcp_std_m=tcp_std, converged=converged, status=int(sol.status), message=str(sol.message),
        cost=float(sol.cost), chi2_reduced=chi2_red, iterations=n_iter, nfev=n_fev,
        tracker_T_base=T_fit.homogeneous.copy(), tracker_T_base_init=T_init, reflector_m=wm.reflector(p_hat),
        probe_R=probe_R, model=wm, effects=list(effects), identifiability=ident, loss=loss, f_scale=fs,
        covariance_scaled=bool(scale_covariance), sigma_source=sigma_source,
        time_s=time.perf_counter() - t_start)


# --------------------------------------------------------------------------- #
# Validation
# --------------------------------------------------------------------------- #
def validate(result: IdentificationResult, data: MeasurementSet) -> dict:
    """Position errors of the identified model on held-out measurements (nothing is re-fitted).

    The tracker pose, reflector offset, geometry and effect parameters all come from
    ``result``; the effects see ``data`` as their auxiliary data (temperature, ...).

    Args:
        result: an identification result.
        data: held-out measurements (same robot joints, SI units).

    Returns:
        ``{"n", "mean_m", "rms_m", "median_m", "p95_m", "max_m", "errors_m"}`` (m), plus
        ``"rot_rms_rad"``, ``"rot_max_rad"`` when both the result and the data are 6-D.

    Raises:
        InputError: missing joint columns, NaN, degrees or out-of-limit joint values.
    """
    model = result.model
    Q = align_data(model.robot, data)
    Y = predict(model, result.p, Q, result.effects, result.theta, data)
    err = np.linalg.norm(data.position_m - Y[:, :3], axis=1)
    out = {"n": int(err.size), "mean_m": float(err.mean()), "rms_m": float(np.sqrt(np.mean(err ** 2))),
           "median_m": float(np.median(err)), "p95_m": float(np.percentile(err, 95)), "max_m": float(err.max()),
           "errors_m": err}
    if model.pose6d and data.rotvec_rad is not None:
        Rp = Rotation.from_rotvec(Y[:, 3:]).as_matrix()
        Rm = Rotation.from_rotvec(data.rotvec_rad).as_matrix()
        a = np.linalg.norm(_log3(Rm @ np.swapaxes(Rp, 1, 2)), axis=1)
        out["rot_rms_rad"] = float(np.sqrt(np.mean(a ** 2)))
        out["rot_max_rad"] = float(a.max())
    return out


def format_validation(stats: dict, title: str = "held-out") -> str:
    """One line of validation statistics in mm (``stats`` from :func:`validate`)."""
    s = (f"{title}: n={stats['n']}, mean {stats['mean_m'] * 1e3:.4f} mm, RMS {stats['rms_m'] * 1e3:.4f} mm, "
         f"p95 {stats['p95_m'] * 1e3:.4f} mm, max {stats['max_m'] * 1e3:.4f} mm")
    if "rot_rms_rad" in stats:
        s += f", orientation RMS {stats['rot_rms_rad'] * 1e3:.4f} mrad"
    return s
