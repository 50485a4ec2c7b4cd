"""Core benchmark: parameter Jacobian and criterion + gradient for 60 configurations (KR 15).

Targets: Jacobian for 60 configurations <= 1 ms; criterion + gradient <= 3 ms (median).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from pin_kpi_oed.oed.criteria import CRITERIA, Criterion
from pin_kpi_oed.oed.objective import DesignCriterion
from pin_kpi_oed.oed.identifiability import analyse
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.model.robot import load_robot

from .common import median_time, report


def main() -> None:
    rb = load_robot("kr15")
    model = TrackerModel(rb, tracker_T_base=pin.SE3(pin.rpy.rpyToMatrix(0, 0, np.pi), np.array([3.0, 0.0, -0.5])),
                         reflector_m=np.array([0.05, 0.02, 0.05]))
    rng = np.random.default_rng(0)
    Q = rb.random_q(rng, 60)
    p0 = np.zeros(model.n_params)
    ident = analyse(model)
    E = model.kpi_jacobian(p0, rb.neutral()[None])[:, ident.base]
    print("== core (KR 15, 60 configurations, 45 raw / 27 identifiable parameters)")
    report("parameter Jacobian dh/dp (60 x 3 x 45)", median_time(lambda: model.jacobian(p0, Q)), 1e-3)
    report("weighted Jacobian + dF/dq", median_time(lambda: model.weighted_jacobian_dq(p0, Q)))
    for name, crit in CRITERIA.items():  # every registered criterion of the information matrix
        if not isinstance(crit, Criterion):
            continue  # the criteria of the configurations: timed by bench_kpi_gp through the design problem
        dc = DesignCriterion(model, ident.base, name, E)
        report(f"criterion {name} + gradient w.r.t. q (60 x 6)", median_time(lambda: dc.value_and_grad(Q)), 3e-3)


if __name__ == "__main__":
    main()
