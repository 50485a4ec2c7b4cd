"""Diagnosis benchmark: the full sim-to-real gap diagnosis of 2,000 measurements (target <= 60 s on 2 cores).

UR10, σ = 10 µm, random geometric errors, joint compliance withheld (visible part 5σ),
temperature column (so all five candidate effects are tried). Two cases:

* split: 1,000 training + 1,000 held-out measurements;
* K-fold: one file of 2,000 measurements, 5-fold cross-validation;
* real data: ``diagnose`` on all of IPA UR10 Series C (2,773 rows, 5-fold, position
  only, σ = 0.1 mm) with the default candidates plus ``transmission_error`` (orders 1–40, sparse
  selection), as ``pin-kpi-oed diagnose --train C.csv --kfold 5 --effects
  joint_compliance,gear_harmonic,backlash,thermal_expansion,joint_scale,transmission_error
  --reflector 0,0,0.109 --sigma 1e-4`` runs it (skipped when the data are not there).

Run: ``python -m benchmarks bench_diagnosis`` (``make bench`` runs every benchmark).
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from .common import report, timed  # noqa: E402

TARGET_S = 60.0


def _data(n_total: int, seed: int = 0):
    from pin_kpi_oed.effects.library import parse_effects_spec, size_effect
    from pin_kpi_oed.data.measurements import MeasurementSet
    from pin_kpi_oed.model.noise import NoiseModel
    from pin_kpi_oed.model.tracker import TrackerModel
    from pin_kpi_oed.model.robot import load_robot
    from pin_kpi_oed.simulation.simulator import Tolerances, default_tracker_pose, random_truth, simulate

    rb = load_robot("ur10")
    refl = np.array([0.05, 0.02, 0.10])
    truth = TrackerModel(rb, tracker_T_base=default_tracker_pose(rb), reflector_m=refl, noise=NoiseModel((1e-5,) * 3))
    p = random_truth(truth, Tolerances(tracker_translation_m=0.01, tracker_rotation_rad=0.01), seed=seed)
    rng = np.random.default_rng(seed)
    Q = rb.random_q(rng, n_total)
    temp = 20 + 5 * rng.random(n_total)
    (eff, th), = parse_effects_spec("joint_compliance=1e-6", rb, rng)
    th = size_effect(truth, p, Q, MeasurementSet(rb.joint_names, Q, np.zeros((n_total, 3)), temperature_c=temp),
                     eff, th, 5e-5)
    data = simulate(truth, Q, p, effects=[(eff, th)], aux={"temperature_c": temp}, seed=seed)
    return TrackerModel(rb, reflector_m=refl, noise=NoiseModel((1e-5,) * 3)), data


def main() -> None:
    from pin_kpi_oed.diagnosis.diagnose import diagnose

    print("== diagnosis (UR10, 2,000 measurements, 5 candidate effects, joint compliance withheld)")
    model, data = _data(2000)
    t_split, rep = timed(lambda: diagnose(model, data.subset(np.arange(1000)), data.subset(np.arange(1000, 2000))))
    report(f"split 1000/1000: dominant={rep.dominant_effect}", t_split, TARGET_S)
    t_kf, rep = timed(lambda: diagnose(model, data, kfold=5))
    report(f"5-fold on 2000: dominant={rep.dominant_effect}", t_kf, TARGET_S)
    series_c()


def series_c() -> float | None:
    """Diagnose all of IPA UR10 Series C with the default candidates + transmission_error; the time (s) or None."""
    from benchmarks.common import find_ipa_data, load_ipa_series
    from pin_kpi_oed.diagnosis.diagnose import diagnose
    from pin_kpi_oed.effects.library import EFFECT_NAMES
    from pin_kpi_oed.model.noise import NoiseModel
    from pin_kpi_oed.model.robot import load_robot
    from pin_kpi_oed.model.tracker import TrackerModel

    root = find_ipa_data()
    if root is None or not (root / "Series_C").is_dir():
        print("   Series C not found (shared/data/ipa_ur10): skipped")
        return None
    data = load_ipa_series(root, "C")
    model = TrackerModel(load_robot("ur10"), reflector_m=np.array([0.0, 0.0, 0.109]),
                         noise=NoiseModel(sigma_xyz_m=(1e-4,) * 3))
    t, rep = timed(lambda: diagnose(model, data, kfold=5, effects=list(EFFECT_NAMES) + ["transmission_error"]))
    ts = rep.term_selection
    report(f"Series C, {len(data)} rows, 5-fold, defaults + transmission_error: dominant={rep.dominant_effect}, "
           f"{len(ts.get('terms', []))} terms, held-out RMS {rep.heldout_before['rms_m'] * 1e3:.3f} -> "
           f"{rep.heldout_after['rms_m'] * 1e3:.3f} mm", t, TARGET_S)
    return t


if __name__ == "__main__":
    import sys

    series_c() if "--series-c" in sys.argv else main()
