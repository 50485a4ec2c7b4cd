"""Hostile inputs of the tool-point surfaces: hand-edited truth files, another robot's poses, options that would
do nothing, outputs that cannot be written, industrial-arm URDFs (a joint range of a few turns, a robot link
named in a cell's obstacles) and the frames of ``compensate``.

``build_friction_inputs(folder)`` adds their inputs to the shared folder of :mod:`tests.hostile.cases`;
``friction_cases()`` lists the cases.
"""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path


def wrist_400_urdf(path: Path) -> Path:
    """The KR 15 URDF with its joint_a6 limits at ±400° (6.98 rad, as an industrial wrist's URDF states them)."""
    import re

    from pin_kpi_oed.model.robot import resolve_robot

    urdf = Path(resolve_robot("kr15")[0]).read_text()
    i = urdf.index('name="joint_a6"')
    j = urdf.index("<limit", i)
    k = urdf.index("/>", j)
    lim = re.sub(r'upper="[^"]+"', 'upper="6.981317"', re.sub(r'lower="[^"]+"', 'lower="-6.981317"', urdf[j:k]))
    path.write_text(urdf[:j] + lim + urdf[k:])
    return path


def build_friction_inputs(d: Path) -> None:
    """Add this module's inputs to ``d`` (needs ``d.json``, ``m.json``; about 2 s)."""
    from pin_kpi_oed.cli.app import main

    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        assert main(["simulate", "--robot", "ur10", "--n", "5", "--seed", "1", "--out", str(d / "t_ur10.csv"),
                     "--truth", str(d / "t_ur10.json")]) == 0
        assert main(["simulate", "--robot", "ur5", "--n", "5", "--seed", "1", "--out", str(d / "p_ur5.csv")]) == 0
        wrist_400_urdf(d / "kr400.urdf")
        assert main(["simulate", "--robot", str(d / "kr400.urdf"), "--n", "12", "--seed", "1", "--out",
                     str(d / "kr400.csv")]) == 0
    rows = [r for r in (d / "kr400.csv").read_text().splitlines() if not r.startswith("#")]  # tool header off
    (d / "kr400.csv").unlink()
    cells = rows[1].split(",")
    cells[5] = "7.3"  # beyond the wrist's own limit (6.98 rad) + 0.1
    rows[1] = ",".join(cells)
    (d / "kr400_beyond.csv").write_text("\n".join(rows) + "\n")
    _build_cells(d)
    truth = json.loads((d / "t_ur10.json").read_text())

    def edited(name: str, edit) -> None:
        t = json.loads(json.dumps(truth))
        edit(t)
        (d / name).write_text(json.dumps(t))

    edited("t_base5mm.json", lambda t: t["tracker_T_base"][0].__setitem__(3, t["tracker_T_base"][0][3] + 0.005))
    edited("t_refl.json", lambda t: t["reflector_m"].__setitem__(2, t["reflector_m"][2] + 0.005))
    edited("t_joint.json", lambda t: t["joint_placements"][2][1].__setitem__(3, t["joint_placements"][2][1][3] + 5e-3))
    edited("t_joint_short.json", lambda t: t["joint_placements"].pop())
    design = json.loads((d / "d.json").read_text())

    def design_edit(name: str, where: str, edit) -> None:
        e = json.loads(json.dumps(design))
        edit(e["cell"] if where == "cell" else e)
        (d / name).write_text(json.dumps(e))

    def stretch(o):  # the rotation block scaled by 1.5: no rotation
        o["tracker_T_base"] = [[v * 1.5 if i < 3 and j < 3 else v for j, v in enumerate(r)]
                               for i, r in enumerate(o["tracker_T_base"])]

    design_edit("d_cell_tracker_stretched.json", "cell", stretch)
    design_edit("d_tracker_stretched.json", "top", stretch)
    design_edit("d_cell_tracker_5mm.json", "cell", lambda o: o["tracker_T_base"][0].__setitem__(
        3, o["tracker_T_base"][0][3] + 0.005))


def _build_cells(d: Path) -> None:
    """KR 15 cells with a working target: the wrist's overlapping capsules not skipped (``cell_noskip.yaml``); a
    fixture every solution's wrist hits (``cell_fixture.yaml``)."""
    import yaml

    from pin_kpi_oed.cell.cell import CELL_DIR

    def cell(name: str, edit) -> None:
        c = yaml.safe_load((CELL_DIR / "kr15.yaml").read_text())
        c.pop("working_configurations_deg")
        c["working_targets"] = [{"xyz_m": [1.1, 0.0, 1.65], "rpy_deg": [180, 0, 0]}]
        edit(c)
        (d / name).write_text(yaml.safe_dump(c))

    def fixture(c):
        c["obstacles"]["capsules"].append({"name": "fixture", "a_m": [1.1, -0.05, 1.86], "b_m": [1.1, 0.05, 1.86],
                                           "radius_m": 0.03})
        c["beam"]["skip"] = ["fixture"]

    cell("cell_noskip.yaml", lambda c: c.update(skip_pairs=[p for p in c["skip_pairs"] if p != ["link_4", "link_6"]]))
    cell("cell_fixture.yaml", fixture)


