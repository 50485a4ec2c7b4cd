"""Is the TCP σ a camera calibration's model file states honest? Monte-Carlo over true robots that are not the model.

Per seed, on the eye-in-hand UR5 camera cell of the tests (``tests/camera_cell.py``: an 8 x 6 inner-corner board of
25 mm squares, 0.2 px noise, the TCP 0.15 m along the tool axis), the same library calls as ``simulate`` ->
``identify --model-out`` -> ``predict --at tcp``:

1. a true robot: every joint placement off by N(0, 0.5 mm / 1 mrad), the hand-eye transform 2 mm / 10 mrad and the
   board 5 mm / 20 mrad off, an unmodelled gear harmonic (σ 50 µrad);
2. ``--images`` images at seeded configurations around the working ones that see the whole board;
3. ``identify_camera`` -> the calibrated model -> ``tcp_sigma`` at 20 other configurations seeing the board: the
   TCP in the board frame and the covariance of its error (parameters + the joint placements held at nominal);
4. the true TCP there (gear harmonic included): the standardised error e^T C^-1 e per configuration.

Printed: the pooled standardised RMS sqrt(mean(e^T C^-1 e) / 3) (honest: near 1; 0.67-1.5 acceptable), the share
inside the 95 % ellipsoid (chi2_3 = 7.81) and within 3 σ (3-D), the median TCP error and σ.

Run: ``python -m benchmarks.camera_pipeline_sigma --seeds 10 [--images 25] [--json out.json]``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

CHI2_3_95 = 7.8147


def one_seed(cell_path: Path, seed: int, n_images: int) -> dict:
    """The standardised TCP errors of one true robot (module docstring)."""
    from pin_kpi_oed.calibrated.tcp_sigma import tcp_sigma
    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.data.corner_measurements import CornerSet
    from pin_kpi_oed.effects.library import parse_effects_spec
    from pin_kpi_oed.identification.camera_identify import identify_camera
    from pin_kpi_oed.simulation.camera_sim import camera_truth, simulate_corners, true_tcp

    cell = load_cell(cell_path)
    model = cell.measurement_model()
    p_true = camera_truth(model, seed=seed)
    effects = parse_effects_spec("gear_harmonic=5e-5", model.robot, np.random.default_rng(seed + 3))
    Q = model.views(n_images, seed=seed + 1, around=cell.q_work)
    uv = simulate_corners(model, Q, p_true, effects, seed=seed + 2)
    cs = CornerSet.from_arrays([f"p{i}" for i in range(len(Q))], Q, uv, list(model.robot.joint_names))
    cm = identify_camera(model, cs, seed=seed, device=cell.camera.to_dict()).calibrated_model()
    Qw = model.views(20, seed=seed + 50, around=cell.q_work)
    ts = tcp_sigma(cm, Qw)
    e = true_tcp(model, Qw, p_true, effects) - ts.position_m
    z = np.einsum("ma,ma->m", e, np.linalg.solve(ts.covariance_m2, e[..., None])[..., 0])
    return {"z": z.tolist(), "e_m": np.linalg.norm(e, axis=1).tolist(), "sigma_m": ts.sigma_m.tolist()}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--seed", type=int, default=0, help="first seed")
    ap.add_argument("--images", type=int, default=25)
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    from pin_kpi_oed.threads import limited_threads

    t0 = time.perf_counter()
    with limited_threads():
        cell_path = Path(__file__).resolve().parents[1] / "examples" / "ur5_camera_cell.yaml"
        runs = [one_seed(cell_path, s, args.images) for s in range(args.seed, args.seed + args.seeds)]
    z = np.concatenate([r["z"] for r in runs])
    e = np.concatenate([r["e_m"] for r in runs])
    s = np.concatenate([r["sigma_m"] for r in runs])
    per_seed = [float(np.sqrt(np.mean(r["z"]) / 3)) for r in runs]
    out = {"seeds": args.seeds, "images": args.images, "standardised_rms": float(np.sqrt(np.mean(z) / 3)),
           "inside_95": float(np.mean(z <= CHI2_3_95)), "within_3_sigma": float(np.mean(e < 3 * s)),
           "median_error_m": float(np.median(e)), "median_sigma_m": float(np.median(s)),
           "per_seed_standardised_rms": per_seed, "time_s": time.perf_counter() - t0}
    print(f"{args.seeds} true robots x 20 configurations, {args.images} images each: standardised RMS "
          f"{out['standardised_rms']:.2f} (per seed {min(per_seed):.2f}-{max(per_seed):.2f}), inside the 95 % "
          f"ellipsoid {out['inside_95'] * 100:.1f} %, within 3 sigma {out['within_3_sigma'] * 100:.1f} %; median TCP "
          f"error {out['median_error_m'] * 1e3:.3f} mm, median sigma {out['median_sigma_m'] * 1e3:.3f} mm "
          f"({out['time_s']:.0f} s)")
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
