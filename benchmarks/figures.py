"""CPU time of each figure function on fixed inputs, against the reference way of writing the same figure.

Inputs (seeded, SI): three designs' C_s at three working configurations (ellipsoid projections, design bars), 30
poses' clearance and incidence per design (pose quality), a trust map of 300 rows (20 % extrapolated) and 200
training configurations, two working paths of 120 samples for three designs with the discrepancy's σ (path
profiles), an eight-point poses-needed curve, and a certificate-like histogram, binned-error panels and a 40 ×
40 correlation matrix (:func:`pin_kpi_oed.report.figures.png_bytes`).

Each figure is drawn ``--pairs`` times by the current code and as many times by the reference, interleaved (one
pair after another, so that the machine's load falls on both alike): the reference writes the PNG with a plain
``fig.savefig(buf, format="png", dpi=dpi)`` (and ``bbox_inches="tight"`` for the certificate's figures), which
draws a figure with a layout engine twice (once without output, for the layout) and compresses at zlib's default
level, and the ellipsoid figure shades its ellipses with ``ax.fill`` (which walks every polygon edge for the data
limits). Printed per figure: the paired median CPU time (s) of both, the median of the per-pair ratios, how many
pairs the current code won, and the sign test's two-sided p; then whether the pixels of both PNGs are equal.

Measured (``nice -n 10 python -m benchmarks.figures --pairs 7``, the 2-core machine at a load average of 3–4 from
other work, so every time is inflated and noisy; s CPU, paired medians, current / reference):

==================  =========  =======  =====  ====
figure              reference  current  ratio  wins
==================  =========  =======  =====  ====
ellipsoids          1.591      1.139    0.85   7/7
design_bars         0.356      0.270    0.91   6/7
pose_quality        0.968      0.761    0.95   6/7
trust_map           0.546      0.430    0.89   6/7
path_profiles       1.356      1.028    0.78   6/7
poses_needed        0.381      0.374    0.86   5/7
certificate (3)     1.595      1.263    0.83   6/7
all                 6.793      5.265    0.78
==================  =========  =======  =====  ====

Every figure's pixels equal in both ways.

Run: ``python -m benchmarks.figures [--pairs N]``.
"""

from __future__ import annotations

import argparse
import io
import sys
import tempfile
from collections.abc import Callable
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import cpu_time, sign_test_p


def _covs() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(0)
    out = {}
    for name, s in (("random", 3.0), ("param", 2.0), ("kpi", 1.0)):
        A = rng.normal(size=(9, 9)) * s * 1e-6
        out[name] = A @ A.T                                   # three working configurations, m²
    return out


def _trust_map() -> Any:
    from pin_kpi_oed.viz.trust_map import TrustMap

    rng = np.random.default_rng(1)
    m, k = 300, 200
    P = rng.normal(size=(m, 3)) * 0.4 + [0.8, 0.0, 0.6]
    s = np.abs(rng.normal(size=m)) * 1e-4 + 2e-5
    T = rng.normal(size=(k, 3)) * 0.3 + [0.8, 0.0, 0.6]
    return TrustMap(P, s, np.stack([s, s, s], 1) / np.sqrt(3), rng.random(m) < 0.2, T,
                    f"measured (training), {k} rows")


def _profiles() -> list[dict]:
    out = []
    for crit, f in (("kpi", 1.0), ("kpi_path", 0.9), ("random", 1.5)):
        s = np.linspace(0, 0.5, 120)
        paths = [{"name": name, "s_m": s.tolist(), "sigma_pos_m": (f * 1e-5 * (1 + np.sin(8 * s))).tolist(),
                  "sigma_rot_rad": (f * 2e-5 * (1 + np.cos(5 * s))).tolist(),
                  "sigma_pos_gp_m": (f * 3e-5 * (1 + 0.5 * np.sin(3 * s))).tolist()} for name in ("seam", "arc")]
        out.append({"criterion": crit, "paths": paths})
    return out


def _curve() -> dict:
    n = np.array([6, 8, 12, 16, 24, 32, 48, 64])
    return {"n": n.tolist(), "sigma_designed_m": (1e-4 / np.sqrt(n)).tolist(),
            "sigma_random_m": (2e-4 / np.sqrt(n)).tolist(), "sigma_random_sd_m": (3e-5 / np.sqrt(n)).tolist(),
            "target_sigma_m": 2e-5, "sigma_now_m": 5e-5}


