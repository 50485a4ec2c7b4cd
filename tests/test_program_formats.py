"""The program format registry: every registered format writes and reads back; formats from outside the package."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pin_kpi_oed.cli.app import main
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.robot import load_robot
from pin_kpi_oed.program.export import FORMATS, parse_program, program_files, write_program
from pin_kpi_oed.program.formats.base import ProgramFormat, ProgramInfo
from pin_kpi_oed.program.formats.registry import PROGRAM_FORMATS, get_format, register_format

KINDS = ["home", "measure", "measure", "via", "measure", "measure", "via", "measure", "home"]
POSES = [-1, 4, 0, -1, 2, 3, -1, 1, -1]


def _info(robot, name: str = "prog") -> ProgramInfo:
    return ProgramInfo(cell="test_cell", design="d.json (kpi)", robot=robot.name, joint_names=list(robot.joint_names),
                       revolute=np.asarray(robot.is_revolute, bool), cycle_time_s=12.5, date="2026-01-01T00:00:00Z",
                       name=name)


class TinyFormat(ProgramFormat):
    """A format of the test: ``kind pose q_1 .. q_n`` per line (rad / m)."""

    name = "tiny"
    suffix = ".tiny"
    description = "test format"

    def write(self, Q, kinds, poses, info):
        return {".tiny": "".join(f"{k} {p} " + " ".join(repr(float(x)) for x in q) + "\n"
                                 for q, k, p in zip(Q, kinds, poses))}

    def parse(self, texts, revolute):
        rows = [r.split() for r in texts[".tiny"].splitlines()]
        return np.array([[float(x) for x in r[2:]] for r in rows]), [int(r[1]) for r in rows if r[0] == "measure"]


class WriteOnlyFormat(ProgramFormat):
    name = "writeonly"
    suffix = ".wo"

    def write(self, Q, kinds, poses, info):
        return {".wo": f"{len(Q)} targets\n"}


@pytest.fixture
def tiny():
    fmts = [register_format(TinyFormat()), register_format(WriteOnlyFormat())]
    yield fmts[0]
    for f in fmts:
        PROGRAM_FORMATS.pop(f.name)


def test_the_registry_holds_the_four_controller_formats_one_class_each():
    assert list(FORMATS) == ["csv", "urscript", "krl", "rapid"]
    assert {f.suffix for f in PROGRAM_FORMATS.values()} == {".csv", ".script", ".src", ".mod"}
    assert all(isinstance(f, ProgramFormat) and f.can_read for f in PROGRAM_FORMATS.values())
    assert len({type(f).__module__ for f in PROGRAM_FORMATS.values()}) == 4


@pytest.mark.parametrize("robot_name", ["kr15", "kr15_track"])
def test_every_registered_format_writes_files_and_reads_them_back(robot_name, tmp_path, tiny):
    rb = load_robot(robot_name)
    Q = rb.random_q(np.random.default_rng(3), len(KINDS))
    checked = []
    for name, fmt in PROGRAM_FORMATS.items():
        if name == "urscript" and robot_name == "kr15_track":
            with pytest.raises(InputError, match="6 revolute joints and no prismatic"):
                write_program(name, Q, KINDS, POSES, _info(rb))
            continue
        texts = write_program(name, Q, KINDS, POSES, _info(rb))
        files = program_files(name, str(tmp_path / f"p_{name}"))
        assert sorted(texts) == sorted(files)  # one text per file the format says it writes
        for suffix, path in files.items():
            path.write_text(texts[suffix])
        if not fmt.can_read:
            with pytest.raises(InputError, match="no parser"):
                parse_program(name, texts, rb.is_revolute)
            continue
        for back, measured in (parse_program(name, texts, rb.is_revolute),
                               fmt.read(tmp_path / f"p_{name}", rb.is_revolute)):
            assert back.shape == Q.shape
            np.testing.assert_allclose(back, Q, atol=1e-6, rtol=0)
            assert measured == [4, 0, 2, 3, 1]
        checked.append(name)
    assert set(checked) == {"csv", "krl", "rapid", "tiny"} | ({"urscript"} if robot_name == "kr15" else set())


def test_krl_writes_the_src_and_the_dat_beside_it(tmp_path):
    files = program_files("krl", str(tmp_path / "a" / "prog"))
    assert files == {".src": tmp_path / "a" / "prog.src", ".dat": tmp_path / "a" / "prog.dat"}
    assert program_files("krl", "x.SRC") == {".src": Path("x.SRC"), ".dat": Path("x.dat")}
    assert program_files("csv", "p.txt") == {".csv": Path("p.txt")}
    (tmp_path / "only.src").write_text("DEF only( )\nEND\n")
    with pytest.raises(InputError, match=r"only\.dat: cannot read the krl program"):
        get_format("krl").read(tmp_path / "only.src", np.ones(6, bool))


def test_unknown_format_and_bad_registration_are_named():
    with pytest.raises(InputError, match=r"program_format: unknown format 'fanuc' \(known: csv, urscript, krl, rapid"):
        write_program("fanuc", np.zeros((1, 6)), ["home"], [-1], _info(load_robot("kr15")))
    from pin_kpi_oed.cli.flags import in_flags  # the command line names its option

    assert in_flags("program_format: unknown format 'fanuc'") == "--format: unknown format 'fanuc'"
    with pytest.raises(InputError, match="already registered"):
        register_format(type(PROGRAM_FORMATS["csv"])())
    with pytest.raises(InputError, match="must be a named ProgramFormat"):
        register_format(object())  # type: ignore[arg-type]
    assert list(FORMATS) == ["csv", "urscript", "krl", "rapid"]


def test_a_format_registered_from_outside_is_known_to_the_cli(tiny, tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        main(["export", "--help"])
    assert e.value.code == 0
    assert "tiny" in capsys.readouterr().out
    design = tmp_path / "d.json"
    assert main(["design", "--cell", "kr15", "--criteria", "random", "--measurements", "9", "--seed", "2",
                 "--quiet", "--json", str(design)]) == 0
    out, js = tmp_path / "prog.tiny", tmp_path / "prog.json"
    assert main(["export", str(design), "--format", "tiny", "--out", str(out), "--json", str(js), "--quiet"]) == 0
    import json

    doc = json.loads(js.read_text())
    Q, measured = tiny.read(out, np.ones(6, bool))
    np.testing.assert_allclose(Q, [w["q"] for w in doc["waypoints"]], atol=1e-12)
    assert sorted(measured) == list(range(9))
