r"""ISO 9283 pose figures from calibration data: pose accuracy AP, multi-directional variation vAP, repeatability RP.

ISO 9283:1998 defines, for a commanded pose measured n times (attained positions x_j, barycentre x̄, commanded x_c):

* pose accuracy (clause 7.2.1) AP = ‖x̄ − x_c‖, per axis AP_x = x̄ − x_c, ...;
* pose repeatability (7.2.2) RP = l̄ + 3·S_l, l_j = ‖x_j − x̄‖, S_l = √(Σ(l_j − l̄)² / (n − 1));
* multi-directional pose accuracy variation (7.3) vAP = max over pairs of approach directions h, k of ‖x̄_h − x̄_k‖.

Here the robot is driven through a model: the position it should reach is what the model predicts for the
configuration, so the attained-minus-commanded vector of row j is its residual e_j = measured − predicted
(tracker frame; the "before" model: the nominal robot with its fitted set-up, "after": the calibration) and
AP = ‖ē‖ over the rows of one commanded position (the *model-prediction variant*; against the commanded poses
themselves: :mod:`pin_kpi_oed.report.iso_commanded`). The rows of one commanded position are those whose commanded
(goal) positions lie within a stated distance (:data:`GOAL_RADIUS_M`, 1 mm) of the goal of the group's first row in
file order (the data's ``goal_x, goal_y, goal_z`` columns, e.g. the IPA series): no group spans more than twice
that distance, however densely the goals lie (no chaining of neighbours); its directions are its distinct
configurations (joints within 1 mrad: another orientation or another inverse-kinematics branch reaches the position
another way), each direction's barycentre the mean residual of its rows. RP needs one configuration measured
repeatedly: rows whose joint values agree within 1 mrad on every joint form a cycle group (≥ 3 rows); RP is
computed on their residuals (what stays when the commanded position is the same).

Where the data hold no such rows the figure is not given, and the certificate says why.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["GOAL_POSITION", "GOAL_RADIUS_M", "clusters", "goal_groups", "commanded_groups", "direction_keys",
           "pose_accuracy", "repeatability", "iso_figures", "CLAUSES"]

#: The data's commanded-position columns (m).
GOAL_POSITION = ("goal_x", "goal_y", "goal_z")
#: Rows whose commanded position lies within this distance of a group's first goal are one commanded position (m).
GOAL_RADIUS_M = 1e-3
#: Clauses of ISO 9283:1998 the figures follow.
CLAUSES = {"AP": "ISO 9283:1998, 7.2.1 (pose accuracy)", "RP": "ISO 9283:1998, 7.2.2 (pose repeatability)",
           "vAP": "ISO 9283:1998, 7.3 (multi-directional pose accuracy variation)"}


def _labels(X: np.ndarray, tol: float) -> np.ndarray:
    """The component 0, 1, ... of each row of X (non-empty) linked by chains of neighbours within ``tol``
    (max-norm)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    pairs = cKDTree(X).query_pairs(r=tol, p=np.inf, output_type="ndarray")
    A = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(X), len(X)))
    return connected_components(A, directed=False)[1].astype(int)


def clusters(X: np.ndarray, tol: float, min_size: int = 2) -> list[np.ndarray]:
    """Rows of X linked by chains of neighbours within ``tol`` (max-norm), groups of at least ``min_size``
    (rows ascending within a group, groups in the order of their labels)."""
    X = np.asarray(X, float)
    return _groups_of(_labels(X, tol), min_size) if len(X) else []


def _groups_of(lab: np.ndarray, min_size: int) -> list[np.ndarray]:
    """The rows of each label 0, 1, ... (ascending) that at least ``min_size`` rows carry, in label order."""
    rows = np.flatnonzero(np.isin(lab, np.flatnonzero(np.bincount(lab) >= min_size)))
    order = rows[np.argsort(lab[rows], kind="stable")]
    return np.split(order, np.flatnonzero(np.diff(lab[order])) + 1) if order.size else []


