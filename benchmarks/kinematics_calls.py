"""The measurement model's typical calls on 1, 10 and 200 configurations: CPU time per call and a digest of the
numbers they return.

Five devices: the UR10 and the KR 15 cells' laser trackers, the KR 15 on its linear track (a prismatic joint first)
and the Panda measured by a tracker with range-dependent noise, and the eye-in-hand camera on a UR5. Per device and
configuration count: ``Chain.frames``, ``Chain.tool_pose``, ``predict``, ``jacobian``, ``jacobian_dq``,
``sensor_point`` (with and without ∂J/∂q) and ``sensor_points`` of 20 parameter vectors, each at parameter vectors
that change from call to call (nothing remembered from the call before), as an identification or a design step asks.

The digest is the SHA-256 of every returned array's bytes, in order: two versions of the package that print the same
digest return the same numbers bit for bit. Run it on two checkouts to compare::

    PYTHONPATH=<checkout> python -m benchmarks.kinematics_calls            # times and digest
    PYTHONPATH=<checkout> python -m benchmarks.kinematics_calls --digest   # the digest only (fast)
"""

from __future__ import annotations

import numpy as np  # imported first, as user scripts do  # noqa: I001

import hashlib
import sys
import time
from collections.abc import Callable

import pinocchio as pin

from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.model.camera import Board, CameraModel, Intrinsics
from pin_kpi_oed.model.noise import NoiseModel
from pin_kpi_oed.model.robot import load_robot
from pin_kpi_oed.model.tracker import TrackerModel

COUNTS = (1, 10, 200)


def _devices() -> dict[str, object]:
    """The five measurement models (nominal parameters)."""
    intr = Intrinsics(1200.0, 1210.0, 640.0, 512.0, np.array([-0.1, 0.05, 1e-3, -5e-4, 0.01]))
    cam = CameraModel(load_robot("ur5"), intr, Board(6, 8, 0.025), mode="eye_in_hand",
                      camera_pose=pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, 0.3), np.array([0.05, 0.0, 0.03])),
                      board_pose=pin.SE3(np.eye(3), np.array([0.4125, 0.0375, 0.0])).inverse(),
                      tcp_m=np.array([0.0, 0.0, 0.15]))
    track = TrackerModel(load_robot("kr15_track"), tracker_T_base=pin.SE3(np.eye(3), np.array([2.0, 0.5, 0.3])),
                         reflector_m=np.array([0.02, -0.01, 0.08]), tcp_m=np.array([0.0, 0.0, 0.12]))
    panda = TrackerModel(load_robot("panda"), tracker_T_base=pin.SE3(pin.rpy.rpyToMatrix(0.1, -0.2, 0.4),
                                                                      np.array([1.5, -0.4, 0.2])),
                         reflector_m=np.array([0.03, 0.0, 0.05]), tcp_m=np.array([0.0, 0.01, 0.1]),
                         noise=NoiseModel(range_a_m=1.5e-5, range_b=6e-6), pose6d=True)
    return {"ur10": load_cell("ur10").tracker_model(), "kr15": load_cell("kr15").tracker_model(),
            "kr15_track": track, "panda6d": panda, "camera_ur5": cam}


def _configurations(model, m: int, seed: int) -> np.ndarray:
    """m configurations within the robot's joint limits (the camera's: around its board-seeing pose)."""
    rng = np.random.default_rng(seed)
    rb = model.robot
    if isinstance(model, CameraModel):
        return np.array([0.0, -1.57, 1.57, -1.57, -1.57, 0.0]) + rng.uniform(-0.3, 0.3, (m, rb.nq))
    return rng.uniform(rb.q_lower, rb.q_upper, (m, rb.nq))


def _calls(model, Q: np.ndarray, P: np.ndarray) -> dict[str, Callable[[int], object]]:
    """The timed calls; call(i) uses parameter vector P[i % len(P)] (a fresh one each call)."""
    k = len(P)
    point = model.tcp_m
    chain = model.chain
    perturbed = [[M * pin.exp6(p[6 * j:6 * j + 6]) for j, M in enumerate(chain.placements)] for p in P]
    calls: dict[str, Callable[[int], object]] = {
        "frames": lambda i: chain.frames(Q, perturbed[i % k]),
        "tool_pose": lambda i: chain.tool_pose(Q, point, perturbed[i % k]),
        "predict": lambda i: model.predict(P[i % k], Q),
        "jacobian": lambda i: model.jacobian(P[i % k], Q),
        "jacobian_dq": lambda i: model.jacobian_dq(P[i % k], Q),
        "sensor_point": lambda i: model.sensor_point(P[i % k], Q, point),
        "sensor_point_dq": lambda i: model.sensor_point(P[i % k], Q, point, with_dq=True),
        "sensor_points": lambda i: model.sensor_points(P[:20], Q, point),
    }
    return calls


def _arrays(out: object) -> list[np.ndarray]:
    """Every array a call returned, in a fixed order."""
    if isinstance(out, np.ndarray):
        return [out]
    if isinstance(out, (tuple, list)):
        return [a for o in out for a in _arrays(o)]
    names = ("R", "t", "R_A", "t_A", "V", "W") if hasattr(out, "W") else ("Y", "J", "dJ", "Ydq")
    return [np.asarray(getattr(out, n)) for n in names if getattr(out, n) is not None]


def _parameters(model, seed: int) -> np.ndarray:
    """Eight parameter vectors of millimetre / milliradian size."""
    return np.random.default_rng(seed).normal(0.0, 1e-3, (8, model.n_params))


def digest() -> str:
    """SHA-256 of every call's numbers on every device and configuration count."""
    h = hashlib.sha256()
    for model in _devices().values():
        for m in COUNTS:
            Q = _configurations(model, m, m)
            for call in _calls(model, Q, _parameters(model, m)).values():
                for i in range(2):
                    for a in _arrays(call(i)):
                        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def _time(call: Callable[[int], object], budget_s: float = 0.15) -> float:
    """CPU seconds per call: the best of three runs of enough calls to fill ``budget_s``."""
    n, t = 1, 0.0
    while t < budget_s / 3 and n < 100_000:
        n *= 2
        t0 = time.process_time()
        for i in range(n):
            call(i)
        t = time.process_time() - t0
    best = t / n
    for _ in range(2):
        t0 = time.process_time()
        for i in range(n):
            call(i)
        best = min(best, (time.process_time() - t0) / n)
    return best


def main(argv: list[str]) -> None:
    """Print the CPU time per call (µs) per device, call and configuration count, and the digest."""
    if "--digest" not in argv:
        print(f"{'device':<11} {'call':<16}" + "".join(f"{f'm={m} (us)':>13}" for m in COUNTS))
        total = dict.fromkeys(COUNTS, 0.0)
        for name, model in _devices().items():
            rows: dict[str, list[float]] = {}
            for m in COUNTS:
                Q = _configurations(model, m, m)
                for call_name, call in _calls(model, Q, _parameters(model, m)).items():
                    rows.setdefault(call_name, []).append(_time(call))
                    total[m] += rows[call_name][-1]
            for call_name, ts in rows.items():
                print(f"{name:<11} {call_name:<16}" + "".join(f"{t * 1e6:13.1f}" for t in ts))
        print(f"{'all':<11} {'sum':<16}" + "".join(f"{total[m] * 1e6:13.1f}" for m in COUNTS))
    print(f"digest {digest()}")


if __name__ == "__main__":
    main(sys.argv[1:])
