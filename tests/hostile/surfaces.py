"""Hostile inputs on the newest surfaces: discrepancy blocks of model files, ``predict`` / ``register`` /
``diagnose --model-out``, the ``kpi_gp`` design options, another arm's calibration, outputs onto inputs.

``build_surface_inputs(folder)`` adds their inputs to the shared folder of :mod:`tests.hostile.cases`
(model files with hand-edited discrepancy values, a UR5 calibration and UR10 rows, damaged data files);
``surface_cases()`` lists the cases; ``EXTRA`` builds inputs too large to copy for every case, in the
case's own folder (``Case.needs``).
"""

from __future__ import annotations

import base64
import contextlib
import io
import json
from pathlib import Path

import numpy as np

#: hand-edited discrepancy blocks: file -> (edit of the block, the field the refusal must name)
_DISC_EDITS = {
    "scale_mm": (lambda b: b.update(scale_m=[v * 1e3 for v in b["scale_m"]]), "scale_m"),
    "len_tiny": (lambda b: b["kernel"].update(length_scale_rad=[1e-300] * 6), "length_scale_rad"),
    "len_huge": (lambda b: b["kernel"].update(joint_length_scale_rad=[1e300] * 6), "joint_length_scale_rad"),
    "amp_1e200": (lambda b: b["kernel"].update(amplitude=1e200), "amplitude"),
    "amp_nan": (lambda b: b["kernel"].update(amplitude=float("nan")), "amplitude"),
    "noise_1e10": (lambda b: b.update(noise=1e10), "noise"),
    "cv_list": (lambda b: b.update(cv=[1, 2]), "cv"),
    "nrows_list": (lambda b: b.update(n_rows=[120]), "n_rows"),
    "white_parametric": (lambda b: b.update(kind="white"), "parametric"),
    "param_unknown": (lambda b: b["parametric"]["param_names"].__setitem__(0, "joint_a9.tx"), "param_names"),
    "z_nan": (lambda b: b.update(Z_rad=_with_nan(b["Z_rad"])), "Z_rad"),
    "y_nan": (lambda b: b.update(y=_with_nan(b["y"])), "discrepancy.y"),
}


def _with_nan(arr: dict) -> dict:
    """An encoded array (``shape`` + ``float64_b64``) with its first value NaN."""
    a = np.frombuffer(base64.b64decode(arr["float64_b64"]), dtype="<f8").copy()
    a[0] = np.nan
    return {**arr, "float64_b64": base64.b64encode(a.astype("<f8").tobytes()).decode()}


def build_surface_inputs(d: Path) -> None:
    """Add this module's inputs to ``d`` (needs ``m.json``, ``tr.csv``, ``te.csv``; about 4 s)."""
    from pin_kpi_oed.cli.app import main

    model = json.loads((d / "m.json").read_text())
    assert model.get("discrepancy", {}).get("kind") == "exact", "m.json must hold a fitted discrepancy"
    nodisc = {k: v for k, v in model.items() if k != "discrepancy"}
    (d / "m_nodisc.json").write_text(json.dumps(nodisc))
    for tag, (edit, _) in _DISC_EDITS.items():
        m = json.loads(json.dumps(model))
        edit(m["discrepancy"])
        (d / f"m_d_{tag}.json").write_text(json.dumps(m))
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        assert main(["simulate", "--robot", "ur5", "--n", "40", "--seed", "1", "--out", str(d / "ur5.csv")]) == 0
        assert main(["identify", "--robot", "ur5", "--data", str(d / "ur5.csv"), "--model-out", str(d / "m_ur5.json"),
                     "--discrepancy", "none", "--quiet", "--accept-poor-fit"]) == 0
        assert main(["simulate", "--robot", "ur10", "--n", "20", "--seed", "2", "--out", str(d / "reg_ur10.csv")]) == 0
    (d / "ur5.csv").unlink()
    (d / "reg_ur10_bare.csv").write_text("\n".join(ln for ln in (d / "reg_ur10.csv").read_text().splitlines()
                                                   if not ln.startswith("#")) + "\n")  # no tool header
    reg = [ln for ln in (d / "reg20.csv").read_text().splitlines() if not ln.startswith("#")]
    h = reg[0].split(",")
    sig = [h.index(c) for c in ("sigma_x", "sigma_y", "sigma_z")]
    rows = [r.split(",") for r in reg[1:]]
    for r in rows:
        for i in sig:
            r[i] = "0.005"  # 5 mm stated, 10 µm real
    (d / "reg20_sigma_mm.csv").write_text("\n".join([reg[0]] + [",".join(r) for r in rows]) + "\n")
    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.design.optimize import DesignProblem

    cell = load_cell("ur10")
    Q, _ = DesignProblem(cell).random_design(10, seed=3, max_tries=10 ** 5)
    (d / "given_ur10.csv").write_text("\n".join([",".join(cell.robot.joint_names)]
                                                + [",".join(f"{x:.10f}" for x in q) for q in Q]) + "\n")
    lines = [ln for ln in (d / "tr.csv").read_text().splitlines() if not ln.startswith("#")]  # tool header off
    head = lines[0].split(",")

    def table(name: str, edit) -> None:
        rows = [r.split(",") for r in lines[1:]]
        h = list(head)
        out = edit(h, rows)
        (d / name).write_text(out if isinstance(out, str) else "\n".join(",".join(r) for r in [h] + rows) + "\n")

    def sig_tiny(h, rows):
        for r in rows:
            for c in ("sigma_x", "sigma_y", "sigma_z"):
                r[h.index(c)] = "1e-300"

    def station(value):
        def f(h, rows):
            h.append("station")
            for k, r in enumerate(rows):
                r.append(value if k % 2 else "a")
        return f

    def outlier59(h, rows):
        del rows[59:]
        rows[16][h.index("x")] = repr(float(rows[16][h.index("x")]) + 0.05)

    table("sig_tiny.csv", sig_tiny)
    table("station_empty.csv", station(""))
    table("station_space.csv", station("  "))
    table("station_newline.csv", lambda h, rows: station('"a\nb"')(h, rows))
    table("tr59.csv", outlier59)


