r"""Below what a Gaussian-process fit needs: the discrepancy as joint-angle errors, its level from the residuals.

What a geometric calibration leaves on an arm is mostly an error of the joint angles (transmission and encoder
errors, gear harmonics): δ(q) = J_q(q) η(q), J_q the measured point's Jacobian w.r.t. the joint angles and η_j a
smooth periodic function of joint j's angle alone,

.. math::  \operatorname{cov}(η_j(q), η_j(q')) = τ^2 κ(q_j, q'_j), \qquad
           κ(a, b) = \exp\!\Big(-\frac{2\sin^2((a - b)/2)}{\ell^2}\Big),

independent between joints. The measured rows are y = h(p, q) + δ(q) + ε with white ε (σ_n² per axis). With few
poses the geometric parameters absorb a large part of such an error (an error of a joint's angle that varies with the
angle looks locally like a tilted or offset joint axis) and extrapolate it: a white level from the residuals, even
corrected for the p fitted parameters, then under-states the error at a new pose, and the rows' own residuals do not
show it (their leave-one-out errors look as the white level says).

**Level.** For each ℓ of :data:`LENGTH_SCALES_RAD`, τ² and σ_n² by restricted maximum likelihood on what the fit
leaves: with N an orthonormal basis of the residual space of the stacked Jacobian F (3n × p) and K the 3n × 3n
covariance of δ at the rows (K_ik = Σ_j J_q,i[:, j] κ(q_ij, q_kj) J_q,k[:, j]ᵀ), z = Nᵀ r ~ N(0, τ² NᵀKN + σ_n² I)
(the restricted likelihood counts what the parameters absorbed, which the residual level alone cannot see). σ_n is
at least the data's stated noise; both variances are widened for their small-sample uncertainty like the white
level (:func:`~pin_kpi_oed.discrepancy.gp.white_level`).

**Which structure.** An ℓ is a candidate when its restricted likelihood rejects τ² = 0 (the white level) at 5 %
(2 Δℓ > 2.71, the boundary's ½χ²₀ + ½χ²₁). Among the candidates and the white level, the one of largest
leave-one-pose-out log predictive density of the least-squares predictor (:func:`loo_log_density`: every pose
predicted by a fit without its rows, its error's Gaussian log density under the structure's covariance) is kept.
The restricted likelihood alone can prefer a short ℓ on real data whose errors it then over-states at new poses (a
few random subsets of the UR10's Series C, docs/results.md); the left-out poses' density, a proper score, sees a σ
too wide as well as one too narrow.

**The σ of the prediction the model makes** (the least-squares parameters p̂ = p + F⁺ (δ_Q + ε_Q), no kriging
mean): at a new configuration q with parameter Jacobian E(q),

.. math::  e(q) = δ(q) + ε - E F^+ (δ_Q + ε_Q), \qquad
           \operatorname{cov} e = τ^2 J_q J_q^T + σ_n^2 I + E\,C\,E^T - E G - G^T E^T,

C = F⁺ (τ² K + σ_n² I) F⁺ᵀ the parameters' covariance under this error (the sandwich, stored as the discrepancy's
``param_cov``) and G = F⁺ k_Q(q), k_Q(q) the 3n × 3 covariance of δ at the rows with δ(q). Far from the rows
(G → 0) the parameters' error and the joint-angle error add; near them the cross term takes back what the fit
absorbed (checked against Monte-Carlo in ``tests/test_joint_angle_sigma.py``). It is the σ of the predictor the
model uses (least-squares parameters, no kriging mean). A kernel of the wrong shape can make that cross term take
back too much near the rows; the covariance a model reports is therefore never below the white level's at the same
pose in any direction (``calibrated.prediction_sigma``: the positive part of the difference is added).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import minimize

from pin_kpi_oed.discrepancy.arrays import decode_array, encode_array
from pin_kpi_oed.discrepancy.sandwich import row_sandwich

__all__ = ["JointAngleTerm", "fit_joint_angle", "loo_log_density", "LENGTH_SCALE_RAD", "LENGTH_SCALES_RAD",
           "LR_CRITICAL", "VETO_SE", "MAX_ROWS", "joint_angle_kernel", "restricted_space", "nll_and_grad",
           "residual_basis", "loo_plan"]

#: ℓ of κ (rad): the one-joint length scale of the design's prior kernel
LENGTH_SCALE_RAD = 0.5
#: the ℓ tried (rad): harmonics of orders about 1 to 5 per revolution
LENGTH_SCALES_RAD = (0.2, 0.35, 0.5, 0.7, 1.0)
#: 2 Δℓ beyond which an ℓ is a candidate (5 % test of τ² = 0, a boundary: ½χ²₀ + ½χ²₁)
LR_CRITICAL = 2.706
#: an ℓ whose leave-one-pose-out log predictive density falls below the white level's by more than this many
#: standard errors of the difference is left out
VETO_SE = 2.0
#: above this many rows the joint-angle errors are not tried (the check is O(n³) per left-out pose)
MAX_ROWS = 400


def _kappa(A: np.ndarray, B: np.ndarray, ell: float) -> np.ndarray:
    """κ per joint between the rows of A (n, d) and B (m, d): (n, m, d)."""
    return np.exp(-(2.0 - 2.0 * np.cos(A[:, None, :] - B[None, :, :])) / (2.0 * ell ** 2))


def joint_angle_kernel(Qa: np.ndarray, Ja: np.ndarray, Qb: np.ndarray, Jb: np.ndarray, ell: float) -> np.ndarray:
    """Covariance of δ (per unit τ²) between rows a and b: (n, 3, m, 3), Σ_j J_a,ij κ_ikj J_b,kj.

    The joints' terms (J_a κ) J_b are added in the joints' order as whole arrays: the products and sums of
    ``einsum("iaj,ikj,kbj->iakb")`` in its order, the same numbers to the last bit (tested), in half its time.
    """
    Ja, Jb = np.asarray(Ja, float), np.asarray(Jb, float)
    kap = _kappa(Qa, Qb, ell)
    n, m, d = kap.shape
    out = np.zeros((n, 3, m, 3))
    term = np.empty_like(out)
    for j in range(d):
        np.multiply(Ja[:, :, None, None, j], kap[:, None, :, None, j], out=term)
        term *= Jb[None, None, :, :, j]
        out += term
    return out


@dataclass
class JointAngleTerm:
    """The joint-angle part of a discrepancy (module docstring).

    Attributes:
        tau2: τ² (rad²), the variance of each joint's angle error.
        noise_var_m2: σ_n² (m²), the white variance per axis.
        length_scale_rad: ℓ.
        Q: the training configurations (n, d) rad; Jq: their ∂y/∂q in the robot base frame (n, 3, d) m/rad.
        Fplus: F⁺ (P, 3n), the least-squares map from the training rows' residuals to the parameters.
        param_cov: C (P, P), the parameters' covariance under this error.
        white_sigma_m: the white level it was chosen over (3,) m, per axis, or None: the σ is never below that
            level's (:meth:`white_covariance`).
    """

    tau2: float
    noise_var_m2: float
    length_scale_rad: float
    Q: np.ndarray
    Jq: np.ndarray
    Fplus: np.ndarray
    param_cov: np.ndarray
    white_sigma_m: np.ndarray | None = None

    def white_covariance(self, E: np.ndarray) -> np.ndarray | None:
        """(m, 3, 3) m²: the white level's covariance of measured − predicted, diag(w²) + E C_w Eᵀ with
        C_w = F⁺ diag(w²) F⁺ᵀ (parameter Jacobian E (m, 3, ≤ P), base frame), or None without a white level."""
        if self.white_sigma_m is None:
            return None
        w2 = np.asarray(self.white_sigma_m, float) ** 2
        P, n3 = self.Fplus.shape
        Cw = (self.Fplus * np.tile(w2, n3 // 3)) @ self.Fplus.T
        D = np.zeros((E.shape[0], 3, P))
        D[:, :, :E.shape[2]] = E
        return row_sandwich(D, Cw) + np.diag(w2)

    def covariance(self, Q: np.ndarray, Jq: np.ndarray, E: np.ndarray,
                   registration: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> np.ndarray:
        """(m, 3, 3) m²: τ² J_q J_qᵀ − E G − Gᵀ Eᵀ at configurations Q (rad) with ∂y/∂q ``Jq`` (m, 3, d) and
        parameter Jacobian E (m, 3, ≤ P; missing columns are zero) in the robot base frame. The white variance and
        E C Eᵀ are added by the caller (the discrepancy's white level and parametric covariance).

        ``registration``: (A (m, 3, 3r), Q_R (r, d), J_q,R (r, 3, d)) of a station whose set-up was registered on
        rows R, A the set-up's move at each q per unit residual at R (E then the projected Ẽ = E − A J_R): the
        registration absorbs A δ_R of the joint-angle error too, so δ(q) becomes δ(q) − A δ_R (its variance, its
        covariance with the training rows, and the registration's own noise A σ_n² Aᵀ)."""
        Q = np.atleast_2d(np.asarray(Q, float))
        m = len(Q)
        P = self.Fplus.shape[0]
        D = np.zeros((m, 3, P))
        D[:, :, :E.shape[2]] = E
        t2, ell, n3 = self.tau2, self.length_scale_rad, 3 * len(self.Q)
        own = t2 * np.einsum("maj,mbj->mab", Jq, Jq)
        k = t2 * joint_angle_kernel(self.Q, self.Jq, Q, Jq, ell).reshape(n3, m, 3)                # cov(δ_Q, δ(q))
        if registration is not None:
            A, QR, JR = registration
            r3 = 3 * len(QR)
            KRq = t2 * joint_angle_kernel(QR, JR, Q, Jq, ell).reshape(r3, m, 3)
            KRR = t2 * joint_angle_kernel(QR, JR, QR, JR, ell).reshape(r3, r3)
            KQR = t2 * joint_angle_kernel(self.Q, self.Jq, QR, JR, ell).reshape(n3, r3)
            AK = np.einsum("man,nmb->mab", A, KRq)
            own = (own - AK - AK.transpose(0, 2, 1) + np.einsum("man,nk,mbk->mab", A, KRR, A)
                   + self.noise_var_m2 * np.einsum("man,mbn->mab", A, A))
            k = k - np.einsum("nr,mar->nma", KQR, A)
        G = np.einsum("pn,nmb->mpb", self.Fplus, k)                                   # (m, P, 3)
        EG = np.einsum("map,mpb->mab", D, G)
        return own - EG - EG.transpose(0, 2, 1)

    def covariance_between(self, Q: np.ndarray, Jq: np.ndarray, E: np.ndarray) -> np.ndarray:
        """(m, 3, m, 3) m²: :meth:`covariance` between every pair of rows (τ² k(q_i, q_k) − E_i G_k − G_iᵀ E_kᵀ), the
        rows' correlations a check of several rows needs; its diagonal blocks equal :meth:`covariance` without a
        registration."""
        Q = np.atleast_2d(np.asarray(Q, float))
        m, P = len(Q), self.Fplus.shape[0]
        D = np.zeros((m, 3, P))
        D[:, :, :E.shape[2]] = E
        own = self.tau2 * joint_angle_kernel(Q, Jq, Q, Jq, self.length_scale_rad)
        k = self.tau2 * joint_angle_kernel(self.Q, self.Jq, Q, Jq, self.length_scale_rad).reshape(3 * len(self.Q), m, 3)
        EG = np.einsum("iap,kpb->iakb", D, np.einsum("pn,nmb->mpb", self.Fplus, k))
        return own - EG - EG.transpose(2, 3, 0, 1)

    def to_dict(self) -> dict:
        """The model file's ``discrepancy.joint_angle`` block (SI units)."""
        return {"tau_rad": float(np.sqrt(self.tau2)), "noise_sigma_m": float(np.sqrt(self.noise_var_m2)),
                "length_scale_rad": float(self.length_scale_rad), "Q_rad": encode_array(self.Q),
                "Jq": encode_array(self.Jq), "Fplus": encode_array(self.Fplus),
                "white_sigma_m": None if self.white_sigma_m is None else [float(v) for v in self.white_sigma_m]}

    @classmethod
    def from_dict(cls, d: Any, n_joints: int, param_cov: np.ndarray | None, where: str) -> JointAngleTerm:
        """Inverse of :meth:`to_dict`; ``param_cov`` is the discrepancy's. Raises ValueError naming the field."""
        if not isinstance(d, dict):
            raise ValueError(f"{where}: must be an object (written by identify)")
        vals = {}
        for key in ("tau_rad", "noise_sigma_m", "length_scale_rad"):
            v = d.get(key)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or v < 0:
                raise ValueError(f"{where}.{key}: must be a finite number >= 0, got {v!r}")
            vals[key] = float(v)
        if not 1e-3 <= vals["length_scale_rad"] <= 1e3 or vals["tau_rad"] > 0.1:
            raise ValueError(f"{where}: length_scale_rad {vals['length_scale_rad']:g} or tau_rad {vals['tau_rad']:g} "
                             "out of range (rad; was the file edited?)")
        Q = decode_array(d.get("Q_rad"), f"{where}.Q_rad", (None, n_joints))
        Jq = decode_array(d.get("Jq"), f"{where}.Jq", (len(Q), 3, n_joints))
        if param_cov is None:
            raise ValueError(f"{where}: needs the parametric block's covariance")
        Fplus = decode_array(d.get("Fplus"), f"{where}.Fplus", (param_cov.shape[0], 3 * len(Q)))
        white = d.get("white_sigma_m")
        if white is not None:
            if (not isinstance(white, list) or len(white) != 3
                    or any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in white)
                    or not all(np.isfinite(v) and v >= 0 for v in white)):
                raise ValueError(f"{where}.white_sigma_m: must be 3 finite numbers >= 0 (m), got {white!r}")
            white = np.asarray(white, float)
        return cls(vals["tau_rad"] ** 2, vals["noise_sigma_m"] ** 2, vals["length_scale_rad"], Q, Jq, Fplus,
                   param_cov, white)


def residual_basis(Fs: np.ndarray) -> np.ndarray:
    """N (3n, k): an orthonormal basis of what a least-squares fit of the columns of Fs (3n, P) leaves (the left
    singular vectors beyond its rank, singular values above 1e-10 of the largest)."""
    U, s, _ = np.linalg.svd(Fs, full_matrices=True)
    rank = int(np.sum(s > 1e-10 * (s[0] if s.size else 1.0)))
    return U[:, rank:]


def restricted_space(K: np.ndarray, r: np.ndarray, Fs: np.ndarray, N: np.ndarray | None = None
                     ) -> tuple[np.ndarray, np.ndarray, int]:
    """(eigenvalues λ of NᵀKN, Vᵀ Nᵀ r, k) with N an orthonormal basis of what a fit of Fs leaves
    (:func:`residual_basis`; ``N`` that basis when already formed: the same numbers, one SVD for every kernel)."""
    if N is None:
        N = residual_basis(Fs)
    B = N.T @ K @ N
    lam, V = np.linalg.eigh(0.5 * (B + B.T))
    return np.maximum(lam, 0.0), V.T @ (N.T @ r), int(N.shape[1])


def _nll(x: np.ndarray, lam: np.ndarray, zt: np.ndarray) -> float:
    """−ℓ(log τ², log σ_n²) up to a constant (normalised units)."""
    v = np.exp(x[0]) * lam + np.exp(x[1])
    return 0.5 * float(np.sum(zt ** 2 / v + np.log(v)))


def nll_and_grad(x: np.ndarray, lam: np.ndarray, zt: np.ndarray) -> tuple[float, np.ndarray]:
    """:func:`_nll` and its gradient in x = (log τ², log σ_n²): with v = τ²λ + σ_n², ∂(−ℓ)/∂v = ½(1/v − z̃²/v²),
    ∂v/∂log τ² = τ²λ, ∂v/∂log σ_n² = σ_n².

    Args:
        x: (log τ², log σ_n²) in normalised units; lam: the eigenvalues λ (k,); zt: the rotated residuals z̃ (k,).

    Returns:
        (−ℓ up to a constant, its gradient (2,)).
    """
    a, b = np.exp(x[0]), np.exp(x[1])
    v = a * lam + b
    w = 0.5 * (1.0 / v - zt ** 2 / v ** 2)
    return 0.5 * float(np.sum(zt ** 2 / v + np.log(v))), np.array([a * float(w @ lam), b * float(np.sum(w))])


def _fit_one(K: np.ndarray, r: np.ndarray, N: np.ndarray, floor: float) -> tuple[float, np.ndarray, float] | None:
    """REML of (τ², σ_n²) for one kernel matrix K (normalised units) in the residual space N
    (:func:`residual_basis`): (−ℓ, x = (log τ², log σ_n²), 2 Δℓ against the white level), or None when nothing lies
    above the floor."""
    lam, zt, k = restricted_space(K, r, np.empty((0, 0)), N)
    white = float(np.sum(zt ** 2)) / max(k, 1)
    if k < 3 or white <= floor:
        return None
    lo = np.log(max(floor, 1e-12))
    bounds = [(np.log(1e-12), np.log(1e6)), (lo, np.log(1e6))]
    best = min((minimize(nll_and_grad, np.array(x0), args=(lam, zt), jac=True, method="L-BFGS-B", bounds=bounds)
                for x0 in ([np.log(white), np.log(max(0.3 * white, floor, 1e-12))],
                           [np.log(0.1 * white), np.log(max(white, floor))])), key=lambda o: o.fun)
    stat = 2.0 * (_nll(np.array([np.log(1e-12), np.log(white)]), lam, zt) - float(best.fun))
    return float(best.fun), best.x, stat


def loo_plan(Fs: np.ndarray, r: np.ndarray, groups: np.ndarray) -> tuple[int, list]:
    """What :func:`loo_log_density` computes without the covariance: (the number of pose groups, per group size
    (the groups' indices, the maps A_g stacked (b, k, 3n), the errors e_g stacked (b, k))). Args as there."""
    H = Fs @ np.linalg.pinv(Fs, rcond=1e-12)
    M = np.eye(len(r)) - H
    members = [np.flatnonzero(groups == g) for g in np.unique(groups)]
    sizes = np.array([m.size for m in members])
    parts = []
    for size in np.unique(sizes):
        which = np.flatnonzero(sizes == size)
        idx = np.array([(3 * members[w][:, None] + np.arange(3)).reshape(-1) for w in which])  # (b, 3 size)
        k = idx.shape[1]
        B = np.linalg.pinv(np.eye(k) - H[idx[:, :, None], idx[:, None, :]], rcond=1e-10)
        parts.append((which, B @ M[idx], (B @ r[idx][..., None])[..., 0]))
    return len(members), parts


def loo_log_density(Sigma: np.ndarray, Fs: np.ndarray, r: np.ndarray, groups: np.ndarray,
                    plan: tuple[int, list] | None = None) -> np.ndarray:
    """Leave-one-pose-out log predictive density of the least-squares predictor's errors under the residual covariance
    ``Sigma`` (3n, 3n): Σ_g log N(e_g; 0, A_g Σ A_gᵀ) with e_g = (I − H_gg)⁻¹ r_g the error of rows g predicted from
    a fit without them (H = F F⁺, r = (I − H) y the fit's residuals) and A_g = (I − H_gg)⁻¹ (I − H)_g· (module
    docstring). ``groups`` (n,): the pose group of each row (near-duplicates together). Returns the terms, one per
    pose group (their sum is the density; −inf where a covariance is singular). The groups of one size are computed
    together (stacked pseudo-inverses, covariances and solves: the per-group numbers to rounding, ~1e-15 relative).
    ``plan``: :func:`loo_plan` of (Fs, r, groups) when already formed (the same numbers: what does not depend on
    Sigma, formed once for every Sigma of a fit)."""
    if plan is None:
        plan = loo_plan(Fs, r, groups)
    terms = np.empty(plan[0])
    for which, A, e in plan[1]:
        k = A.shape[1]
        C = A @ Sigma @ np.swapaxes(A, 1, 2)
        C = 0.5 * (C + np.swapaxes(C, 1, 2)) + (1e-12 * np.trace(C, axis1=1, axis2=2) / k)[:, None, None] * np.eye(k)
        sign, logdet = np.linalg.slogdet(C)
        ok = sign > 0  # the others' density is −inf (a singular covariance is not solved)
        quad = np.einsum("bi,bi->b", e[ok], np.linalg.solve(C[ok], e[ok][..., None])[..., 0])
        terms[which] = -np.inf
        terms[which[ok]] = -0.5 * (quad + logdet[ok] + k * np.log(2.0 * np.pi))
    return terms


def fit_joint_angle(Q: np.ndarray, R: np.ndarray, Jq: np.ndarray, F: np.ndarray, floor_m: np.ndarray | None,
                    widen: float, white_var_m2: np.ndarray, groups: np.ndarray | None = None,
                    length_scales_rad: tuple = LENGTH_SCALES_RAD) -> tuple[JointAngleTerm, float] | None:
    """The joint-angle part of residuals R (module docstring), or None when the white level predicts left-out poses
    as well.

    Args:
        Q: training configurations (n, d) rad; R: the fit's residuals (n, 3) m, robot base frame.
        Jq: ∂y/∂q at the rows (n, 3, d) m/rad, base frame; F: the fit's parameter Jacobian (n, 3, P), base frame.
        floor_m: the data's stated noise per axis (m), or None; widen: the small-sample factor on both σ.
        white_var_m2: the white level's variance per axis (3,) m² (the competitor).
        groups: the pose group of each row (n,) (near-duplicate poses together); None: every row its own.
        length_scales_rad: the ℓ tried.

    Returns:
        (the term, the gain in leave-one-pose-out log predictive density over the white level), or None.
    """
    Q = np.atleast_2d(np.asarray(Q, float))
    n = len(Q)
    if n > MAX_ROWS:
        return None
    Fs = np.asarray(F, float).reshape(3 * n, -1)
    groups = np.arange(n) if groups is None else np.asarray(groups)
    unit = max(float(np.sqrt(np.mean(np.asarray(R, float) ** 2))), 1e-15)       # residuals in units of their RMS
    jn = max(float(np.sqrt(np.mean(np.sum(np.asarray(Jq) ** 2, axis=(1, 2))))), 1e-15)
    floor = 0.0 if floor_m is None else float(np.max(np.asarray(floor_m, float))) ** 2 / unit ** 2
    r = np.asarray(R, float).reshape(-1)
    plan = loo_plan(Fs, r, groups)                        # formed once: the same for every covariance below
    white = loo_log_density(np.diag(np.tile(np.asarray(white_var_m2, float).reshape(3), n)), Fs, r, groups, plan)
    N = residual_basis(Fs)                                 # one SVD for every length scale
    best = None
    for ell in length_scales_rad:
        K = joint_angle_kernel(Q, Jq, Q, Jq, float(ell)).reshape(3 * n, 3 * n)
        got = _fit_one(K / jn ** 2, r / unit, N, floor)
        if got is None or got[2] <= LR_CRITICAL:                  # the restricted evidence does not support it
            continue
        tau2 = float(np.exp(got[1][0])) * unit ** 2 / jn ** 2 * widen ** 2
        sn2 = float(np.exp(got[1][1])) * unit ** 2 * widen ** 2
        S = tau2 * K + sn2 * np.eye(3 * n)
        diff = loo_log_density(S, Fs, r, groups, plan) - white
        gain, se = float(np.sum(diff)), float(np.sqrt(diff.size * np.var(diff)))
        if not np.isfinite(gain) or gain < -VETO_SE * se:        # left-out poses: clearly worse than the white level
            continue
        if best is None or gain > best[0]:
            best = (gain, tau2, sn2, float(ell), S)
    if best is None:
        return None
    gain, tau2, sn2, ell, S = best
    Fplus = np.linalg.pinv(Fs, rcond=1e-12)
    C = Fplus @ S @ Fplus.T
    return (JointAngleTerm(tau2, sn2, ell, Q.copy(), np.asarray(Jq, float).copy(), Fplus, 0.5 * (C + C.T),
                           np.sqrt(np.asarray(white_var_m2, float).reshape(3))),
            gain)
