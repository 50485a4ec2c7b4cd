"""The fit-quality gate and the joint-placement prior on few poses of one session used in another.

On the directed pair Series D → Series C of the real UR10 (the split of ``benchmarks.learning_curves``, 20 seeds),
every method's set of 12, 20 and 30 poses of D is identified (geometry + set-up, least squares) and judged by
:func:`~pin_kpi_oed.identification.quality.assess_fit`; its error is the mean 3-D error of C's scored rows after
C's set-up is registered on 60 rows of C. Printed: per method and size the sets above 2 mm, how many of them and
of the others the gate's geometry check ("implausibly far from the nominal model") flags, and the sets above 2 mm
when the same rows are identified with the weak joint-placement prior of ``identify --geometry-prior 5e-3,1e-2``
(:meth:`~pin_kpi_oed.model.parameters.ParameterLayout.set_joint_prior`), with the largest change it makes to a
set below 2 mm.

Run:  OMP_NUM_THREADS=1 python -m benchmarks.fit_gate_pairs [--seeds 20] [--cache runs/curves]   (about 10 min)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from benchmarks.common import find_ipa_data, load_ipa_series
from benchmarks.learning_curves import ur10_model, prior_of_series


def main(argv: list[str]) -> dict:
    from pin_kpi_oed.identification.identify import identify
    from pin_kpi_oed.identification.quality import assess_fit
    from pin_kpi_oed.studies.learning_curves import PoolDesigns, make_split, score_split

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--cache", default="runs/learning_curves", help="where the Series D prior is cached")
    a = ap.parse_args(argv)
    folder = find_ipa_data()
    if folder is None:
        sys.exit("IPA data not found: set PIN_KPI_OED_IPA_DATA")
    S = {s: load_ipa_series(folder, s) for s in "CD"}
    model = ur10_model()
    weak = ur10_model()
    weak.layout.set_joint_prior(5e-3, 1e-2)
    cache = Path(a.cache)
    cache.mkdir(parents=True, exist_ok=True)
    prior = prior_of_series(model, "D", S, cache)
    rows = []
    for seed in range(a.seeds):
        sp = make_split(S["D"], S["C"], np.random.default_rng(seed), 0.3, 5, 0.5, 5, None, 60)
        des = PoolDesigns(model, sp, prior, seed, 0.5, 5, 100)
        for m in (12, 20, 30):
            for meth in ("kpi_gp", "kpi", "D", "random"):
                idx = np.sort(des.choose(meth, m))
                res = identify(model, sp.pool.subset(idx), use_orientation=False, raise_on_failure=False)
                flagged = "implausibly far" in assess_fit(res).line()
                rows.append((meth, m, score_split(model, sp.pool.subset(idx), sp, prior)[0], flagged,
                             score_split(weak, sp.pool.subset(idx), sp, prior)[0]))
        print(f"seed {seed}: done", file=sys.stderr, flush=True)
    out = {}
    print(f"{'design':<8}{'m':>4}{'sets > 2 mm':>13}{'flagged of them':>17}{'flagged of the others':>23}"
          f"{'> 2 mm with the prior':>23}")
    for meth in ("kpi_gp", "kpi", "D", "random"):
        for m in (12, 20, 30):
            r = [(e, f, w) for k, mm, e, f, w in rows if k == meth and mm == m]
            bad = sum(e > 2e-3 for e, _, _ in r)
            fb = sum(f and e > 2e-3 for e, f, _ in r)
            fo = sum(f and e <= 2e-3 for e, f, _ in r)
            wb = sum(w > 2e-3 for _, _, w in r)
            out[f"{meth}_{m}"] = {"sets": len(r), "above_2mm": bad, "flagged_above": fb, "flagged_below": fo,
                                  "above_2mm_with_prior": wb}
            print(f"{meth:<8}{m:>4}{bad:>13}{fb:>17}{fo:>19}/{len(r) - bad}{wb:>23}")
    e, f, w = (np.array([x[i] for x in rows]) for i in (2, 3, 4))
    good = e <= 2e-3
    print(f"all: {int((~good).sum())} sets above 2 mm, {int((f & ~good).sum())} of them flagged; "
          f"{int((f & good).sum())} of the {int(good.sum())} others flagged; with the prior {int((w > 2e-3).sum())} "
          f"above 2 mm; the sets below 2 mm: at most {(w - e)[good].max() * 1e3:+.3f} mm worse, at most "
          f"{-(w - e)[good].min() * 1e3:.3f} mm better, median |change| {np.median(np.abs(w - e)[good]) * 1e3:.4f} mm")
    return out


if __name__ == "__main__":
    main(sys.argv[1:])
