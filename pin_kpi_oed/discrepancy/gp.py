r"""Model discrepancy δ(q): a Gaussian process over the joint angles, beside the parametric robot model.

The measurement model becomes (Kennedy & O'Hagan 2001)

.. math::  y = h(p, q) + R_s\,\delta(q) + \varepsilon, \qquad
           \delta \sim \mathcal{GP}(0, S\,k(q, q')\,S), \quad \varepsilon \sim \mathcal N(0, w S^2),

with h the parametric model (geometry, effects, set-up of station s), R_s the rotation of
station s's tracker frame relative to the robot base (δ is a property of the robot, expressed in
its base frame, so it survives a moved tracker), k the :class:`~pin_kpi_oed.discrepancy.kernel.JointKernel`
and S = diag(s_x, s_y, s_z) the per-axis scale (m) of the residuals. The white term w S² holds
what repeats from pose to pose only: tracker noise and the robot's repeatability.

Separation of p and δ (confounding, Plumlee 2017): the parametric part is fitted first, exactly
as without a discrepancy, and δ is fitted to its residuals. The residuals of a least-squares fit
are orthogonal to the span of the parameter Jacobian, so δ only learns what no parameter of the
model can express, and the identified parameters are the same with or without the discrepancy
(tested). The parameter covariance is then the generalised-least-squares one under
Σ = K + w S² (:func:`gls_covariance`), larger than the noise-only one because correlated
residuals carry less information.

Hyper-parameters (k's amplitudes and length scales, w) by maximum marginal likelihood
(:mod:`~pin_kpi_oed.discrepancy.marginal`: scikit-learn's regressor's objective, evaluated on the pairs of rows;
L-BFGS-B from each deterministic start, at most ``max_iter`` iterations: more change the hyper-parameters but not the
held-out error) on a seeded subset of at most ``n_fit`` rows; the K-fold check of each start comes
from one inverse of Σ = K + wI (block inversion, no refit per fold); the posterior uses every row: exactly up to
``max_exact`` rows, above that the projected-process (DTC) approximation on ``n_inducing``
seeded inducing configurations (Titsias 2009; Rasmussen & Williams §8.3), built in chunks so a
100,000-row file needs O(n · m) time and O(m²) memory.

Posterior at configurations W (normalised units, one kernel for the three axes):

* exact:  μ = K_WQ (K_QQ + wI)⁻¹ ỹ,   v = k_WW − K_WQ (K_QQ + wI)⁻¹ K_QW;
* DTC:    A = K_ZZ + w⁻¹ K_ZQ K_QZ,  μ = w⁻¹ K_WZ A⁻¹ K_ZQ ỹ,  v = k_WW − K_WZ (K_ZZ⁻¹ − A⁻¹) K_ZW;

then δ(W) = S μ + mean, var δ = S² v, and the variance of a new measurement adds w S².
"""

from __future__ import annotations

import base64
import time
from dataclasses import dataclass, field
from typing import Any
from collections.abc import Sequence

import numpy as np
from scipy import linalg as sla

from pin_kpi_oed.discrepancy.kernel import JointKernel
from pin_kpi_oed.errors import InputError

__all__ = ["DiscrepancyOptions", "Discrepancy", "fit_discrepancy", "encode_array", "decode_array",
           "COVERAGE_BIN_RAD"]

#: Width of the joint-angle bins that record the training coverage (rad).
COVERAGE_BIN_RAD = 0.05
_NBINS = int(np.ceil(2 * np.pi / COVERAGE_BIN_RAD))
_JITTER = 1e-8


def encode_array(a: np.ndarray) -> dict:
    """A float64 array as plain data: shape and base64 of its little-endian bytes (compact, exact)."""
    a = np.ascontiguousarray(np.asarray(a, dtype="<f8"))
    return {"shape": list(a.shape), "float64_b64": base64.b64encode(a.tobytes()).decode("ascii")}


