r"""Held out means held out: held-out rows that repeat a training configuration are removed and counted.

A row repeats a training configuration when some training row's joint values agree with it within the
tolerance δq = resolution / reach on every joint (max-norm, rad; m for a linear joint): two such configurations put
the TCP within about the tracker's resolution of each other, so the row says nothing the fit did not see. The
comparison is by joint values, so training rows reordered, re-saved or mixed into another file are found whatever
the file's bytes are. The certificate states how many rows were removed; when too few are left it refuses.
"""

from __future__ import annotations

import numpy as np

from pin_kpi_oed.errors import InputError

__all__ = ["repeated_rows", "joint_tolerance", "held_out_only", "MIN_HELD_OUT"]

#: The fewest held-out rows a certificate states accuracy on.
MIN_HELD_OUT = 10


def joint_tolerance(reach_m: float, resolution_m: float) -> float:
    """δq = resolution / reach (rad): joint values closer than this on every joint are one configuration."""
    return float(resolution_m) / max(float(reach_m), 1e-9)


def repeated_rows(Q_train: np.ndarray, Q_test: np.ndarray, tol: float) -> np.ndarray:
    """(m,) bool: held-out rows with a training row within ``tol`` on every joint (max-norm)."""
    from scipy.spatial import cKDTree

    Qa, Qb = np.atleast_2d(np.asarray(Q_train, float)), np.atleast_2d(np.asarray(Q_test, float))
    if not len(Qa) or not len(Qb):
        return np.zeros(len(Qb), bool)
    d, _ = cKDTree(Qa).query(Qb, k=1, p=np.inf, distance_upper_bound=tol * (1 + 1e-12) + 1e-15)
    return np.isfinite(d)


def held_out_only(Q_train: np.ndarray, Q_test: np.ndarray, reach_m: float, resolution_m: float, where: str
                  ) -> tuple[np.ndarray, dict]:
    """(indices of the held-out rows kept, the record the certificate prints).

    Args:
        Q_train, Q_test: training and held-out configurations (rad / m).
        reach_m: the robot's reach (m).
        resolution_m: the tracker's resolution at the TCP (m).
        where: the held-out file (named in the refusal).

    Returns:
        (kept rows, ``{"rows", "removed", "kept", "tol_rad", "resolution_m"}``).

    Raises:
        InputError: fewer than :data:`MIN_HELD_OUT` rows are left.
    """
    tol = joint_tolerance(reach_m, resolution_m)
    rep = repeated_rows(Q_train, Q_test, tol)
    keep = np.flatnonzero(~rep)
    rec = {"rows": int(len(rep)), "removed": int(rep.sum()), "kept": int(keep.size), "tol_rad": tol,
           "resolution_m": float(resolution_m)}
    if keep.size < MIN_HELD_OUT:
        raise InputError(f"{where}: {rec['removed']} of {rec['rows']} rows repeat training configurations (joints "
                         f"within {tol * 1e6:.3g} µrad, {resolution_m * 1e6:g} µm at the reach): {keep.size} rows are "
                         f"held out, a certificate needs {MIN_HELD_OUT}")
    return keep, rec
