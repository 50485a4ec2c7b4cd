"""The measurement reader on pandas: declared units, column mappings, and the refusals without them."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from pin_kpi_oed import NoiseModel, TrackerModel, load_robot
from pin_kpi_oed.cli.app import main
from pin_kpi_oed.data.measurements import read_measurements, write_measurements
from pin_kpi_oed.data.table import parse_columns, parse_units
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.simulation.simulator import default_tracker_pose, simulate

KUKA_NAMES = ["A1", "A2", "A3", "A4", "A5", "A6"]


@pytest.fixture(scope="module")
def ur10_data():
    robot = load_robot("ur10")
    tm = TrackerModel(robot, tracker_T_base=default_tracker_pose(robot), reflector_m=np.array([0.0, 0.0, 0.1]),
                      noise=NoiseModel((1e-5,) * 3))
    return robot, simulate(tm, robot.random_q(np.random.default_rng(4), 40), seed=1)


def _foreign(path: Path, ms, with_sigma: bool = True) -> Path:
    """The same measurements as another tool writes them: mm, degrees, its own column names, other order."""
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["X", "Y", "Z"] + KUKA_NAMES + (["Sx", "Sy", "Sz"] if with_sigma else []))
        for i in range(len(ms)):
            row = [repr(float(v)) for v in ms.position_m[i] * 1e3] + [repr(float(v)) for v in np.degrees(ms.q[i])]
            if with_sigma:
                row += [repr(float(v)) for v in ms.sigma_m[i] * 1e3]
            w.writerow(row)
    return path


def _mapping(robot) -> str:
    return ",".join([f"{j}={a}" for j, a in zip(robot.joint_names, KUKA_NAMES)]
                    + ["x=X", "y=Y", "z=Z", "sigma_x=Sx", "sigma_y=Sy", "sigma_z=Sz"])


def test_mm_degrees_other_names_read_with_units_and_columns(ur10_data, tmp_path):
    robot, ms = ur10_data
    f = _foreign(tmp_path / "foreign.csv", ms)
    back = read_measurements(f, joint_names=robot.joint_names, reach_m=robot.reach(), units="mm,deg",
                             columns=_mapping(robot), joint_units=robot.joint_units)
    assert back.joint_names == list(robot.joint_names)
    assert np.allclose(back.q, ms.q, rtol=1e-14, atol=1e-15)
    assert np.allclose(back.position_m, ms.position_m, rtol=1e-14, atol=1e-15)
    assert np.allclose(back.sigma_m, ms.sigma_m, rtol=1e-14, atol=1e-20)
    assert back.extra == {}


def test_refused_with_one_clear_line_without_units_or_columns(ur10_data, tmp_path):
    robot, ms = ur10_data
    f = _foreign(tmp_path / "foreign.csv", ms)
    with pytest.raises(InputError) as exc:
        read_measurements(f, joint_names=robot.joint_names, reach_m=robot.reach())
    msg = str(exc.value)
    assert "missing position column(s) x, y, z" in msg and "columns='x=X" in msg and "\n" not in msg
    with pytest.raises(InputError) as exc:
        read_measurements(f, joint_names=robot.joint_names, reach_m=robot.reach(), columns=_mapping(robot))
    msg = str(exc.value)
    assert "looks like mm/degrees" in msg and "units='mm,deg'" in msg and "\n" not in msg
    with pytest.raises(InputError, match="maps column"):
        read_measurements(f, joint_names=robot.joint_names, columns="x=NOPE")


def test_only_angles_in_degrees(ur10_data, tmp_path):
    robot, ms = ur10_data
    deg = ms.subset(np.arange(10))
    deg.q = np.degrees(deg.q)
    write_measurements(deg, tmp_path / "deg.csv")
    with pytest.raises(InputError, match="looks like mm/degrees"):
        read_measurements(tmp_path / "deg.csv", joint_names=robot.joint_names)
    back = read_measurements(tmp_path / "deg.csv", joint_names=robot.joint_names, units="deg")
    assert np.allclose(back.q, ms.q[:10], rtol=1e-14) and np.array_equal(back.position_m, ms.position_m[:10])


def test_prismatic_joint_is_a_length_under_units(tmp_path):
    f = tmp_path / "track.csv"
    f.write_text("track,j1,x,y,z\n6400.0,90.0,1000,2000,500\n3200.0,-45.0,1500,2000,500\n")
    ms = read_measurements(f, joint_names=["track", "j1"], units="mm,deg", joint_units=["m", "rad"])
    assert np.allclose(ms.q, [[6.4, np.pi / 2], [3.2, -np.pi / 4]])
    assert np.allclose(ms.position_m[0], [1.0, 2.0, 0.5])


def test_parse_units_and_columns_refusals():
    assert parse_units("mm,deg").length_m == 1e-3 and parse_units("deg").length == "m"
    assert parse_units(None).is_si and not parse_units(None).declared
    for bad, frag in (("furlong", "unknown unit 'furlong'"), ("mm,m", "two length units"), (",", "no unit")):
        with pytest.raises(InputError, match=frag):
            parse_units(bad)
    assert parse_columns("joint_a1=A1, x = X") == {"A1": "joint_a1", "X": "x"}
    for bad, frag in (("joint_a1", "ours=theirs"), ("a=X,b=X", "mapped twice"), ("a=X,a=Y", "given twice")):
        with pytest.raises(InputError, match=frag):
            parse_columns(bad)


def test_cli_identify_and_predict_take_units_and_columns(ur10_data, tmp_path, capsys):
    robot, ms = ur10_data
    f = _foreign(tmp_path / "foreign.csv", ms)
    base = ["identify", "--robot", "ur10", "--data", str(f), "--reflector", "0,0,0.1", "--sigma", "1e-5",
            "--model-out", str(tmp_path / "model.json"), "--quiet"]
    assert main(base) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--columns" in err
    assert main(base + ["--columns", _mapping(robot)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--units mm,deg" in err
    assert main(base + ["--columns", _mapping(robot), "--units", "mm,deg"]) == 0
    assert main(["predict", "--model", str(tmp_path / "model.json"), "--data", str(f), "--out",
                 str(tmp_path / "pred.csv"), "--columns", _mapping(robot), "--units", "mm,deg", "--quiet"]) == 0
    rows = list(csv.DictReader(open(tmp_path / "pred.csv")))
    err = np.array([float(r["error"]) for r in rows])
    assert len(rows) == len(ms) and err.max() < 1e-4  # the nominal robot, σ = 10 µm: a good fit
    assert main(base + ["--units", "furlong"]) == 2
    assert "unknown unit 'furlong'" in capsys.readouterr().err


# --------------------------------------------------------------------------- tracker-software export
SAMPLE = """// pin_kpi_oed tracker point export
// Frame: Tracker
// Units: mm
Collection,Group,Target,X,Y,Z,Timestamp
Cell1,Robot,P0001,2143.0712,-1032.5531,415.2207,2026-11-22T10:15:03.250
Cell1,Robot,P0002,2098.6617,-1104.0093,388.9410,2026-11-22T10:15:09.875

