"""Hostile inputs: every case must end in one clear line, exit code 2 and no file written.

``build_inputs(folder)`` writes the shared inputs (a simulated KR 15 data set with sigma columns and an
off-axis reflector, a cell file, a design file, broken variants of each); ``CASES`` lists the cases
(``Case.argv`` uses ``{d}`` for that folder); ``run_case`` runs one in-process through
``pin_kpi_oed.cli.app.main`` and returns what happened. ``tests/test_hostile.py`` asserts every case;
``python -m tests.hostile.run_hostile`` reruns them all as real subprocesses and prints a table and the counts of
each kind of failure. The cases of the newest surfaces (discrepancy blocks, ``kpi_gp`` design options, another
arm's model file, outputs onto inputs) are in :mod:`tests.hostile.surfaces`.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import io
import json
import os
import re
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import yaml

from pin_kpi_oed.cell.cell import CELL_DIR
from pin_kpi_oed.model.robot import resolve_robot

COMMANDS_WITH_SEED = ["info kr15", "demo", "design --measurements 10", "simulate --robot kr15 --out {d}/new.csv",
                      "identify --robot kr15 --data {d}/tr.csv", "import-ipa {d}/tr.csv --out {d}/new.csv",
                      "diagnose --robot kr15 --train {d}/tr.csv --validate {d}/te.csv", "study kuka --out {d}/st"]


@dataclass(frozen=True)
class Case:
    """One hostile input: ``argv`` (``{d}`` = inputs folder) and a text the answer must contain.

    ``kind`` ``refuse`` (the default): exit 2, ``expect`` in the one-line refusal, nothing written.
    ``warn``: the command may run (exit 0 or 2), but ``expect`` is said on stdout or stderr and no input changes.
    ``max_s``: beyond this many CPU seconds the case counts as a hang (CPU time: wall time depends on the machine's
    load). ``needs``: an input too large to copy for every case, built in the case's folder first
    (:data:`tests.hostile.surfaces.EXTRA`). ``slow``: left out of the default test run (``-m slow`` runs it;
    ``run_hostile`` always does).
    """

    id: str
    argv: str
    expect: str
    kind: str = "refuse"
    max_s: float = 60.0
    needs: str | None = None
    slow: bool = False


def _cases() -> list[Case]:
    c = [
        # 2. outputs never destroy inputs (and never each other)
        Case("out-import-ipa-onto-src", "import-ipa {d}/tr.csv --out {d}/tr.csv", "would destroy the input"),
        Case("out-identify-json-onto-data", "identify --robot kr15 --data {d}/tr.csv --json {d}/tr.csv",
             "would destroy the input"),
        Case("out-identify-urdf-onto-validate", "identify --robot kr15 --data {d}/tr.csv --validate {d}/te.csv "
             "--urdf-out {d}/te.csv", "would destroy the input"),
        Case("out-design-json-onto-cell", "design --cell {d}/cell.yaml --json {d}/cell.yaml", "would destroy"),
        Case("out-view-html-onto-design", "view {d}/d.json --html {d}/d.json --no-open", "would destroy"),
        Case("out-evaluate-json-onto-design", "evaluate {d}/d.json --json {d}/d.json", "would destroy"),
        Case("out-import-train-equals-test", "import-ipa {d}/tr.csv --split 0.5 --train {d}/a.csv --test {d}/a.csv",
             "give each output its own file"),
        Case("out-simulate-out-equals-test-out", "simulate --robot kr15 --n-test 5 --out {d}/a.csv --test-out "
             "{d}/a.csv", "give each output its own file"),
        Case("out-identify-json-equals-model-out", "identify --robot kr15 --data {d}/tr.csv --json {d}/r.json "
             "--model-out {d}/r.json", "give each output its own file"),
        Case("out-symlink-onto-input", "identify --robot kr15 --data {d}/tr.csv --json {d}/link.csv",
             "would destroy the input"),
        Case("out-missing-folder", "identify --robot kr15 --data {d}/tr.csv --json {d}/nodir/r.json",
             "does not exist"),
        Case("out-is-a-folder", "simulate --robot kr15 --out {d}/sub", "is a folder"),
        Case("out-under-a-file", "simulate --robot kr15 --out {d}/tr.csv/x.csv", "does not exist"),
        Case("out-diagnose-missing-folder-fast", "diagnose --robot kr15 --train {d}/tr.csv --validate {d}/te.csv "
             "--json {d}/nodir/x.json", "does not exist"),
        Case("out-diagnose-figures-is-file", "diagnose --robot kr15 --train {d}/tr.csv --validate {d}/te.csv "
             "--figures {d}/tr.csv", "not a folder"),
        Case("out-study-out-is-file", "study kuka --out {d}/tr.csv", "not a folder"),
        Case("validate-equals-data", "identify --robot kr15 --data {d}/tr.csv --validate {d}/tr.csv",
             "must not be training data"),
        Case("diagnose-validate-equals-train", "diagnose --robot kr15 --train {d}/tr.csv --validate {d}/tr.csv",
             "must not be training data"),
        # 3. units in cells and files, one unit guard for every command
        Case("cell-degrees-under-rad", "design --cell {d}/cell_deg_as_rad.yaml", "joint_bounds.lower_rad"),
        Case("cell-sigma-1m", "design --cell {d}/cell_sigma1.yaml", "noise.sigma_xyz_m"),
        Case("cell-nested-typo", "design --cell {d}/cell_typo.yaml", "sigma_xyz"),
        Case("simulate-effect-size-named-as-written", "simulate --robot kr15 --out {d}/new.csv --effects "
             "joint_compliance=1.5e-4", "joint_compliance=1.5e-4 rad/(N*m) is more than 0.0001"),
        Case("simulate-n-ignored-with-design", "simulate --design {d}/d.json --n 50 --out {d}/new.csv",
             "--n 50: not with --design"),
        Case("report-required-accuracy-in-mm", "report --model {d}/m.json --train {d}/tr.csv --validate {d}/te.csv "
             "--required-accuracy 0.05 --json {d}/cert.json", "0.05 mm is 5e-05"),
        Case("cell-incidence-in-rad", "design --cell {d}/cell_incidence_rad.yaml", "0.5 rad = 28.6 deg"),
        Case("cell-top-level-typo", "design --cell {d}/cell_top_typo.yaml", "did you mean 'reflector_m'"),
        Case("cell-reflector-mm", "design --cell {d}/cell_refl_mm.yaml", "reflector_m"),
        Case("cell-text-for-number", "design --cell {d}/cell_sixty.yaml", "measurements"),
        Case("cell-ragged-working", "design --cell {d}/cell_ragged.yaml", "working_configurations"),
        Case("urdf-in-mm", "info {d}/mm.urdf", "looks like mm"),
        Case("urdf-zero-axis", "info {d}/zaxis.urdf", "zero length"),
        Case("urdf-swapped-limits", "info {d}/swap.urdf", "reversed"),
        Case("urdf-xacro", "info {d}/robot.xacro.urdf", "xacro"),
        Case("urdf-xacro-property", "info {d}/property.xacro.urdf", "property.xacro.urdf > robot.urdf"),
        Case("urdf-xacro-no-xmlns", "info {d}/bare.xacro.urdf", "a xacro file"),
        Case("urdf-broken-parent", "info {d}/broken.urdf", "parent link [nolink]"),
        Case("cell-tracker-mm", "design --cell {d}/cell_tracker_mm.yaml", "tracker.xyz_m"),
        Case("identify-sigma-10", "identify --robot kr15 --data {d}/tr.csv --sigma 10", "give it in m"),
        Case("diagnose-sigma-15", "diagnose --robot kr15 --train {d}/tr.csv --validate {d}/te.csv --sigma 15",
             "give it in m"),
        Case("simulate-noise-10", "simulate --robot kr15 --out {d}/new.csv --noise 10", "give it in m"),
        Case("simulate-sigma-rot-degrees", "simulate --robot kr15 --out {d}/new.csv --sigma-rot 5", "rad"),
        # 4. tracebacks -> one line
        Case("evaluate-json-list", "evaluate {d}/list.json", "top level"),
        Case("view-json-list", "view {d}/list.json --html {d}/o.html --no-open", "top level"),
        Case("evaluate-ragged", "evaluate {d}/ragged.json", "ragged"),
        Case("view-ragged", "view {d}/ragged.json --html {d}/o.html --no-open", "ragged"),
        Case("evaluate-strings", "evaluate {d}/strings.json", "q_meas"),
        Case("view-strings", "view {d}/strings.json --html {d}/o.html --no-open", "q_meas"),
        Case("temperature-reversed", "simulate --robot kr15 --out {d}/new.csv --temperature 30,20", "--temperature"),
        Case("temperature-text", "simulate --robot kr15 --out {d}/new.csv --temperature warm,hot", "--temperature"),
        Case("fix-star", "identify --robot kr15 --data {d}/tr.csv --fix *", "--fix"),
        Case("fix-all-glob", "identify --robot kr15 --data {d}/tr.csv --fix *,tracker.*", "--fix"),
        Case("pool-size-negative", "design --certificate --pool-size -5", "--pool-size"),
        Case("study-workers-0", "study kuka --out {d}/st --workers 0", "--workers"),
        Case("study-scheduler-foo", "study kuka --out {d}/st --scheduler foo", "--scheduler"),
        Case("reflector-text", "identify --robot kr15 --data {d}/tr.csv --reflector a,b,c", "--reflector"),
        Case("tracker-negative-values-ok-but-text", "simulate --robot kr15 --out {d}/new.csv --tracker -1,x,0",
             "--tracker"),
        # 5. zero and negative are refused, never replaced by defaults
        Case("measurements-0", "design --measurements 0", "--measurements"),
        Case("starts-0", "design --starts 0", "--starts"),
        Case("max-iter-0", "design --max-iter 0", "--max-iter"),
        Case("pool-size-0", "design --certificate --pool-size 0", "--pool-size"),
        Case("arms-0", "study notional90 --out {d}/st --arms 0", "--arms"),
        Case("arms-negative", "study notional90 --out {d}/st --arms -3", "--arms"),
        Case("seeds-0", "study kuka --out {d}/st --seeds 0", "--seeds"),
        Case("study-measurements-5", "study kuka --out {d}/st --measurements 5", "--measurements"),
        Case("n-0", "simulate --robot kr15 --out {d}/new.csv --n 0", "--n"),
        Case("n-test-negative", "simulate --robot kr15 --out {d}/new.csv --n-test -1", "--n-test"),
        Case("kfold-1", "diagnose --robot kr15 --train {d}/tr.csv --kfold 1", "--kfold"),
        Case("register-rows-0", "identify --robot kr15 --data {d}/tr.csv --validate {d}/te.csv --register-rows 0",
             "--register-rows"),
        Case("max-nfev-0", "identify --robot kr15 --data {d}/tr.csv --max-nfev 0", "--max-nfev"),
        Case("split-negative", "import-ipa {d}/tr.csv --split -0.5 --train {d}/a.csv --test {d}/b.csv", "--split"),
        Case("view-scale-0", "view {d}/d.json --scale 0 --html {d}/o.html --no-open", "--scale"),
        Case("view-level-1", "view {d}/d.json --level 1 --html {d}/o.html --no-open", "--level"),
        Case("tol-negative", "simulate --robot kr15 --out {d}/new.csv --tol-translation -1e-4", "--tol-translation"),
        # 6. unclear refusals made clear
        Case("sigma-negative-small", "identify --robot kr15 --data {d}/tr.csv --sigma -1e-5", "--sigma"),
        Case("sigma-zero", "identify --robot kr15 --data {d}/tr.csv --sigma 0", "must be positive"),
        Case("two-rows", "identify --robot kr15 --data {d}/two.csv", "two.csv"),
        # 7. view trusts stored numbers
        Case("view-identical-poses", "view {d}/same.json --html {d}/o.html --no-open", "do not determine C_s"),
        # 8. frictions
        Case("test-out-without-n-test", "simulate --robot kr15 --out {d}/new.csv --test-out {d}/new2.csv",
             "--n-test"),
    ]
    c += [Case(f"seed-negative-{cmd.split()[0]}", cmd + " --seed -1", "--seed") for cmd in COMMANDS_WITH_SEED]
    from tests.hostile.frictions import friction_cases
    from tests.hostile.surfaces import surface_cases

    return c + _issue24() + _generated() + surface_cases() + friction_cases()


def _issue24() -> list[Case]:
    """Issue 24: the commands added since issue 15 (model files, register, predict, compensate,
    import-tracker, export, pools with --given / --given-prior), attacked the same way."""
    exp = "import-tracker {d}/exp_mm.txt --joints {d}/joints_deg.csv --robot kr15"
    c = [
        # 1. a colliding program never written without --force; exported values never clipped
        Case("export-work-in-wall", "export {d}/d_wall.json --format krl --out {d}/p.src", "working configuration #0"),
        Case("export-work-in-wall-csv", "export {d}/d_wall.json --format csv --out {d}/p.csv", "collides"),
        Case("export-pose-beyond-limit", "export {d}/d_a5.json --format rapid --out {d}/p.mod", "outside its limits"),
        Case("export-pose-beyond-limit-ur", "export {d}/d_a5.json --format csv --out {d}/p.csv", "joint_a5"),
        Case("export-pose-in-wall", "export {d}/d_pose_wall.json --format csv --out {d}/p.csv", "collides"),
        # 2. outliers flagged with unknown noise, fitted plainly: never "good" (refused when poor)
        # 3. import-tracker units against the robot's reach and the joint limits; register gate
        Case("tracker-m-file-read-as-mm", "import-tracker {d}/exp_m_nounit.txt --joints {d}/joints_deg.csv "
             "--robot kr15 --out {d}/o.csv", "look like m, not mm"),
        Case("tracker-joints-rad-read-as-deg", "import-tracker {d}/exp_mm.txt --joints {d}/joints_rad.csv "
             "--robot kr15 --out {d}/o.csv", "--angle-unit rad"),
        Case("tracker-header-m-under-units-mm", "import-tracker {d}/exp_hdr_m.txt --joints {d}/joints_deg.csv "
             "--robot kr15 --out {d}/o.csv", "[m]"),
        Case("tracker-units-m-with-mm-values", "import-tracker {d}/exp_m_decl_mmvals.txt --joints "
             "{d}/joints_deg.csv --robot kr15 --out {d}/o.csv", "look like mm, not m"),
        Case("tracker-units-option-m-with-mm-values", "import-tracker {d}/exp_mm_nounit.txt --joints "
             "{d}/joints_deg.csv --robot kr15 --units m --out {d}/o.csv", "look like mm, not m"),
        Case("tracker-joints-deg-as-rad", "import-tracker {d}/exp_mm.txt --joints {d}/joints_deg.csv --robot kr15 "
             "--angle-unit rad --out {d}/o.csv", "joints_deg.csv"),
        Case("tracker-another-robot", "import-tracker {d}/exp_mm.txt --joints {d}/joints_deg.csv --robot ur10 "
             "--out {d}/o.csv", "joints_deg.csv"),
        # a calibration for another session: the registration configurations are checked before any design
        Case("design-reregister-missing", "design --criteria kpi_gp --work-samples 10 --measurements 10 --reregister "
             "{d}/nope.csv --json {d}/o.json", "nope.csv"),
        Case("design-reregister-degrees", "design --criteria kpi_gp --work-samples 10 --measurements 10 --reregister "
             "{d}/joints_deg.csv --json {d}/o.json", "joints_deg.csv"),
        Case("design-reregister-one-pose", "design --criteria kpi_gp --work-samples 10 --measurements 10 --reregister "
             "{d}/one_pose.csv --json {d}/o.json", "do not determine the set-up"),
        Case("design-reregister-no-discrepancy", "design --criteria random,kpi --measurements 10 --reregister work "
             "--json {d}/o.json", "needs the discrepancy"),
        Case("register-3-rows", "register --model {d}/m.json --data {d}/reg3.csv --model-out {d}/o.json",
             "at least 6 rows"),
        Case("register-xy-swapped", "register --model {d}/m.json --data {d}/reg_swap.csv --model-out {d}/o.json",
             "mirrored"),
        Case("register-z-negated", "register --model {d}/m.json --data {d}/reg_negz.csv --model-out {d}/o.json",
             "mirrored"),
        Case("register-another-robot", "register --model {d}/m_ur10.json --data {d}/reg20.csv --model-out "
             "{d}/o.json", "reg20.csv"),
        Case("register-m-declared-mm", "register --model {d}/m.json --data {d}/reg20.csv --units mm "
             "--model-out {d}/o.json", "reg20.csv"),
        Case("register-5-rows-hold-ok-but-4", "register --model {d}/m.json --data {d}/reg4.csv --model-out "
             "{d}/o.json", "at least 6 rows"),
        Case("predict-m-declared-mm", "predict --model {d}/m.json --data {d}/reg20.csv --units mm --out {d}/o.csv",
             "reg20.csv"),
        # 7. inputs never overwritten: every command that writes goes through the output-path check
        Case("out-compensate-out-onto-targets", "compensate --model {d}/m.json --targets {d}/targets.csv --out "
             "{d}/targets.csv", "would destroy the input"),
        Case("out-compensate-json-onto-model", "compensate --model {d}/m.json --targets {d}/targets.csv --out "
             "{d}/o.csv --json {d}/m.json", "would destroy the input"),
        Case("out-compensate-out-onto-program", "compensate --model {d}/m.json --program {d}/prog.csv --out "
             "{d}/prog.csv", "would destroy the input"),
        Case("out-compensate-out-equals-json", "compensate --model {d}/m.json --targets {d}/targets.csv --out "
             "{d}/o.csv --json {d}/o.csv", "its own file"),
        Case("out-export-onto-design", "export {d}/d.json --format csv --out {d}/d.json", "would destroy the input"),
        Case("out-export-json-onto-design", "export {d}/d.json --format csv --out {d}/p.csv --json {d}/d.json",
             "would destroy the input"),
        Case("out-export-krl-dat-onto-input", "export {d}/d.dat --format krl --out {d}/d.src",
             "would destroy the input"),
        Case("out-export-out-equals-json", "export {d}/d.json --format csv --out {d}/p.csv --json {d}/p.csv",
             "its own file"),
        Case("out-export-krl-dat-equals-json", "export {d}/d.json --format krl --out {d}/p.src --json {d}/p.dat",
             "its own file"),
        Case("out-export-html-onto-design", "export {d}/d.json --format csv --out {d}/p.csv --html {d}/d.json",
             "would destroy the input"),
        Case("out-export-missing-folder", "export {d}/d.json --format csv --out {d}/nodir/p.csv", "does not exist"),
        Case("out-import-tracker-onto-export", exp + " --out {d}/exp_mm.txt", "would destroy the input"),
        Case("out-import-tracker-onto-joints", exp + " --out {d}/joints_deg.csv", "would destroy the input"),
        Case("out-import-tracker-folder", exp + " --out {d}/sub", "is a folder"),
        # 8. invalid programs: --dwell nan / inf / negative; options range-checked
        Case("export-dwell-nan", "export {d}/d.json --format krl --out {d}/p.src --dwell nan", "--dwell"),
        Case("export-dwell-inf", "export {d}/d.json --format rapid --out {d}/p.mod --dwell inf", "--dwell"),
        Case("export-dwell-inf-ur", "export {d}/d.json --format urscript --out {d}/p.script --dwell inf", "--dwell"),
        Case("export-dwell-negative", "export {d}/d.json --format csv --out {d}/p.csv --dwell -1", "--dwell"),
        Case("export-seed-negative", "export {d}/d.json --format csv --out {d}/p.csv --seed -1", "--seed"),
        Case("export-margin-nan", "export {d}/d.json --format csv --out {d}/p.csv --margin nan", "--margin"),
        Case("export-margin-mm", "export {d}/d.json --format csv --out {d}/p.csv --margin 10", "--margin"),
        Case("export-margin-1m", "export {d}/d.json --format csv --out {d}/p.csv --margin 0.4", "--margin"),
        Case("export-speed-0", "export {d}/d.json --format csv --out {d}/p.csv --speed-override 0",
             "--speed-override"),
        Case("export-speed-2", "export {d}/d.json --format csv --out {d}/p.csv --speed-override 2",
             "--speed-override"),
        Case("export-format-unknown", "export {d}/d.json --format gcode --out {d}/p.nc", "--format"),
        Case("compensate-seed-negative", "compensate --model {d}/m.json --targets {d}/targets.csv --out {d}/o.csv "
             "--seed -1", "--seed"),
        Case("compensate-tcp-mm", "compensate --model {d}/m.json --targets {d}/targets.csv --out {d}/o.csv "
             "--tcp 0,0,50000", "--tcp"),
        Case("compensate-tcp-text", "compensate --model {d}/m.json --targets {d}/targets.csv --out {d}/o.csv "
             "--tcp a,b,c", "--tcp"),
        Case("compensate-all-unreachable", "compensate --model {d}/m.json --targets {d}/targets_far.csv --out "
             "{d}/o.csv --tcp 0,0,0.1", "unreachable"),
        Case("compensate-model-without-tcp", "compensate --model {d}/m.json --targets {d}/targets.csv --out "
             "{d}/o.csv", "states no TCP"),
    ]
    # 5. model files through a schema: every field typed and ranged, covariances symmetric PSD, file named
    bad = {"m_str.json": "joint_a2.tx", "m_dict.json": "joint_a2.tx", "m_list.json": "tcp_m",
           "m_null.json": "reflector_m", "m_covstr.json": "covariance", "m_cov_elem_str.json": "covariance",
           "m_negdef.json": "positive semi-definite", "m_zerocov.json": "all zero", "m_asym.json": "symmetric",
           "m_noise_mm.json": "noise.sigma_xyz_m", "m_refl_mm.json": "reflector_m", "m_unknown_key.json": "geometri",
           "m_std_negative.json": "std", "m_rows_text.json": "n_rows", "m_nan.json": "range_b"}
    for f, expect in bad.items():
        tag = f[2:-5]
        c += [Case(f"model-{tag}-predict", f"predict --model {{d}}/{f} --data {{d}}/te.csv --out {{d}}/o.csv", expect),
              Case(f"model-{tag}-register", f"register --model {{d}}/{f} --data {{d}}/reg20.csv --model-out "
                   f"{{d}}/o.json", expect),
              Case(f"model-{tag}-compensate", f"compensate --model {{d}}/{f} --targets {{d}}/targets.csv --out "
                   f"{{d}}/o.csv", expect),
              Case(f"model-{tag}-design-model", f"design --model {{d}}/{f} --measurements 10 --json {{d}}/o.json",
                   expect),
              Case(f"model-{tag}-given-prior", f"design --given {{d}}/given.csv --given-prior {{d}}/{f} "
                   f"--measurements 5 --json {{d}}/o.json", expect)]
    return c


#: command -> (valid arguments, {output option: a valid default when another is under test}, input paths)
_OUT = {
    "evaluate": ("evaluate {d}/d.json", {"--json": None}, ["{d}/d.json"]),
    "demo": ("demo", {"--json": None}, []),
    "design": ("design --cell {d}/cell.yaml", {"--json": None}, ["{d}/cell.yaml"]),
    "simulate": ("simulate --robot kr15 --n-test 5", {"--out": "{d}/o1.csv", "--test-out": "{d}/o2.csv",
                                                      "--truth-json": None}, []),
    "identify": ("identify --robot kr15 --data {d}/tr.csv --validate {d}/te.csv",
                 {"--json": None, "--urdf-out": None, "--model-out": None}, ["{d}/tr.csv", "{d}/te.csv"]),
    "import-ipa": ("import-ipa {d}/tr.csv --split 0.5", {"--out": None, "--train": "{d}/o1.csv",
                                                          "--test": "{d}/o2.csv"}, ["{d}/tr.csv"]),
    "register": ("register --model {d}/m.json --data {d}/te.csv", {"--model-out": "{d}/o1.json", "--json": None},
                 ["{d}/m.json", "{d}/te.csv"]),
    "predict": ("predict --model {d}/m.json --data {d}/te.csv", {"--out": "{d}/o1.csv", "--figure": "{d}/o2.png"},
                ["{d}/m.json", "{d}/te.csv"]),
    "diagnose": ("diagnose --robot kr15 --train {d}/tr.csv --validate {d}/te.csv", {"--json": None},
                 ["{d}/tr.csv", "{d}/te.csv"]),
    "view": ("view {d}/d.json --no-open", {"--html": "{d}/o1.html"}, ["{d}/d.json"]),
}
#: (command with valid arguments, option, bad value, expected text) for numeric options
_NUMERIC = [
    ("design", "--measurements", ["0", "-1", "ten"]), ("design", "--starts", ["0", "-2", "x"]),
    ("design", "--max-iter", ["0", "-1", "1.5"]), ("design --certificate", "--pool-size", ["0", "-5", "many"]),
    ("design", "--seed", ["-1", "-100", "1e3"]),
    ("simulate --robot kr15 --out {d}/new.csv", "--n", ["0", "-1", "x"]),
    ("simulate --robot kr15 --out {d}/new.csv", "--n-test", ["-1", "x"]),
    ("simulate --robot kr15 --out {d}/new.csv", "--noise", ["0", "-1e-5", "10", "1", "nan", "inf", "x", "1,2"]),
    ("simulate --robot kr15 --out {d}/new.csv", "--sigma-rot", ["0", "-1", "5", "nan"]),
    ("simulate --robot kr15 --out {d}/new.csv", "--tol-translation", ["-1e-4", "nan", "x"]),
    ("simulate --robot kr15 --out {d}/new.csv", "--tol-rotation", ["-1e-3", "inf"]),
    ("simulate --robot kr15 --out {d}/new.csv", "--tol-reflector", ["-1"]),
    ("simulate --robot kr15 --out {d}/new.csv", "--temperature", ["30,20", "20", "a,b", "nan,20"]),
    ("simulate --robot kr15 --out {d}/new.csv", "--reflector", ["1,2", "a,b,c", "60,0,120"]),
    ("simulate --robot kr15 --out {d}/new.csv", "--tracker", ["1,2", "x,0,0"]),
    ("identify --robot kr15 --data {d}/tr.csv", "--sigma", ["0", "-1e-5", "10", "0.5", "nan", "x", "1,2"]),
    ("identify --robot kr15 --data {d}/tr.csv", "--sigma-rot", ["0", "-1e-4", "3"]),
    ("identify --robot kr15 --data {d}/tr.csv", "--reflector", ["a,b,c", "1,2", "30,20,80"]),
    ("identify --robot kr15 --data {d}/tr.csv", "--max-nfev", ["0", "-1", "x"]),
    ("identify --robot kr15 --data {d}/tr.csv --validate {d}/te.csv", "--register-rows", ["0", "-3", "2", "x"]),
    ("identify --robot kr15 --data {d}/tr.csv", "--fix", ["*", "**", "?*", ","]),
    ("identify --robot kr15 --data {d}/tr.csv", "--seed", ["-1"]),
    ("identify --robot kr15 --data {d}/tr.csv", "--loss", ["l2"]),
    ("diagnose --robot kr15 --train {d}/tr.csv --validate {d}/te.csv", "--sigma", ["0", "-1", "15", "x"]),
    ("diagnose --robot kr15 --train {d}/tr.csv --validate {d}/te.csv", "--alpha", ["0", "1", "-0.1", "x"]),
    ("diagnose --robot kr15 --train {d}/tr.csv", "--kfold", ["0", "1", "-2", "x"]),
    ("diagnose --robot kr15 --train {d}/tr.csv --validate {d}/te.csv", "--reflector", ["60,0,120", "x"]),
    ("import-ipa {d}/tr.csv --train {d}/a.csv --test {d}/b.csv", "--split", ["0", "-0.5", "x", "nan"]),
    ("view {d}/d.json --no-open --html {d}/o.html", "--scale", ["0", "-1", "x"]),
    ("view {d}/d.json --no-open --html {d}/o.html", "--level", ["0", "1", "1.5", "x"]),
    ("study kuka --out {d}/st", "--measurements", ["0", "5", "x"]), ("study kuka --out {d}/st", "--seeds", ["0", "-1"]),
    ("study notional90 --out {d}/st", "--arms", ["0", "-3"]), ("study kuka --out {d}/st", "--starts", ["0", "-1"]),
    ("study kuka --out {d}/st", "--workers", ["0", "-1"]),
    ("study kuka --out {d}/st", "--scheduler", ["foo", "http://x", "tcp://"]),
    ("info kr15", "--reflector", ["a", "1,2"]), ("info kr15", "--seed", ["-1"]),
]


def _generated() -> list[Case]:
    """Every output option onto an input / a folder / a missing folder / below a file / another output;
    every numeric option at zero, negative, text, NaN and out-of-range values."""
    out: list[Case] = []
    for cmd, (base, outs, ins) in _OUT.items():
        for opt in outs:
            rest = " ".join(f"{o} {v}" for o, v in outs.items() if o != opt and v)
            bad = [(f"onto-input{k}", p, "would destroy the input") for k, p in enumerate(ins)]
            bad += [("folder", "{d}/sub", "is a folder"), ("missing-folder", "{d}/nodir/x.out", "does not exist"),
                    ("below-a-file", "{d}/tr.csv/x.out", "does not exist")]
            bad += [(f"same-as{o}", v, "its own file") for o, v in outs.items() if o != opt and v]
            for tag, path, expect in bad:
                out.append(Case(f"gen-out-{cmd}{opt}-{tag}", f"{base} {rest} {opt} {path}", expect))
    for cmd, opt in (("diagnose --robot kr15 --train {d}/tr.csv --validate {d}/te.csv", "--figures"),
                     ("view {d}/d.json --no-open --html {d}/o.html", "--figures"), ("study kuka", "--out")):
        out += [Case(f"gen-dir-{cmd.split()[0]}{opt}-is-file", f"{cmd} {opt} {{d}}/tr.csv", "not a folder"),
                Case(f"gen-dir-{cmd.split()[0]}{opt}-parent-missing", f"{cmd} {opt} {{d}}/nodir/f", "does not exist")]
    for cmd, opt, values in _NUMERIC:
        for v in values:
            out.append(Case(f"gen-num-{cmd.split()[0]}{opt}={v}", f"{cmd} {opt} {v}", opt))
    return out


CASES: list[Case] = _cases()


def build_inputs(d: Path) -> None:
    """Write the shared inputs into ``d`` (about 5 s: one simulation, one random design)."""
    from pin_kpi_oed.cli.app import main

    d.mkdir(parents=True, exist_ok=True)
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["simulate", "--robot", "kr15", "--n", "120", "--n-test", "60", "--seed", "4", "--out",
                     str(d / "tr.csv"), "--test-out", str(d / "te.csv")]) == 0
        assert main(["design", "--cell", "kr15", "--criteria", "random", "--measurements", "20", "--json",
                     str(d / "d.json"), "--quiet"]) == 0
        # --discrepancy on: the simulated robot has no unmodelled effect, so auto rightly keeps a white level; the
        # hostile cases need a fitted Gaussian process in m.json
        assert main(["identify", "--robot", "kr15", "--data", str(d / "tr.csv"), "--model-out", str(d / "m.json"),
                     "--discrepancy", "on", "--quiet"]) == 0
    lines = [ln for ln in (d / "tr.csv").read_text().splitlines() if not ln.startswith("#")]  # tool header off
    (d / "two.csv").write_text("\n".join(lines[:3]) + "\n")
    (d / "sub").mkdir(exist_ok=True)
    (d / "link.csv").symlink_to(d / "tr.csv")
    cell = yaml.safe_load((CELL_DIR / "kr15.yaml").read_text())
    (d / "cell.yaml").write_text(yaml.safe_dump(cell))

    def variant(name: str, **changes) -> None:
        v = json.loads(json.dumps(cell))
        for k, val in changes.items():
            v[k] = val
        (d / name).write_text(yaml.safe_dump(v))

    variant("cell_deg_as_rad.yaml", joint_bounds={"lower_rad": cell["joint_bounds"]["lower_deg"],
                                                  "upper_rad": cell["joint_bounds"]["upper_deg"]})
    variant("cell_sigma1.yaml", noise={"sigma_xyz_m": [1, 1, 1]})
    variant("cell_typo.yaml", noise={"sigma_xyz": [1e-6, 1e-6, 1e-6]})
    variant("cell_incidence_rad.yaml", incidence_max_deg=0.5)  # radians under a _deg key
    typo = {("reflector" if k == "reflector_m" else k): v for k, v in cell.items()}  # the unit suffix forgotten
    (d / "cell_top_typo.yaml").write_text(yaml.safe_dump(typo))
    variant("cell_refl_mm.yaml", reflector_m=[60.0, 0.0, 120.0])
    variant("cell_sixty.yaml", measurements="sixty")
    variant("cell_tracker_mm.yaml", tracker={"xyz_m": [-200.0, -2300.0, 1400.0], "rpy_deg": [0.0, 0.0, 90.0]})
    variant("cell_ragged.yaml", working_configurations_deg=[[0, -70, 65, 0, 95, 0], [0, 1]])
    urdf = resolve_robot("kr15")[0].read_text()
    (d / "broken.urdf").write_text(urdf.replace('<parent link="base_link"/>', '<parent link="nolink"/>', 1))
    (d / "zaxis.urdf").write_text(re.sub(r'<axis xyz="[^"]*"', '<axis xyz="0 0 0"', urdf, count=1))
    m = re.search(r'lower="([^"]+)" upper="([^"]+)"', urdf)
    (d / "swap.urdf").write_text(urdf[:m.start()] + f'lower="{m.group(2)}" upper="{m.group(1)}"' + urdf[m.end():])
    (d / "mm.urdf").write_text(re.sub(r'(?<=<origin )xyz="([^"]+)"',
                                      lambda mo: 'xyz="' + " ".join(str(float(x) * 1000) for x in mo.group(1).split())
                                      + '"', urdf))
    (d / "property.xacro.urdf").write_text(re.sub(r'<axis xyz="[^"]*"', '<axis xyz="0 0 ${axis_sign}"', urdf,
                                                  count=1))
    (d / "bare.xacro.urdf").write_text(urdf.replace("</robot>", '<xacro:include filename="x.xacro"/></robot>'))
    (d / "robot.xacro.urdf").write_text(urdf.replace("<robot ", '<robot xmlns:xacro="http://www.ros.org/wiki/xacro" ',
                                                     1).replace("</robot>", '<xacro:include filename="x.xacro"/>'
                                                                "</robot>"))
    design = json.loads((d / "d.json").read_text())
    _build_issue24(d, design)
    (d / "list.json").write_text(json.dumps([design]))
    rag = json.loads(json.dumps(design))
    rag["q_meas"] = [rag["q_meas"][0], rag["q_meas"][1][:3]]
    rag["designs"][0]["q_meas"] = rag["q_meas"]
    (d / "ragged.json").write_text(json.dumps(rag))
    st = json.loads(json.dumps(design))
    st["q_meas"] = [["a"] * 6] * 20
    st["designs"][0]["q_meas"] = st["q_meas"]
    (d / "strings.json").write_text(json.dumps(st))
    same = json.loads(json.dumps(design))
    same["designs"][0]["q_meas"] = [design["designs"][0]["q_meas"][0]] * 20
    same["q_meas"] = same["designs"][0]["q_meas"]
    (d / "same.json").write_text(json.dumps(same))


def _build_issue24(d: Path, design: dict) -> None:
    """Inputs of the issue-24 cases: edited designs, tracker exports and joint logs in wrong units,
    registration rows (too few, mirrored), targets and a program for compensate, a UR10 model."""
    import numpy as np

    from pin_kpi_oed.cli.app import main

    wall = [2.6, -1.0, 0.8, 0.0, 0.5, 0.0]  # the KR 15 reaching back into its wall (x >= -0.45 m)

    def edited(name: str, edit) -> None:
        e = json.loads(json.dumps(design))
        edit(e)
        (d / name).write_text(json.dumps(e))

    def set_work(e):
        e["q_work"] = [wall]
        e["cell"]["q_work"] = [wall]

    def set_pose(k, j, v):
        def f(e):
            e["q_meas"][k][j] = v
            e["designs"][0]["q_meas"][k][j] = v
        return f

    def set_pose_q(k, q):
        def f(e):
            e["q_meas"][k] = list(q)
            e["designs"][0]["q_meas"][k] = list(q)
        return f

    edited("d_wall.json", set_work)
    edited("d_a5.json", set_pose(3, 4, 2.299))  # A5 limit ±130° = ±2.269 rad
    edited("d_pose_wall.json", set_pose_q(0, wall))
    (d / "d.dat").write_text(json.dumps(design))
    rows = [ln for ln in (d / "te.csv").read_text().splitlines() if not ln.startswith("#")]
    head = rows[0].split(",")
    xi, yi, zi = (head.index(c) for c in "xyz")
    data = [r.split(",") for r in rows[1:]]
    J = np.array([[float(r[head.index(f"joint_a{k}")]) for k in range(1, 7)] for r in data])
    P = np.array([[float(r[k]) for k in (xi, yi, zi)] for r in data])
    names = [f"P{i + 1:04d}" for i in range(len(data))]

    def export(name: str, unit_line: str | None, pts, head_line="Collection,Group,Target,X,Y,Z"):
        out = ["// export", "// Frame: Tracker"] + ([unit_line] if unit_line else []) + [head_line]
        out += [f"C,R,{n},{p[0]:.6f},{p[1]:.6f},{p[2]:.6f}" for n, p in zip(names, pts)]
        (d / name).write_text("\n".join(out) + "\n")

    export("exp_mm.txt", "// Units: mm", P * 1e3)
    export("exp_mm_nounit.txt", None, P * 1e3)
    export("exp_m_nounit.txt", None, P)
    export("exp_hdr_m.txt", "// Units: mm", P, "Collection,Group,Target,X [m],Y [m],Z [m]")
    export("exp_m_decl_mmvals.txt", "// Units: m", P * 1e3)

    def log(name: str, Q) -> None:
        out = ["Target," + ",".join(f"joint_a{k}" for k in range(1, 7))]
        out += [n + "," + ",".join(f"{v:.8f}" for v in q) for n, q in zip(names, Q)]
        (d / name).write_text("\n".join(out) + "\n")

    log("joints_deg.csv", np.degrees(J))
    log("joints_rad.csv", J)

    def table(name: str, body) -> None:
        (d / name).write_text("\n".join([rows[0]] + [",".join(r) for r in body]) + "\n")

    table("reg3.csv", data[:3])
    table("reg4.csv", data[:4])
    table("reg20.csv", data[:20])
    table("reg_swap.csv", [r[:xi] + [r[yi], r[xi], r[zi]] + r[zi + 1:] for r in data[:20]])
    table("reg_negz.csv", [r[:zi] + [repr(-float(r[zi]))] + r[zi + 1:] for r in data[:20]])
    (d / "targets.csv").write_text("x,y,z\n" + "\n".join(",".join(f"{v:.6f}" for v in p) for p in P[:5]) + "\n")
    (d / "targets_far.csv").write_text("x,y,z\n" + "\n".join(",".join(f"{v + 6.0:.6f}" for v in p)
                                                              for p in P[:3]) + "\n")
    (d / "prog.csv").write_text(",".join(f"joint_a{k}" for k in range(1, 7)) + "\n"
                                + "\n".join(",".join(f"{v:.8f}" for v in q) for q in J[:5]) + "\n")
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["simulate", "--robot", "ur10", "--n", "60", "--seed", "1", "--out", str(d / "ur.csv")]) == 0
        assert main(["identify", "--robot", "ur10", "--data", str(d / "ur.csv"), "--model-out", str(d / "m_ur10.json"),
                     "--quiet", "--accept-poor-fit"]) == 0
    (d / "ur.csv").unlink()
    model = json.loads((d / "m.json").read_text())

    def bad_model(name: str, edit) -> None:
        e = json.loads(json.dumps(model))
        edit(e)
        (d / name).write_text(json.dumps(e))

    def put(path: str, value):
        def f(e):
            *head, last = path.split("/")
            o = e
            for k in head:
                o = o[int(k)] if isinstance(o, list) else o[k]
            if isinstance(o, list):
                o[int(last)] = value
            else:
                o[last] = value
        return f

    cov = np.asarray(model["geometry"]["parameters"]["covariance"], float)
    bad_model("m_str.json", put("geometry/joint_placement_errors/joint_a2.tx", "abc"))
    bad_model("m_dict.json", put("geometry/joint_placement_errors/joint_a2.tx", {"v": 1}))
    bad_model("m_list.json", put("tcp_m", [[0.0], [0.0], [0.0]]))
    bad_model("m_null.json", put("stations/tr/reflector_m", None))
    bad_model("m_covstr.json", put("geometry/parameters/covariance", "diag(1e-8)"))
    bad_model("m_cov_elem_str.json", put("geometry/parameters/covariance/0/1", "x"))
    bad_model("m_negdef.json", put("geometry/parameters/covariance", (-cov).tolist()))
    bad_model("m_zerocov.json", put("geometry/parameters/covariance", np.zeros_like(cov).tolist()))
    bad_model("m_asym.json",
              put("geometry/parameters/covariance", (cov + np.triu(np.full_like(cov, 1e-3), 1)).tolist()))
    bad_model("m_noise_mm.json", put("noise/sigma_xyz_m", [10.0, 10.0, 10.0]))
    bad_model("m_refl_mm.json", put("stations/tr/reflector_m", [30.0, 20.0, 80.0]))
    bad_model("m_unknown_key.json", put("geometri", {}))
    bad_model("m_std_negative.json", put("geometry/parameters/std/0", -1.0))
    bad_model("m_rows_text.json", put("stations/tr/n_rows", "120"))
    (d / "m_nan.json").write_text((d / "m.json").read_text().replace('"range_b": 0.0', '"range_b": NaN'))
    from tests.hostile.surfaces import build_surface_inputs

    build_surface_inputs(d)
    from tests.hostile.frictions import build_friction_inputs

    build_friction_inputs(d)
    Qd = np.asarray(design["q_meas"], float)[:10]
    (d / "given.csv").write_text(",".join(f"joint_a{k}" for k in range(1, 7)) + "\n"
                                 + "\n".join(",".join(f"{v:.10f}" for v in q) for q in Qd) + "\n")
    (d / "one_pose.csv").write_text(",".join(f"joint_a{k}" for k in range(1, 7)) + "\n"
                                    + ",".join(f"{v:.10f}" for v in Qd[0]) + "\n")


#: SHA-256 of a file by (path below the snapshot's folder, size, modification time in ns): a case's inputs are
#: copies keeping the originals' times (shutil.copytree), so each input is hashed once for all cases, and any
#: write gives its file a new time, hence a new key and a fresh hash.
_DIGESTS: dict[tuple[str, int, int], str] = {}


def snapshot(d: Path) -> dict[str, str]:
    """Path (relative to ``d``, '/'-separated) -> SHA-256 of every file below ``d`` (symlinks by target), folders as
    ``<dir>`` (a folder's symlink listed as a folder, not entered: ``os.walk``'s rule). One ``os.scandir`` per folder,
    its entries' own paths and stats (the cases take two snapshots each: ``os.walk`` with a join and a stat per file
    cost half as much again, 0.34 ms instead of 0.23 ms on a folder of 108 entries)."""
    out = {}
    todo = [("", str(d))]
    while todo:
        prefix, top = todo.pop()
        with os.scandir(top) as it:
            for e in it:
                rel = prefix + e.name
                if e.is_dir():
                    out[rel] = "<dir>"
                    if not e.is_symlink():
                        todo.append((rel + "/", e.path))
                    continue
                st = e.stat()
                key = (rel, st.st_size, st.st_mtime_ns)
                if key not in _DIGESTS:
                    with open(e.path, "rb") as f:
                        _DIGESTS[key] = hashlib.sha256(f.read()).hexdigest()
                out[rel] = _DIGESTS[key]
    return out


@dataclass
class Outcome:
    """What one case did: exit code, stderr, time (s), files written or changed (``changed``), inputs among them
    (``inputs_changed``), a traceback seen, stdout."""

    rc: int
    err: str
    time_s: float
    changed: list[str]
    traceback: bool
    out: str = ""
    inputs_changed: tuple[str, ...] = ()
    cpu_s: float = 0.0

    def verdict(self, case: Case) -> str:
        """``ok`` or what went wrong, worst first: ``traceback``, ``input changed``, ``hang``, ``exit 0`` (a refusal
        was due), ``silent`` (a warning was due and not said), ``written`` (a refusal left files), ``unclear``
        (refused without the expected text in one line)."""
        lines = [ln for ln in self.err.strip().splitlines() if ln.strip()]
        if self.traceback or "Traceback" in self.err:
            return "traceback"
        if self.inputs_changed:
            return "input changed"
        if self.cpu_s > case.max_s:
            return "hang"
        if case.kind == "warn":
            if case.expect not in self.out + self.err or self.rc not in (0, 2):
                return "silent"
            return "ok"
        if self.rc == 0:
            return "exit 0"
        if self.changed:
            return "written"
        if self.rc != 2 or not lines or case.expect not in lines[-1]:
            return "unclear"
        return "ok"

    def ok(self, case: Case) -> bool:
        """The case's answer is right (see :meth:`verdict`)."""
        return self.verdict(case) == "ok"


