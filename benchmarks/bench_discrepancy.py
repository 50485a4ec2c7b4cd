"""Discrepancy speed and memory: identify with ``discrepancy="auto"`` on the seeded half of Series C (1,387 rows, the
test half of ``import-ipa --split 0.5 --seed 0``) ≤ 5 s CPU and wall, and beside two CPU-bound processes
(:class:`~benchmarks.common.BusyCore`) at most 2.5 times its wall time alone; on 2,773 real rows ≤ 10 s CPU and ≤ 30 s;
on 12,000 rows ≤ 120 s and ≤ 2 GB; predict (with σ) of 10,000 rows ≤ 5 s.

Data: the IPA UR10 Series C (2,773 random poses) and Series A (11,911 grid poses, 89 rows of Series C added to
reach 12,000), position only, σ = 0.1 mm uniform weights; the baseline is the same identification without the
discrepancy (``discrepancy="none"``), timed in the same run. Peak memory: the process's maximum resident set
(``resource.getrusage``) after the 12,000-row fit. Without the IPA data the benchmark says so and skips.

Run:  python -m benchmarks bench_discrepancy
      python -m benchmarks.bench_discrepancy --big   (also a simulated 100,000-row file: UR10 with a withheld gear
      harmonic, σ = 10 µm; identify with the discrepancy, then 2,000 held-out rows scored with their σ)
"""

from __future__ import annotations

import argparse
import resource

import numpy as np

from benchmarks.common import BusyCore, figure, stopwatch, timed as timed_call


def main() -> dict:
    from benchmarks.common import find_ipa_data, load_ipa_series
    from pin_kpi_oed import NoiseModel, TrackerModel, load_robot
    from pin_kpi_oed.data.measurements import MeasurementSet, concat_measurements
    from pin_kpi_oed.identification.identify import identify

    folder = find_ipa_data()
    if folder is None or not (folder / "Series_A").is_dir():
        print("== bench_discrepancy: IPA UR10 data not found (PIN_KPI_OED_IPA_DATA): skipped")
        return {}
    model = TrackerModel(load_robot("ur10"), reflector_m=np.array([0.0, 0.0, 0.109]),
                         noise=NoiseModel(sigma_xyz_m=(1e-4,) * 3))
    C = load_ipa_series(folder, "C")
    out = {}

    def timed(data, mode="auto"):
        return timed_call(lambda: identify(model, data, discrepancy=mode, raise_on_failure=False))

    _, half = C.split(0.5, seed=0)  # import-ipa --split 0.5 --seed 0: the held-out half, 1,387 rows
    t_half, res = timed(half, "auto")
    figure(f"identify --discrepancy auto, {len(half)} rows (Series C, seeded half), CPU", t_half.cpu_s, 5.0, "s")
    figure(f"identify --discrepancy auto, {len(half)} rows (Series C, seeded half)", t_half, 5.0, "s")
    with BusyCore(), BusyCore():
        t_busy, _ = timed(half)
    figure("  the same beside two CPU-bound processes / alone, wall", t_busy / t_half, 2.5, "x")
    out.update({"identify_auto_1387_s": t_half, "identify_auto_1387_cpu_s": t_half.cpu_s,
                "identify_auto_1387_busy_ratio": t_busy / t_half})
    t_none, _ = timed(C, "none")
    t_auto, res = timed(C, "auto")
    figure(f"identify --discrepancy auto, {len(C)} rows (Series C), CPU", t_auto.cpu_s, 10.0, "s")
    out["identify_auto_2773_s"] = t_auto
    figure(f"identify --discrepancy auto, {len(C)} rows (Series C)", t_auto, 30.0, "s", t_none, "without")
    print(f"   {res.discrepancy.decision}")
    A = load_ipa_series(folder, "A")
    big = concat_measurements([A, C.subset(np.arange(12000 - len(A)))], ["A", "C"])
    t_none, _ = timed(big, "none")
    t_auto, res = timed(big, "auto")
    peak_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024 ** 2
    out.update({"identify_auto_12000_s": t_auto, "peak_rss_gb": peak_gb})
    figure(f"identify --discrepancy auto, {len(big)} rows (Series A + C)", t_auto, 120.0, "s", t_none, "without")
    figure("peak resident memory of the process after it", peak_gb, 2.0, "GB")
    print(f"   {res.discrepancy.decision}")
    cm = res.calibrated_model()
    Q = np.vstack([A.q, A.q])[:10000]
    aux = MeasurementSet(A.joint_names, Q, np.full((len(Q), 3), np.nan), station=np.array(["A"] * len(Q)))
    t_pred, _ = timed_call(lambda: cm.predict_with_sigma(Q, aux))
    t_plain, _ = timed_call(lambda: cm.predict(Q, aux))
    out["predict_10000_s"] = t_pred
    figure("predict with sigma, 10,000 rows", t_pred, 5.0, "s", t_plain, "predict without sigma")
    return out


def big(n: int = 100_000, n_test: int = 2_000) -> dict:
    """The inducing-point posterior on a simulated ``n``-row file: time, peak memory, held-out honesty."""
    from benchmarks.common import withheld_ur10
    from pin_kpi_oed.identification.identify import identify, validate

    model, data = withheld_ur10(n + n_test)
    train, test = data.subset(np.arange(n)), data.subset(np.arange(n, n + n_test))
    with stopwatch() as sw:
        res = identify(model, train, discrepancy="auto", raise_on_failure=False)
    wall, cpu = sw.timing, sw.timing.cpu_s
    peak_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024 ** 2
    cm = res.calibrated_model()
    v, v0 = validate(cm, test), validate(cm.noise_only(), test)
    print(f"identify --discrepancy auto, {n:,} simulated rows: {wall.words()}")
    figure("peak resident memory of the process after it (laptop)", peak_gb, 2.0, "GB")
    print(f"   {res.discrepancy.decision}")
    print(f"   {n_test} held-out rows: mean {v0['mean_m'] * 1e6:.1f} -> {v['mean_m'] * 1e6:.1f} um, standardised RMS "
          f"{v['z_rms']:.2f}, {v['inside_95'] * 100:.1f} % inside the 95 % ellipsoid")
    return {"identify_auto_big_s": wall, "cpu_s": cpu, "peak_rss_gb": peak_gb, "z_rms": v["z_rms"],
            "inside_95": v["inside_95"]}


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--big", action="store_true", help="also the simulated 100,000-row file (a few minutes)")
    if ap.parse_args().big:
        big()
    else:
        main()
