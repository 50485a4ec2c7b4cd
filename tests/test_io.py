"""Tests of pin_kpi_oed.data.measurements (measurement CSV files, atomic writes) and pin_kpi_oed.data.ipa."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import pin_kpi_oed.data.atomic as patomic
import pin_kpi_oed.data.measurement_writer as measurement_writer
import pin_kpi_oed.data.measurements as pio
from pin_kpi_oed.errors import InputError, PinKpiOedError
from pin_kpi_oed.data.measurements import MeasurementSet, read_measurements, write_measurements
from pin_kpi_oed.data.atomic import atomic_write_json, atomic_write_text
from tests._cache_g import IPA_GROUP, ipa_series

JOINTS = ["j1", "j2", "j3"]
_HERE = Path(__file__).resolve()
IPA_DIR = next((p / "shared" / "data" / "ipa_ur10" for p in (_HERE.parents[2], _HERE.parents[3])
                if (p / "shared" / "data" / "ipa_ur10").is_dir()), _HERE.parents[2] / "shared" / "data" / "ipa_ur10")
needs_ipa = pytest.mark.skipif(not IPA_DIR.is_dir(), reason=f"IPA data not found at {IPA_DIR}")


def _full_set(m: int = 25, seed: int = 1) -> MeasurementSet:
    rng = np.random.default_rng(seed)
    return MeasurementSet(
        joint_names=list(JOINTS),
        q=rng.uniform(-3.0, 3.0, (m, 3)),
        position_m=rng.normal([2.0, -1.0, 0.5], 0.5, (m, 3)),
        rotvec_rad=Rotation.random(m, random_state=seed).as_rotvec(),
        sigma_m=rng.uniform(1e-6, 5e-5, (m, 3)),
        temperature_c=rng.uniform(20.0, 23.0, m),
        payload_kg=rng.uniform(0.0, 10.0, m),
        time_s=np.cumsum(rng.uniform(1.0, 10.0, m)),
        source="memory",
        extra={"humidity": rng.uniform(30, 60, m), "goal_x": rng.normal(size=m) * 1e-17},
    )


def _write_csv(path: Path, header: list[str], rows: list[list[object]]) -> Path:
    lines = [",".join(header)] + [",".join(str(v) for v in r) for r in rows]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def _good_rows() -> tuple[list[str], list[list[object]]]:
    header = JOINTS + ["x", "y", "z"]
    rows = [
        [0.1, 0.2, 0.3, 2.0, 1.0, 0.5],
        [0.4, 0.5, 0.6, 2.1, 1.1, 0.6],
        [0.7, 0.8, 0.9, 2.2, 1.2, 0.7],
        [1.0, 1.1, 1.2, 2.3, 1.3, 0.8],
    ]
    return header, rows


def _raises(path: Path, *fragments: str, **kwargs) -> str:
    with pytest.raises(InputError) as exc:
        read_measurements(path, **kwargs)
    msg = str(exc.value)
    for frag in fragments:
        assert frag in msg, f"{frag!r} not in {msg!r}"
    return msg


# --------------------------------------------------------------------------- #
# Round trip
# --------------------------------------------------------------------------- #
def test_round_trip_preserves_every_column(tmp_path: Path) -> None:
    ms = _full_set()
    f = tmp_path / "meas.csv"
    write_measurements(ms, f)
    header = f.read_text().splitlines()[0].split(",")
    assert header == JOINTS + ["x", "y", "z", "rx", "ry", "rz", "sigma_x", "sigma_y", "sigma_z",
                               "temperature", "payload", "time", "humidity", "goal_x"]
    back = read_measurements(f, joint_names=JOINTS)
    assert back.joint_names == JOINTS and len(back) == len(ms) and back.source == str(f)
    for name in ("q", "position_m", "rotvec_rad", "sigma_m", "temperature_c", "payload_kg", "time_s"):
        np.testing.assert_allclose(getattr(back, name), getattr(ms, name), rtol=0, atol=1e-12, err_msg=name)
        assert np.array_equal(getattr(back, name), getattr(ms, name)), name  # repr format is exact
    assert list(back.extra) == ["humidity", "goal_x"]
    for k in ms.extra:
        np.testing.assert_allclose(back.extra[k], ms.extra[k], rtol=0, atol=1e-12)
        assert np.array_equal(back.extra[k], ms.extra[k])


def test_round_trip_minimal_and_inferred_joints(tmp_path: Path) -> None:
    ms = _full_set()
    minimal = MeasurementSet(joint_names=ms.joint_names, q=ms.q, position_m=ms.position_m)
    f = tmp_path / "min.csv"
    write_measurements(minimal, f)
    assert f.read_text().splitlines()[0] == "j1,j2,j3,x,y,z"
    back = read_measurements(f)  # joints inferred from the unrecognised columns
    assert back.joint_names == JOINTS
    assert back.rotvec_rad is None and back.sigma_m is None and back.temperature_c is None
    assert back.payload_kg is None and back.time_s is None and back.extra == {}
    assert np.array_equal(back.q, ms.q) and np.array_equal(back.position_m, ms.position_m)


def test_isotropic_sigma_and_joint_order(tmp_path: Path) -> None:
    f = _write_csv(tmp_path / "s.csv", ["x", "j3", "y", "j1", "z", "j2", "sigma", "note"],
                   [[2, 0.3, 1, 0.1, 0.5, 0.2, 1e-5, 7], [2.1, 0.6, 1.1, 0.4, 0.6, 0.5, 2e-5, 8]])
    ms = read_measurements(f, joint_names=JOINTS)
    np.testing.assert_array_equal(ms.q, [[0.1, 0.2, 0.3], [0.4, 0.5, 0.6]])
    np.testing.assert_array_equal(ms.sigma_m, [[1e-5] * 3, [2e-5] * 3])
    np.testing.assert_array_equal(ms.extra["note"], [7, 8])


def test_station_column_round_trip_text_and_integer_labels(tmp_path: Path) -> None:
    ms = _full_set(6)
    ms = MeasurementSet(**{**ms.__dict__, "station": ["B", "B", " 1 ", "1", "C, left", "B"]})
    assert ms.station.tolist() == ["B", "B", "1", "1", "C, left", "B"]  # labels are text, stripped
    assert ms.station_labels() == ["B", "1", "C, left"]
    assert {k: v.tolist() for k, v in ms.station_rows().items()} == {"B": [0, 1, 5], "1": [2, 3], "C, left": [4]}
    f = tmp_path / "st.csv"
    write_measurements(ms, f)
    header = f.read_text().splitlines()[0].split(",")
    assert header[header.index("time") + 1] == "station"
    back = read_measurements(f, joint_names=JOINTS)
    assert back.station.tolist() == ms.station.tolist() and np.array_equal(back.q, ms.q)
    assert back.subset([4, 2]).station.tolist() == ["C, left", "1"]
    assert [len(t) for t, _ in back.kfold(2)] == [3, 3] and back.split(0.5)[0].station is not None
    # an integer column is read as text labels; an empty label is refused with its row
    header, rows = _good_rows()
    f2 = _write_csv(tmp_path / "int.csv", header + ["station"], [r + [k % 2 + 1] for k, r in enumerate(rows)])
    assert read_measurements(f2, joint_names=JOINTS).station.tolist() == ["1", "2", "1", "2"]
    f3 = _write_csv(tmp_path / "empty.csv", header + ["station"], [r + [lab] for r, lab in zip(rows, "AA A")])
    _raises(f3, "empty.csv", "column 'station', row 3", "empty station label", joint_names=JOINTS)


def test_concat_measurements_stations(tmp_path: Path) -> None:
    a, b = _full_set(4, seed=1), _full_set(3, seed=2)
    a.source, b.source = "/x/B.csv", "/y/C.csv"
    both = pio.concat_measurements([a, b])
    assert both.station.tolist() == ["B"] * 4 + ["C"] * 3 and len(both) == 7
    assert np.array_equal(both.q[4:], b.q) and both.source == "/x/B.csv+/y/C.csv"
    labelled = MeasurementSet(**{**b.__dict__, "station": ["s1", "s2", "s1"], "rotvec_rad": None})
    mixed = pio.concat_measurements([a, labelled])
    assert mixed.station_labels() == ["B", "s1", "s2"] and mixed.rotvec_rad is None  # kept only if all have it
    twin = MeasurementSet(**{**b.__dict__, "source": "/z/B.csv"})
    with pytest.raises(InputError, match="station 'B' like /x/B.csv"):
        pio.concat_measurements([a, twin])
    other = MeasurementSet(joint_names=["k1", "k2", "k3"], q=b.q, position_m=b.position_m, source="o.csv")
    with pytest.raises(InputError, match="o.csv: joint columns k1, k2, k3 differ"):
        pio.concat_measurements([a, other])


def test_stations_unit_guard_per_station(tmp_path: Path) -> None:
    """Two tracker placements far apart: each station's points are compact, the file is not 'in mm'."""
    rng = np.random.default_rng(0)
    q = rng.uniform(-1, 1, (40, 3))
    pos = np.vstack([rng.normal([30.0, 0, 0], 0.3, (20, 3)), rng.normal([-30.0, 0, 0], 0.3, (20, 3))])
    ms = MeasurementSet(JOINTS, q, pos, station=["near"] * 20 + ["far"] * 20)
    write_measurements(ms, tmp_path / "two.csv")
    assert read_measurements(tmp_path / "two.csv", joint_names=JOINTS, reach_m=1.0).station_labels() == ["near", "far"]
    write_measurements(MeasurementSet(JOINTS, q, pos), tmp_path / "one.csv")
    _raises(tmp_path / "one.csv", "looks like mm", joint_names=JOINTS, reach_m=1.0)