def _big(work: Path) -> None:
    """``big.csv``: 50,000 rows, the training rows repeated with joint values 1e-7 rad apart (made in the case's
    folder: too large to copy for every case)."""
    lines = [ln for ln in (work / "tr.csv").read_text().splitlines() if not ln.startswith("#")]
    head = lines[0].split(",")
    nj = sum(h.startswith("joint_") for h in head)
    rows = [r.split(",") for r in lines[1:]]
    out = [lines[0]]
    k = 0
    while len(out) <= 50_000:
        for r in rows:
            q = [repr(float(v) + 1e-7 * (k + 1)) for v in r[:nj]]
            out.append(",".join(q + r[nj:]))
        k += 1
    (work / "big.csv").write_text("\n".join(out[:50_001]) + "\n")


#: inputs built in a case's own folder before it runs (name -> builder)
EXTRA = {"big.csv": _big}


def surface_cases() -> list:
    """The cases of this module (:class:`tests.hostile.cases.Case`)."""
    from tests.hostile.cases import Case

    diag = "diagnose --robot kr15 --train {d}/tr.csv --validate {d}/te.csv"
    gp = "design --criteria kpi_gp --measurements 8 --work-samples 5"
    c = [
        # (a) outputs never destroy inputs, never each other, and are checked before any work
        Case("s-out-diag-model-out-onto-register-data", f"{diag} --register-data {{d}}/reg20.csv --model-out "
             "{d}/reg20.csv", "would destroy the input"),
        Case("s-out-design-curve-onto-given", f"{gp} --given {{d}}/given.csv --curve {{d}}/given.csv",
             "would destroy the input"),
        Case("s-out-design-curve-onto-model", "design --model {d}/m.json --measurements 8 --curve {d}/m.json",
             "would destroy the input"),
        Case("s-out-design-curve-onto-pool", f"{gp} --pool {{d}}/given.csv --curve {{d}}/given.csv",
             "would destroy the input"),
        Case("s-out-design-json-onto-reregister", f"{gp} --reregister {{d}}/given.csv --json {{d}}/given.csv",
             "would destroy the input"),
        Case("s-out-design-curve-equals-json", f"{gp} --curve {{d}}/c.png --json {{d}}/c.png", "its own file"),
        Case("s-out-diag-model-out-equals-json", f"{diag} --json {{d}}/o.json --model-out {{d}}/o.json",
             "its own file"),
        Case("s-out-diag-model-out-equals-figures", f"{diag} --figures {{d}}/figs --model-out {{d}}/figs",
             "its own file"),
        Case("s-out-design-curve-missing-folder", f"{gp} --curve {{d}}/nodir/c.png --json {{d}}/o.json",
             "does not exist"),
        Case("s-out-predict-figure-jpg", "predict --model {d}/m.json --data {d}/te.csv --out {d}/p.csv --figure "
             "{d}/t.jpg",
             "end the file name"),
        Case("s-out-design-curve-no-suffix", f"{gp} --curve {{d}}/curve", "end the file name"),
        # (h) units and ranges
        Case("s-unit-target-sigma-mm", f"{gp} --target-sigma 0.035", "give the TCP sigma in m"),
        Case("s-unit-target-sigma-1e-9", f"{gp} --target-sigma 1e-9", "--target-sigma"),
        Case("s-unit-work-radius-degrees", f"{gp} --work-radius 30", "give it in rad"),
        Case("s-unit-work-radius-inf", f"{gp} --work-radius inf", "--work-radius"),
        Case("s-unit-geometry-prior-mm-deg", "identify --robot kr15 --data {d}/tr.csv --geometry-prior 5,10",
             "--geometry-prior"),
        Case("s-unit-geometry-prior-deg", "identify --robot kr15 --data {d}/tr.csv --geometry-prior 0.001,10",
             "give it in rad"),
        Case("s-unit-clearance-margin-mm", "design --measurements 8 --clearance-margin 20", "--clearance-margin"),
        # (i) options that would be ignored without a word
        Case("s-ignored-work-radius-without-kpi-gp", "design --criteria kpi --measurements 8 --work-radius 0.3",
             "--work-radius"),
        Case("s-ignored-work-samples-without-kpi-gp", "design --criteria kpi --measurements 8 --work-samples 50",
             "--work-samples"),
        Case("s-ignored-robot-class-without-discrepancy", "design --criteria kpi --measurements 8 --robot-class "
             "industrial", "--robot-class"),
        Case("s-ignored-robot-class-with-model-discrepancy", "design --model {d}/m.json --measurements 8 "
             "--robot-class industrial", "--robot-class"),
        Case("s-ignored-curve-model-without-discrepancy", "design --model {d}/m_nodisc.json --measurements 8 "
             "--curve {d}/c.png", "--curve"),
        Case("s-ignored-urdf-frames-without-urdf-out", "identify --robot kr15 --data {d}/tr.csv --urdf-frames",
             "--urdf-frames"),
        Case("s-ignored-sigma-rot-without-pose6d", "simulate --robot kr15 --out {d}/new.csv --sigma-rot 1e-4",
             "add --pose6d"),
        Case("s-ignored-position-only-with-targets", "compensate --model {d}/m.json --targets {d}/targets.csv --out "
             "{d}/o.csv --position-only", "--position-only"),
        Case("s-ignored-harmonics-without-transmission-error", f"{diag} --effects joint_compliance --harmonics 5",
             "--harmonics"),
        Case("s-ignored-term-prior-without-terms", f"{diag} --effects joint_compliance --term-prior 1e-4",
             "--term-prior"),
        Case("s-unit-simulate-gear-harmonic-degrees", "simulate --robot kr15 --out {d}/new.csv --effects "
             "gear_harmonic=5", "give it in SI units (rad)"),
        Case("s-unit-simulate-compliance-large", "simulate --robot kr15 --out {d}/new.csv --effects "
             "joint_compliance=2", "rad/(N*m)"),
        Case("s-unit-simulate-temperature-kelvin", "simulate --robot kr15 --out {d}/new.csv --temperature 293,303",
             "give the temperature in °C"),
        # (j) another arm's calibration
        Case("s-robot-ur5-model-for-ur10-cell", "design --cell ur10 --model {d}/m_ur5.json --measurements 8",
             "contradicts"),
        Case("s-robot-ur5-prior-for-ur10-cell", "design --cell ur10 --given {d}/given_ur10.csv --given-prior "
             "{d}/m_ur5.json --measurements 5", "calibrates the robot 'ur5'"),
        Case("s-robot-ur5-model-on-ur10-rows", "register --model {d}/m_ur5.json --data {d}/reg_ur10.csv --model-out "
             "{d}/o.json", "contradicts"),
        Case("s-robot-ur5-model-on-ur10-rows-no-header", "register --model {d}/m_ur5.json --data "
             "{d}/reg_ur10_bare.csv --model-out {d}/o.json", "another robot's"),
        # wrong exit 0 and unclear answers
        Case("s-unclear-register-sigma-in-mm", "register --model {d}/m.json --data {d}/reg20_sigma_mm.csv "
             "--model-out {d}/o.json", "give sigma in m"),
        Case("s-unclear-predict-hint-names-its-options", "predict --model {d}/m.json --data {d}/reg20.csv --units deg "
             "--out {d}/o.csv", "drop deg from --units"),
        # tracebacks and unclear answers of damaged data files
        Case("s-data-sigma-1e-300", "identify --robot kr15 --data {d}/sig_tiny.csv", "sigma"),
        Case("s-data-station-empty", "identify --robot kr15 --data {d}/station_empty.csv", "station"),
        Case("s-data-station-blank", "identify --robot kr15 --data {d}/station_space.csv", "station"),
        Case("s-data-station-newline", "identify --robot kr15 --data {d}/station_newline.csv", "station"),
        Case("s-data-59-rows-outlier-named", "identify --robot kr15 --data {d}/tr59.csv --discrepancy on",
             "17 flagged as outlier"),
        Case("s-hang-identify-50000-rows-discrepancy", "identify --robot kr15 --data {d}/big.csv --discrepancy on",
             "on a seeded subset", kind="warn", max_s=60.0, needs="big.csv", slow=True),
    ]
    cmds = {"predict": "predict --model {m} --data {{d}}/te.csv --out {{d}}/o.csv",
            "register": "register --model {m} --data {{d}}/reg20.csv --model-out {{d}}/o.json",
            "compensate": "compensate --model {m} --targets {{d}}/targets.csv --out {{d}}/o.csv",
            "design": "design --model {m} --measurements 30 --json {{d}}/o.json"}
    for tag, (_, field) in _DISC_EDITS.items():
        for cmd, argv in cmds.items():
            c.append(Case(f"s-disc-{tag}-{cmd}", argv.format(m=f"{{d}}/m_d_{tag}.json"), field))
    return c