def argv_of(case: Case, d: Path) -> list[str]:
    """The case's arguments with ``{d}`` replaced."""
    return [a.replace("{d}", str(d)) for a in case.argv.split()]


#: base folder -> (its pristine copy, each file's (size, modification time in ns) as built): :func:`prepare`'s guard
_PRISTINE: dict[Path, tuple[Path, dict[str, tuple[int, int]]]] = {}


def _stat_key(p: Path) -> tuple[int, int]:
    st = p.stat()
    return st.st_size, st.st_mtime_ns


def _guard_base(base: Path) -> None:
    """Keep ``base`` as built: a pristine copy made on the first call; later calls put back from it any file a case
    changed through its hard link (a command writing an input in place: the case fails on it, the next cases still
    get the inputs as built)."""
    if base not in _PRISTINE:
        pristine = base.with_name(f".{base.name}.pristine")
        if pristine.exists():
            shutil.rmtree(pristine)
        shutil.copytree(base, pristine, symlinks=True)
        _PRISTINE[base] = pristine, {str(p.relative_to(base)): _stat_key(p) for p in base.rglob("*")
                                     if p.is_file() and not p.is_symlink()}
        return
    pristine, built = _PRISTINE[base]
    for rel, key in built.items():
        p = base / rel
        if not p.is_file() or _stat_key(p) != key:
            p.unlink(missing_ok=True)
            shutil.copy2(pristine / rel, p)
            built[rel] = _stat_key(p)


