"""How often the default loss (``identify(loss="auto")``, ``identify`` on the command line) switches to the robust
loss, on outlier-free Gaussian data and on data with outliers.

Simulated KR 15 robots in its shipped cell (every joint-placement parameter perturbed by the default tolerances,
reflector of the cell, tracker noise 20 µm per axis, Gaussian), measured at seeded random poses, identified with the
default options (the parametric fit: the model discrepancy is fitted after the loss decision and does not enter it):

* noise stated (the cell's noise, as ``identify --cell`` takes it, or sigma columns), 35 and 300 poses;
* noise unknown (no sigma columns, no cell noise: the covariance scaled by the reduced χ²), 300 poses;
* the same 300-pose data with three rows moved by 5 mm (the switch must happen).

Printed per scenario: the fits that switched to the robust loss, the fits with any row flagged as an outlier, and
the fits in which a row lies beyond the per-row threshold sqrt(χ²₃(1 − α)) · s of the earlier flag (α = 1e-3, s the
MAD scale; before the flag was family-wise), computed from the same fits' plain residuals. Target: ≤ 1 % switches
on outlier-free data with the noise stated.

Run:  python -m benchmarks.robust_switch [--fits 200]   (about 1 min)
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
from scipy.stats import chi2

#: tracker noise of the simulation (m per axis)
NOISE_M = 2e-5


def _one(model, cell, m: int, seed: int, scale: bool, outliers: int) -> tuple[bool, bool, bool]:
    """(switched, any row flagged, any row beyond the per-row threshold of the plain fit) of one simulated fit."""
    from pin_kpi_oed.identification.identify import identify
    from pin_kpi_oed.simulation.simulator import random_truth, simulate

    rng = np.random.default_rng(10_000 + seed)
    Q = cell.robot.random_q(rng, m)
    data = simulate(model, Q, random_truth(model, seed=seed), seed=seed, record_sigma=False)
    if outliers:
        rows = rng.choice(m, outliers, replace=False)
        data.position_m[rows] += 5e-3 * rng.normal(size=(outliers, 3)) / np.sqrt(3)
    res = identify(model, data, discrepancy="none", scale_covariance=scale)
    plain = res if res.loss == "linear" else identify(model, data, discrepancy="none", scale_covariance=scale,
                                                      loss="linear")
    fw = plain.residuals_m / NOISE_M
    s = 1.4826 * float(np.median(np.abs(fw)))
    per_row = bool(np.any(np.linalg.norm(fw, axis=1) > np.sqrt(chi2.ppf(1 - 1e-3, 3)) * s))
    return res.loss != "linear", bool(res.outliers.size), per_row


def main(argv: list[str] | None = None) -> dict:
    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.model.noise import NoiseModel

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fits", type=int, default=200, help="simulated fits per scenario (default 200)")
    a = ap.parse_args(sys.argv[1:] if argv is None else argv)
    cell = load_cell("kr15")
    cell.noise = NoiseModel(sigma_xyz_m=(NOISE_M,) * 3)
    model = cell.tracker_model()
    out = {}
    for name, m, scale, outl in (("noise stated, 35 poses", 35, False, 0), ("noise stated, 300 poses", 300, False, 0),
                                 ("noise unknown, 300 poses", 300, True, 0),
                                 ("noise stated, 300 poses, 3 rows moved 5 mm", 300, False, 3)):
        r = np.array([_one(model, cell, m, s, scale, outl) for s in range(a.fits)])
        out[name] = r.sum(axis=0).tolist()
        print(f"{name:<44} robust loss {int(r[:, 0].sum()):>3}/{a.fits}, rows flagged {int(r[:, 1].sum()):>3}/"
              f"{a.fits}, beyond the per-row threshold {int(r[:, 2].sum()):>3}/{a.fits}", flush=True)
    return out


if __name__ == "__main__":
    main()