def test_positions_optional_for_predictions(tmp_path: Path) -> None:
    f = _write_csv(tmp_path / "q.csv", JOINTS, [[0.1, 0.2, 0.3], [0.4, 0.5, 0.6]])
    _raises(f, "missing position column(s) x, y, z")
    ms = read_measurements(f, joint_names=JOINTS, require_position=False)
    assert not ms.has_position and np.array_equal(ms.q, [[0.1, 0.2, 0.3], [0.4, 0.5, 0.6]])
    f2 = _write_csv(tmp_path / "xy.csv", JOINTS + ["x", "y"], [[0.1, 0.2, 0.3, 1, 2]])
    _raises(f2, "missing position column(s) z", require_position=False)  # partial x, y, z is still an error
    with pytest.raises(InputError, match="no measured positions"):
        write_measurements(ms, tmp_path / "out.csv")
    assert not (tmp_path / "out.csv").exists()


# --------------------------------------------------------------------------- #
# Bad input
# --------------------------------------------------------------------------- #
def test_missing_file(tmp_path: Path) -> None:
    _raises(tmp_path / "nope.csv", "nope.csv", "does not exist")


def test_error_is_package_error(tmp_path: Path) -> None:
    with pytest.raises(PinKpiOedError):
        read_measurements(tmp_path / "nope.csv")