#: work folder -> every entry below it as :func:`prepare` linked it (:func:`_entries`)
_LINKED: dict[Path, dict[str, tuple[int, ...]]] = {}


def _entries(d: Path) -> dict[str, tuple[int, ...]]:
    """Path (relative to ``d``, '/'-separated) -> (mode, size, modification and change times in ns, inode) of every
    file and symlink below ``d`` (the symlink itself), () for a folder: a file written, replaced, removed or added
    (in a new folder too), a symlink replaced, changes it."""
    out: dict[str, tuple[int, ...]] = {}
    todo = [("", str(d))]
    while todo:
        prefix, top = todo.pop()
        with os.scandir(top) as it:
            for e in it:
                if e.is_dir(follow_symlinks=False):
                    out[prefix + e.name] = ()
                    todo.append((prefix + e.name + "/", e.path))
                else:
                    st = e.stat(follow_symlinks=False)
                    out[prefix + e.name] = (st.st_mode, st.st_size, st.st_mtime_ns, st.st_ctime_ns, st.st_ino)
    return out


def prepare(case: Case, base: Path, work: Path) -> None:
    """Give ``work`` the inputs ``base`` (the symlink pointing into ``work``) and build what the case needs.

    The files are hard links to ``base``'s (a copy costs about 10 ms a case, a link a fraction of it): a command's
    output replaces a file (written aside, then renamed) and leaves ``base`` as it was; a write into an input in
    place shows in the case's snapshot (the input changed: the case fails) and :func:`_guard_base` puts the file
    back before the next case. A folder the previous case left exactly as linked (:func:`_entries`: the same
    entries, each the same inode with the same size and times; a refusal writes nothing) is kept as it is: linking
    the inputs afresh would give the same folder (3 ms a case).
    """
    from tests.hostile.surfaces import EXTRA

    if not case.needs and work in _LINKED and _entries(work) == _LINKED[work]:
        return
    _LINKED.pop(work, None)
    _guard_base(base)
    if work.exists():
        shutil.rmtree(work)
    shutil.copytree(base, work, symlinks=True, copy_function=os.link)
    (work / "link.csv").unlink()
    (work / "link.csv").symlink_to(work / "tr.csv")
    if case.needs:
        EXTRA[case.needs](work)
    else:
        _LINKED[work] = _entries(work)