def decode_array(d: Any, where: str, shape: Sequence[int | None] | None = None) -> np.ndarray:
    """Inverse of :func:`encode_array` (``shape`` entries None = any), finite values required.

    Raises:
        ValueError: not such an object, bad base64, a size or shape that does not match, non-finite values.
    """
    if not isinstance(d, dict) or "shape" not in d or "float64_b64" not in d:
        raise ValueError(f"{where}: must be an object with 'shape' and 'float64_b64'")
    try:
        shp = tuple(int(s) for s in d["shape"])
        raw = base64.b64decode(str(d["float64_b64"]).encode("ascii"), validate=True)
        a = np.frombuffer(raw, dtype="<f8").reshape(shp).astype(float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: damaged array ({exc})") from None
    if shape is not None and (len(shp) != len(shape) or any(s is not None and s != t for s, t in zip(shape, shp))):
        raise ValueError(f"{where}: shape {shp} where {tuple(shape)} is expected")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{where}: non-finite values")
    return a


@dataclass
class DiscrepancyOptions:
    """How the discrepancy is fitted.

    Attributes:
        mode: ``auto`` (fitted when there are at least ``min_rows`` measurements and the K-fold
            held-out error drops by at least ``min_gain``; otherwise a white discrepancy: the residual
            level as an independent error per row), ``on`` (always the GP), ``none`` (the paper's
            noise-only model).
        n_fit: rows for the marginal-likelihood fit of the hyper-parameters (seeded subset).
        max_exact: largest number of rows for the exact posterior; above it, DTC with ``n_inducing``.
        n_inducing: inducing configurations of the sparse posterior.
        folds: K of the K-fold held-out check.
        min_rows: fewest measurements for a GP.
        min_gain: smallest relative drop of the K-fold held-out mean error that keeps the GP.
        max_iter: iterations of the marginal-likelihood optimiser (L-BFGS-B) per start.
        restarts: extra random starts of the marginal-likelihood optimiser (scikit-learn's, drawn over the
            bounds).
        starts: the additive part's amplitude at each deterministic start; the marginal likelihood of
            this kernel has local optima (the product or the one-joint part explaining the residuals), so
            each start is fitted and the one with the smaller K-fold held-out error kept.
        seed: seed of every random choice (subsets, folds, restarts).
    """

    mode: str = "auto"
    n_fit: int = 400
    max_exact: int = 3000
    n_inducing: int = 600
    folds: int = 5
    min_rows: int = 60
    min_gain: float = 0.01
    max_iter: int = 60
    restarts: int = 0
    starts: tuple = (0.1, 0.01)
    seed: int = 0

    def __post_init__(self) -> None:
        if self.mode not in ("auto", "on", "none"):
            raise InputError(f"discrepancy mode must be auto, on or none, got '{self.mode}'")
        for name in ("n_fit", "max_exact", "n_inducing", "folds", "min_rows", "max_iter"):
            if int(getattr(self, name)) < (2 if name == "folds" else 1):
                raise InputError(f"discrepancy option {name} must be a positive integer, got {getattr(self, name)}")


def _coverage_bins(Q: np.ndarray) -> np.ndarray:
    """(d, _NBINS) bool: which angle bins of each joint hold a training row (angles wrapped to [−π, π))."""
    W = np.mod(Q + np.pi, 2 * np.pi)
    idx = np.minimum((W / COVERAGE_BIN_RAD).astype(int), _NBINS - 1)
    out = np.zeros((Q.shape[1], _NBINS), bool)
    for j in range(Q.shape[1]):
        out[j, idx[:, j]] = True
    return out


@dataclass
class Discrepancy:
    """A fitted discrepancy in the robot base frame (see the module docstring).

    Attributes:
        kind: ``exact``, ``inducing`` (DTC) or ``white`` (no correlation: the residual level per row).
        joint_names: the robot's joints, in the order of the columns of Q.
        scale_m: S, per-axis scale (3,) m; mean_m: the residuals' mean (3,) m.
        noise: w, the white level in normalised units (variance ratio).
        kernel: the :class:`JointKernel` (None for ``white``).
        Z: training (exact) or inducing (DTC) configurations (m, d) rad.
        y: normalised training residuals (exact only), (m, 3).
        alpha: posterior weights (m, 3) (DTC: stored; exact: computed).
        Minv: DTC's K_ZZ⁻¹ − A⁻¹ (m, m).
        coverage: (d, bins) bool, the joint-angle bins the training rows visit.
        n_rows: training rows; cv: the K-fold held-out check (plain numbers); decision: one line.
        param_names, param_cov, Bn: the parametric part's uncertainty under the discrepancy (universal
            kriging, :meth:`set_parametric` / :meth:`parametric_covariance`): the names of the robot
            parameters it covers, C = (Σ_a s_a⁻² F_aᵀ (K + wI)⁻¹ F_a)⁻¹ over them and the training set-ups
            (P, P), and (K + wI)⁻¹ F_a per axis (n, 3, P) (exact only; the white kind needs none).
    """

    kind: str
    joint_names: list
    scale_m: np.ndarray
    mean_m: np.ndarray
    noise: float
    kernel: JointKernel | None = None
    Z: np.ndarray | None = None
    y: np.ndarray | None = None
    alpha: np.ndarray | None = None
    Minv: np.ndarray | None = None
    coverage: np.ndarray | None = None
    n_rows: int = 0
    cv: dict = field(default_factory=dict)
    decision: str = ""
    time_s: float = 0.0
    param_names: list = field(default_factory=list)
    param_cov: np.ndarray | None = None
    Bn: np.ndarray | None = None
    _chol: Any = field(default=None, repr=False)

    # ------------------------------------------------------------------ posterior
    def _factor(self) -> Any:
        if self._chol is None and self.kind == "exact":
            K = self.kernel(self.Z) + (self.noise + _JITTER) * np.eye(len(self.Z))
            self._chol = sla.cho_factor(K, lower=True, check_finite=False)
            self.alpha = sla.cho_solve(self._chol, self.y, check_finite=False)
        return self._chol

    def set_factor(self, L: np.ndarray) -> None:
        """Use L, the lower Cholesky factor of K(Z, Z) + (w + jitter) I (the K-fold check's), as the exact posterior's
        factor instead of forming it again."""
        self._chol = (L, True)
        self.alpha = sla.cho_solve(self._chol, self.y, check_finite=False)

    def predict_normalised(self, Q: np.ndarray, return_var: bool = True, chunk: int = 4000
                           ) -> tuple[np.ndarray, np.ndarray | None]:
        """Posterior mean (m, 3) and variance (m,) of δ in normalised units (variance without the white term)."""
        Q = np.atleast_2d(np.asarray(Q, float))
        m = Q.shape[0]
        if self.kind == "white":
            return np.zeros((m, 3)), (np.zeros(m) if return_var else None)
        self._factor()
        mu = np.empty((m, 3))
        var = np.empty(m) if return_var else None
        for a in range(0, m, chunk):
            W = Q[a:a + chunk]
            Kwz = self.kernel(W, self.Z)
            mu[a:a + chunk] = Kwz @ self.alpha
            if return_var:
                if self.kind == "exact":
                    V = sla.solve_triangular(self._chol[0], Kwz.T, lower=True, check_finite=False)
                    red = np.einsum("ij,ij->j", V, V)
                else:
                    red = np.einsum("ij,ij->i", Kwz @ self.Minv, Kwz)
                var[a:a + chunk] = np.maximum(self.kernel.diag(W) - red, 0.0)
        return mu, var

    def predict(self, Q: np.ndarray, return_var: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """δ at configurations Q in the base frame: mean (m, 3) m and its variance per axis (m, 3) m².

        The variance is that of δ (posterior); :attr:`noise_var_m2` is added for a new measurement.
        """
        mu, v = self.predict_normalised(Q, return_var)
        mean = mu * self.scale_m + self.mean_m if self.kind != "white" else np.zeros_like(mu)
        var = None
        if return_var:
            var = v[:, None] * self.scale_m ** 2
        return mean, var

    def set_parametric(self, F: np.ndarray, names: list) -> None:
        """Store the generalised-least-squares covariance of the parameters under Σ = S²(K + wI).

        Args:
            F: Jacobian of the training rows' predictions (base frame) w.r.t. the parameters, (n, 3, P)
                (robot parameters first, named by ``names``; then the training stations' set-up parameters).
            names: the robot parameters' names (the first ``len(names)`` columns of F).
        """
        n, _, P = F.shape
        if self.kind == "exact":
            self._factor()
            Bn = np.stack([sla.cho_solve(self._chol, F[:, a, :], check_finite=False) for a in range(3)], axis=1)
            info = sum(F[:, a, :].T @ Bn[:, a, :] / self.scale_m[a] ** 2 for a in range(3))
            self.Bn = Bn
        elif self.kind == "white":
            info = sum(F[:, a, :].T @ F[:, a, :] / self.noise_var_m2[a] for a in range(3))
        else:
            return
        self.param_cov = np.linalg.pinv(0.5 * (info + info.T), rcond=1e-12, hermitian=True)
        self.param_names = list(names)

    def parametric_covariance(self, Q: np.ndarray, E: np.ndarray) -> np.ndarray:
        """(m, 3, 3) base-frame covariance (m²) of the prediction error the parametric part adds at Q.

        Universal kriging: (E − K_WQ Σ⁻¹ F) C (E − K_WQ Σ⁻¹ F)ᵀ with E the Jacobian of the predictions at Q
        w.r.t. the robot parameters (base frame, (m, 3, R); the set-up columns are zero: a new station's set-up
        is re-registered). Near the training rows the discrepancy reproduces the parametric error
        (K_WQ Σ⁻¹ F ≈ E) and the term vanishes; far from them it is E C Eᵀ.
        """
        m = len(Q)
        if self.param_cov is None:
            return np.zeros((m, 3, 3))
        P = self.param_cov.shape[0]
        D = np.zeros((m, 3, P))
        D[:, :, :E.shape[2]] = E
        if self.Bn is not None:
            Kwq = self.kernel(np.atleast_2d(Q), self.Z)
            for a in range(3):
                D[:, a, :] -= Kwq @ self.Bn[:, a, :]
        return np.einsum("map,pq,mbq->mab", D, self.param_cov, D)

    @property
    def prior_sigma_m(self) -> np.ndarray:
        """Per-axis σ (m) of the residuals of the parametric model alone: prior variance of δ plus the white level."""
        k0 = 0.0 if self.kind == "white" else float(self.kernel.diag(np.zeros((1, len(self.joint_names))))[0])
        return np.sqrt((k0 + self.noise) * self.scale_m ** 2)

    @property
    def noise_var_m2(self) -> np.ndarray:
        """Variance per axis (m²) of what repeats from pose to pose only (tracker noise, repeatability)."""
        return self.noise * self.scale_m ** 2

    def covariance(self, Qa: np.ndarray, Qb: np.ndarray | None = None) -> np.ndarray:
        """Prior covariance k(Qa, Qb) in normalised units (multiply by s_a² for axis a, m²)."""
        if self.kind == "white":
            Qb = Qa if Qb is None else Qb
            return np.zeros((len(Qa), len(Qb)))
        return self.kernel(np.atleast_2d(Qa), None if Qb is None else np.atleast_2d(Qb))

    def extrapolation(self, Q: np.ndarray) -> np.ndarray:
        """(m,) bool: rows with a joint angle in a bin (``COVERAGE_BIN_RAD``) no training row visited, or its
        neighbour."""
        if self.coverage is None:
            return np.zeros(len(Q), bool)
        cov = self.coverage | np.roll(self.coverage, 1, axis=1) | np.roll(self.coverage, -1, axis=1)
        W = np.mod(np.atleast_2d(Q) + np.pi, 2 * np.pi)
        idx = np.minimum((W / COVERAGE_BIN_RAD).astype(int), _NBINS - 1)
        inside = np.ones(len(idx), bool)
        for j in range(idx.shape[1]):
            inside &= cov[j, idx[:, j]]
        return ~inside

    # ------------------------------------------------------------------ plain data
    def to_dict(self) -> dict:
        """The model file's ``discrepancy`` block (SI units; arrays base64 float64)."""
        d: dict[str, Any] = {"format": "pin_kpi_oed.discrepancy/1", "kind": self.kind, "frame": "robot_base",
             "joint_names": list(self.joint_names), "scale_m": [float(v) for v in self.scale_m],
             "mean_m": [float(v) for v in self.mean_m], "noise": float(self.noise), "n_rows": int(self.n_rows),
             "coverage_bin_rad": COVERAGE_BIN_RAD, "cv": self.cv, "decision": self.decision}
        if self.coverage is not None:
            d["coverage"] = ["".join("1" if b else "0" for b in row) for row in self.coverage]
        if self.param_cov is not None:
            d["parametric"] = {"param_names": list(self.param_names), "covariance": encode_array(self.param_cov)}
            if self.Bn is not None:
                d["parametric"]["Bn"] = encode_array(self.Bn)
        if self.kind != "white":
            d["kernel"] = self.kernel.to_dict()
            d["Z_rad"] = encode_array(self.Z)
            if self.kind == "exact":
                d["y"] = encode_array(self.y)
            else:
                d["alpha"] = encode_array(self.alpha)
                d["Minv"] = encode_array(self.Minv)
        return d

    @classmethod
    def from_dict(cls, d: Any, joint_names: Sequence[str], where: str = "discrepancy") -> Discrepancy:
        """Rebuild from :meth:`to_dict` output, every field checked against the robot's joints.

        Raises:
            InputError: a damaged block (the field named, with ``where``).
        """
        try:
            return cls._from_dict(d, list(joint_names), where)
        except ValueError as exc:
            raise InputError(f"{exc}") from None

    @classmethod
    def _from_dict(cls, d: Any, names: list, where: str) -> Discrepancy:
        if not isinstance(d, dict):
            raise ValueError(f"{where}: must be an object (write it with identify or diagnose --model-out)")
        if d.get("format") != "pin_kpi_oed.discrepancy/1":
            raise ValueError(f"{where}.format: {d.get('format')!r} is not 'pin_kpi_oed.discrepancy/1'")
        kind = d.get("kind")
        if kind not in ("exact", "inducing", "white"):
            raise ValueError(f"{where}.kind: {kind!r} is not exact, inducing or white")
        if list(d.get("joint_names") or []) != names:
            raise ValueError(f"{where}.joint_names: {d.get('joint_names')!r} do not match the robot's joints "
                             f"{', '.join(names)}")

        def vec3(key: str, positive: bool) -> np.ndarray:
            try:
                v = np.asarray(d.get(key), dtype=float)
            except (TypeError, ValueError):
                raise ValueError(f"{where}.{key}: must be 3 numbers (m), got {d.get(key)!r}") from None
            if v.shape != (3,) or not np.all(np.isfinite(v)) or (positive and np.any(v <= 0)):
                raise ValueError(f"{where}.{key}: must be 3 finite{' positive' if positive else ''} numbers (m), "
                                 f"got {d.get(key)!r}")
            return v
        scale, mean = vec3("scale_m", True), vec3("mean_m", False)
        noise = d.get("noise")
        if isinstance(noise, bool) or not isinstance(noise, (int, float)) or not np.isfinite(noise) or noise < 0:
            raise ValueError(f"{where}.noise: must be a non-negative number, got {noise!r}")
        cov = d.get("coverage")
        coverage = None
        if cov is not None:
            if (not isinstance(cov, list) or len(cov) != len(names)
                    or any(not isinstance(r, str) or len(r) != _NBINS or set(r) - {"0", "1"} for r in cov)):
                raise ValueError(f"{where}.coverage: must be {len(names)} strings of {_NBINS} '0'/'1'")
            coverage = np.array([[c == "1" for c in r] for r in cov])
        out = cls(kind, names, scale, mean, float(noise), coverage=coverage, n_rows=_file_int(d, "n_rows", where),
                  cv=_file_cv(d.get("cv"), where), decision=str(d.get("decision") or ""))
        par = d.get("parametric")
        if par is not None:
            if not isinstance(par, dict) or not isinstance(par.get("param_names"), list):
                raise ValueError(f"{where}.parametric: must hold 'param_names' and 'covariance'")
            out.param_names = _file_param_names(par["param_names"], names, where)
            if kind == "white" and par.get("Bn") is not None:
                raise ValueError(f"{where}.parametric.Bn: a white discrepancy ('kind') has no Gaussian process to "
                                 "hold it; the block was written for kind exact (was 'kind' edited?)")
            out.param_cov = decode_array(par.get("covariance"), f"{where}.parametric.covariance", (None, None))
            P = out.param_cov.shape[0]
            if out.param_cov.shape != (P, P) or len(out.param_names) > P:
                raise ValueError(f"{where}.parametric.covariance: must be square with at least one row per name")
            if par.get("Bn") is not None:
                out.Bn = decode_array(par["Bn"], f"{where}.parametric.Bn", (None, 3, P))
        if kind == "white":
            _check_file_sigma(out, where)
            return out
        out.kernel = JointKernel.from_dict(d.get("kernel"), len(names), f"{where}.kernel")
        _check_file_sigma(out, where)
        out.Z = decode_array(d.get("Z_rad"), f"{where}.Z_rad", (None, len(names)))
        m = out.Z.shape[0]
        if out.Bn is not None and out.Bn.shape[0] != m:
            raise ValueError(f"{where}.parametric.Bn: {out.Bn.shape[0]} rows for {m} training configurations")
        if kind == "exact":
            out.y = decode_array(d.get("y"), f"{where}.y", (m, 3))
        else:
            out.alpha = decode_array(d.get("alpha"), f"{where}.alpha", (m, 3))
            out.Minv = decode_array(d.get("Minv"), f"{where}.Minv", (m, m))
        return out


#: the largest per-axis sigma of a discrepancy a model file may hold (m): a robot's residual after its geometric
#: calibration is a fraction of a millimetre; 5 mm means a value written in mm (``scale_m``) or an edited kernel
FILE_SIGMA_MAX_M = 5e-3
#: the largest white level of a model file (normalised units; the fit keeps it at most 10)
FILE_NOISE_MAX = 1e3
_PARAM_KINDS = ("tx", "ty", "tz", "rx", "ry", "rz")


def _cv_rows(n: int, opts: DiscrepancyOptions) -> np.ndarray:
    """The rows of the K-fold check: all up to ``max_exact`` (exact folds); beyond, a seeded subset of ``max_exact``
    (folds of inducing posteriors over every row cost minutes on 50,000 rows and tell no more about the gain)."""
    if n <= opts.max_exact:
        return np.arange(n)
    return np.sort(np.random.default_rng(opts.seed + 7).choice(n, opts.max_exact, replace=False))


def _file_int(d: dict, key: str, where: str) -> int:
    v = d.get(key) or 0
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or v < 0 or v != int(v):
        raise ValueError(f"{where}.{key}: must be a whole number >= 0, got {v!r}")
    return int(v)


def _file_cv(cv: Any, where: str) -> dict:
    if cv is None:
        return {}
    if not isinstance(cv, dict):
        raise ValueError(f"{where}.cv: must be an object (the K-fold check's numbers), got {cv!r:.60}")
    return dict(cv)


def _file_param_names(names: list, joints: list, where: str) -> list:
    known = {f"{j}.{k}" for j in joints for k in _PARAM_KINDS}
    for x in names:
        if str(x) not in known:
            raise ValueError(f"{where}.parametric.param_names: {x!r} is not a joint-placement parameter of this robot "
                             f"(JOINT.tx .. JOINT.rz of {', '.join(joints)})")
    return [str(x) for x in names]


def _check_file_sigma(disc: "Discrepancy", where: str) -> None:
    if disc.noise > FILE_NOISE_MAX:
        raise ValueError(f"{where}.noise: {disc.noise:g} is more than {FILE_NOISE_MAX:g} (normalised units; the fit "
                         "keeps it at most 10); was the file edited?")
    sig = disc.prior_sigma_m
    if not np.all(np.isfinite(sig)) or np.any(sig > FILE_SIGMA_MAX_M):
        raise ValueError(f"{where}.scale_m: the discrepancy's sigma per axis {', '.join(f'{s:.3g}' for s in sig)} m is "
                         f"more than {FILE_SIGMA_MAX_M * 1e3:g} mm: scale_m is in m (and noise, kernel amplitudes "
                         "normalised); was it written in mm?")


# --------------------------------------------------------------------------- fitting
def _hyper_fit(Q: np.ndarray, Y: np.ndarray, opts: DiscrepancyOptions, joint_amplitude: float
               ) -> tuple[JointKernel, float]:
    """Maximum marginal likelihood of the kernel and the white level on a seeded subset (normalised Y),
    from a start whose additive (one-joint) amplitudes are ``joint_amplitude``
    (:func:`~pin_kpi_oed.discrepancy.marginal.maximise_marginal_likelihood`)."""
    from pin_kpi_oed.discrepancy.marginal import maximise_marginal_likelihood

    d = Q.shape[1]
    rng = np.random.default_rng(opts.seed)
    sub = rng.permutation(len(Q))[:opts.n_fit]
    k0 = JointKernel(0.7, np.ones(d), np.full(d, joint_amplitude), np.full(d, 0.5))
    kernel, noise, _ = maximise_marginal_likelihood(Q[sub], Y[sub], k0, 0.3, (1e-5, 10.0), opts.max_iter,
                                                    opts.restarts, opts.seed)
    return kernel, noise


def _posterior(kernel: JointKernel, noise: float, Q: np.ndarray, Y: np.ndarray, opts: DiscrepancyOptions,
               rng: np.random.Generator, chunk: int = 2000) -> dict:
    """Exact (n ≤ max_exact) or DTC posterior pieces for :class:`Discrepancy`."""
    n = len(Q)
    if n <= opts.max_exact:
        return {"kind": "exact", "Z": Q.copy(), "y": Y.copy()}
    Z = Q[np.sort(rng.permutation(n)[:opts.n_inducing])]
    m = len(Z)
    Lz = _stable_cholesky(kernel(Z))
    # A = K_ZZ + w⁻¹ K_ZQ K_QZ = L_z B L_zᵀ with B = I + w⁻¹ V Vᵀ, V = L_z⁻¹ K_ZQ (eigenvalues of B ≥ 1)
    B = np.eye(m)
    c = np.zeros((m, 3))
    for a in range(0, n, chunk):
        V = sla.solve_triangular(Lz, kernel(Z, Q[a:a + chunk]), lower=True, check_finite=False)
        B += V @ V.T / noise
        c += V @ Y[a:a + chunk] / noise
    cB = sla.cho_factor(B, lower=True, check_finite=False)
    alpha = sla.solve_triangular(Lz, sla.cho_solve(cB, c, check_finite=False), lower=True, trans="T",
                                 check_finite=False)
    inner = np.eye(m) - sla.cho_solve(cB, np.eye(m), check_finite=False)           # I − B⁻¹
    Li = sla.solve_triangular(Lz, np.eye(m), lower=True, check_finite=False)       # L_z⁻¹
    Minv = Li.T @ inner @ Li                                                      # K_ZZ⁻¹ − A⁻¹
    return {"kind": "inducing", "Z": Z, "alpha": alpha, "Minv": 0.5 * (Minv + Minv.T)}


def _stable_cholesky(K: np.ndarray) -> np.ndarray:
    """Lower Cholesky factor of K, with jitter raised from 1e-8 to 1e-2 of its mean diagonal until it succeeds."""
    scale = float(np.mean(np.diag(K)))
    for jitter in (1e-8, 1e-6, 1e-4, 1e-2):
        try:
            return np.linalg.cholesky(K + jitter * scale * np.eye(len(K)))
        except np.linalg.LinAlgError:
            continue
    raise np.linalg.LinAlgError("the inducing configurations' kernel matrix is not positive definite")


def _spd_inverse(S: np.ndarray, keep: dict | None = None) -> np.ndarray:
    """Inverse of a symmetric positive-definite matrix from its Cholesky factor (LAPACK potrf + potri); the lower
    factor is stored in ``keep["chol"]`` when ``keep`` is given."""
    Lc, info = sla.lapack.dpotrf(S, lower=1, clean=1, overwrite_a=0)
    if info != 0:
        raise np.linalg.LinAlgError("the discrepancy covariance is not positive definite")
    if keep is not None:
        keep["chol"] = Lc.copy()
    Si, info = sla.lapack.dpotri(Lc, lower=1, overwrite_c=1)
    if info != 0:
        raise np.linalg.LinAlgError("the discrepancy covariance could not be inverted")
    Si = np.tril(Si)
    return Si + np.tril(Si, -1).T


def _kfold(kernel: JointKernel, noise: float, Q: np.ndarray, Y: np.ndarray, scale: np.ndarray,
           opts: DiscrepancyOptions, names: list, keep: dict | None = None) -> dict:
    """K-fold held-out check with the hyper-parameters fixed: mean 3-D error (m) without and with δ,
    and the standardised errors of the held-out rows.

    Up to ``max_exact`` rows the folds come from one inverse of Σ = K + wI (block inversion: the
    held-out residuals of fold I are (Σ⁻¹)_II⁻¹ (Σ⁻¹y)_I with covariance (Σ⁻¹)_II⁻¹, exactly what refitting
    the posterior without fold I gives); above it each fold's DTC posterior is built. Σ is the exact posterior's
    (jitter included), and its Cholesky factor is stored in ``keep["chol"]`` for the posterior when ``keep`` is given.
    """
    rng = np.random.default_rng(opts.seed + 1)
    fold = rng.permutation(len(Q)) % opts.folds
    e0, e1, z2, inside = [], [], [], []
    exact = len(Q) <= opts.max_exact
    if exact:
        S = kernel(Q)
        S[np.diag_indices_from(S)] += noise + _JITTER
        Si = _spd_inverse(S, keep)
        alpha = Si @ Y
    for k in range(opts.folds):
        tr, te = fold != k, fold == k
        if exact:
            c = sla.cho_factor(Si[np.ix_(te, te)], lower=True, check_finite=False)
            r = sla.cho_solve(c, alpha[te], check_finite=False)                  # y_I − μ_I (normalised)
            var = np.diag(sla.cho_solve(c, np.eye(int(te.sum())), check_finite=False))
        else:
            post = _posterior(kernel, noise, Q[tr], Y[tr], opts, np.random.default_rng(opts.seed + 2 + k))
            dk = Discrepancy(post["kind"], names, scale, np.zeros(3), noise, kernel, post["Z"], post.get("y"),
                             post.get("alpha"), post.get("Minv"))
            mu, v = dk.predict_normalised(Q[te])
            r, var = Y[te] - mu, v + noise
        e0.append(np.linalg.norm(Y[te] * scale, axis=1))
        e1.append(np.linalg.norm(r * scale, axis=1))
        zz = r ** 2 / var[:, None]
        z2.append(zz)
        inside.append(zz.sum(1) <= 7.8147)
    a0, a1, zz2 = np.concatenate(e0), np.concatenate(e1), np.vstack(z2)
    return {"folds": opts.folds, "mean_without_m": float(a0.mean()), "mean_with_m": float(a1.mean()),
            "rms_without_m": float(np.sqrt(np.mean(a0 ** 2))), "rms_with_m": float(np.sqrt(np.mean(a1 ** 2))),
            "z_rms": float(np.sqrt(zz2.mean())), "inside_95": float(np.concatenate(inside).mean())}


def fit_discrepancy(Q: np.ndarray, R: np.ndarray, joint_names: Sequence[str],
                    options: DiscrepancyOptions | None = None) -> Discrepancy | None:
    """Fit δ to the residuals of a parametric fit.

    Args:
        Q: training configurations (n, d) rad.
        R: residuals measured − predicted in the robot base frame (n, 3) m.
        joint_names: the robot's joints (columns of Q).
        options: :class:`DiscrepancyOptions` (mode ``none`` returns None).

    Returns:
        The :class:`Discrepancy` (``decision`` says what was decided and why), or None for mode ``none``.

    Raises:
        InputError: too few rows for mode ``on``, non-finite residuals.
    """
    t0 = time.perf_counter()
    opts = options or DiscrepancyOptions()
    if opts.mode == "none":
        return None
    Q = np.atleast_2d(np.asarray(Q, float))
    R = np.asarray(R, float).reshape(-1, 3)
    names = list(joint_names)
    if not np.all(np.isfinite(R)) or not np.all(np.isfinite(Q)):
        raise InputError("discrepancy: non-finite residuals or joint values")
    n = len(Q)
    mean = R.mean(axis=0)
    scale = np.maximum(R.std(axis=0), 1e-12)
    white = Discrepancy("white", names, scale, np.zeros(3), 1.0, coverage=_coverage_bins(Q), n_rows=n)
    white.scale_m = np.sqrt(np.mean(R ** 2, axis=0))
    if n < opts.min_rows:
        if opts.mode == "on":
            raise InputError(f"discrepancy: {n} measurements are too few for the Gaussian process (at least "
                             f"{opts.min_rows}); measure more poses or use --discrepancy auto/none")
        white.decision = (f"discrepancy: white (residual RMS per axis only): {n} measurements, fewer than the "
                          f"{opts.min_rows} a Gaussian process needs")
        white.time_s = time.perf_counter() - t0
        return white
    Y = (R - mean) / scale
    best = None
    cv_rows = _cv_rows(n, opts)
    for a0 in opts.starts:
        kernel, noise = _hyper_fit(Q, Y, opts, float(a0))
        keep: dict = {}  # the factor of all rows (reused by an exact posterior): only when the check uses them all
        cv = _kfold(kernel, noise, Q[cv_rows], Y[cv_rows], scale, opts, names, keep if len(cv_rows) == n else None)
        if best is None or cv["mean_with_m"] < best[2]["mean_with_m"]:
            best = (kernel, noise, cv, keep.get("chol"))
    kernel, noise, cv, chol = best
    gain = 1.0 - cv["mean_with_m"] / cv["mean_without_m"]
    cv["gain"] = float(gain)
    words = (f"{opts.folds}-fold held-out mean {cv['mean_without_m'] * 1e3:.4f} -> {cv['mean_with_m'] * 1e3:.4f} mm "
             f"({gain * 100:+.1f} %), standardised RMS {cv['z_rms']:.2f}"
             + (f", on a seeded subset of {len(cv_rows)} of the {n} rows" if len(cv_rows) < n else ""))
    if opts.mode == "auto" and gain < opts.min_gain:
        white.cv = cv
        white.decision = (f"discrepancy: white (residual RMS per axis only): the Gaussian process does not lower the "
                          f"held-out error enough ({words}; needs {opts.min_gain * 100:.0f} %)")
        white.time_s = time.perf_counter() - t0
        return white
    post = _posterior(kernel, noise, Q, Y, opts, np.random.default_rng(opts.seed + 100))
    out = Discrepancy(post["kind"], names, scale, mean, noise, kernel, post["Z"], post.get("y"), post.get("alpha"),
                      post.get("Minv"), _coverage_bins(Q), n, cv)
    if post["kind"] == "exact" and chol is not None:
        out.set_factor(chol)
    out.decision = (f"discrepancy: Gaussian process fitted ({post['kind']}, {n} rows): {words}")
    out.time_s = time.perf_counter() - t0
    return out
