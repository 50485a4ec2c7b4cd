"""Diagnosis benchmark: the full sim-to-real gap diagnosis of 2,000 measurements (target <= 60 s on 2 cores).

UR10, σ = 10 µm, random geometric errors, joint compliance withheld (visible part 5σ),
temperature column (so all five candidate effects are tried). Two cases:

* split: 1,000 training + 1,000 held-out measurements;
* K-fold: one file of 2,000 measurements, 5-fold cross-validation.

Run: ``python -m benchmarks bench_diagnosis`` (``make bench`` runs every benchmark).
"""

from __future__ import annotations

import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from .common import report  # noqa: E402

TARGET_S = 60.0


def _data(n_total: int, seed: int = 0):
    from pin_kpi_oed.effects.library import parse_effects_spec, size_effect
    from pin_kpi_oed.data.measurements import MeasurementSet
    from pin_kpi_oed.model.noise import NoiseModel
    from pin_kpi_oed.model.tracker import TrackerModel
    from pin_kpi_oed.model.robot import load_robot
    from pin_kpi_oed.identification.simulate import Tolerances, default_tracker_pose, random_truth, simulate

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


def series_c() -> None:
    """The real UR10 data: diagnose on all of Series C (2,773 rows, 5-fold), target <= 60 s (issue 16)."""
    from pathlib import Path

    from pin_kpi_oed.data.ipa import import_ipa
    from pin_kpi_oed.data.measurements import MeasurementSet
    from pin_kpi_oed.diagnosis.diagnose import diagnose
    from pin_kpi_oed.model.noise import NoiseModel
    from pin_kpi_oed.model.robot import load_robot
    from pin_kpi_oed.model.tracker import TrackerModel

    here = Path(__file__).resolve()
    ipa = next((q / "shared" / "data" / "ipa_ur10" for q in (here.parents[2], here.parents[3])
                if (q / "shared" / "data" / "ipa_ur10").is_dir()), None)
    if ipa is None:
        print("Series C: IPA UR10 data not found; skipped")
        return
    ms = import_ipa(ipa / "Series_C")
    ms = MeasurementSet(ms.joint_names, ms.q, ms.position_m, temperature_c=ms.temperature_c, source=ms.source)
    model = TrackerModel(load_robot("ur10"), reflector_m=np.array([0.0, 0.0, 0.109]),
                         noise=NoiseModel(range_a_m=7.5e-6, range_b=3e-6))
    print(f"== diagnosis on the real UR10 Series C ({len(ms)} rows, 5-fold cross-validation, noise weights)")
    t0 = time.perf_counter()
    rep = diagnose(model, ms, kfold=5, weights="noise")
    report(f"Series C, all {len(ms)} rows, 5-fold: dominant={rep.dominant_effect}", time.perf_counter() - t0,
           TARGET_S)


def main() -> None:
    from pin_kpi_oed.diagnosis.diagnose import diagnose

    print("== diagnosis (UR10, 2,000 measurements, 5 candidate effects, joint compliance withheld)")
    model, data = _data(2000)
    t0 = time.perf_counter()
    rep = diagnose(model, data.subset(np.arange(1000)), data.subset(np.arange(1000, 2000)))
    t_split = time.perf_counter() - t0
    report(f"split 1000/1000: dominant={rep.dominant_effect}", t_split, TARGET_S)
    t0 = time.perf_counter()
    rep = diagnose(model, data, kfold=5)
    t_kf = time.perf_counter() - t0
    report(f"5-fold on 2000: dominant={rep.dominant_effect}", t_kf, TARGET_S)
    series_c()


if __name__ == "__main__":
    main()