def goal_groups(G: np.ndarray, radius_m: float = GOAL_RADIUS_M, min_size: int = 2) -> list[np.ndarray]:
    """Rows per commanded position: in file order, an unassigned row's goal opens a group that takes every unassigned
    row whose goal lies within ``radius_m`` (Euclidean, m) of it; groups of at least ``min_size`` rows.

    Args:
        G: commanded positions (m, 3) m.
        radius_m: the stated distance to the group's goal (m).
        min_size: the fewest rows of a group returned.

    Returns:
        Row indices per group (ascending), in the order the groups were opened.
    """
    from scipy.spatial import cKDTree

    G = np.asarray(G, float)
    free = np.ones(len(G), bool)
    tree = cKDTree(G) if len(G) else None
    out = []
    for i in range(len(G)):
        if not free[i]:
            continue
        near = np.asarray(tree.query_ball_point(G[i], r=radius_m), int)
        g = np.sort(near[free[near]])
        free[g] = False
        if g.size >= min_size:
            out.append(g)
    return out


def commanded_groups(data: Any, radius_m: float = GOAL_RADIUS_M) -> list[np.ndarray] | None:
    """Rows per commanded position (≥ 2 rows, :func:`goal_groups`), or None when the data have no goal columns."""
    if not all(k in data.extra for k in GOAL_POSITION):
        return None
    return goal_groups(np.column_stack([data.extra[k] for k in GOAL_POSITION]), radius_m)


def direction_keys(Q: np.ndarray, tol_rad: float = 1e-3) -> np.ndarray:
    """An integer per row naming its configuration: rows whose joints agree within ``tol_rad`` share one (the
    same commanded pose reached the same way); the directions of a commanded position are its configurations."""
    Q = np.asarray(Q, float)
    return _labels(Q, tol_rad) if len(Q) else np.full(0, -1)


