r"""A camera's joint-angle error level from its own images: the term a camera's TCP σ adds when the images ask for it.

A camera measures the board's pose relative to the camera in every image; an error of the joint angles the geometry
does not model (gear harmonics, transmission errors) moves every corner of an image together, through the image's
joint Jacobian B_i = ∂uv/∂q / σ_px. On the σ-weighted residuals r of a fit with Jacobian F (rows of all images):

.. math::  r = F β + ε + B δ, \qquad ε \sim N(0, σ^2 I), \qquad δ_i \sim N(0, \operatorname{diag}(s_1^2 … s_d^2)),

δ_i independent between images (the images are far apart in joint space; what a smooth error shares between
images the fit absorbs into the joint placements, the held-out check below sees what is left). σ² ≥ 1 (the stated
pixel noise is the floor) and s_j ≥ 0 by restricted maximum likelihood (REML: β the fitted parameters, so what the
fit absorbed counts), every matrix of size d per image by Woodbury: V = σ² I + B D Bᵀ.

**When.** The term is kept only when both say so: the REML likelihood ratio against s = 0 (σ² alone, the χ²
scaling the camera's σ has without it) exceeds the 95 % point of χ²_d, and a K-fold held-out check on images (each
fold predicted by the fit on the others, linearised at the fit: Δp = M₋ₖ⁻¹ F_kᵀ r_k; the levels re-estimated
without the fold) gives the held-out images a larger Gaussian log density under the joint-angle structure than
under the white level max(1, χ²_red).

**What the TCP σ gets.** The parameters' covariance under that error, the sandwich
C = M⁻¹ (Fᵀ V F + P) M⁻¹ (M = FᵀF + P, P the prior's information), instead of M⁻¹ max(1, χ²_red); and at a
configuration q the joint-angle term J_q(q) diag(s²) J_q(q)ᵀ of the TCP (independent of the fit's images:
:func:`~pin_kpi_oed.calibrated.tcp_sigma.tcp_sigma` adds it from the model file's ``fit.joint_angle_sigma_rad``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import minimize
from scipy.stats import chi2

__all__ = ["JointNoise", "JointLevels", "RemlBlocks", "reml_levels", "joint_noise", "camera_joint_noise",
           "MAX_SIGMA_RAD", "N_FOLDS", "LR_LEVEL"]

#: the largest joint-angle σ (rad) the estimate may reach
MAX_SIGMA_RAD = 0.01
#: the held-out check's folds of images
N_FOLDS = 5
#: the level of the likelihood-ratio test against s = 0
LR_LEVEL = 0.05


@dataclass
class JointLevels:
    """σ² (in units of σ_px²) and s (rad per joint) of the structure in the module docstring, and the REML
    log-likelihoods at them (``loglik``) and at s = 0 (``loglik_white``)."""

    noise_var: float
    sigma_rad: np.ndarray
    loglik: float
    loglik_white: float


@dataclass
class JointNoise:
    """The joint-angle level of a camera fit and whether the held-out check keeps it (module docstring).

    Attributes:
        used: the term is kept (the likelihood ratio and the held-out check both ask for it).
        sigma_rad: s per joint (rad), zeros when not used.
        noise_var: σ² in units of σ_px² (≥ 1).
        covariance: the parameters' covariance under the kept structure (the sandwich), or the white level's
            M⁻¹ max(1, χ²_red) when not used, (b, b).
        lr: 2 Δℓ of the REML against s = 0; lr_critical: its 95 % point.
        heldout_gain: Σ over held-out images of the log density under the joint structure minus the white one's
            (NaN when the likelihood ratio alone says no: the check is then not run).
        reason: one line saying why it is (not) used.
    """

    used: bool
    sigma_rad: np.ndarray
    noise_var: float
    covariance: np.ndarray
    lr: float
    lr_critical: float
    heldout_gain: float
    reason: str = ""
    fold_gains: list[float] = field(default_factory=list)

    def to_dict(self) -> dict:
        """The model file's ``fit.joint_noise`` block (rad, σ_px² units)."""
        return {"used": bool(self.used), "sigma_rad": [float(v) for v in self.sigma_rad],
                "noise_var_px2_units": float(self.noise_var), "lr": float(self.lr),
                "lr_critical": float(self.lr_critical),
                "heldout_gain": float(self.heldout_gain) if np.isfinite(self.heldout_gain) else None,
                "reason": self.reason}


