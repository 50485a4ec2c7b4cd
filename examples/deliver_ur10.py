"""Deliver a UR10 calibration: start from the robot's own UR kinematics file, calibrate, write the certificate and
the calibrated kinematics file for the UR ROS driver.

Steps (Python API; the command-line equivalents are in docs/deliver.md):
1. the robot's factory kinematics (here ``ur_description``'s default UR10 file stands in for ``ur_calibration``'s
   output) as the nominal model: ``load_robot("ur10", kinematics=...)``;
2. simulated tracker measurements of that robot with random geometric errors (240 training, 120 held-out rows);
3. identification, the model file (with the data files it was fitted on, so the certificate can check them);
4. the certificate (HTML, JSON) and ``export_model(..., "ur-yaml")``, read back within 1e-9 m before it is written.

Run: ``python examples/deliver_ur10.py`` (writes into the current folder; ``--quick`` or PIN_KPI_OED_QUICK=1: the same
steps on 120 training and 60 held-out rows).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np

from pin_kpi_oed import (IdentifyOptions, NoiseModel, Tolerances, TrackerModel, analyse, build_certificate,
                         export_model, identify, load_robot, random_truth, simulate, write_certificate,
                         write_measurements)
from pin_kpi_oed.data.provenance import file_record
from pin_kpi_oed.simulation.simulator import default_tracker_pose
from pin_kpi_oed.model.ur_kinematics import UR_KINEMATICS_DIR

#: --quick (or PIN_KPI_OED_QUICK=1): smaller sizes, the same steps (the tests' run)
QUICK = os.environ.get("PIN_KPI_OED_QUICK") == "1" or "--quick" in sys.argv[1:]
N_TRAIN, N_HELD = (120, 60) if QUICK else (240, 120)

factory = UR_KINEMATICS_DIR / "ur10.yaml"   # your robot's file from ur_calibration
robot = load_robot("ur10", kinematics=factory)
print(f"nominal model: {robot.name} with kinematics {robot.kinematics.hash}")

reflector = np.array([0.02, 0.01, 0.10])
tm = TrackerModel(robot, tracker_T_base=default_tracker_pose(robot), reflector_m=reflector,
                  noise=NoiseModel((2e-5,) * 3))
base = [i for i in analyse(tm).base if i < 6 * robot.nq]
truth = random_truth(tm, Tolerances(5e-4, 1e-3, 0.01, 0.01), seed=4, only=base)
rng = np.random.default_rng(2)
for name, n, seed in (("train", N_TRAIN, 5), ("held", N_HELD, 6)):
    write_measurements(simulate(tm, robot.random_q(rng, n), truth, seed=seed, record_sigma=False), f"ur10_{name}.csv")

from pin_kpi_oed import read_measurements  # noqa: E402  (after the files exist)

train = read_measurements("ur10_train.csv", joint_names=robot.joint_names)
result = identify(TrackerModel(robot, reflector_m=reflector, noise=NoiseModel((2e-5,) * 3)), train,
                  IdentifyOptions(weights="noise"))
cm = result.calibrated_model()
cm.history[-1]["train_files"] = [file_record("ur10_train.csv", len(train))]
cm.save("ur10_model.json")
print(f"identified {len(result.names)} parameters on {len(train)} rows, RMS {result.rms_m * 1e3:.4f} mm")

cert = build_certificate("ur10_model.json", ["ur10_train.csv"], "ur10_held.csv",
                         command="python examples/deliver_ur10.py")
out = write_certificate(cert, html="ur10_certificate.html", json_path="ur10_certificate.json")
acc = cert.data["accuracy"]
print(f"held-out RMS {acc['before']['rms_m'] * 1e3:.4f} mm before, {acc['after']['rms_m'] * 1e3:.4f} mm after; "
      f"wrote {', '.join(out['written'])} ({out['html_bytes'] / 1e6:.2f} MB)")

rep = export_model(cm, "ur10_calibration.yaml", "ur-yaml", source="ur10_model.json")
print(rep.summary())
back = load_robot("ur10", kinematics=Path("ur10_calibration.yaml"))
print(f"read back: kinematics {back.kinematics.hash}")
