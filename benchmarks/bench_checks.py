"""Cost of the input checks every writing command runs: each ≤ 50 ms per command.

Measured on a model file with a fitted discrepancy (UR10, simulated, 400 rows with a withheld gear harmonic: the
largest model file a user handles routinely, with its base64 training block) and a 60-row registration:

* the output-path check (``check_outputs``: three outputs against two inputs, claims included);
* the model file's schema check (``validate_model_dict``: every field typed and ranged, covariances symmetric
  positive semi-definite), without the file read and the model build;
* the registration gate (``assess_registration``: rows against unknowns, χ² against the noise, the mirrored frame);
* the joint-limit check of a 2,000-row measurement table (``robot.check_q``, as ``register``/``predict`` run it).

The baseline is loading the model file (JSON parse + build) in the same run. Median of 20 repetitions each.

Run:  python -m benchmarks bench_checks
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np

from benchmarks.common import figure, median_time, withheld_ur10


def _median(fn) -> float:
    return median_time(fn, repeat=20, warmup=1)


def main() -> dict:
    from pin_kpi_oed.identification.identify import identify
    from pin_kpi_oed.calibrated.model_file import load_model_file
    from pin_kpi_oed.identification.quality import assess_registration
    from pin_kpi_oed.validation.paths import check_outputs, release_outputs
    from pin_kpi_oed.validation.schema import validate_model_dict

    model, data = withheld_ur10(2400)
    rb = model.robot
    cm = identify(model, data.subset(np.arange(400)), discrepancy="on", raise_on_failure=False).calibrated_model()
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        mf = Path(tmp) / "model.json"
        cm.save(mf)
        doc = json.loads(mf.read_text())
        ins = [("--model", mf), ("--data", Path(tmp) / "data.csv")]
        (Path(tmp) / "data.csv").write_text("x\n")
        outs = [("--out", Path(tmp) / "pred.csv"), ("--json", Path(tmp) / "r.json"),
                ("--figure", Path(tmp) / "t.png")]

        def paths():
            check_outputs(outs, ins)
            release_outputs()

        t_load = _median(lambda: load_model_file(mf))
        checks = {"output-path check (3 outputs, 2 inputs)": _median(paths),
                  f"model-file schema ({mf.stat().st_size / 1e3:.0f} kB, discrepancy block)":
                      _median(lambda: validate_model_dict(doc, str(mf)))}
    reg = data.subset(np.arange(400, 460))
    Y = cm.predict(reg.q)
    checks["registration gate (60 rows)"] = _median(
        lambda: assess_registration("s", Y, reg.position_m, np.linalg.norm(reg.position_m - Y, axis=1),
                                    np.full(3, 1e-5), 9))
    big = data.subset(np.arange(400, 2400))
    checks["joint limits of 2,000 rows"] = _median(lambda: rb.check_q(big.q, "data"))
    for label, t in checks.items():
        out[label] = t
        figure(label, t * 1e3, 50.0, "ms", t_load * 1e3, "loading the model file")
    return out


if __name__ == "__main__":
    main()