def friction_cases() -> list:
    """The cases of this module (:class:`tests.hostile.cases.Case`)."""
    from tests.hostile.cases import Case

    again = "--poses {d}/t_ur10.csv --out {d}/o.csv"
    c = [
        # a truth file is p_raw with its nominal set-up: a derived field edited alone is refused, named
        Case("f-truth-tracker-edited", "simulate --truth {d}/t_base5mm.json " + again, "'tracker_T_base' disagrees"),
        Case("f-truth-reflector-edited", "simulate --truth {d}/t_refl.json " + again, "'reflector_m' disagrees"),
        Case("f-truth-joint-placement-edited", "simulate --truth {d}/t_joint.json " + again,
             "'joint_placements[2]' disagrees"),
        Case("f-truth-joint-placements-short", "simulate --truth {d}/t_joint_short.json " + again,
             "'joint_placements' is malformed"),
        Case("f-truth-ur10-at-ur5-poses", "simulate --truth {d}/t_ur10.json --poses {d}/p_ur5.csv --out {d}/o.csv",
             "robot 'ur5', but the true robot of --truth"),
        # a design's tracker pose: a rigid transform, the one of the cell's world frames
        Case("f-view-cell-tracker-not-rotation", "view {d}/d_cell_tracker_stretched.json --html {d}/o.html --no-open",
             "cell.tracker_T_base: the rotation block is not a proper rotation"),
        Case("f-view-tracker-not-rotation", "view {d}/d_tracker_stretched.json --html {d}/o.html --no-open",
             "tracker_T_base: the rotation block is not a proper rotation"),
        Case("f-view-cell-tracker-edited", "view {d}/d_cell_tracker_5mm.json --html {d}/o.html --no-open",
             "cell.tracker_T_base disagrees with cell.W_T_tracker"),
        Case("f-evaluate-tracker-not-rotation", "evaluate {d}/d_tracker_stretched.json",
             "tracker_T_base: the rotation block"),
        # options that would do nothing are refused, saying why
        Case("f-ignored-export-model-ur-yaml-tcp", "export-model --model {d}/m.json --format ur-yaml --tcp 0,0,0.1 "
             "--out {d}/o.yaml", "--tcp: places the URDF's 'tcp' frame"),
        Case("f-ignored-export-model-ur-yaml-no-frames", "export-model --model {d}/m.json --format ur-yaml "
             "--no-frames --out {d}/o.yaml", "--no-frames: leaves the set-up frames out of a URDF"),
        Case("f-ignored-export-model-urdf-tcp-no-frames", "export-model --model {d}/m.json --format urdf --no-frames "
             "--tcp 0,0,0.1 --out {d}/o.urdf", "without --no-frames"),
        Case("f-ignored-monitor-poll-without-follow", "monitor --model {d}/m.json --data {d}/te.csv --poll 2",
             "--poll: sets the seconds between reads while following a growing file: add --follow"),
        Case("f-ignored-monitor-idle-without-follow", "monitor --model {d}/m.json --data {d}/te.csv --idle 5",
             "--idle: sets the seconds without a new row"),
        Case("f-ignored-predict-tool-length-3d", "predict --model {d}/m.json --data {d}/te.csv --out {d}/o.csv "
             "--tool-length 0.3", "--tool-length: states a 6-D model's orientation sigma"),
        Case("f-ignored-compensate-program-tool-length-3d", "compensate --model {d}/m.json --program {d}/prog.csv "
             "--out {d}/o.csv --tcp 0,0,0.1 --tool-length 0.3", "is a position-only (3-D) model"),
        Case("f-ignored-compensate-targets-tool-length-3d", "compensate --model {d}/m.json --targets "
             "{d}/targets.csv --out {d}/o.csv --tcp 0,0,0.1 --tool-length 0.3", "drop --tool-length"),
        # an output folder that takes no file is refused before any work, naming the output (not a temporary file)
        Case("out-export-model-into-proc", "export-model --model {d}/m.json --format urdf --out /proc/x.urdf",
             "--out /proc/x.urdf: "),
        Case("out-identify-json-into-proc", "identify --robot kr15 --data {d}/tr.csv --json /proc/r.json",
             "--json /proc/r.json: "),
        # a size beyond its limit names the option and the limit
        Case("f-check-design-measurements-beyond-pool", "check design --model {d}/m.json --measurements 100000 "
             "--json {d}/o.json", "--measurements: 100000 poses from --pool-size 400 candidates: give --measurements "
             "3..400"),
        Case("f-check-design-pool-beyond-limit", "check design --model {d}/m.json --pool-size 10000000 "
             "--json {d}/o.json", "--pool-size: 10000000 candidate poses is more than 20000"),
        # a wrist of a few turns: values beyond its own limit (not 2π) look like degrees
        Case("f-units-wrist-400-beyond-own-limit", "identify --robot {d}/kr400.urdf --data {d}/kr400_beyond.csv",
             "exceeds 7.081 rad (the joint's own limit + 0.1)"),
        # a robot's own links are named as such; a colliding working target says how to skip a pair
        Case("f-cell-robot-links-overlap-named-as-links", "design --cell {d}/cell_noskip.yaml --measurements 10 "
             "--criteria random --json {d}/o.json", "the robot's links 'link_4' and 'link_6' collide with each other"),
        Case("f-cell-working-target-colliding-pair-skip-hint", "design --cell {d}/cell_fixture.yaml --measurements 10 "
             "--criteria random --json {d}/o.json", "skip_pairs: [[link_5, fixture]]"),
        # compensate's frames: the station's tracker frame or the base frame; 'cell' named neither a cell file's frame
        Case("f-compensate-frame-cell-ambiguous", "compensate --model {d}/m.json --targets {d}/targets.csv --out "
             "{d}/o.csv --tcp 0,0,0.1 --frame cell", "--frame cell: ambiguous"),
    ]
    return c