def _certificate_figures() -> list[Callable[[], Any]]:
    """Figures drawn as the certificate draws them (:mod:`pin_kpi_oed.report.figures`: no layout engine, tight
    bounding box); each callable returns the figure."""
    from pin_kpi_oed.report.figures import AFTER, BEFORE, outside_legend

    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    rng = np.random.default_rng(3)

    def fig(w: float, h: float) -> Any:
        f = Figure(figsize=(w, h))
        FigureCanvasAgg(f)
        return f

    def histogram() -> Any:
        f = fig(7.0, 3.2)
        ax = f.subplots()
        eb, ea = np.abs(rng.normal(size=1000)) * 0.3, np.abs(rng.normal(size=1000)) * 0.05
        bins = np.linspace(0.0, float(max(eb.max(), ea.max())), 40)
        ax.hist(eb, bins=bins, color=BEFORE, alpha=0.6, label="before (RMS 0.300 mm)")
        ax.hist(ea, bins=bins, color=AFTER, alpha=0.6, label="after (RMS 0.050 mm)")
        ax.set_xlabel("3-D position error (mm)")
        outside_legend(ax)
        return f

    def panels() -> Any:
        f = fig(10.0, 5.2)
        axes = f.subplots(2, 4).ravel()
        axes[0].scatter(rng.uniform(0.3, 1.2, 1000), np.abs(rng.normal(size=1000)) * 0.05, s=3, color=AFTER,
                        alpha=0.3)
        for ax in axes[:-1]:
            mid = np.linspace(-3, 3, 10)
            ax.plot(mid, 0.3 + 0.1 * np.sin(mid), "o-", color=BEFORE, label="before")
            ax.plot(mid, 0.05 + 0.01 * np.cos(mid), "o-", color=AFTER, label="after")
        outside_legend(axes[0], fontsize=8)
        axes[-1].axis("off")
        f.tight_layout()
        return f

    def correlation() -> Any:
        f = fig(9.4, 8.9)
        ax = f.subplots()
        A = rng.normal(size=(40, 60))
        C = np.corrcoef(A)
        im = ax.imshow(C, vmin=-1, vmax=1, cmap="RdBu_r")
        names = [f"joint_a{i // 6 + 1}.{'txyz'[i % 4]}{i}" for i in range(40)]
        ax.set_xticks(range(40), names, rotation=90, fontsize=6.5)
        ax.set_yticks(range(40), names, fontsize=6.5)
        f.colorbar(im, ax=ax, label="correlation")
        return f

    return [histogram, panels, correlation]


#: the PNGs each figure job writes
FILES = {"ellipsoids": ["ellipsoids.png"], "design_bars": ["bars.png"], "pose_quality": ["poses.png"],
         "trust_map": ["trust_map.png"], "path_profiles": ["path_profiles.png"], "poses_needed": ["poses_needed.png"],
         "certificate (3)": [f"certificate_{i}.png" for i in range(3)]}


def _jobs(out: Path) -> dict[str, Callable[[], Any]]:
    from pin_kpi_oed.report import figures as report_figures
    from pin_kpi_oed.viz import figures
    from pin_kpi_oed.viz.path_profile_plot import plot_path_profiles
    from pin_kpi_oed.viz.poses_needed import plot_poses_needed
    from pin_kpi_oed.viz.trust_map import plot_trust_map

    c = _covs()
    rng = np.random.default_rng(2)
    clear = {n: np.r_[rng.uniform(-0.002, 0.2, 29), np.inf] for n in c}
    inc = {n: rng.uniform(0, 35, 30) for n in c}
    tm = _trust_map()
    cert = _certificate_figures()

    def certificate() -> Any:
        for i, make in enumerate(cert):
            (out / f"certificate_{i}.png").write_bytes(report_figures.png_bytes(make()))

    return {
        "ellipsoids": lambda: figures.plot_ellipsoid_projections(c, out / "ellipsoids.png",
                                                                 labels={"random": "heuristic"}),
        "design_bars": lambda: figures.plot_design_bars({k: float(np.trace(v)) for k, v in c.items()},
                                                        out / "bars.png", n_work=3),
        "pose_quality": lambda: figures.plot_pose_quality(clear, inc, out / "poses.png"),
        "trust_map": lambda: plot_trust_map(None, None, out=out / "trust_map.png", computed=tm,
                                            title="UR10: predicted σ on 300 rows"),
        "path_profiles": lambda: plot_path_profiles(_profiles(), out / "path_profiles.png", title="σ along paths"),
        "poses_needed": lambda: plot_poses_needed(_curve(), out / "poses_needed.png", title="poses needed"),
        "certificate (3)": certificate,
    }


