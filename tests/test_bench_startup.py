"""The start-up benchmark reads the README's worked example as the README states it, and reports honestly."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks.bench_startup import (cell_text, example_files, paired_wins, readme_commands, readme_table,
                                      sign_test_p, step_labels)

ROOT = Path(__file__).resolve().parents[1]


def test_the_readme_example_is_read_command_by_command() -> None:
    cmds = readme_commands()
    assert step_labels(cmds) == ["design", "export", "simulate", "identify", "diagnose", "identify --effects",
                                 "compensate"]
    files = example_files()
    assert files and all((ROOT / "examples" / f).is_file() for f in files)
    words = [w for c in cmds for w in c]
    assert not any("$" in w or "\\" in w for w in words), words  # variables replaced, continuations joined
    assert all(f in words for f in files)  # the examples' files are read from the run's folder


def test_a_failed_command_is_named_not_timed() -> None:
    ok = {"cpu_s": 1.0, "wall_s": 2.0, "load": 1.0, "rc": 0, "error": ""}
    bad = {**ok, "rc": 2, "error": "pin-kpi-oed simulate: error: unrecognized arguments: --test-out x.csv"}
    assert cell_text([ok, ok]) == "1.00 / 2.00"
    assert "unrecognized arguments: --test-out" in cell_text([bad, ok]) and "1 of 2 runs" in cell_text([bad, ok])
    assert paired_wins([bad, {**ok, "cpu_s": 3.0}], [ok, ok]) == (1, 1)
    table = readme_table({"before": [[bad]], "after": [[ok]]}, [["simulate"]])
    assert "failed" in table[2] and table[-1].startswith("| whole example | — | 1.00 / 2.00 | 0 of 0 pairs")


@pytest.mark.parametrize("wins, n, p", [(3, 3, 0.25), (21, 21, 2.0 ** -20), (5, 10, 1.0), (0, 6, 2.0 ** -5)])
def test_sign_test(wins: int, n: int, p: float) -> None:
    assert sign_test_p(wins, n) == pytest.approx(p)