def test_missing_joint_columns_named_and_found_listed(tmp_path: Path) -> None:
    header, rows = _good_rows()
    f = _write_csv(tmp_path / "m.csv", header, rows)
    msg = _raises(f, "m.csv", "missing joint column(s) j4, j5", "columns found: j1, j2, j3, x, y, z",
                  joint_names=JOINTS + ["j4", "j5"])
    assert "j1," not in msg.split("missing")[1].split(";")[0]


def test_missing_xyz(tmp_path: Path) -> None:
    f = _write_csv(tmp_path / "m.csv", JOINTS + ["x", "y"], [[0.1, 0.2, 0.3, 2.0, 1.0]])
    _raises(f, "m.csv", "missing position column(s) z", "columns found: j1, j2, j3, x, y", joint_names=JOINTS)


def test_non_numeric_cell(tmp_path: Path) -> None:
    header, rows = _good_rows()
    rows[2][1] = "abc"
    f = _write_csv(tmp_path / "m.csv", header, rows)
    _raises(f, "m.csv", "column 'j2'", "row 3 (line 4)", "'abc'", "not a number", joint_names=JOINTS)


def test_empty_cell(tmp_path: Path) -> None:
    header, rows = _good_rows()
    rows[1][4] = ""
    f = _write_csv(tmp_path / "m.csv", header, rows)
    _raises(f, "column 'y'", "row 2 (line 3)", "empty cell", joint_names=JOINTS)


@pytest.mark.parametrize("bad", ["nan", "inf", "-Infinity", "NaN"])
def test_non_finite_cell(tmp_path: Path, bad: str) -> None:
    header, rows = _good_rows()
    rows[3][5] = bad
    f = _write_csv(tmp_path / "m.csv", header, rows)
    _raises(f, "m.csv", "column 'z'", "row 4 (line 5)", repr(bad), "not finite", joint_names=JOINTS)


def test_duplicate_rows(tmp_path: Path) -> None:
    header, rows = _good_rows()
    rows.append(list(rows[0]))
    rows.append(list(rows[2]))
    rows.append(list(rows[0]))
    f = _write_csv(tmp_path / "m.csv", header, rows)
    msg = _raises(f, "m.csv", "duplicate", joint_names=JOINTS)
    assert "row 5 (line 6), row 7 (line 8) are duplicates of row 1 (line 2)" in msg
    assert "row 6 (line 7) is a duplicate of row 3 (line 4)" in msg


def test_same_joints_different_measurement_is_not_duplicate(tmp_path: Path) -> None:
    header, rows = _good_rows()
    rows.append(list(rows[0][:3]) + [2.0, 1.0, 0.5001])
    f = _write_csv(tmp_path / "m.csv", header, rows)
    assert len(read_measurements(f, joint_names=JOINTS)) == 5


def test_positions_in_mm(tmp_path: Path) -> None:
    header, rows = _good_rows()
    rows = [r[:3] + [1000.0 * v for v in r[3:]] for r in rows]
    f = _write_csv(tmp_path / "m.csv", header, rows)
    _raises(f, "m.csv", "columns x, y, z", "median distance", "looks like mm/degrees; convert to m/rad",
            joint_names=JOINTS)


