"""Where the held-out residuals lie: association with regressors (η², ANOVA) and workspace octants."""

from __future__ import annotations

import numpy as np
from scipy import stats as _st

from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.effects.library import gravity_torque, loaded_joints
from pin_kpi_oed.model.tracker import TrackerModel

__all__ = ["locate"]


def _regressors(model: TrackerModel, p: np.ndarray, data: MeasurementSet, order: np.ndarray) -> dict:
    """Candidate regressors per held-out measurement: name -> (values, unit)."""
    rb = model.robot
    Q = np.asarray(data.q, float)[:, [data.joint_names.index(j) for j in rb.joint_names]]
    kin = model.kinematics(p, Q, model.reflector(p))
    P = kin.p
    out: dict[str, tuple[np.ndarray, str]] = {
        "tcp_x_base": (P[:, 0], "m"), "tcp_y_base": (P[:, 1], "m"), "tcp_z_base": (P[:, 2], "m"),
        "tcp_reach": (np.hypot(P[:, 0], P[:, 1]), "m"),
        "tracker_range": (np.linalg.norm(data.position_m, axis=1), "m"),
    }
    for j, n in enumerate(rb.joint_names):
        out[f"q_{n}"] = (Q[:, j], "rad")
    tau = gravity_torque(rb, Q, data.payload_kg)
    for k in np.flatnonzero(loaded_joints(rb)):
        out[f"gravity_torque_{rb.joint_names[k]}"] = (tau[:, k], "N*m")
    if data.temperature_c is not None and np.ptp(data.temperature_c) > 0:
        out["temperature"] = (np.asarray(data.temperature_c, float), "degC")
    if data.time_s is not None and np.ptp(data.time_s) > 0:
        out["time"] = (np.asarray(data.time_s, float), "s")
    out["order"] = (np.asarray(order, float), "row")
    if data.payload_kg is not None and np.ptp(data.payload_kg) > 0:
        out["payload"] = (np.asarray(data.payload_kg, float), "kg")
    return out


def _association(x: np.ndarray, Z: np.ndarray, R: np.ndarray) -> dict:
    """η² (pooled over axes) of standardised residuals Z (n, 3) on quantile bins of x, ANOVA p, bin table."""
    n = x.size
    uniq = np.unique(x)
    nb = int(np.clip(n // 30, 3, 10))
    if uniq.size <= nb:
        labels = np.searchsorted(uniq, x)
        edges = uniq
    else:
        edges = np.quantile(x, np.linspace(0, 1, nb + 1))
        labels = np.clip(np.searchsorted(edges[1:-1], x, side="right"), 0, nb - 1)
    B = int(labels.max()) + 1 if n else 0
    gm = Z.mean(axis=0)
    ss_tot = float(np.sum((Z - gm) ** 2))
    ss_b = 0.0
    bins = []
    used = 0
    for b in range(B):
        sel = labels == b
        c = int(sel.sum())
        if c == 0:
            continue
        used += 1
        mb = Z[sel].mean(axis=0)
        ss_b += c * float(np.sum((mb - gm) ** 2))
        e = np.linalg.norm(R[sel], axis=1)
        bins.append({"lo": float(x[sel].min()), "hi": float(x[sel].max()), "n": c,
                     "rms_m": float(np.sqrt(np.mean(e ** 2))), "mean_residual_m": R[sel].mean(axis=0).tolist()})
    eta2 = ss_b / ss_tot if ss_tot > 0 else 0.0
    df1, df2 = 3 * (used - 1), 3 * (n - used)
    if df1 > 0 and df2 > 0 and ss_tot - ss_b > 0:
        F = (ss_b / df1) / ((ss_tot - ss_b) / df2)
        p = float(_st.f.sf(F, df1, df2))
    else:
        p = 1.0
    return {"eta2": float(eta2), "p_value": p, "bins": bins}


def locate(model: TrackerModel, p: np.ndarray, data: MeasurementSet, order: np.ndarray, R: np.ndarray,
           S: np.ndarray, alpha: float) -> tuple[dict, dict]:
    """Where the held-out residuals ``R`` (n, 3) m with σ ``S`` (n, 3) m vary: regressors and octants.

    Args:
        model, p: the fitted measurement model and its raw parameters.
        data: the held-out rows; ``order`` their row numbers in their file (the order regressor).
        alpha: significance level of the ANOVA F-test naming the strongest regressors.

    Returns:
        (the report's ``where`` dict: every regressor with η², p-value and bins, the strongest ones,
        the workspace octants; the regressors by name -> (values, unit)).
    """
    regs = _regressors(model, p, data, order)
    Z = R / S
    items = []
    for name, (x, unit) in regs.items():
        a = _association(x, Z, R)
        items.append({"name": name, "unit": unit, **a})
    items.sort(key=lambda d: -d["eta2"])
    strongest = [{"name": d["name"], "eta2": d["eta2"], "p_value": d["p_value"]} for d in items
                 if d["p_value"] < alpha][:3]
    P = model.kinematics(p, np.asarray(data.q, float)[:, [data.joint_names.index(j) for j in model.robot.joint_names]],
                         model.reflector(p)).p
    med = np.median(P, axis=0)
    regions = []
    e = np.linalg.norm(R, axis=1)
    code = (P > med).astype(int)
    for cx in (0, 1):
        for cy in (0, 1):
            for cz in (0, 1):
                sel = (code[:, 0] == cx) & (code[:, 1] == cy) & (code[:, 2] == cz)
                if not sel.any():
                    continue
                regions.append({"region": f"x{'+-'[1 - cx]} y{'+-'[1 - cy]} z{'+-'[1 - cz]}", "n": int(sel.sum()),
                                "mean_m": float(e[sel].mean()), "rms_m": float(np.sqrt(np.mean(e[sel] ** 2))),
                                "max_m": float(e[sel].max())})
    where = {"regressors": items, "strongest": strongest, "regions": regions,
             "regions_about": "octants around the median TCP position in the robot base frame (x+ = above median)"}
    return where, regs
