"""Does the K-fold gain of the term selection hold on another session? Seeded random folds against folds that keep
near-duplicate poses together (the default), on the real UR10.

For each pair X -> Y of IPA UR10 series: a geometric calibration of X (position rows, σ = 0.1 mm, plain loss), the
sparse term selection on X (``select_terms``: transmission-error orders 1..40 and link bending, 5 folds, refit with
the selected terms) once with folds that split near-duplicate poses at random (every row its own fold at random, as
the selection did before) and once with the default folds (near-duplicate configurations, within 0.05 rad, in one
fold). "CV gain" is the selection's own K-fold figure, 1 − CV RMS(with terms) / CV RMS(geometry); "held-out gain"
the same ratio on Y's rows after re-registering the set-up of both models on 60 seeded rows of Y (scored on the
others). A K-fold that leaks repeats promises a gain Y does not show.

Run:  python -m benchmarks.selection_folds [--pairs A->C,D->C] [--rows 3000] [--json out.json]
      (IPA data: $PIN_KPI_OED_IPA_DATA or shared/data/ipa_ur10 beside the repository)
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from benchmarks.common import ipa_folder_or_say, ipa_ur10_model, load_ipa_series  # noqa: E402


def _rms(R: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(R ** 2, axis=1))))


def heldout_rms(fit, target, seed: int) -> float:
    """3-D RMS (m) of ``fit`` on ``target`` after re-registering its set-up on 60 seeded rows (the others scored)."""
    from pin_kpi_oed.identification.problem import align_data
    from pin_kpi_oed.upkeep.transfer import register_setup, registration_split

    reg, held = registration_split(len(target), 60, seed)
    rr = register_setup(fit.calibrated_model(), target.subset(reg), station="target")
    h = target.subset(held)
    return _rms(h.position_m - rr.model.predict(align_data(fit.model.robot, h), h, station="target"))


def run_pair(model, src, tgt, seed: int) -> dict:
    """Both fold kinds on src -> tgt: CV gain and held-out gain (see the module docstring)."""
    from pin_kpi_oed.diagnosis.selection import select_terms
    from pin_kpi_oed.identification.identify import identify

    geo = identify(model, src, discrepancy="none", loss="linear", on_poor_fit="ignore", raise_on_failure=False)
    base = heldout_rms(geo, tgt, seed)
    random_folds = np.empty(len(src), int)
    random_folds[np.random.default_rng(seed).permutation(len(src))] = np.arange(len(src)) % 5
    out = {"n_train": len(src), "n_target": len(tgt), "heldout_geometry_mm": base * 1e3}
    for kind, folds in (("random", random_folds), ("grouped", 5)):
        t0 = time.process_time()
        sel = select_terms(geo, src, folds=folds, seed=seed, show_progress=False)
        fit = sel.fit if sel.fit is not None else geo
        after = heldout_rms(fit, tgt, seed)
        out[kind] = {"terms": len(sel.terms), "cv_gain": 1.0 - sel.cv_rms_m[-1] / sel.cv_rms_m[0],
                     "heldout_gain": 1.0 - after / base, "heldout_mm": after * 1e3, "cpu_s": time.process_time() - t0}
    return out


def main(argv: list[str] | None = None) -> int:
    from pin_kpi_oed.data.atomic import atomic_write_json

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", default="A->C,D->C", help="directed pairs (default %(default)s)")
    ap.add_argument("--rows", type=int, default=3000, help="seeded subset of a larger training series (rows)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    folder = ipa_folder_or_say()
    if folder is None:
        return 0
    model = ipa_ur10_model()
    results = {}
    for pair in [p.strip() for p in a.pairs.split(",") if p.strip()]:
        s, t = pair.split("->")
        src, tgt = load_ipa_series(folder, s), load_ipa_series(folder, t)
        if len(src) > a.rows:
            src = src.subset(np.sort(np.random.default_rng(a.seed).permutation(len(src))[:a.rows]))
        r = run_pair(model, src, tgt, a.seed)
        results[pair] = r
        print(f"{pair}: {r['n_train']} training rows, held-out geometry {r['heldout_geometry_mm']:.4f} mm")
        for kind in ("random", "grouped"):
            k = r[kind]
            print(f"  {kind:<8} folds: {k['terms']:>2} terms, CV gain {100 * k['cv_gain']:+.1f} %, held-out gain "
                  f"{100 * k['heldout_gain']:+.1f} % ({k['heldout_mm']:.4f} mm), CPU {k['cpu_s']:.0f} s", flush=True)
    if a.json:
        atomic_write_json(a.json, results)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