def test_positions_in_mm_reach_rule(tmp_path: Path) -> None:
    # A small robot close to the tracker: |p| stays below 50 m even in mm, but the
    # points spread over more than 3 x reach (validation.units.POSITION_SPREAD_FACTOR).
    rng = np.random.default_rng(3)
    pts = rng.normal(0.0, 0.2, (30, 3)) * 1000.0 / 20.0  # spread of ~10 "m"
    rows = [[0.01 * i, 0.0, 0.0] + list(p) for i, p in enumerate(pts)]
    f = _write_csv(tmp_path / "m.csv", JOINTS + ["x", "y", "z"], rows)
    assert len(read_measurements(f, joint_names=JOINTS)) == 30  # passes without reach
    _raises(f, "3 x reach (0.3 m)", "looks like mm; convert to m/rad", joint_names=JOINTS, reach_m=0.3)
    _raises(f, "reach_m", joint_names=JOINTS, reach_m=-1.0)


def test_joints_in_degrees(tmp_path: Path) -> None:
    header, rows = _good_rows()
    rows[1][2] = 95.0
    f = _write_csv(tmp_path / "m.csv", header, rows)
    _raises(f, "m.csv", "column 'j3'", "row 2 (line 3)", "value 95.0 exceeds",
            "looks like mm/degrees; convert to m/rad",
            joint_names=JOINTS)


def test_rotvec_in_degrees(tmp_path: Path) -> None:
    header, rows = _good_rows()
    rows = [r + [0.1, 0.2, 0.3] for r in rows]
    rows[0][7] = -45.0
    f = _write_csv(tmp_path / "m.csv", header + ["rx", "ry", "rz"], rows)
    _raises(f, "column 'ry'", "row 1 (line 2)", "value -45.0 exceeds", "looks like mm/degrees", joint_names=JOINTS)


def test_sigma_in_mm_and_non_positive(tmp_path: Path) -> None:
    header, rows = _good_rows()
    f = _write_csv(tmp_path / "m.csv", header + ["sigma"], [r + [0.5] for r in rows])
    _raises(f, "column(s) sigma", "looks like mm/degrees", joint_names=JOINTS)
    rows2 = [r + [1e-5] for r in rows]
    rows2[2][6] = 0.0
    f2 = _write_csv(tmp_path / "m2.csv", header + ["sigma"], rows2)
    _raises(f2, "column 'sigma'", "row 3 (line 4)", "standard deviation 0.0 m must be > 0", joint_names=JOINTS)


def test_header_problems(tmp_path: Path) -> None:
    header, rows = _good_rows()
    f = _write_csv(tmp_path / "a.csv", header + ["rx", "ry"], [r + [0, 0] for r in rows])
    _raises(f, "rx, ry, rz", "found only rx, ry", joint_names=JOINTS)
    f = _write_csv(tmp_path / "b.csv", header + ["sigma", "sigma_x", "sigma_y", "sigma_z"],
                   [r + [1e-5] * 4 for r in rows])
    _raises(f, "either 'sigma' or", joint_names=JOINTS)
    f = _write_csv(tmp_path / "c.csv", header + ["x"], [r + [1] for r in rows])
    _raises(f, "column 'x' appears twice")
    f = tmp_path / "d.csv"
    f.write_text("j1;j2;x;y;z\n0,1;0,2;1;2;3\n")
    _raises(f, "';'-separated")
    f = tmp_path / "e.csv"
    f.write_text("\n\n")
    _raises(f, "empty file")
    f = _write_csv(tmp_path / "f.csv", header, [])
    _raises(f, "no measurement rows")


def test_wrong_number_of_cells(tmp_path: Path) -> None:
    header, rows = _good_rows()
    rows[1] = rows[1][:-1]
    f = _write_csv(tmp_path / "m.csv", header, rows)
    _raises(f, "row 2 (line 3) has 5 cells, the header has 6", joint_names=JOINTS)


def test_blank_lines_are_skipped_and_line_numbers_kept(tmp_path: Path) -> None:
    f = tmp_path / "m.csv"
    f.write_text("j1,j2,j3,x,y,z\n\n0.1,0.2,0.3,2,1,0.5\n\n0.1,0.2,0.3,2,1,zz\n")
    _raises(f, "column 'z'", "row 2 (line 5)", "'zz'", joint_names=JOINTS)


def test_measurement_set_shape_checks() -> None:
    with pytest.raises(InputError, match="position_m"):
        MeasurementSet(joint_names=JOINTS, q=np.zeros((4, 3)), position_m=np.zeros((3, 3)))
    with pytest.raises(InputError, match="'q'"):
        MeasurementSet(joint_names=JOINTS, q=np.zeros((4, 2)), position_m=np.zeros((4, 3)))
    with pytest.raises(InputError, match="sigma_m"):
        MeasurementSet(joint_names=JOINTS, q=np.zeros((4, 3)), position_m=np.zeros((4, 3)), sigma_m=np.zeros(4))


def test_write_rejects_reserved_names(tmp_path: Path) -> None:
    ms = _full_set(5)
    ms.extra["x"] = np.zeros(5)
    with pytest.raises(InputError, match="reserved"):
        write_measurements(ms, tmp_path / "m.csv")
    assert not (tmp_path / "m.csv").exists()


# --------------------------------------------------------------------------- #
# Atomic writes
# --------------------------------------------------------------------------- #
def _only_file(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir())


