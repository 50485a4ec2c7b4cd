"""Real data: calibration of a UR10 (CB3) from the IPA laser-tracker data set, Series C.

Random 50/50 split of the 2,773 random poses (seed 0, ``MeasurementSet.split(0.5, seed=0)``), position
only, uniform weights. "Before" = nominal UR10 (example-robot-data ``ur10``, the CB3 DH geometry) with
only the tracker pose and the reflector offset fitted; "after" = geometric calibration (the 25
identifiable parameters: 16 robot, 6 tracker, 3 reflector; the T-Mac sits on the wrist-3 axis, so the
two wrist-3 rotations and the translation along it are not identifiable). Nothing is re-fitted on
the held-out half.

The T-Mac offset: ``Trafo_TM_F_init.txt`` holds T_TM_F with translation (0, 0.087, −109.0) mm and a
90° rotation about z; read as "flange pose in the T-Mac frame", the T-Mac origin sits at
−Rᵀt = (0, 0, +109.0) mm on the flange z axis, i.e. on tool0's z axis (tool0 z points out of the flange;
ee_link's x does). That is the starting guess; the fit moves it to about (−0.05, 0.20, 93.2) mm in
tool0, whatever the start (0, ±109 mm, ee_link frame: same held-out errors).

Run:  python examples/identify_ur10.py [--series DIR] [--seed 0] [--out DIR]
(``--quick`` or PIN_KPI_OED_QUICK=1: the same steps on 120 seeded random rows of each half, for the tests)
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

import numpy as np

from pin_kpi_oed import NoiseModel, TrackerModel, load_robot
from pin_kpi_oed.identification.identify import format_validation, identify, validate
from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.data.atomic import atomic_write_json
from pin_kpi_oed.data.ipa import import_ipa, read_ipa_flange_transform

_IPA = next((p / "shared" / "data" / "ipa_ur10" for p in (ROOT.parent, ROOT.parent.parent)
             if (p / "shared" / "data" / "ipa_ur10").is_dir()), ROOT.parent / "shared" / "data" / "ipa_ur10")
SERIES_C = _IPA / "Series_C"
SPLIT_SEED = 0  # documented seed of the random 50/50 split
QUICK_ROWS = 120  # rows kept of each half by --quick (>= twice the 60 rows a Gaussian process needs)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--series", default=str(SERIES_C), help="IPA series folder")
    ap.add_argument("--seed", type=int, default=SPLIT_SEED, help="seed of the 50/50 split")
    ap.add_argument("--out", default=None, help="folder for result.json and calibrated.urdf")
    ap.add_argument("--quick", action="store_true", default=os.environ.get("PIN_KPI_OED_QUICK") == "1",
                    help=f"the same steps on {QUICK_ROWS} seeded random rows of each half")
    a = ap.parse_args(argv)

    if not Path(a.series).is_dir():
        print(f"IPA UR10 data not found at {a.series}: nothing to do (pass --series DIR)")
        return 0
    full = import_ipa(a.series)
    pos = MeasurementSet(joint_names=full.joint_names, q=full.q, position_m=full.position_m,
                         temperature_c=full.temperature_c, source=full.source)  # position only, uniform weights
    train, test = pos.split(0.5, seed=a.seed)
    if a.quick:
        rng = np.random.default_rng(a.seed)
        train, test = (ms.subset(np.sort(rng.choice(len(ms), min(QUICK_ROWS, len(ms)), replace=False)))
                       for ms in (train, test))
        print(f"quick run: {QUICK_ROWS} seeded random rows of each half (the figures below are not the example's)")

    T = read_ipa_flange_transform(a.series)
    reflector0 = -T[:3, :3].T @ T[:3, 3]  # T-Mac origin in the flange (tool0) frame, m
    print(f"T-Mac offset guess from Trafo_TM_F_init.txt: {np.round(reflector0 * 1e3, 3)} mm in tool0")

    robot = load_robot("ur10")  # CB3: d = 127.3, 0, 0, 163.941, 115.7, 92.2 mm; a = 0, -612, -572.3, 0, 0, 0 mm
    model = TrackerModel(robot, reflector_m=np.round(reflector0, 6), noise=NoiseModel(sigma_xyz_m=(1e-4,) * 3))
    before = identify(model, train, setup_only=True, scale_covariance=True)
    after = identify(model, train, scale_covariance=True)
    print(after.summary())
    vb, va = validate(before, test), validate(after, test)
    print(f"UR10 Series C, {len(train)} train / {len(test)} held-out (split seed {a.seed}), position only:")
    print(format_validation(vb, "  before (nominal + fitted tracker pose and reflector)"))
    print(format_validation(va, "  after  (geometric calibration)                      "))
    print(f"  fitted reflector in tool0: {np.round(after.reflector_m * 1e3, 3).tolist()} mm "
          f"(baseline fit: {np.round(before.reflector_m * 1e3, 3).tolist()} mm)")
    print(f"  identification time {after.time_s * 1e3:.0f} ms, {after.nit} LM iterations")
    ok = va["mean_m"] <= 0.45e-3
    print(f"  target held-out mean ≤ 0.45 mm: {'met' if ok else 'NOT met'}")
    if a.out:
        from pin_kpi_oed.calibrated.urdf_export import export_result_urdf

        out = Path(a.out)
        atomic_write_json(out / "result.json", {"result": after.to_dict(), "baseline": before.to_dict(),
                                                "validation": {"before": vb, "after": va}, "split_seed": a.seed})
        export_result_urdf(after, out / "calibrated.urdf")
        print(f"  wrote {out / 'result.json'}, {out / 'calibrated.urdf'}")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