#: (command, lazy) -> the argument parser :func:`pin_kpi_oed.cli.app.build_parser` built for it
_PARSERS: dict[tuple[str | None, bool], argparse.ArgumentParser] = {}


@contextlib.contextmanager
def _parsers_built_once():
    """:func:`pin_kpi_oed.cli.app.main` with each command's parser built once for all cases (5 to 12 ms a case
    otherwise): parsing makes a new namespace each time and changes nothing of the parser (no option of the command
    line has a mutable default; ``append`` options start from a new list), so a case parses as with a fresh parser."""
    from pin_kpi_oed.cli import app

    build = app.build_parser

    def cached(command: str | None = None, lazy: bool = False) -> argparse.ArgumentParser:
        if (command, lazy) not in _PARSERS:
            _PARSERS[command, lazy] = build(command, lazy)
        return _PARSERS[command, lazy]

    app.build_parser = cached
    try:
        yield
    finally:
        app.build_parser = build


def run_case(case: Case, base: Path, work: Path) -> Outcome:
    """Give ``work`` the inputs ``base``, run the case in-process, compare the files before and after."""
    prepare(case, base, work)
    before = snapshot(work)
    from pin_kpi_oed.cli.app import main

    err, out = io.StringIO(), io.StringIO()
    t0, c0 = time.perf_counter(), time.process_time()
    tb = False
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out), _parsers_built_once():
            rc = main(argv_of(case, work))
    except SystemExit as exc:  # argparse
        rc = int(exc.code or 0)
    except Exception as exc:  # noqa: BLE001 - a traceback is what this test hunts
        rc, tb = -1, True
        err.write(f"Traceback: {type(exc).__name__}: {exc}")
    dt, cpu = time.perf_counter() - t0, time.process_time() - c0
    after = snapshot(work)
    changed = sorted(k for k in set(before) | set(after) if before.get(k) != after.get(k))
    return Outcome(rc, err.getvalue(), dt, changed, tb, out.getvalue(), tuple(k for k in changed if k in before), cpu)
