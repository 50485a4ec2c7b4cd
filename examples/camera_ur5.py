"""A camera instead of a tracker: a UR5 with a camera on its tool calibrated from simulated board images.

The cell (``examples/ur5_camera_cell.yaml``) puts a camera on the UR5's tool and a printed chessboard on the table. A
true robot with every joint placement, the hand-eye transform and the board off nominal and an unmodelled gear
harmonic is "photographed" at configurations that see the board (0.2 px noise); the corners identify the robot, the
hand-eye transform and the board; the TCP's σ at new configurations is printed beside its true error. Most of the
TCP's σ is the flange's offset along the last joint's axis: no image of the board can see it (the hand-eye transform
absorbs it), so its tolerance stays in the σ.

Run:  python examples/camera_ur5.py [--images 25] [--seed 0]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from pin_kpi_oed.calibrated.tcp_sigma import tcp_sigma
from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.data.corner_measurements import CornerSet
from pin_kpi_oed.effects.library import parse_effects_spec
from pin_kpi_oed.identification.camera_identify import identify_camera
from pin_kpi_oed.simulation.camera_sim import camera_truth, simulate_corners, true_tcp

CELL = Path(__file__).resolve().parent / "ur5_camera_cell.yaml"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--images", type=int, default=25, help="board images (one per configuration)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    cell = load_cell(CELL)
    model = cell.measurement_model()
    p_true = camera_truth(model, seed=args.seed)
    effects = parse_effects_spec("gear_harmonic=5e-5", model.robot, np.random.default_rng(args.seed + 3))
    Q = model.views(args.images, seed=args.seed + 1, around=cell.q_work)
    uv = simulate_corners(model, Q, p_true, effects, seed=args.seed + 2)
    corners = CornerSet.from_arrays([f"p{i}" for i in range(len(Q))], Q, uv, list(model.robot.joint_names))
    cm = identify_camera(model, corners, seed=args.seed, device=cell.camera.to_dict()).calibrated_model()
    Q_new = model.views(10, seed=args.seed + 50, around=cell.q_work)
    ts = tcp_sigma(cm, Q_new)
    err_m = np.linalg.norm(true_tcp(model, Q_new, p_true, effects) - ts.position_m, axis=1)
    print(f"{len(Q)} images of the board; TCP at 10 new configurations (mm):")
    print("   true error   σ (of it held at nominal)")
    for e, s, h in zip(err_m, ts.sigma_m, ts.held_sigma_m):
        print(f"   {e * 1e3:10.3f}   {s * 1e3:.3f} ({h * 1e3:.3f})")
    inside = int(np.sum(err_m < 3 * ts.sigma_m))
    print(f"{inside} of {len(err_m)} true errors within 3 σ")
    return 0 if inside >= len(err_m) - 1 else 1


if __name__ == "__main__":
    raise SystemExit(main())