def test_atomic_write_keeps_old_file_if_serialisation_fails_midway(tmp_path: Path, monkeypatch) -> None:
    f = tmp_path / "meas.csv"
    write_measurements(_full_set(10, seed=1), f)
    before = f.read_bytes()
    calls = {"n": 0}
    real = measurement_writer._format_float

    def flaky(v: float) -> str:
        calls["n"] += 1
        if calls["n"] == 37:
            raise RuntimeError("boom in the middle")
        return real(v)

    monkeypatch.setattr(measurement_writer, "_format_float", flaky)
    with pytest.raises(RuntimeError, match="boom"):
        write_measurements(_full_set(10, seed=2), f)
    assert f.read_bytes() == before
    assert _only_file(tmp_path) == ["meas.csv"]


@pytest.mark.parametrize("where", ["fsync", "replace"])
def test_atomic_write_keeps_old_file_if_disk_step_fails(tmp_path: Path, monkeypatch, where: str) -> None:
    f = tmp_path / "out.json"
    atomic_write_json(f, {"a": 1})
    before = f.read_bytes()

    def fail(*args, **kwargs):
        raise OSError("disk on fire")

    monkeypatch.setattr(patomic.os, where, fail)
    with pytest.raises(OSError, match="disk on fire"):
        atomic_write_text(f, "x" * 100_000)
    monkeypatch.undo()
    assert f.read_bytes() == before
    assert _only_file(tmp_path) == ["out.json"]


def test_atomic_write_json_numpy_and_failure(tmp_path: Path) -> None:
    f = tmp_path / "r.json"
    obj = {"a": np.arange(3), "b": np.float32(1.5), "c": np.int64(7), "d": [np.eye(2)], "e": np.bool_(True),
           "p": tmp_path}
    atomic_write_json(f, obj)
    text = f.read_text()
    assert text.endswith("\n") and '\n  "a": [\n' in text
    assert json.loads(text) == {"a": [0, 1, 2], "b": 1.5, "c": 7, "d": [[[1.0, 0.0], [0.0, 1.0]]], "e": True,
                                "p": str(tmp_path)}
    before = f.read_bytes()
    with pytest.raises(TypeError):
        atomic_write_json(f, {"ok": 1, "bad": object()})
    assert f.read_bytes() == before
    assert _only_file(tmp_path) == ["r.json"]


def test_atomic_write_missing_directory_and_mode(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="does not exist"):
        atomic_write_text(tmp_path / "nodir" / "a.txt", "hi")
    f = tmp_path / "a.txt"
    f.write_text("old")
    os.chmod(f, 0o640)
    atomic_write_text(f, "new\r\nline")
    assert f.read_bytes() == b"new\r\nline"
    assert (f.stat().st_mode & 0o777) == 0o640


# --------------------------------------------------------------------------- #
# Splits
# --------------------------------------------------------------------------- #
def _rows_of(part: MeasurementSet, full: MeasurementSet) -> np.ndarray:
    # time_s is strictly increasing in _full_set, so it identifies the rows
    return np.searchsorted(full.time_s, part.time_s)


def test_split_disjoint_cover_reproducible() -> None:
    ms = _full_set(25)
    train, test = ms.split(0.7, seed=4)
    a, b = _rows_of(train, ms), _rows_of(test, ms)
    assert len(train) == round(0.7 * 25) and len(train) + len(test) == 25
    assert set(a).isdisjoint(b) and sorted(np.concatenate([a, b])) == list(range(25))
    assert np.all(np.diff(a) > 0) and np.all(np.diff(b) > 0)  # file order kept
    np.testing.assert_array_equal(train.q, ms.q[a])
    np.testing.assert_array_equal(test.extra["humidity"], ms.extra["humidity"][b])
    train2, test2 = ms.split(0.7, seed=4)
    assert np.array_equal(train2.q, train.q) and np.array_equal(test2.q, test.q)
    assert not np.array_equal(ms.split(0.7, seed=5)[0].q, train.q)
    for bad in (0.0, 1.0, -0.1, 0.01):
        with pytest.raises(InputError, match="split"):
            ms.split(bad, seed=0)


def test_kfold_disjoint_cover_reproducible() -> None:
    ms = _full_set(23)
    folds = ms.kfold(5, seed=9)
    assert len(folds) == 5
    tests = [_rows_of(te, ms) for _, te in folds]
    assert sorted(np.concatenate(tests)) == list(range(23))
    assert sorted(len(t) for t in tests) == [4, 4, 5, 5, 5]
    for (tr, _te), t in zip(folds, tests):
        tri = _rows_of(tr, ms)
        assert set(tri).isdisjoint(t) and len(tri) + len(t) == 23
    again = ms.kfold(5, seed=9)
    for (tr, te), (tr2, te2) in zip(folds, again):
        assert np.array_equal(te.q, te2.q) and np.array_equal(tr.position_m, tr2.position_m)
    for bad in (1, 24, 2.5, True):
        with pytest.raises(InputError, match="kfold"):
            ms.kfold(bad)