class RemlBlocks:
    """The small matrices of the Woodbury forms: per image BᵢᵀBᵢ (d, d), BᵢᵀF (d, b), Bᵢᵀr (d,); FᵀF, Fᵀr, rᵀr.

    Args:
        F, B, r, img, m: as :func:`reml_levels`.
    """

    def __init__(self, F: np.ndarray, B: np.ndarray, r: np.ndarray, img: np.ndarray, m: int):
        d = B.shape[1]
        self.n, self.m, self.d = F.shape[0], m, d
        self.BB = np.zeros((m, d, d))
        self.BF = np.zeros((m, d, F.shape[1]))
        self.Br = np.zeros((m, d))
        for i in range(m):
            k = img == i
            self.BB[i] = B[k].T @ B[k]
            self.BF[i] = B[k].T @ F[k]
            self.Br[i] = B[k].T @ r[k]
        self.FF, self.Fr, self.rr = F.T @ F, F.T @ r, float(r @ r)

    def loglik(self, noise_var: float, s: np.ndarray) -> float:
        """The REML log-likelihood at σ² (σ_px² units) and s (rad per joint), up to a constant independent of both:
        −½ (log|V| + log|FᵀV⁻¹F| + rᵀV⁻¹r − rᵀV⁻¹F (FᵀV⁻¹F)⁻¹ FᵀV⁻¹r), every product by Woodbury in d × d blocks."""
        w = np.asarray(s, float)
        A = noise_var * np.eye(self.d) + w[None, :, None] * self.BB * w[None, None, :]
        L = np.linalg.cholesky(A)
        logdetV = (self.n - self.m * self.d) * np.log(noise_var) + 2.0 * np.log(np.diagonal(L, axis1=1, axis2=2)).sum()
        WBF = w[None, :, None] * self.BF
        WBr = w[None, :] * self.Br
        AiBF = np.linalg.solve(A, WBF)
        AiBr = np.linalg.solve(A, WBr[..., None])[..., 0]
        FVF = (self.FF - np.einsum("mdb,mdc->bc", WBF, AiBF)) / noise_var
        FVr = (self.Fr - np.einsum("mdb,md->b", WBF, AiBr)) / noise_var
        rVr = (self.rr - np.einsum("md,md->", WBr, AiBr)) / noise_var
        Lf = np.linalg.cholesky(FVF)
        z = np.linalg.solve(Lf, FVr)
        return -0.5 * (logdetV + 2.0 * np.log(np.diag(Lf)).sum() + rVr - z @ z)


def reml_levels(F: np.ndarray, B: np.ndarray, r: np.ndarray, img: np.ndarray, m: int,
                start: JointLevels | None = None) -> JointLevels:
    """σ² ≥ 1 and s ∈ [0, MAX_SIGMA_RAD] by restricted maximum likelihood (module docstring).

    Args:
        F: the σ-weighted parameter Jacobian of the pixel rows, (n, b) per parameter unit.
        B: the σ-weighted joint Jacobian of the same rows, (n, d) per rad (m for a prismatic joint).
        r: the σ-weighted residuals, (n,); img: each row's image index in 0..m-1, (n,); m: the images.
        start: levels to start the search from (the whole data's, for a fold of them), or None.

    Returns:
        The :class:`JointLevels`.
    """
    bl = RemlBlocks(F, B, r, img, m)
    d = B.shape[1]
    scale = 1.0 / np.maximum(np.sqrt(bl.BB.diagonal(axis1=1, axis2=2).mean(axis=0)), 1e-12)  # rad per σ_px

    def nll(x: np.ndarray) -> float:
        return -bl.loglik(float(np.exp(x[0])), x[1:] * scale)

    dof = max(bl.n - F.shape[1], 1)
    white = max(1.0, _white_var(bl) * bl.n / dof)  # the REML σ² at s = 0 (closed form), floored at 1
    ll_white = bl.loglik(white, np.zeros(d))
    bounds = [(0.0, 10.0)] + [(0.0, MAX_SIGMA_RAD / s) for s in scale]
    x0 = (np.r_[np.log(white), np.full(d, 0.3)] if start is None or not np.any(start.sigma_rad > 0) else
          np.r_[np.log(max(start.noise_var, 1.0)), np.maximum(start.sigma_rad / scale, 0.05)])
    res = minimize(nll, x0, method="L-BFGS-B", bounds=bounds)
    if res.fun >= -ll_white:
        return JointLevels(white, np.zeros(d), ll_white, ll_white)
    return JointLevels(float(np.exp(res.x[0])), res.x[1:] * scale, float(-res.fun), ll_white)


