"""The σ at tool points off the reflector, held out on real data through the measured probe orientation.

The IPA UR10's rows carry the probe's orientation with the reflector's position, so the position of any point fixed
to the tool is measured too: the reflector's measured position plus the measured tool orientation times the point's
offset from the fitted reflector. Each point's predicted position and σ (``calibrated.tcp_sigma.tcp_sigma``, the σ of
``predict --at tcp``) is scored against it on held-out rows: the standardised RMS with and without the held part
(the parameters no measurement determines, held at their tolerance: the data cannot test that part, the fitted
reflector absorbs it). The measured point carries the orientation's own noise times the offset (about 1 mrad × the
distance).

Run (files from the certificate commands of docs/certificates/README.md: ``import-ipa $IPA/Series_C --split 0.5
--seed 0 ...`` and ``identify ... --model-out ur10_c.json``):
    python -m benchmarks.tcp_off_reflector ur10_c.json c_test.csv
"""

from __future__ import annotations

import argparse

import numpy as np
import pinocchio as pin

from pin_kpi_oed.calibrated.model_file import load_model_file
from pin_kpi_oed.calibrated.tcp_sigma import tcp_sigma
from pin_kpi_oed.data.measurement_reader import read_measurements


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model", help="a 6-D calibrated model file (position and probe orientation)")
    ap.add_argument("data", help="held-out rows with x, y, z and rx, ry, rz")
    args = ap.parse_args(argv)
    cm = load_model_file(args.model)
    data = read_measurements(args.data, joint_names=list(cm.robot.joint_names))
    st = cm.setups[cm.station(None)]
    r, Rp = np.asarray(st.reflector_m), np.asarray(st.probe_R)
    R_tool = np.array([pin.exp3(w) for w in data.rotvec_rad]) @ Rp.T  # measured tool orientation, tracker frame
    points = [("fitted reflector", r), ("0,0,0.109 m", np.array([0, 0, 0.109])), ("0,0,0.05 m", np.array([0, 0, 0.05])),
              ("tool0", np.zeros(3)), ("0.1,0,z_r m", np.array([0.1, 0, r[2]]))]
    for name, c in points:
        measured = data.position_m + R_tool @ (c - r)
        ts = tcp_sigma(cm, data.q, c, aux=data)
        e = measured - ts.position_m
        z = np.einsum("ma,mab,mb->m", e, np.linalg.inv(ts.covariance_m2), e)
        C_free = ts.covariance_m2 - ts.held_m2 + 1e-18 * np.eye(3)
        z_free = np.einsum("ma,mab,mb->m", e, np.linalg.inv(C_free), e)
        print(f"{name:17s} {1e3 * np.linalg.norm(c - r):6.1f} mm from the reflector: error RMS "
              f"{1e3 * np.sqrt(np.mean((e ** 2).sum(1))):.3f} mm, σ RMS {1e3 * ts.rms_m:.3f} mm (held "
              f"{1e3 * np.sqrt(np.mean(ts.held_sigma_m ** 2)):.3f} mm), standardised RMS {np.sqrt(np.mean(z) / 3):.2f}"
              f" (without the held part {np.sqrt(np.mean(z_free) / 3):.2f})")


if __name__ == "__main__":
    main()
