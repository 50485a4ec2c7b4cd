"""Certificate speed and size: ``report`` on a 3,000-row model <= 10 s, the HTML <= 5 MB.

A simulated UR10 (random geometric errors, an unmodelled gear harmonic of 50 µrad per joint, sigma 20 µm, seeds fixed):
3,000 training rows calibrated by ``identify --discrepancy auto --model-out`` (not timed; the discrepancy it keeps makes
the honest σ and the trust map cost what they cost on real data), 1,000 held-out rows with 200 commanded positions of 5
rows (the ISO 9283 section is filled). Timed: the whole ``pin-kpi-oed report --html --json`` command in this process
(reading the files, the nominal comparison fit, both scorings, identifiability, ISO figures, the five figures, the
HTML), wall and CPU time.

Run: ``python -m benchmarks bench_report``.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np

from benchmarks.common import figure, timed

TARGET_S = 10.0
TARGET_BYTES = 5e6


def _model(d: Path, n_train: int = 3000, n_test: int = 1000) -> list[str]:
    from pin_kpi_oed import NoiseModel, TrackerModel, load_robot
    from pin_kpi_oed.cli.app import main
    from pin_kpi_oed.data.measurements import MeasurementSet, write_measurements
    from pin_kpi_oed.effects.library import parse_effects_spec
    from pin_kpi_oed.simulation.simulator import Tolerances, default_tracker_pose, random_truth, simulate
    from pin_kpi_oed.oed.identifiability import analyse

    robot = load_robot("ur10")
    tm = TrackerModel(robot, tracker_T_base=default_tracker_pose(robot), reflector_m=np.array([0.02, 0.01, 0.1]),
                      noise=NoiseModel((2e-5,) * 3))
    base = [i for i in analyse(tm).base if i < 36]
    truth = random_truth(tm, Tolerances(5e-4, 1e-3, 0.01, 0.01), seed=4, only=base)
    rng = np.random.default_rng(2)
    effects = parse_effects_spec("gear_harmonic=5e-5", robot, rng)  # unmodelled: the discrepancy learns it
    for name, n, seed in (("train", n_train, 5), ("test", n_test, 6)):
        ms = simulate(tm, robot.random_q(rng, n), truth, effects=effects, seed=seed, record_sigma=False)
        g = np.repeat(rng.uniform(-1, 1, size=(n // 5, 3)), 5, axis=0)
        write_measurements(MeasurementSet(ms.joint_names, ms.q, ms.position_m, source=name,
                                          extra={"goal_x": g[:, 0], "goal_y": g[:, 1], "goal_z": g[:, 2]}),
                           d / f"{name}.csv")
    assert main(["identify", "--robot", "ur10", "--data", str(d / "train.csv"), "--reflector", "0.02,0.01,0.1",
                 "--sigma", "2e-5", "--discrepancy", "auto", "--model-out", str(d / "model.json"), "--quiet"]) == 0
    return ["report", "--model", str(d / "model.json"), "--train", str(d / "train.csv"), "--validate",
            str(d / "test.csv"), "--html", str(d / "cert.html"), "--json", str(d / "cert.json"), "--quiet"]


def main() -> None:
    from pin_kpi_oed.cli.app import main as cli

    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        argv = _model(d)
        t, code = timed(lambda: cli(argv))
        assert code == 0
        size = (d / "cert.html").stat().st_size
        disc = (json.loads((d / "cert.json").read_text())["parameters"]["discrepancy"] or {}).get("decision")
    figure("report, 3,000-row model, 1,000 held-out rows (wall)", float(t), TARGET_S)
    figure("report, 3,000-row model, 1,000 held-out rows (CPU)", t.cpu_s, TARGET_S)
    figure("certificate HTML size", size / 1e6, TARGET_BYTES / 1e6, unit="MB")
    print(f"discrepancy of the model: {disc}")


if __name__ == "__main__":
    main()