def test_subset_mask_and_errors() -> None:
    ms = _full_set(6)
    mask = np.array([True, False, True, False, False, True])
    sub = ms.subset(mask)
    np.testing.assert_array_equal(sub.q, ms.q[[0, 2, 5]])
    sub.q[0, 0] = 99.0
    assert ms.q[0, 0] != 99.0  # copies
    with pytest.raises(InputError, match="out of range"):
        ms.subset([0, 6])
    with pytest.raises(InputError, match="mask"):
        ms.subset(mask[:-1])


# --------------------------------------------------------------------------- #
# IPA UR10 data
# --------------------------------------------------------------------------- #
@needs_ipa
def test_ipa_series_c() -> None:
    from pin_kpi_oed.data.ipa import UR10_JOINT_NAMES, import_ipa

    ms = import_ipa(IPA_DIR / "Series_C" / "measurements_random_poses.csv")
    assert len(ms) == 2773
    assert ms.joint_names == list(UR10_JOINT_NAMES)
    d = np.linalg.norm(ms.position_m, axis=1)
    assert d.min() > 1.0 and d.max() < 6.0
    assert np.all(np.abs(ms.q) <= 2 * np.pi)
    assert ms.temperature_c.min() >= 21.6 and ms.temperature_c.max() <= 22.2
    assert ms.time_s is None and ms.payload_kg is None
    assert ms.sigma_m is not None and 0 < ms.sigma_m.min() and ms.sigma_m.max() < 1e-4  # mm -> m
    assert ms.rotvec_rad is not None and np.all(np.linalg.norm(ms.rotvec_rad, axis=1) <= np.pi + 1e-9)
    # first data row: 383,97123 mm ; std 0,041565 mm ; 21,68000031 °C
    np.testing.assert_allclose(ms.position_m[0], [0.38397123, -3.2407562, 0.20172621], rtol=0, atol=1e-12)
    np.testing.assert_allclose(ms.sigma_m[0], [4.1565e-5, 2.2023e-5, 5.5848e-6], rtol=0, atol=1e-15)
    np.testing.assert_allclose(ms.q[0], [-3.14159, -1.5708, 0, -1.5708, 0, 0])
    np.testing.assert_allclose(
        Rotation.from_rotvec(ms.rotvec_rad[0]).as_matrix(),
        Rotation.from_euler("XYZ", [-90.179563, -20.112975, -90.157388], degrees=True).as_matrix(), atol=1e-12)
    assert {"goal_x", "goal_yaw", "sigma_euler_rx"} <= set(ms.extra)


@needs_ipa
@pytest.mark.xdist_group(IPA_GROUP)
def test_ipa_series_a_time() -> None:
    ms = ipa_series(IPA_DIR / "Series_A")  # imported once with the other tests of Series A (tests/_cache_g.py)
    assert len(ms) == 11911 and ms.sigma_m is None
    t = ms.time_s
    assert t is not None and t[0] == 0.0 and t[1] == 20.0  # 16:39:04 -> 16:39:24
    # Seconds, not raw stamps. The file is not in chronological order: the rows
    # span ~100.8 h over 4 days (last minus first row is 12.37 h), and 9 steps go back.
    assert t.min() == 0.0 and abs(t.max() / 3600 - 100.81) < 0.01
    assert abs((t[-1] - t[0]) / 3600 - 12.37) < 0.01
    assert int(np.sum(np.diff(t) <= 0)) == 9
    assert 1.0 < np.median(np.diff(t)) < 60.0
    assert ms.temperature_c.min() >= 22.9 and ms.temperature_c.max() <= 23.7


@needs_ipa
@pytest.mark.parametrize("series", [pytest.param("Series_A", marks=pytest.mark.xdist_group(IPA_GROUP)), "Series_B",
                                    "Series_C", "Series_D"])
def test_ipa_euler_convention(series: str) -> None:
    """The angle between two measured orientations must match the nominal UR10 FK
    (it does not depend on the unknown tracker or probe frames)."""
    ms = ipa_series(IPA_DIR / series)
    alpha = [math.pi / 2, 0, 0, math.pi / 2, -math.pi / 2, 0]  # UR10 CB3 nominal DH
    R = Rotation.identity(len(ms))
    for k in range(6):
        R = R * Rotation.from_euler("z", ms.q[:, k, None]) * Rotation.from_euler("x", alpha[k])
    rng = np.random.default_rng(0)
    i, j = rng.integers(0, len(ms), (2, 2000))
    ang_fk = (R[i] * R[j].inv()).magnitude()
    meas = Rotation.from_rotvec(ms.rotvec_rad)
    mismatch = np.degrees(np.median(np.abs((meas[i] * meas[j].inv()).magnitude() - ang_fk)))
    assert mismatch < 0.1
    # The extrinsic reading of the same angles ("xyz") is clearly worse.
    eul = meas.as_euler("XYZ")
    wrong = Rotation.from_euler("xyz", eul)
    mismatch_wrong = np.degrees(np.median(np.abs((wrong[i] * wrong[j].inv()).magnitude() - ang_fk)))
    assert mismatch_wrong > 3 * mismatch


