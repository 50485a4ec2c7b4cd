"""A linear track in the discrepancy kernel: on the line (Δ² in m) against every joint taken for an angle.

A KR 15 on its 6.4 m track (``kr15_track``'s joint layout: the track, then six revolute joints) whose residual
discrepancy varies along the rail (a waviness of periods 2.5 m and 1.1 m, 0.1 mm) and with two arm joints
(0.05 mm), plus 10 µm noise. The Gaussian process (``fit_discrepancy``, mode ``on``) is fitted on 260 rows on the
first 5.2 m of the track, twice: the track on the line (``linear``, length scales relative to its travel, what the
package does) and as an angle (4 sin²(Δ/2): period 2π m, what it did). Scored on 80 rows at the far end of the
track (6.2 .. 6.4 m, about 2π m from its start) and on 80 rows inside the trained stretch: the mean 3-D error of
the residual after δ (mm), the RMS of the standardised errors z per axis (honest: within [0.67, 1.5]) and the share
of rows inside their 95 % ellipsoid.

Run:  python -m benchmarks.track_kernel [--seeds 0,1,2,3,4]
"""

from __future__ import annotations

import argparse

import numpy as np

from pin_kpi_oed.discrepancy.fit import fit_discrepancy
from pin_kpi_oed.discrepancy.gp import DiscrepancyOptions

TRACK_M = 6.4
D = 7
LINEAR = np.array([True] + [False] * 6)


def configurations(rng: np.random.Generator, n: int, lo: float, hi: float) -> np.ndarray:
    """n configurations: the track uniform in [lo, hi] m, the six arm joints in [-3, 3] rad."""
    Q = rng.uniform(-3.0, 3.0, (n, D))
    Q[:, 0] = rng.uniform(lo, hi, n)
    return Q


def residuals(Q: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The simulated discrepancy (m) along the rail and with two arm joints, plus 10 µm noise."""
    x = Q[:, 0]
    along = 1e-4 * np.sin(2 * np.pi * x / 2.5 + 0.3) + 6e-5 * np.sin(2 * np.pi * x / 1.1)
    arm = 5e-5 * np.sin(Q[:, 1]) * np.cos(Q[:, 2])
    R = np.column_stack([along + arm, 0.5 * along - arm, 0.3 * arm + 0.2 * along])
    return R + 1e-5 * rng.standard_normal(R.shape)


def score(disc, Q: np.ndarray, R: np.ndarray) -> tuple[float, float, float]:
    """(mean 3-D error after δ (mm), z RMS, share inside the 95 % ellipsoid)."""
    mu, var = disc.predict(Q)
    r = R - mu
    z2 = r ** 2 / (var + disc.noise_var_m2)
    return float(np.mean(np.linalg.norm(r, axis=1)) * 1e3), float(np.sqrt(z2.mean())), \
        float(np.mean(z2.sum(1) <= 7.8147))


def run(seed: int) -> dict:
    rng = np.random.default_rng(seed)
    Qt = configurations(rng, 260, 0.0, 5.2)
    Qf, Qi = configurations(rng, 80, 6.2, TRACK_M), configurations(rng, 80, 0.0, 5.2)
    Rt, Rf, Ri = residuals(Qt, rng), residuals(Qf, rng), residuals(Qi, rng)
    names = [f"j{i}" for i in range(D)]
    opts = DiscrepancyOptions(mode="on", n_fit=260, seed=seed)
    per = np.zeros(D, bool)
    span = np.r_[TRACK_M, np.full(6, 6.0)]
    out = {}
    for key, kw in (("line", {"linear": LINEAR, "joint_span": span}), ("angle", {})):
        disc = fit_discrepancy(Qt, Rt, names, opts, periodic=per, **kw)
        out[key] = {"far": score(disc, Qf, Rf), "inside": score(disc, Qi, Ri)}
    return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0,1,2,3,4", help="comma-separated seeds (default 0,1,2,3,4)")
    args = ap.parse_args(argv)
    print(f"{'seed':>4} {'track':<6}{'far: mean mm':>13}{'z RMS':>7}{'in 95%':>8}"
          f"{'inside: mean mm':>17}{'z RMS':>7}{'in 95%':>8}")
    for seed in (int(s) for s in args.seeds.split(",")):
        res = run(seed)
        for key, r in res.items():
            f, i = r["far"], r["inside"]
            print(f"{seed:>4} {key:<6}{f[0]:>13.4f}{f[1]:>7.2f}{f[2] * 100:>7.1f}%"
                  f"{i[0]:>17.4f}{i[1]:>7.2f}{i[2] * 100:>7.1f}%", flush=True)


if __name__ == "__main__":
    main()
