"""Compensation: targets reached by the real robot with the calibrated model, against the nominal kinematics.

A UR10 with random geometric errors, a tracker-pose error and a withheld gear-harmonic error
(3 σ visible per axis, not in the calibration model) is calibrated from 200 simulated tracker
rows (σ = 10 µm); 100 more rows give the calibration's held-out error. Then 200 random Cartesian
TCP targets (the reflector, in the cell = tracker frame) are compensated
(``pin-kpi-oed compensate --model model.json --targets targets.csv --out joints.csv``): IK on the
calibrated model from the nominal solution. The truth simulator says where the TCP really goes
with the nominal joints and with the compensated ones.

Second route on the real UR10 (IPA Series C, when the data are present): calibrate on half of the
rows; for the other half, the commanded joints -> where the compensation module says the TCP goes
(:func:`pin_kpi_oed.compensation.compensator.forward`), against the measured positions: the same
figure as the model's held-out error; and the measured points compensated back to joints.

Run: python examples/compensate_simulated.py   (PIN_KPI_OED_QUICK=1: fewer targets, no UR10 part)
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np

from pin_kpi_oed import NoiseModel, TrackerModel, load_robot
from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.data.targets import TargetSet
from pin_kpi_oed.effects.library import parse_effects_spec, size_effect
from pin_kpi_oed.compensation.compensator import CompensationOptions, compensate, forward
from pin_kpi_oed.identification.identify import identify, predict, validate
from pin_kpi_oed.simulation.simulator import Tolerances, default_tracker_pose, random_truth, simulate
from pin_kpi_oed.oed.identifiability import analyse

#: --quick (or PIN_KPI_OED_QUICK=1): smaller sizes, the same steps (the tests' run)
QUICK = os.environ.get("PIN_KPI_OED_QUICK") == "1" or "--quick" in sys.argv[1:]
N_TARGETS = 25 if QUICK else 200
SIGMA = 1e-5
_HERE = Path(__file__).resolve()
IPA = next((p / "shared" / "data" / "ipa_ur10" for p in (_HERE.parents[2], _HERE.parents[3])
            if (p / "shared" / "data" / "ipa_ur10").is_dir()), _HERE.parents[2] / "shared" / "data" / "ipa_ur10")


def no_aux(robot, m):
    return MeasurementSet(robot.joint_names, np.zeros((m, robot.nq)), np.full((m, 3), np.nan))


def simulated() -> None:
    robot = load_robot("ur10")
    refl = np.array([0.03, 0.02, 0.08])
    tm = TrackerModel(robot, tracker_T_base=default_tracker_pose(robot), reflector_m=refl,
                      noise=NoiseModel((SIGMA,) * 3))
    base = [i for i in analyse(tm).base if i < 6 * robot.nq]
    truth = random_truth(tm, Tolerances(5e-4, 1e-3, 0.01, 0.01), seed=3, only=base + list(range(36, 42)))
    rng = np.random.default_rng(1)
    Q = robot.random_q(rng, 300)
    (eff, th), = parse_effects_spec("gear_harmonic=5e-5", robot, rng)
    th = size_effect(tm, truth, Q, MeasurementSet(robot.joint_names, Q, np.zeros((300, 3))), eff, th, 3 * SIGMA)
    data = simulate(tm, Q, truth, effects=[(eff, th)], seed=2)
    cm = identify(TrackerModel(robot, reflector_m=refl, noise=tm.noise), data.subset(np.arange(200))
                  ).calibrated_model()
    held = validate(cm, data.subset(np.arange(200, 300)))

    Qt = robot.random_q(np.random.default_rng(5), N_TARGETS) * 0.9
    truth_tcp = lambda Qx: predict(tm, truth, Qx, [eff], [th], no_aux(robot, len(Qx)))[:, :3]  # noqa: E731
    Yt = truth_tcp(Qt)
    ts = TargetSet([str(i) for i in range(N_TARGETS)], Yt, None, None, list(robot.joint_names),
                   no_aux(robot, N_TARGETS), "targets")
    # the targets are where the true reflector goes: the TCP is the fitted reflector (a model that states no TCP is
    # refused without one)
    res = compensate(cm, ts, CompensationOptions(frame="cell", tcp_m=cm.setups[cm.station(None)].reflector_m))
    print(res.summary())
    e_nom = np.linalg.norm(truth_tcp(res.q_nominal) - Yt, axis=1)
    e_cmp = np.linalg.norm(truth_tcp(res.q) - Yt, axis=1)
    print(f"\n{N_TARGETS} Cartesian targets, where the true robot's TCP goes (mm):")
    print(f"{'joints sent':<26}{'mean':>9}{'RMS':>9}{'max':>9}")
    for name, e in (("nominal IK", e_nom), ("compensated (calibrated)", e_cmp)):
        print(f"{name:<26}{e.mean() * 1e3:>9.4f}{np.sqrt(np.mean(e ** 2)) * 1e3:>9.4f}{e.max() * 1e3:>9.4f}")
    print(f"{'calibration held-out':<26}{held['mean_m'] * 1e3:>9.4f}{held['rms_m'] * 1e3:>9.4f}"
          f"{held['max_m'] * 1e3:>9.4f}")
    ratio = e_cmp.mean() / held["mean_m"]
    print(f"compensated mean / held-out mean = {ratio:.2f} (requirement <= 2)")


def real_ur10() -> None:
    from pin_kpi_oed.data.ipa import import_ipa
    from pin_kpi_oed.upkeep.transfer import registration_split

    ms = import_ipa(IPA / "Series_C")
    ms = MeasurementSet(ms.joint_names, ms.q, ms.position_m, temperature_c=ms.temperature_c, source="C.csv")
    tr_idx, held_idx = registration_split(len(ms), len(ms) // 2, seed=0)
    robot = load_robot("ur10")
    model = TrackerModel(robot, reflector_m=np.array([0.0, 0.0, 0.109]), noise=NoiseModel(sigma_xyz_m=(1e-4,) * 3))
    cm = identify(model, ms.subset(tr_idx)).calibrated_model()
    held = ms.subset(held_idx)
    v = validate(cm, held)
    e = np.linalg.norm(forward(cm, held.q, held) - held.position_m, axis=1)
    ts = TargetSet([str(i) for i in range(len(held))], held.position_m, None, held.q, list(robot.joint_names),
                   held, "held")
    res = compensate(cm, ts, CompensationOptions(tcp_m=cm.setups[cm.station(None)].reflector_m))  # measured points
    ok = np.array([s == "ok" for s in res.target_status])
    dq = np.degrees(np.abs(res.q - held.q)[ok]).max(axis=1)
    print(f"\nreal UR10, IPA Series C: geometry calibrated on {len(tr_idx)} rows, {len(held)} held-out rows")
    print(f"  model held-out error (validate):                    mean {v['mean_m'] * 1e3:.4f} mm, "
          f"RMS {v['rms_m'] * 1e3:.4f} mm")
    print(f"  commanded joints -> compensation FK vs measured:    mean {e.mean() * 1e3:.4f} mm, "
          f"RMS {np.sqrt(np.mean(e ** 2)) * 1e3:.4f} mm")
    print(f"  measured points compensated back to joints: {ok.sum()} of {len(held)} ok; joint change vs commanded "
          f"median {np.median(dq) * 3600:.1f} arcsec, max {dq.max() * 3600:.1f} arcsec")


if __name__ == "__main__":
    simulated()
    if not QUICK and (IPA / "Series_C").is_dir():
        real_ur10()
