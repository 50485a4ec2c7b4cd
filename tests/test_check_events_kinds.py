"""The check benchmark's event kinds: ``--kinds`` parses (default: the published figures' kinds), and the report
compares the chosen action with the other per choice, paired."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.check_events import parser, report_simulated
from pin_kpi_oed.studies.check_robots import CHANGE_KINDS, COMBINED_KINDS


def test_kinds_default_to_the_published_figures_and_take_the_combined_kind() -> None:
    assert tuple(parser().parse_args([]).kinds) == CHANGE_KINDS[1:]
    assert parser().parse_args(["--kinds", "placement_tracker"]).kinds == ["placement_tracker"]
    assert "placement_tracker" in COMBINED_KINDS


def test_unknown_kind_is_refused(capsys) -> None:
    with pytest.raises(SystemExit) as err:
        parser().parse_args(["--kinds", "crash"])
    assert err.value.code == 2
    assert "crash" in capsys.readouterr().err


def _event(robot: int, verdict: str, refit: float, recal: float, exp_refit: float, exp_recal: float) -> dict:
    return {"kind": "placement_tracker", "joint": "elbow_joint", "robot": robot, "verdict": verdict,
            "group": "elbow_joint placement", "right": True, "tcp_change_m": 3e-4, "refit_error_m": refit,
            "recal_error_m": recal, "predicted_refit_m": exp_refit, "predicted_recal_m": exp_recal, "alike": [],
            "sized": True, "recal_draws_m": [recal], "calibration_error_m": refit}


def test_report_pairs_the_chosen_action_with_the_other_per_choice(capsys) -> None:
    # 6 re-calibrations chosen: the re-calibration better in 5 (by 20 %), worse in 1 (by 50 %)
    events = [_event(r, "recalibrate", 1.2e-4, 1.0e-4, 1.15e-4, 1.0e-4) for r in range(5)]
    events.append(_event(5, "recalibrate", 1.0e-4, 1.5e-4, 1.12e-4, 1.0e-4))
    events += [_event(r, "robot_changed", 1.0e-4, 1.0e-4 * (1 + 0.01 * r), 1.05e-4, 1.0e-4) for r in range(4)]
    report_simulated(events)
    out = capsys.readouterr().out
    assert "placement_tracker >= 1.5x tolerance: named right: 10 of 10" in out
    recal = out.split("chose re-calibrate in 6 events")[1]
    ratios = np.r_[[1.0 / 1.2] * 5, 1.5]
    assert f"median ratio chosen / other {np.median(ratios):.3f}, chosen worse in 1 of 6 (sign test p 0.22)" in recal
    assert "worse by > 10 % in 1" in recal
    refit = out.split("chose re-fit in 4 events")[1].split("chose re-calibrate")[0]
    assert "chosen worse in 0 of 4" in refit and "(ratio 1.050-1.050)" in refit
    # the re-fits here carry exactly the calibration's own error: they add none of the variance expected
    assert "re-calibrate chosen (6 events): the re-fit adds to the calibration's own error 0.00 x" in out
