"""Real UR10, 6-D: the orientation-weighted KPI (``kpi6``) against the position KPI on the measured orientation error
and the position error at 200 mm along the tool axis, at held-out working configurations of Series C.

Series C of the IPA UR10 data: 2,773 random poses measured with a T-Mac 6-DoF probe (position and orientation).
Per seeded split: ``--work`` rows held out as the working configurations W (scored), the rest the pool. The design
model: the nominal UR10 with the set-up (tracker pose, reflector, probe orientation) fitted to the pool, σ = 0.1 mm
per axis and 0.5 mrad per orientation axis (the weights of the 6-D calibration below). m ∈ ``--sizes`` poses chosen
from the pool by

* ``kpi6``: the mean 6-D KPI at W with the orientation at L = ``--length`` (0.2 m): K = [E_i; L·Ω_i]/√t over the
  identifiable parameters, E_i the measured point's and Ω_i the measured orientation's sensitivity at W_i
  (:mod:`pin_kpi_oed.oed.pose_kpi`; pool selection :func:`~pin_kpi_oed.oed.pool.select`),
* ``kpi``: the position KPI at W (K = E),
* ``random``: m seeded pool rows;

every set calibrated the same way (6-D: geometry, set-up and probe orientation by least squares on the position and
orientation rows, ``identify(..., discrepancy="none")``), then scored at W: the mean orientation error
|log(R_measured R_predictedᵀ)| (mrad) and the mean error of the point L along the tool axis, |e_pos + L·(ω × z)| (mm,
z the predicted tool axis). Paired over the splits (Wilcoxon signed-rank, two-sided): ``kpi6`` against ``kpi`` and
``random``.

Run: ``OMP_NUM_THREADS=1 python -m benchmarks.orientation_real [--splits 20] [--sizes 12,20,60] [--work 30]
[--json out.json]`` (IPA data: ``$PIN_KPI_OED_IPA_DATA`` or ``shared/data/ipa_ur10`` above the repository).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

METHODS = ("kpi6", "kpi", "random")
SCORES = ("rot_error_rad", "error_at_length_m")


def design_model(model, data):
    """The 6-D design model: the nominal robot with the set-up and probe orientation fitted to ``data``."""
    import pinocchio as pin

    from pin_kpi_oed import TrackerModel
    from pin_kpi_oed.identification.identify import identify

    s = identify(model, data, setup_only=True, use_orientation=True, discrepancy="none", on_poor_fit="ignore")
    T = np.asarray(s.tracker_T_base)
    return TrackerModel(model.robot, tracker_T_base=pin.SE3(T[:3, :3].copy(), T[:3, 3].copy()),
                        reflector_m=s.reflector_m, noise=model.noise, pose6d=True, probe_R=s.probe_R)


def score(cm, held, length_m: float) -> dict:
    """Mean orientation error (rad) and mean error of the point ``length_m`` along the tool axis (m) at ``held``."""
    from scipy.spatial.transform import Rotation

    Y = cm.predict(held.q, held, orientation=True)
    w = (Rotation.from_rotvec(held.rotvec_rad) * Rotation.from_rotvec(Y[:, 3:]).inv()).as_rotvec()
    model, p = cm.station_model()
    z = model.kinematics(p, held.q, model.reflector(p)).R_tool[:, :, 2] @ model.tracker_pose(p).rotation.T
    e_l = held.position_m - Y[:, :3] + length_m * np.cross(w, z)
    return {"rot_error_rad": float(np.linalg.norm(w, axis=1).mean()),
            "error_at_length_m": float(np.linalg.norm(e_l, axis=1).mean())}


def run_split(model, ms, seed: int, sizes: tuple[int, ...], n_work: int, length_m: float) -> dict:
    """The designs of one split and their scores at the held-out working configurations (module docstring)."""
    from pin_kpi_oed.identification.identify import identify
    from pin_kpi_oed.oed.identifiability import analyse
    from pin_kpi_oed.oed.pool import select

    rng = np.random.default_rng(seed)
    perm = rng.permutation(len(ms))
    work, pool = perm[:n_work], perm[n_work:]
    dm = design_model(model, ms.subset(pool))
    b = analyse(dm).base
    p0 = np.zeros(dm.n_params)
    Fp = dm.weighted_jacobian(p0, ms.q[pool])[:, :, b]
    J = dm.jacobian(p0, ms.q[work])[:, :, b]               # (t, 6, nb): measured point, then orientation
    E6 = np.concatenate([J[:, :3], length_m * J[:, 3:]], axis=1).reshape(-1, b.size)
    K = {"kpi6": E6 / np.sqrt(n_work), "kpi": J[:, :3].reshape(-1, b.size)}
    held = ms.subset(work)
    rec: dict = {"seed": seed, "work": work.tolist(), "sizes": {}}
    for m in sizes:
        rec["sizes"][m] = {}
        for meth in METHODS:
            chosen = rng.choice(pool, m, replace=False) if meth == "random" else \
                pool[select(Fp, m, K[meth], seed=seed).indices]
            res = identify(model, ms.subset(chosen), use_orientation=True, raise_on_failure=False,
                           discrepancy="none", on_poor_fit="ignore")
            rec["sizes"][m][meth] = {**score(res.calibrated_model(), held, length_m), "rows": chosen.tolist()}
    return rec


def summarise(recs: list[dict], sizes: tuple[int, ...]) -> dict:
    """Means over the splits and the paired tests of ``kpi6`` against the others, per m and score."""
    from benchmarks.common import paired_by_size

    return paired_by_size(recs, sizes, METHODS, SCORES)


def table(summary: dict, n_splits: int, n_work: int, length_m: float) -> str:
    """The table (mrad, mm) and the paired tests."""
    from benchmarks.common import paired_lines

    lines = [f"Series C, {n_splits} splits, {n_work} held-out working configurations; mean orientation error (mrad) / "
             f"mean error {length_m * 1e3:g} mm along the tool axis (mm)",
             f"{'m':>4} " + "".join(f"{meth:>22}" for meth in METHODS)]
    for m, s in summary.items():
        lines.append(f"{m:>4} " + "".join(f"{s['means'][meth]['rot_error_rad'] * 1e3:>12.4f} / "
                                          f"{s['means'][meth]['error_at_length_m'] * 1e3:<6.4f}" for meth in METHODS))
    return "\n".join(lines + paired_lines(summary))


def main(argv: list[str] | None = None) -> int:
    from benchmarks.common import ipa_folder_or_say
    from pin_kpi_oed import NoiseModel, TrackerModel, load_robot
    from pin_kpi_oed.data.atomic import atomic_write_json
    from pin_kpi_oed.data.ipa import import_ipa

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--splits", type=int, default=20)
    ap.add_argument("--sizes", default="12,20,60")
    ap.add_argument("--work", type=int, default=30, help="held-out working configurations per split")
    ap.add_argument("--length", type=float, default=0.2, help="the orientation's length along the tool axis (m)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the first split")
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    folder = ipa_folder_or_say("C")
    if folder is None:
        return 0
    sizes = tuple(int(s) for s in a.sizes.split(","))
    ms = import_ipa(folder / "Series_C")
    model = TrackerModel(load_robot("ur10"), reflector_m=np.array([0.0, 0.0, 0.109]),
                         noise=NoiseModel(sigma_xyz_m=(1e-4,) * 3, sigma_rot_rad=5e-4), pose6d=True)
    t0, c0 = time.perf_counter(), time.process_time()
    recs = []
    for k in range(a.splits):
        recs.append(run_split(model, ms, a.seed + k, sizes, a.work, a.length))
        print(f"split {k + 1}/{a.splits} done ({time.perf_counter() - t0:.0f} s)", file=sys.stderr, flush=True)
    summary = summarise(recs, sizes)
    print(table(summary, a.splits, a.work, a.length))
    print(f"wall {time.perf_counter() - t0:.0f} s, CPU {time.process_time() - c0:.0f} s")
    if a.json:
        atomic_write_json(a.json, {"benchmark": "orientation_real", "splits": a.splits, "work": a.work,
                                   "length_m": a.length, "sizes": list(sizes), "summary": summary, "records": recs})
    return 0


if __name__ == "__main__":
    sys.exit(main())