def _white_var(bl: RemlBlocks) -> float:
    """rᵀ(I − F F⁺) r / n of the blocks' rows (the least-squares residual level per row)."""
    beta = np.linalg.lstsq(bl.FF, bl.Fr, rcond=None)[0]
    return max(float(bl.rr - bl.Fr @ beta), 0.0) / max(bl.n, 1)


def _gauss_logpdf(x: np.ndarray, S: np.ndarray) -> float:
    L = np.linalg.cholesky(S)
    z = np.linalg.solve(L, x)
    return float(-0.5 * (z @ z) - np.log(np.diag(L)).sum() - 0.5 * x.size * np.log(2 * np.pi))


def _sandwich(F: np.ndarray, B: np.ndarray, img: np.ndarray, m: int, noise_var: float, s: np.ndarray,
              P: np.ndarray) -> np.ndarray:
    """M⁻¹ (Fᵀ V F + P) M⁻¹ with M = FᵀF + P, V = σ² I + B D Bᵀ (block diagonal by image)."""
    FF = F.T @ F
    FVF = noise_var * FF
    for i in range(m):
        k = img == i
        G = (B[k] * s[None, :]).T @ F[k]
        FVF += G.T @ G
    Mi = np.linalg.inv(FF + P)
    return Mi @ (FVF + P) @ Mi


def joint_noise(F: np.ndarray, B: np.ndarray, r: np.ndarray, img: np.ndarray, m: int, prior_info: np.ndarray,
                chi2_reduced: float, n_folds: int = N_FOLDS, seed: int = 0) -> JointNoise:
    """The joint-angle level of a camera fit and the decision whether its TCP σ carries it (module docstring).

    Args:
        F, B, r, img, m: as :func:`reml_levels` (the fit's detected pixel rows at its solution).
        prior_info: the prior's information on the fitted parameters, (b, b) (zeros without a prior).
        chi2_reduced: the fit's reduced χ² (the white level max(1, χ²) the σ has without the term).
        n_folds: folds of images of the held-out check (at most the images); seed: their split.

    Returns:
        The :class:`JointNoise`.
    """
    d = B.shape[1]
    white = max(1.0, float(chi2_reduced))
    C_white = np.linalg.inv(F.T @ F + prior_info) * white
    lv = reml_levels(F, B, r, img, m)
    lr = max(2.0 * (lv.loglik - lv.loglik_white), 0.0)
    crit = float(chi2.ppf(1.0 - LR_LEVEL, d))
    # the held-out check only when the likelihood ratio asks for the term (both must)
    gains = _heldout_gains(F, B, r, img, m, prior_info, min(n_folds, m), seed, lv) if lr > crit else []
    gain = float(sum(gains)) if gains else float("nan")
    used = lr > crit and gain > 0.0 and bool(np.any(lv.sigma_rad > 0))
    if used:
        C = _sandwich(F, B, img, m, lv.noise_var, lv.sigma_rad, prior_info)
        why = (f"joint-angle errors of {_fmt(lv.sigma_rad)} urad per joint: likelihood ratio {lr:.1f} > {crit:.1f}, "
               f"held-out images' log density +{gain:.1f} over the white level")
        return JointNoise(True, lv.sigma_rad, lv.noise_var, C, lr, crit, gain, why, gains)
    why = (f"no joint-angle term: likelihood ratio {lr:.1f} <= {crit:.1f}" if not gains else
           f"no joint-angle term: likelihood ratio {lr:.1f} > {crit:.1f} but held-out images' log density {gain:+.1f} "
           "against the white level")
    return JointNoise(False, np.zeros(d), white, C_white, lr, crit, gain, why, gains)