@contextmanager
def _reference():
    """Inside this block the figure modules draw as before: PNGs written by a plain ``savefig``, the ellipsoid
    figure's shading by ``ax.fill`` (the reference)."""
    from pin_kpi_oed.data.atomic import atomic_write_bytes
    from pin_kpi_oed.report import figures as report_figures
    from pin_kpi_oed.viz import figures, path_profile_plot, poses_needed, trust_map

    def save_png(fig: Any, path: Any, dpi: int = 150) -> Path:
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=dpi)
        atomic_write_bytes(path, buf.getvalue())
        return Path(path)

    def png_bytes(fig: Any, dpi: int = report_figures.DPI) -> bytes:
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
        return buf.getvalue()

    def shade(ax: Any, P: np.ndarray, colour: str, alpha: float) -> Any:
        return ax.fill(P[:, 0], P[:, 1], color=colour, alpha=alpha)[0]

    mods = (figures, path_profile_plot, poses_needed, trust_map)
    kept = [m.save_png for m in mods], report_figures.png_bytes, figures.shade
    for m in mods:
        m.save_png = save_png  # type: ignore[attr-defined]
    report_figures.png_bytes = png_bytes
    figures.shade = shade
    try:
        yield
    finally:
        for m, f in zip(mods, kept[0]):
            m.save_png = f  # type: ignore[attr-defined]
        report_figures.png_bytes = kept[1]
        figures.shade = kept[2]


def _same_pixels(a: Path, b: Path) -> bool:
    from PIL import Image

    with Image.open(a) as ia, Image.open(b) as ib:
        return ia.size == ib.size and np.array_equal(np.asarray(ia), np.asarray(ib))


def run(pairs: int = 7) -> dict[str, dict]:
    """Time every figure ``pairs`` times by the current code and by the reference, interleaved.

    Args:
        pairs: number of pairs per figure.

    Returns:
        Per figure: ``current_s`` and ``reference_s`` (medians, s CPU), ``ratio`` (median of current / reference per
        pair), ``wins``, ``p`` (sign test), ``same_pixels`` (every PNG of the figure equal in both ways).
    """
    out: dict[str, dict] = {}
    with tempfile.TemporaryDirectory() as tmp:
        cur_dir, ref_dir = Path(tmp) / "current", Path(tmp) / "reference"
        cur_dir.mkdir()
        ref_dir.mkdir()
        cur, ref = _jobs(cur_dir), _jobs(ref_dir)
        for name in cur:                                   # warm-up: imports, font cache
            cur[name]()
            with _reference():
                ref[name]()
        for name in cur:
            tc, tr = [], []
            for _ in range(pairs):
                t0 = cpu_time()
                cur[name]()
                tc.append(cpu_time() - t0)
                with _reference():
                    t0 = cpu_time()
                    ref[name]()
                    tr.append(cpu_time() - t0)
            c, r = np.array(tc), np.array(tr)
            wins = int(np.sum(c < r))
            out[name] = {"current_s": float(np.median(c)), "reference_s": float(np.median(r)),
                         "ratio": float(np.median(c / r)), "wins": wins, "p": sign_test_p(wins, pairs)}
        for name in cur:
            out[name]["same_pixels"] = all(_same_pixels(cur_dir / f, ref_dir / f) for f in FILES[name])
    return out


def main(argv: list[str] | None = None) -> int:
    """Print the table; ``argv``: this benchmark's options (none when ``python -m benchmarks figures`` runs it)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=7)
    args = ap.parse_args(argv or [])
    res = run(args.pairs)
    print(f"{'figure':17s} {'reference s':>11s} {'current s':>10s} {'ratio':>6s} {'wins':>6s} {'p':>7s}  pixels")
    for name, r in res.items():
        print(f"{name:17s} {r['reference_s']:11.3f} {r['current_s']:10.3f} {r['ratio']:6.2f} "
              f"{r['wins']:3d}/{args.pairs:<2d} {r['p']:7.3f}  {'equal' if r['same_pixels'] else 'DIFFER'}")
    tot_c = sum(r["current_s"] for r in res.values())
    tot_r = sum(r["reference_s"] for r in res.values())
    print(f"{'all':17s} {tot_r:11.3f} {tot_c:10.3f} {tot_c / tot_r:6.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