@needs_ipa
def test_ipa_round_trip_through_csv(tmp_path: Path) -> None:
    from pin_kpi_oed.data.ipa import UR10_JOINT_NAMES, import_ipa

    ms = import_ipa(IPA_DIR / "Series_D" / "measurements_iso_cubes.csv")
    f = tmp_path / "d.csv"
    write_measurements(ms, f)
    back = read_measurements(f, joint_names=list(UR10_JOINT_NAMES), reach_m=1.3)
    assert len(back) == 632
    for name in ("q", "position_m", "rotvec_rad", "sigma_m", "temperature_c"):
        assert np.array_equal(getattr(back, name), getattr(ms, name)), name
    assert set(back.extra) == set(ms.extra)


@needs_ipa
def test_ipa_flange_transform() -> None:
    from pin_kpi_oed.data.ipa import read_ipa_flange_transform

    T = read_ipa_flange_transform(IPA_DIR / "Series_C")
    assert T.shape == (4, 4)
    np.testing.assert_array_equal(T[3], [0, 0, 0, 1])
    np.testing.assert_allclose(T[:3, 3], [0.0, 0.08679961e-3, -0.10899996544], atol=1e-12)
    np.testing.assert_allclose(T[:3, :3].T @ T[:3, :3], np.eye(3), atol=1e-5)
    Tc = read_ipa_flange_transform(IPA_DIR / "Series_C", "Trafo_TM_F_init_calib.txt")
    np.testing.assert_array_equal(Tc[:3, :3], [[0, 0, 1], [-1, 0, 0], [0, -1, 0]])


def test_ipa_bad_inputs(tmp_path: Path) -> None:
    from pin_kpi_oed.data.ipa import UR10_JOINT_NAMES, import_ipa, read_ipa_flange_transform

    header = ["Timestamp", *UR10_JOINT_NAMES, "measurement_temperature", "measurement_x", "measurement_y",
              "measurement_z"]
    f = tmp_path / "measurements_x.csv"
    f.write_text(";".join(header) + "\n2,02011E+13;0;0;0;0;0;0;21,5;1000;2000;abc\n")
    with pytest.raises(InputError, match=r"column 'measurement_z', row 1 \(line 2\): 'abc'"):
        import_ipa(f)
    f.write_text(";".join(header[:-1]) + "\n2,02011E+13;0;0;0;0;0;0;21,5;1000;2000\n")
    with pytest.raises(InputError, match="missing column.*measurement_z"):
        import_ipa(f)
    with pytest.raises(InputError, match="does not exist"):
        import_ipa(tmp_path / "none.csv")
    (tmp_path / "Trafo_TM_F_init.txt").write_text("1 0 0 0\n0 1 0 0\n0 0 1 0\n")
    with pytest.raises(InputError, match="4 lines"):
        read_ipa_flange_transform(tmp_path)
    (tmp_path / "Trafo_TM_F_init.txt").write_text("1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1")
    np.testing.assert_array_equal(read_ipa_flange_transform(tmp_path), np.eye(4))


def test_ipa_cells_and_timestamps_read_as_the_cell_parser_and_strptime_read_them(tmp_path: Path) -> None:
    """The decimal-comma cells (blanks, NUL padding, exponents) give float() of the cleaned text; the timestamps give
    strptime's seconds, and a stamp strptime refuses is refused with its words (row and line named)."""
    from pin_kpi_oed.data.ipa import UR10_JOINT_NAMES, import_ipa

    header = ["Timestamp", *UR10_JOINT_NAMES, "measurement_x", "measurement_y", "measurement_z"]
    cells = ["0", " 1,5 ", "-0,25\x00", "2,78E-05", "1e-3", "3", " 1000,125", "2000", "-3,5E+02 "]
    f = tmp_path / "measurements_t.csv"
    f.write_text(";".join(header) + "\n" + "\n".join(f"{t};" + ";".join(cells) for t in
                                                     ("20200229235959", "20200301000004")) + "\n")
    ms = import_ipa(f)
    want = [float(c.strip().strip("\x00").strip().replace(",", ".")) for c in cells]
    assert ms.q.tolist() == [want[:6]] * 2 and ms.position_m.tolist() == [[v * 1e-3 for v in want[6:]]] * 2
    assert ms.time_s.tolist() == [0.0, 5.0]
    for stamp, words in (("20200230000000", "day is out of range for month"),
                         ("20201301120000", "unconverted data remains: 0")):
        f.write_text(";".join(header) + "\n20200229235959;" + ";".join(cells) + f"\n{stamp};" + ";".join(cells) + "\n")
        with pytest.raises(InputError, match=rf"row 2 \(line 3\): '{stamp}' is not a valid YYYYMMDDhhmmss time "
                                             rf"\({words}\)"):
            import_ipa(f)