def pose_accuracy(resid_m: np.ndarray, groups: list[np.ndarray], directions: np.ndarray) -> dict:
    """AP and vAP per commanded position and their summary (m).

    Args:
        resid_m: residuals e_j = measured − predicted, (m, 3) m.
        groups: rows of each commanded position.
        directions: commanded orientation key per row.

    Returns:
        ``n_positions``, ``n_samples``, ``AP`` (``mean_m``, ``max_m``, ``per_axis_mean_m``), ``vAP`` (``mean_m``,
        ``max_m``, ``n_positions``: those with ≥ 2 directions, ``directions_mean``), ``per_position`` (AP_m,
        AP_xyz_m, vAP_m, n, directions).
    """
    resid_m = np.asarray(resid_m, float)
    sizes = np.array([len(g) for g in groups], int)
    at = np.concatenate([np.asarray(g, int) for g in groups]) if groups else np.zeros(0, int)
    group = np.repeat(np.arange(len(groups)), sizes)  # each row of each group (groups may share rows)
    E = resid_m[at]
    _, code = np.unique(np.asarray(directions)[at], return_inverse=True)
    width = int(code.max(initial=0)) + 1
    cells, cell = np.unique(group * width + code.reshape(-1), return_inverse=True)  # (position, direction) pairs
    bary = _sums(group, E, len(groups)) / sizes[:, None]  # each position's barycentre
    B = _sums(cell, E, len(cells)) / np.bincount(cell, minlength=len(cells))[:, None]  # each direction's
    first = np.searchsorted(cells // width, np.arange(len(groups) + 1))  # a position's directions: B[first[k]:...]
    rows: list[dict] = []
    for k in range(len(groups)):
        Bk = B[first[k]:first[k + 1]]
        vap = float(np.sqrt(((Bk[:, None, :] - Bk[None, :, :]) ** 2).sum(axis=2).max())) if len(Bk) > 1 else None
        rows.append({"AP_m": float(np.linalg.norm(bary[k])), "AP_xyz_m": bary[k].tolist(), "vAP_m": vap,
                     "n": int(sizes[k]), "directions": int(len(Bk))})
    ap = np.array([r["AP_m"] for r in rows])
    axes = np.array([r["AP_xyz_m"] for r in rows]).reshape(-1, 3)
    vaps = np.array([r["vAP_m"] for r in rows if r["vAP_m"] is not None])
    return {"n_positions": len(rows), "n_samples": int(sum(r["n"] for r in rows)),
            "AP": {"mean_m": float(ap.mean()) if ap.size else None, "max_m": float(ap.max()) if ap.size else None,
                   "per_axis_mean_m": axes.mean(axis=0).tolist() if ap.size else None},
            "vAP": {"mean_m": float(vaps.mean()) if vaps.size else None,
                    "max_m": float(vaps.max()) if vaps.size else None, "n_positions": int(vaps.size),
                    "directions_mean": float(np.mean([r["directions"] for r in rows])) if rows else None},
            "per_position": rows}


def _sums(label: np.ndarray, E: np.ndarray, n: int) -> np.ndarray:
    """Column sums of the rows of E (k, 3) per label 0..n-1, (n, 3)."""
    return np.column_stack([np.bincount(label, weights=E[:, a], minlength=n) for a in range(3)])


def repeatability(resid_m: np.ndarray, groups: list[np.ndarray]) -> dict:
    """RP = l̄ + 3·S_l per cycle group (rows of one configuration) and the summary (m)."""
    rp = []
    for g in groups:
        e = resid_m[g]
        ell = np.linalg.norm(e - e.mean(axis=0), axis=1)
        rp.append({"RP_m": float(ell.mean() + 3.0 * np.std(ell, ddof=1)), "n": int(g.size)})
    v = np.array([r["RP_m"] for r in rp])
    return {"n_groups": len(rp), "n_samples": int(sum(r["n"] for r in rp)),
            "median_m": float(np.median(v)) if v.size else None, "max_m": float(v.max()) if v.size else None,
            "per_group": rp}


def iso_figures(data: Any, Q: np.ndarray, resid_before_m: np.ndarray, resid_after_m: np.ndarray,
                q_tol_rad: float = 1e-3, goal_radius_m: float = GOAL_RADIUS_M,
                commanded: dict | None = None) -> dict:
    """The ISO 9283 section of a certificate: AP / vAP before and after (the model-prediction variant), RP, the
    figures against the commanded poses where the rows carry them, or why a figure cannot be given.

    Args:
        data: the scored rows (their ``extra`` goal columns name the commanded poses).
        Q: their configurations (rad).
        resid_before_m, resid_after_m: residuals of the nominal and the calibrated model (m, 3) m.
        q_tol_rad: joint tolerance of a repeated configuration (rad).
        goal_radius_m: the stated distance of a commanded position's rows to its goal (m, :func:`goal_groups`).
        commanded: :func:`~pin_kpi_oed.report.iso_commanded.commanded_figures` of the same rows, or None.

    Returns:
        ``clauses``, ``statements``, ``variant`` (what AP is measured against), ``goal_radius_m``, ``AP_vAP``
        (``before``, ``after``), ``RP``, ``commanded`` where the data give them.
    """
    out: dict = {"clauses": CLAUSES, "statements": [], "goal_radius_m": float(goal_radius_m),
                 "variant": "model prediction: AP of the residuals measured − predicted (the position the model "
                            "says the measured joints reach), not of the commanded poses"}
    groups = commanded_groups(data, goal_radius_m)
    keys = direction_keys(Q, q_tol_rad)  # one configuration per key: the directions and the cycle groups
    if groups is None:
        out["statements"].append("no commanded positions in the data (goal_x, goal_y, goal_z columns): no AP, vAP")
    elif not groups:
        out["statements"].append(f"no commanded position was measured more than once (goals within "
                                 f"{goal_radius_m * 1e3:g} mm): no AP, vAP")
    else:
        out["AP_vAP"] = {"before": pose_accuracy(resid_before_m, groups, keys),
                         "after": pose_accuracy(resid_after_m, groups, keys)}
        if out["AP_vAP"]["after"]["vAP"]["n_positions"] == 0:
            out["statements"].append("every commanded position was reached in one configuration only: no vAP")
    cycles = _groups_of(keys, 3)
    if cycles:
        out["RP"] = repeatability(resid_after_m, cycles)
        out["RP"]["note"] = (f"repeated configurations (all joints within {q_tol_rad * 1e3:g} mrad, ≥ 3 rows); "
                             "ISO 9283 asks for 30 cycles per pose")
    else:
        out["statements"].append(f"no configuration was measured 3 times or more (joints within {q_tol_rad * 1e3:g} "
                                 "mrad): no RP")
    if commanded is not None:
        out["commanded"] = commanded
    return out
