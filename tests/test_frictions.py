"""Frictions of an industrial arm's URDF as it ships and of the JSON every command writes: a wrist of a few turns
read in its own range (with and without declared units), and no bare NaN in any JSON output."""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import numpy as np

from pin_kpi_oed.cli.app import main
from tests.hostile.frictions import wrist_400_urdf


def _run(*argv) -> tuple[int, str, str]:
    o, e = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(o), contextlib.redirect_stderr(e):
        rc = main([str(a) for a in argv])
    return rc, o.getvalue(), e.getvalue()


def test_a_wrist_of_a_few_turns_is_read_in_its_own_range(tmp_path: Path):
    """A ±400° wrist (6.98 rad, the URDF's own limit): rows beyond 2π are data, not degrees, declared or not."""
    urdf = wrist_400_urdf(tmp_path / "kr400.urdf")
    data = tmp_path / "d.csv"
    assert _run("simulate", "--robot", urdf, "--n", "40", "--seed", "1", "--out", data)[0] == 0
    rows = [r.split(",") for r in data.read_text().splitlines() if not r.startswith("#")]
    q6 = np.array([float(r[5]) for r in rows[1:]])
    assert np.any(np.abs(q6) > 2 * np.pi + 0.1)  # the case the guard used to refuse
    for units in ([], ["--units", "m,rad"]):
        rc, out, err = _run("identify", "--robot", urdf, "--data", data, "--discrepancy", "none", "--quiet", *units)
        assert rc == 0, err
    prog = tmp_path / "prog.csv"
    beyond = [r for r in rows[1:] if abs(float(r[5])) > 2 * np.pi + 0.1]
    prog.write_text(",".join(rows[0][:6]) + "\n" + "\n".join(",".join(r[:6]) for r in beyond) + "\n")
    model = tmp_path / "m.json"
    assert _run("identify", "--robot", urdf, "--data", data, "--discrepancy", "none", "--quiet", "--model-out",
                model)[0] == 0
    rc, out, err = _run("compensate", "--model", model, "--program", prog, "--tcp", "0,0,0.1", "--out",
                        tmp_path / "c.csv", "--quiet")
    assert rc == 0, err


def _strict(text: str):
    """JSON as the standard has it: a bare NaN / Infinity is an error (Python's reader accepts them by default)."""
    import json

    def refuse(name: str):
        raise ValueError(f"bare {name} in JSON")

    return json.loads(text, parse_constant=refuse)


def _nan_free(obj) -> bool:
    if isinstance(obj, dict):
        return all(_nan_free(v) for v in obj.values())
    if isinstance(obj, list):
        return all(_nan_free(v) for v in obj)
    return not (isinstance(obj, float) and not np.isfinite(obj))


def test_json_outputs_are_strict_json(tmp_path: Path):
    """compensate --json with an unreachable target and report --json parse as strict JSON (no bare NaN)."""
    tr, te, model = tmp_path / "tr.csv", tmp_path / "te.csv", tmp_path / "m.json"
    assert _run("simulate", "--robot", "kr15", "--n", "60", "--n-test", "20", "--seed", "3", "--out", tr,
                "--test-out", te)[0] == 0
    assert _run("identify", "--robot", "kr15", "--data", tr, "--discrepancy", "none", "--quiet", "--model-out",
                model)[0] == 0
    rows = [r.split(",") for r in te.read_text().splitlines() if not r.startswith("#")]
    ix = [rows[0].index(c) for c in "xyz"]
    pts = [[r[i] for i in ix] for r in rows[1:4]] + [["9.0", "9.0", "9.0"]]  # the last one out of reach
    targets = tmp_path / "t.csv"
    targets.write_text("x,y,z\n" + "\n".join(",".join(p) for p in pts) + "\n")
    rc, out, err = _run("compensate", "--model", model, "--targets", targets, "--tcp", "0.03,0.02,0.08", "--out",
                        tmp_path / "c.csv", "--json", tmp_path / "c.json", "--quiet")
    assert rc == 0, err
    text = (tmp_path / "c.json").read_text()
    doc = _strict(text)
    assert "unreachable" in doc["target_status"] and _nan_free(doc)
    rc, out, err = _run("report", "--model", model, "--train", tr, "--validate", te, "--json", tmp_path / "r.json",
                        "--quiet")
    assert rc == 0, err
    assert _nan_free(_strict((tmp_path / "r.json").read_text()))