def _jsonable_walk(obj):
    """Reference: the entry-by-entry JSON clean-up (every array through its ``tolist()`` walked value by value)."""
    import os

    if isinstance(obj, dict):
        return {str(k): _jsonable_walk(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, set, frozenset)):
        return [_jsonable_walk(v) for v in (sorted(obj) if isinstance(obj, (set, frozenset)) else obj)]
    if isinstance(obj, np.ndarray):
        return _jsonable_walk(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        v = float(obj)
        return v if np.isfinite(v) else None
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    return obj


def test_to_jsonable_gives_the_entry_by_entry_result():
    """Arrays of booleans, integers and finite floats go to lists at once: the result equals the entry-by-entry walk's
    value for value and type for type (NaN / inf as None, float32, 0-d and empty arrays, NumPy scalars, sets, paths),
    on a certificate the package wrote and on a document made of every kind of value."""
    import json

    from pin_kpi_oed.data.atomic import to_jsonable

    def typed(x):  # the value with every entry's type, so that 1 == 1.0 == True do not pass for one another
        if isinstance(x, dict):
            return {k: typed(v) for k, v in x.items()}
        if isinstance(x, list):
            return [typed(v) for v in x]
        return (type(x).__name__, x)

    rng = np.random.default_rng(0)
    a = rng.normal(size=(4, 3))
    a[1, 2], a[3, 0] = np.nan, -np.inf
    doc = {"f": rng.normal(size=(5, 4)), "f32": rng.normal(size=3).astype(np.float32), "nan": a,
           "i": np.arange(6, dtype=np.int32).reshape(2, 3), "u": np.array([2**63], dtype=np.uint64),
           "b": np.array([True, False]), "0d": np.array(2.5), "0d_nan": np.array(np.nan), "empty": np.zeros((0, 3)),
           "scalars": [np.float64(1.5), np.float32(np.inf), np.int64(3), np.bool_(True), 1, 2.0, True, None, "x"],
           "set": {3, 1, 2}, "path": Path("a/b.json"), 7: (np.ones(2), [np.zeros(1)]), "c": np.array([1 + 2j]),
           "s": np.array(["a", "b"])}
    assert typed(to_jsonable(doc)) == typed(_jsonable_walk(doc))
    cert = json.loads((Path(__file__).resolve().parents[1] / "docs" / "certificates" / "ur5_cell.json").read_text())
    with_arrays = {k: np.asarray(v) if isinstance(v, list) and v and all(isinstance(x, (int, float)) for x in v)
                   else v for k, v in cert.items()}
    assert typed(to_jsonable(cert)) == typed(_jsonable_walk(cert)) == typed(cert)
    assert typed(to_jsonable(with_arrays)) == typed(_jsonable_walk(with_arrays))


def test_an_ipa_file_read_again_gives_a_fresh_copy_of_the_same_set(tmp_path: Path) -> None:
    """``import_ipa`` converts a file once per content: a second read gives a set equal to a fresh conversion (field
    for field, of a copy of the file under another name: not from the cache), in arrays of its own; the same name
    with other bytes of the same size, written within the same clock tick, is converted afresh."""
    import dataclasses

    from pin_kpi_oed.data.ipa import UR10_JOINT_NAMES, import_ipa

    header = ["Timestamp", *UR10_JOINT_NAMES, "measurement_x", "measurement_y", "measurement_z"]
    rows = ["20200229235959;0,1;0,2;0,3;0,4;0,5;0,6;1000,5;2000;-3,5E+02",
            "20200301000004;1,1;1,2;1,3;1,4;1,5;1,6;1100,5;2100;-4,5E+02"]
    f, other = tmp_path / "measurements_a.csv", tmp_path / "measurements_b.csv"
    f.write_text(";".join(header) + "\n" + "\n".join(rows) + "\n")
    other.write_bytes(f.read_bytes())

    def fields(ms) -> dict:
        return {k: (v.tolist() if isinstance(v, np.ndarray) else
                    {n: a.tolist() for n, a in v.items()} if isinstance(v, dict) else v)
                for k, v in dataclasses.asdict(ms).items() if k != "source"}

    first, again, fresh = import_ipa(f), import_ipa(f), import_ipa(other)
    assert fields(first) == fields(again) == fields(fresh) and again.source == first.source == str(f)
    assert not np.shares_memory(first.q, again.q) and not np.shares_memory(first.time_s, again.time_s)
    first.q[0, 0] = 99.0
    assert import_ipa(f).q[0, 0] == 0.1
    f.write_text(f.read_text().replace("0,1;0,2", "0,7;0,8"))  # the same size: only the bytes tell
    assert import_ipa(f).q[0, :2].tolist() == [0.7, 0.8]
