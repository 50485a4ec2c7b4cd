"""The README runs as written: its Python example and its own-robot worked example (UR5, not a shipped cell)."""

from __future__ import annotations

import json
import re
import shlex
from pathlib import Path

import numpy as np
import pytest

from pin_kpi_oed.cli import main

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()


def _block(after: str, lang: str) -> str:
    """The first fenced ``lang`` block after the line that starts with ``after``."""
    start = README.index(after)
    m = re.compile(rf"^```{lang}\n(.*?)^```", re.S | re.M).search(README, start)
    assert m, f"no ```{lang} block after {after!r} in README.md"
    return m.group(1)


def _commands(block: str) -> tuple[dict[str, str], list[list[str]]]:
    """(shell variables, pin-kpi-oed argument lists) of a bash block: continuations joined, comments dropped."""
    text = block.replace("\\\n", " ")
    env: dict[str, str] = {}
    cmds: list[list[str]] = []
    for line in text.splitlines():
        words = shlex.split(line, comments=True)
        if not words:
            continue
        if len(words) == 1 and re.fullmatch(r"[A-Z_]+=\S+", words[0]):
            k, v = words[0].split("=", 1)
            env[k] = v
            continue
        assert words[0] == "pin-kpi-oed", f"README worked example: unexpected line {line!r}"
        cmds.append([re.sub(r"\$(\w+)", lambda m: env[m.group(1)], w) for w in words[1:]])
    return env, cmds


def test_readme_python_example_runs(tmp_path, monkeypatch, capsys) -> None:
    code = _block("## Python API", "python")
    assert 10 <= len([c for c in code.splitlines() if c.strip()]) <= 20, "the README's example should stay short"
    monkeypatch.chdir(tmp_path)
    exec(compile(code, "README.md", "exec"), {"__name__": "readme_example"})
    out = capsys.readouterr().out
    m = re.search(r"held-out error: mean ([\d.]+) um, max ([\d.]+) um", out)
    assert m, out
    # the shipped cell's tracker noise is 1 um per axis: a calibration from 30 designed poses predicts held-out
    # points to a few um; the nominal robot would be off by about a millimetre
    assert 0.5 < float(m.group(1)) < 10.0 and float(m.group(2)) < 30.0, out
    from pin_kpi_oed import load_model_file

    cm = load_model_file(tmp_path / "model.json")
    assert cm.robot.name.startswith("kr15")


def test_readme_own_robot_recipe_runs(tmp_path, monkeypatch, capsys) -> None:
    env, cmds = _commands(_block("**Worked example: a UR5**", "bash"))
    assert env == {"EX": "examples"}
    steps = [c[0] for c in cmds]
    assert steps == ["design", "export", "simulate", "identify", "diagnose", "identify", "compensate"], steps
    for c in cmds:  # the example's files are read from the repository's examples folder
        c[:] = [str(ROOT / w) if w.startswith("examples/") else w for w in c]
    monkeypatch.chdir(tmp_path)
    held = {}
    for c in cmds:
        assert main(c) == 0, f"pin-kpi-oed {' '.join(c)} failed:\n{capsys.readouterr().err}"
        out = capsys.readouterr().out
        if c[0] == "identify":
            means = re.findall(r"^(?:before|after)\b.*?mean ([\d.]+) mm", out, re.M)
            held[c[c.index("--model-out") + 1]] = [float(x) for x in means]

    design = json.loads((tmp_path / "ur5_design.json").read_text())
    tr = {d["criterion"]: d["trace_cs_m2"] for d in design["designs"]}
    assert tr["kpi"] < 0.5 * tr["random"]  # the KPI design is far more precise at the working configuration
    assert all(d["status"] != "max_iter" for d in design["designs"])
    script = (tmp_path / "ur5_kpi.script").read_text()
    assert script.count("MEASURE") >= 40 and "movej(" in script
    meas = (tmp_path / "ur5_meas.csv").read_text().splitlines()
    assert '# tool_frame: "tool0"' in meas and len([ln for ln in meas if not ln.startswith("#")]) == 1 + 40

    before, geo = held["ur5_geo.json"]            # held-out mean: nominal robot, geometric calibration
    _, with_effect = held["ur5_model.json"]       # ... with the joint compliance identified too
    assert geo < 0.2 * before and with_effect < 0.6 * geo
    report = json.loads((tmp_path / "ur5_diagnosis.json").read_text())
    assert report["gap_detected"] and report["dominant_effect"] == "joint_compliance"
    model = json.loads((tmp_path / "ur5_model.json").read_text())
    assert [e["name"] for e in model["effects"]] == ["joint_compliance"]
    assert (tmp_path / "ur5_calibrated.urdf").is_file()

    rows = (tmp_path / "ur5_joints.csv").read_text().splitlines()
    head = rows[0].split(",")
    assert len(rows) == 1 + 3  # reached; a target outside the 40 poses' joint-space coverage is flagged, never "ok",
    # and so is one whose TCP sigma is mostly the parameters no reflector measurement determines (tcp_unmeasured)
    from pin_kpi_oed import load_model_file
    from pin_kpi_oed.calibrated.tcp_sigma import tcp_sigma

    cm = load_model_file(tmp_path / "ur5_model.json")
    Q = np.array([[float(r.split(",")[head.index(j)]) for j in cm.robot.joint_names] for r in rows[1:]])
    at = tcp_sigma(cm, Q, frame="base")
    mostly_held = at.held_sigma_m ** 2 > 0.5 * at.sigma_m ** 2
    assert [r.split(",")[head.index("status")] for r in rows[1:]] == [
        "extrapolated" if r.split(",")[head.index("extrapolation")] == "1" else ("tcp_unmeasured" if h else "ok")
        for r, h in zip(rows[1:], mostly_held)]
    corr = np.array([float(r.split(",")[head.index("correction_m")]) for r in rows[1:]])
    assert np.all((corr > 1e-4) & (corr < 1e-2))  # the calibrated model moves the joints by a millimetre or so


def _table(text: str) -> dict[str, list[str]]:
    """criterion -> cells of the design table rows in ``text``."""
    return {ln.split()[0]: ln.split() for ln in text.splitlines() if re.match(r"(random|param|kpi) +\d", ln)}


def test_readme_demo_output_is_what_the_demo_prints(capsys) -> None:
    """The README shows the demo's actual table: tr(C_s), TCP sigma and efficiency within 1 % of a fresh run."""
    shown = _table(_block("## The demo", ""))
    assert set(shown) == {"random", "param", "kpi"}
    assert main(["demo"]) == 0
    printed = _table(capsys.readouterr().out)
    for crit, row in shown.items():
        for col in (1, 2, -2):  # tr(C_s) mm^2, TCP sigma um, effic. %
            assert float(printed[crit][col]) == pytest.approx(float(row[col]), rel=0.01), (crit, col)
        assert printed[crit][-1] == row[-1] == "ok"


def test_readme_names_every_shipped_robot() -> None:
    from pin_kpi_oed.model.robot import ROBOT_NAMES

    missing = [n for n in ROBOT_NAMES if f"`{n}`" not in README]
    assert not missing, f"README.md does not list the shipped robot names {missing}"
