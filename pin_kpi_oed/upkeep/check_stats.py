r"""The check's statistics on the whitened rows, none of them asking the calibrated model: the Šidák level of each
of the verdict's two tests, whether a change is shown above the tolerance, the power of the check against each
parameter group's weakest change that matters, the group that explains the residuals (Akaike's criterion among the
groups that fit) and that group's fit with the set-up held. The check's pass over the rows
(:func:`~pin_kpi_oed.upkeep.check_rows.measure_rows`) computes them once; the verdict
(:func:`~pin_kpi_oed.upkeep.check.check_calibration`) reads them.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from pin_kpi_oed.oed.check_power import CheckNull, CheckPower

__all__ = ["FIT_SHARE", "check_group_name", "check_powers", "held_fit", "shown_above", "sidak", "verdict_powers"]

#: The named group's goodness of fit is tested at α / FIT_SHARE.
FIT_SHARE = 5.0


def sidak(alpha: float, k: int = 2) -> float:
    """The level of each of k independent tests whose union has level α: 1 − (1 − α)^{1/k}."""
    return float(1.0 - (1.0 - alpha) ** (1.0 / k))


def shown_above(size_m: float, sigma_m: float, tolerance_m: float, alpha: float) -> bool:
    """Whether a change of ``size_m`` ± ``sigma_m`` is shown to exceed the tolerance: size − z₁₋ₐ σ > τ."""
    return bool(np.isfinite(size_m) and np.isfinite(sigma_m)
                and size_m - float(stats.norm.isf(alpha)) * sigma_m > tolerance_m)


def held_fit(F: np.ndarray, z_old: np.ndarray, best: tuple, null: CheckNull, alpha: float) -> tuple | None:
    """The named group fitted with the set-up *held* at the model's station (the tracker did not move): (its change,
    covariance of its basis coordinates, remaining χ²) when that simpler explanation passes its fit test at
    α / :data:`FIT_SHARE` on 3m − r_g degrees of freedom, else None. The held set-up was determined by the
    calibration's many rows, so the change is determined better than with the set-up re-fitted on the check rows.

    Args:
        F: whitened Jacobian of the rows (3m, np); z_old: whitened residuals under the model's own set-up (3m,).
        best: the named group (group, basis coordinates, their covariance, determined) of :func:`check_group_name`.
        null: the law of T under no change; alpha: the verdict's false-alarm rate.

    Returns:
        (change in the group's columns, raw units; covariance of its basis coordinates; remaining χ²), or None.
    """
    g, _, _, det = best
    if not det:
        return None
    A = F[:, g.cols] @ g.basis
    x, *_ = np.linalg.lstsq(A, z_old, rcond=None)
    rem = float(np.sum((z_old - A @ x) ** 2))
    if not rem <= null.threshold(len(z_old) - A.shape[1], alpha / FIT_SHARE):
        return None
    return g.basis @ x, np.linalg.pinv(A.T @ A), rem


def check_powers(crit: CheckPower, F: np.ndarray, tolerance_m: float, alpha: float, null: CheckNull | None = None
                 ) -> dict:
    """Group -> power of the check with whitened Jacobian F (3m, np) against the group's weakest change of size τ, under
    the law ``null`` of the statistic (default the plain χ²;
    :func:`~pin_kpi_oed.calibrated.check_view.check_null`)."""
    dof = F.shape[0] - crit.setup.size
    mu = crit.mu(F.T @ F)[0]
    law = null or CheckNull()
    return {g.name: float(p) for g, p in zip(crit.groups, law.powers(tolerance_m ** 2 * mu, dof, alpha))}


def verdict_powers(crit: CheckPower, F: np.ndarray, tolerance_m: float, alpha: float, null: CheckNull,
                   factor: float = 1.5) -> dict:
    """Group -> the probability that the verdict says *the robot changed* for the group's weakest change of
    ``factor`` × τ at the TCP: T above its critical value at α' (Šidák) and the change shown above τ (its TCP size
    less z₁₋ₐ times its σ, 1/√μ_g scaled by the held-out standardised RMS, above τ); the product of the two (m)."""
    a1 = sidak(alpha)
    dof = F.shape[0] - crit.setup.size
    mu = np.maximum(crit.mu(F.T @ F)[0], 1e-300)
    z = float(stats.norm.isf(alpha))
    detect = null.powers((factor * tolerance_m) ** 2 * mu, dof, a1)
    sd = null.factor / np.sqrt(mu)
    shown = stats.norm.cdf((factor - 1.0) * tolerance_m / sd - z)
    return {g.name: float(d * s) for g, d, s in zip(crit.groups, detect, shown)}


def check_group_name(crit: CheckPower, F: np.ndarray, z: np.ndarray, dof: int, alpha: float, null: CheckNull) -> dict:
    """Each group fitted with the set-up; among the groups whose remaining χ² passes at α / :data:`FIT_SHARE` (the
    true group fails its own fit test at that rate, which caps the share named right at 1 − α / FIT_SHARE), the one
    of the least remaining χ² + 2 r_g (Akaike's criterion of the whitened rows: a larger group must explain more, a
    one-column group is not preferred when a three-column one fits far better)."""
    Gs = F[:, crit.setup]
    T = float(z @ z)
    fits = []
    for g in crit.groups:
        A = np.hstack([Gs, F[:, g.cols] @ g.basis])
        x, *_ = np.linalg.lstsq(A, z, rcond=1e-6)
        sv = np.linalg.svd(A / np.maximum(np.linalg.norm(A, axis=0), 1e-300), compute_uv=False)
        det = bool(sv[-1] > 1e-6 * sv[0]) and A.shape[0] > A.shape[1]
        r = g.basis.shape[1] if det else max(int(np.sum(sv > 1e-6 * sv[0])) - Gs.shape[1], 0)
        fits.append((g, A, x, det, r, float(np.sum((z - A @ x) ** 2))))
    rs = np.array([f[4] for f in fits], float)
    limits = null.thresholds(dof - rs, alpha / FIT_SHARE)        # the laws of every group at once
    gains = null.sfs(T - np.array([f[5] for f in fits], float), rs).tolist()
    table, passing = [], []
    for (g, A, x, det, r, rem), limit in zip(fits, limits.tolist()):
        # a group the rows do not determine may still explain them: named, with the poses that determine it
        ok = r > 0 and rem <= limit
        table.append({"name": g.name, "chi2_remaining": rem, "dof": dof - r, "determined": det, "explains": ok})
        if ok:
            k = g.basis.shape[1]
            cov = np.linalg.pinv(A.T @ A, rcond=1e-12)[-k:, -k:]
            passing.append((r, rem, g, x[-k:], cov, det))
    best = min(passing, key=lambda c: c[1] + 2 * c[0]) if passing else None
    significant = bool(min(gains) < alpha / len(crit.groups)) if gains else False
    return {"best": best[2:] if best else None, "table": table, "significant": significant,
            "alike": _alike(best, passing, null, alpha) if best else []}


def _alike(best: tuple, passing: list, null: CheckNull, alpha: float) -> list[str]:
    """The other parts (a joint, the tool) the rows do not tell apart from the named group's: a group that explains
    the rows whose Akaike criterion exceeds the named one's by at most χ²₁₋ₐ(1) (in the law's scale: the rows reject
    neither at α). A joint's offset and placement are one part (its joint is named either way)."""
    part = best[2].name.rsplit(" ", 1)[0]
    lim = float(stats.chi2.isf(alpha, 1)) * null.scale
    ref = best[1] + 2 * best[0]
    out: dict[str, float] = {}
    for r, rem, g, *_ in passing:
        other = g.name.rsplit(" ", 1)[0]
        if other != part and rem + 2 * r - ref <= lim and rem + 2 * r < out.get(other, np.inf):
            out[other] = rem + 2 * r
    return sorted(out, key=out.get)
