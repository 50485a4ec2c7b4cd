"""A stand-in design file of random configurations, for previews before a real design exists.

**Not an optimised design.** The real one comes from ``pin-kpi-oed design ... --json``; the stand-in
lets the viewer and the report figures be tried (and their examples run) without the optimiser.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from pin_kpi_oed.cell.cell import capsules_from_urdf
from pin_kpi_oed.cell.cell_model import DEFAULT_INCIDENCE_MAX_DEG
from pin_kpi_oed.design.design_file import load_design
from pin_kpi_oed.errors import InfeasibleError
from pin_kpi_oed.model.noise import NoiseModel
from pin_kpi_oed.model.robot import Robot, load_robot


def _stand_in_cell(rb: Robot) -> dict:
    """The design-file fields of a cell modelled on the paper's, scaled to the robot's reach.

    Floor, a wall behind the robot, a car body in front as two capsules, the tracker in a corner;
    the working configuration over the car (arm stretched forward and down).
    """
    k = rb.reach() / 2.147  # the KR 15's reach
    world_T_base = pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.0]))
    world_T_tracker = pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, np.radians(135.0)), np.array([3.2, -2.4, 1.2]) * k)
    q_work = rb.neutral()
    if rb.nq >= 6:
        # KR 15: TCP at about (1.26, 0, 1.37) m, tool pointing down, over the car roof
        q_work[:6] = np.clip(np.radians([0.0, -41.26, 14.04, 0.0, 114.24, 0.0]), rb.q_lower[:6], rb.q_upper[:6])
    return {
        "robot": {"name": rb.name, "urdf_path": rb.urdf_path, "tool_frame": rb.tool_frame},
        "tracker_T_base": (world_T_tracker.inverse() * world_T_base).homogeneous.tolist(),
        "world_T_base": world_T_base.homogeneous.tolist(),
        "reflector_m": [0.05, 0.0, 0.06],
        "tcp_m": [0.0, 0.0, 0.0],
        "noise": NoiseModel(sigma_xyz_m=(10e-6, 10e-6, 10e-6)).to_dict(),
        "capsules": [c.to_dict() for c in capsules_from_urdf(rb)],
        "obstacles": [
            {"name": "car_body", "type": "capsule", "a": [1.55 * k, -0.9 * k, 0.45 * k],
             "b": [1.55 * k, 0.9 * k, 0.45 * k], "radius": 0.4 * k},
            {"name": "car_roof", "type": "capsule", "a": [1.55 * k, -0.45 * k, 0.85 * k],
             "b": [1.55 * k, 0.45 * k, 0.85 * k], "radius": 0.3 * k},
        ],
        "half_spaces": [{"name": "floor", "normal": [0, 0, 1], "offset": 0.0},
                        {"name": "wall", "normal": [1, 0, 0], "offset": -0.45 * k}],
        "incidence_limit_deg": DEFAULT_INCIDENCE_MAX_DEG,
        "q_work": [q_work.tolist()],
        "stand_in": "random configurations, not an optimised design (pin_kpi_oed.design.stand_in)",
    }


def stand_in_design(robot: str = "kr15", m: int = 30, seed: int = 0, n_sets: int = 24,
                    margin_m: float = 0.02) -> dict:
    """A design JSON (dict) built from random configurations.

    Poses: uniform random configurations that are visible (incidence within the limit) and clear of
    everything by ``margin_m`` (the independent check of the design file's cell, beam included).
    Designs: ``random`` = one random set of ``m`` poses; ``kpi`` (labelled ``best-of-random``) = the
    best of ``n_sets`` random sets by tr(C_s).

    Args:
        robot: shipped robot name.
        m: poses per design.
        seed: seed of every random choice.
        n_sets: random sets compared for the ``kpi`` design.
        margin_m: clearance every pose keeps (m).

    Returns:
        The design dict (as :func:`~pin_kpi_oed.design.design_file.load_design` reads it).

    Raises:
        InfeasibleError: fewer than ``m`` acceptable random poses found.
    """
    from pin_kpi_oed.oed.evaluate import score_design
    from pin_kpi_oed.oed.identifiability import analyse

    rb = load_robot(robot)
    d = _stand_in_cell(rb)
    q_work = np.asarray(d["q_work"], float)
    df = load_design({**d, "designs": [{"criterion": "tmp", "q_meas": d["q_work"], "cov_s_m2": np.eye(3).tolist()}]})
    rng = np.random.default_rng(seed)
    pool: list[np.ndarray] = []
    tries = 0
    while len(pool) < m * 4 and tries < 60:
        tries += 1
        Q = rb.random_q(rng, 400)
        Q = Q[df.incidence_deg(Q) <= d["incidence_limit_deg"]]
        if Q.size:
            pool.extend(Q[df.pose_clearance(Q) > margin_m])
    if len(pool) < m:
        raise InfeasibleError(f"stand-in design: only {len(pool)} visible collision-free random poses found for "
                              f"{m} measurements")
    pool_a = np.array(pool)
    ident = analyse(df.model)
    sets = [pool_a[rng.choice(len(pool_a), m, replace=False)] for _ in range(n_sets)]
    covs = [score_design(df.model, S, q_work, ident).cov_s_m2 for S in sets]
    traces = [float(np.trace(C)) for C in covs]
    ib = int(np.argmin(traces))
    d["designs"] = [
        {"criterion": "random", "q_meas": sets[0].tolist(), "trace_cs_m2": traces[0], "cov_s_m2": covs[0].tolist(),
         "status": "stand-in"},
        {"criterion": "kpi", "label": "best-of-random", "q_meas": sets[ib].tolist(), "trace_cs_m2": traces[ib],
         "cov_s_m2": covs[ib].tolist(), "status": "stand-in"}]
    return d