Cell1,Robot,P0003,1987.1000,-998.2500,502.0001,2026-11-22T10:15:16.000
"""
JOINT_LOG = """Target,A1,A2,A3,A4,A5,A6,temperature
P0003,30,-60,90,-45,60,10,21.5
P0001,10,-80,100,-30,45,0,21.0
P0002,20,-70,95,-40,50,5,21.2
"""


def test_tracker_export_sample_file_round_trips(tmp_path):
    from pin_kpi_oed.data.tracker_export import import_tracker_export, read_point_export, write_tracker_export

    robot = load_robot("ur10")
    (tmp_path / "export.txt").write_text(SAMPLE)
    (tmp_path / "joints.csv").write_text(JOINT_LOG)
    exp = read_point_export(tmp_path / "export.txt")
    assert exp.names == ["P0001", "P0002", "P0003"] and exp.units == "mm" and exp.frame == "Tracker"
    assert np.allclose(exp.position_m[0], [2.1430712, -1.0325531, 0.4152207], rtol=0, atol=1e-15)
    assert np.allclose(exp.time_s, [0.0, 6.625, 12.75])
    cols = ",".join(f"{j}={a}" for j, a in zip(robot.joint_names, KUKA_NAMES))
    ms, names = import_tracker_export(tmp_path / "export.txt", tmp_path / "joints.csv", robot.joint_names,
                                      columns=cols)
    assert names == exp.names  # the export's order; the joint log was in another order
    assert np.allclose(np.degrees(ms.q[0]), [10, -80, 100, -30, 45, 0]) and np.allclose(ms.temperature_c,
                                                                                        [21.0, 21.2, 21.5])
    assert np.array_equal(ms.position_m, exp.position_m) and np.array_equal(ms.time_s, exp.time_s)
    # write it back in the layout: the same text, point for point (4 decimals of mm, ms time stamps)
    write_tracker_export(tmp_path / "again.txt", names, ms.position_m, ms.time_s, start="2026-11-22T10:15:03.250",
                         collection="Cell1", group="Robot")
    assert (tmp_path / "again.txt").read_text() == SAMPLE.replace("\n\n", "\n")
    again = read_point_export(tmp_path / "again.txt")
    assert np.array_equal(again.position_m, exp.position_m) and np.allclose(again.time_s, exp.time_s, atol=1e-9)
    # the joined set is a valid measurement file of the package
    write_measurements(ms, tmp_path / "meas.csv")
    back = read_measurements(tmp_path / "meas.csv", joint_names=robot.joint_names, reach_m=robot.reach())
    assert np.array_equal(back.q, ms.q) and np.array_equal(back.time_s, ms.time_s)


def test_tracker_export_refusals(tmp_path):
    from pin_kpi_oed.data.tracker_export import import_tracker_export, read_point_export

    (tmp_path / "e.txt").write_text(SAMPLE)
    with pytest.raises(InputError, match="says 'Units: mm' but m was given"):
        read_point_export(tmp_path / "e.txt", units="m")
    (tmp_path / "bad.txt").write_text(SAMPLE.replace("415.2207", "4l5.2207"))
    with pytest.raises(InputError, match=r"column 'z', row 1 \(line 5\): '4l5.2207' is not a number"):
        read_point_export(tmp_path / "bad.txt")
    (tmp_path / "t.txt").write_text(SAMPLE.replace("2026-11-22T10:15:09.875", "yesterday"))
    with pytest.raises(InputError, match="line 6: 'yesterday' is neither an ISO date-time"):
        read_point_export(tmp_path / "t.txt")
    (tmp_path / "n.txt").write_text(SAMPLE.replace("Target", "Punkt"))
    with pytest.raises(InputError, match="missing column.*target.*columns='target=NAME"):
        read_point_export(tmp_path / "n.txt")
    assert read_point_export(tmp_path / "n.txt", columns="target=Punkt").names[0] == "P0001"
    robot = load_robot("ur10")
    (tmp_path / "j.csv").write_text(JOINT_LOG.replace("P0002", "P0009"))
    cols = ",".join(f"{j}={a}" for j, a in zip(robot.joint_names, KUKA_NAMES))
    with pytest.raises(InputError, match="point.*P0002 have no joint values"):
        import_tracker_export(tmp_path / "e.txt", tmp_path / "j.csv", robot.joint_names, columns=cols)


def test_cli_import_tracker(tmp_path, capsys):
    robot = load_robot("ur10")
    (tmp_path / "export.txt").write_text(SAMPLE)
    (tmp_path / "joints.csv").write_text(JOINT_LOG)
    cols = ",".join(f"{j}={a}" for j, a in zip(robot.joint_names, KUKA_NAMES))
    argv = ["import-tracker", str(tmp_path / "export.txt"), "--joints", str(tmp_path / "joints.csv"), "--robot",
            "ur10", "--out", str(tmp_path / "m.csv"), "--quiet"]
    assert main(argv) == 2 and "--columns" in capsys.readouterr().err
    assert main(argv + ["--columns", cols]) == 0
    ms = read_measurements(tmp_path / "m.csv", joint_names=robot.joint_names, reach_m=robot.reach())
    assert len(ms) == 3 and np.allclose(ms.time_s, [0.0, 6.625, 12.75]) and ms.temperature_c[2] == 21.5


def test_joint_beyond_a_turn_within_its_own_limit(ur10_data, tmp_path):
    """A wrist of ±400° (6.98 rad, an ABB's joint 6) is an angle up to its own limit, not degrees; beyond it, and
    for a joint without such a limit, the guard still refuses."""
    robot, ms = ur10_data
    wide = ms.subset(np.arange(5))
    wide.q = wide.q.copy()
    wide.q[:, 5] = [6.9, -6.9, 6.5, 0.1, -0.2]
    write_measurements(wide, tmp_path / "wide.csv")
    with pytest.raises(InputError, match="2π"):
        read_measurements(tmp_path / "wide.csv", joint_names=robot.joint_names)
    guard = [2 * np.pi + 0.1] * 5 + [6.9813 + 0.1]  # a wrist of ±400°: its own limit + 0.1 rad
    back = read_measurements(tmp_path / "wide.csv", joint_names=robot.joint_names, joint_guard=guard)
    assert np.array_equal(back.q[:, 5], wide.q[:, 5])
    wide.q[0, 5] = 7.2  # beyond 6.9813 + 0.1
    write_measurements(wide, tmp_path / "wider.csv")
    with pytest.raises(InputError, match=r"wrist_3_joint.*7.081 rad \(the joint's own limit \+ 0.1\)"):
        read_measurements(tmp_path / "wider.csv", joint_names=robot.joint_names, joint_guard=guard)


def test_robot_unit_guard_takes_a_wrist_beyond_a_turn():
    """Robot.check_units: a revolute joint whose limits pass a turn takes values up to its limit + 0.1 rad."""
    robot = load_robot("ur10")
    robot.q_lower, robot.q_upper = robot.q_lower.copy(), robot.q_upper.copy()
    q = np.zeros((1, 6))
    q[0, 5] = 6.9
    with pytest.raises(InputError, match="looks like degrees"):
        robot.check_units(q, "m.csv")
    robot.q_lower[5], robot.q_upper[5] = -6.9813, 6.9813
    robot.check_units(q, "m.csv")
    q[0, 5] = 7.2
    with pytest.raises(InputError, match="wrist_3_joint.*beyond 7.081"):
        robot.check_units(q, "m.csv")


def test_quoted_cells_and_blank_lines_keep_every_row_and_its_line():
    """The table reader is the standard library's csv: a quoted cell holding the separator is one cell, a doubled
    quote inside it is a quote, blank lines are skipped but counted, and a header after a blank line is read (a
    pandas python-engine reader returned no table at all for the last case). A whitespace separator splits each
    line's stripped text."""
    from pin_kpi_oed.data.table import parse_text_table

    text = '\nname,"x,y",z\n\n1,"2,5","say ""hi"""\n3,4\n'
    header, line, rows, lines = parse_text_table(text, "t.csv")
    assert (header, line) == (["name", "x,y", "z"], 2)
    assert rows == [["1", "2,5", 'say "hi"'], ["3", "4"]] and lines == [4, 5]
    assert parse_text_table("\na;\"x,y\"\n", "t.csv", sep=";")[:2] == (["a", "x,y"], 2)
    assert parse_text_table("  a  b\tc\n 1 2  3\n", "t.txt", sep=r"\s+")[::2] == (["a", "b", "c"], [["1", "2", "3"]])


def test_reading_a_measurement_file_loads_no_table_library(ur10_data, tmp_path):
    """Reading measurements needs no pandas (its import alone cost every command that reads a measurement file
    about 0.4 s of CPU): a fresh process reads a file and pandas is not among its modules."""
    import subprocess
    import sys

    path = tmp_path / "m.csv"
    write_measurements(ur10_data[1], path)
    code = ("import sys; from pin_kpi_oed.data.measurements import read_measurements; "
            f"ms = read_measurements({str(path)!r}); print(len(ms.q), 'pandas' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert int(out[0]) > 0 and out[1] == "False", out