def _fmt(s: np.ndarray) -> str:
    return "/".join(f"{v * 1e6:.0f}" for v in s)


def _heldout_gains(F: np.ndarray, B: np.ndarray, r: np.ndarray, img: np.ndarray, m: int, P: np.ndarray,
                   k: int, seed: int, start: JointLevels | None = None) -> list[float]:
    """Per fold: the held-out images' log density under the joint structure (levels re-estimated without the fold)
    minus under the white level (the χ² of the fit without the fold), the fold predicted by the fit without it
    linearised at the solution."""
    if k < 2:
        return [0.0]
    fold = np.random.default_rng(seed).permutation(m) % k
    out = []
    M = F.T @ F + P
    for f in range(k):
        ho = fold[img] == f
        Fk, rk = F[ho], r[ho]
        Fo, ro, io = F[~ho], r[~ho], img[~ho]
        Mo = M - Fk.T @ Fk
        rt = rk + Fk @ np.linalg.solve(Mo, Fk.T @ rk)
        keep = np.flatnonzero(fold != f)
        io = np.searchsorted(keep, io)
        dof = max(Fo.shape[0] - F.shape[1], 1)
        beta = np.linalg.solve(Mo, Fo.T @ ro)
        w = max(1.0, float(np.sum((ro - Fo @ beta) ** 2)) / dof)
        Ci_white = w * np.linalg.inv(Mo)
        lv = reml_levels(Fo, B[~ho], ro, io, keep.size, start)
        ik = np.searchsorted(np.flatnonzero(fold == f), img[ho])
        Co = _sandwich(Fo, B[~ho], io, keep.size, lv.noise_var, lv.sigma_rad, P)
        g = 0.0
        for i in np.unique(ik):  # each held-out image's own density (a proper score per image)
            own = ik == i
            Fi, Bi = Fk[own], B[ho][own] * lv.sigma_rad[None, :]
            S_joint = lv.noise_var * np.eye(Fi.shape[0]) + Bi @ Bi.T + Fi @ Co @ Fi.T
            S_white = w * np.eye(Fi.shape[0]) + Fi @ Ci_white @ Fi.T
            g += _gauss_logpdf(rt[own], S_joint) - _gauss_logpdf(rt[own], S_white)
        out.append(g)
    return out


def camera_joint_noise(model: Any, p: np.ndarray, base: np.ndarray, Q: np.ndarray, uv: np.ndarray,
                       chi2_reduced: float, seed: int = 0) -> JointNoise:
    """:func:`joint_noise` of a camera fit: its detected pixel rows at the solution ``p`` (module docstring).

    Args:
        model: the :class:`~pin_kpi_oed.model.camera.CameraModel`; p: the fit's raw parameters; base: the fitted
            parameters' indices; Q: the images' joints (m, n) rad; uv: their corners (m, 2N) px, NaN not detected.
        chi2_reduced: the fit's reduced χ²; seed: the held-out folds' split.

    Returns:
        The :class:`JointNoise`.
    """
    Q = np.atleast_2d(np.asarray(Q, float))
    rows = np.isfinite(uv)
    sig = float(model.sigma_px)
    F = model.weighted_jacobian(p, Q).reshape(-1, model.n_params)[:, base][rows.ravel()]
    B = (model.prediction_dq(p, Q) / sig)[rows]
    r = ((model.predict(p, Q) - uv) / sig)[rows]
    img = np.broadcast_to(np.arange(len(Q))[:, None], rows.shape)[rows]
    prior = model.layout.prior_sigma[base]
    info = np.diag(np.where(np.isfinite(prior), 1.0 / np.where(np.isfinite(prior), prior, 1.0) ** 2, 0.0))
    return joint_noise(F, B, r, img, len(Q), info, chi2_reduced, seed=seed)
