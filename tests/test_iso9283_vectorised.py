"""The ISO 9283 figures computed with NumPy equal the plain per-pair loops (kept here as the independent reference):
configurations, cycle groups, AP and vAP per commanded position, on the IPA UR10 series and on random inputs."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose

from pin_kpi_oed.report.iso9283 import clusters, commanded_groups, direction_keys, iso_figures, pose_accuracy, \
    repeatability
from tests._cache_g import IPA_GROUP, ipa_series

REPO = Path(__file__).resolve().parents[1]
_IPA = next((p / "shared" / "data" / "ipa_ur10" for p in (REPO.parents[0], REPO.parents[1])
             if (p / "shared" / "data" / "ipa_ur10").is_dir()), None)


def _loop_clusters(X: np.ndarray, tol: float, min_size: int = 2) -> list[np.ndarray]:
    """Reference: one mask per component label."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    X = np.asarray(X, float)
    if len(X) == 0:
        return []
    pairs = cKDTree(X).query_pairs(r=tol, p=np.inf, output_type="ndarray")
    A = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(X), len(X)))
    _, lab = connected_components(A, directed=False)
    rows: dict[int, list[int]] = {}  # each label's rows, ascending: one pass (a mask per label was n x labels)
    for i, k in enumerate(lab.tolist()):
        rows.setdefault(k, []).append(i)
    return [np.array(rows[k]) for k in sorted(rows) if len(rows[k]) >= min_size]


def _loop_direction_keys(Q: np.ndarray, tol_rad: float = 1e-3) -> np.ndarray:
    key = np.full(len(Q), -1)
    for k, g in enumerate(_loop_clusters(Q, tol_rad, min_size=1)):
        key[g] = k
    return key


def _loop_pose_accuracy(resid_m: np.ndarray, groups: list[np.ndarray], directions: np.ndarray) -> list[dict]:
    """Reference: per position, each direction's barycentre by a mask, vAP over every pair in a double loop."""
    rows = []
    for g in groups:
        e = resid_m[g]
        bary = e.mean(axis=0)
        dirs = np.unique(directions[g])
        B = np.array([e[directions[g] == d].mean(axis=0) for d in dirs])
        b = B.tolist()  # the distance of each pair by math.dist (np.linalg.norm's call cost 5 us a pair)
        vap = max(math.dist(b[i], b[j]) for i in range(len(b)) for j in range(i + 1, len(b))) if len(b) > 1 else None
        rows.append({"AP_m": float(np.linalg.norm(bary)), "AP_xyz_m": bary.tolist(), "vAP_m": vap, "n": int(g.size),
                     "directions": int(len(dirs))})
    return rows


def _assert_same_positions(got: dict, want: list[dict]) -> None:
    rows = got["per_position"]
    assert len(rows) == len(want) == got["n_positions"]
    assert [(r["n"], r["directions"], r["vAP_m"] is None) for r in rows] == \
        [(r["n"], r["directions"], r["vAP_m"] is None) for r in want]
    assert_allclose([r["AP_m"] for r in rows], [r["AP_m"] for r in want], rtol=1e-12, atol=0)
    assert_allclose([r["AP_xyz_m"] for r in rows], [r["AP_xyz_m"] for r in want], rtol=1e-12, atol=1e-24)
    assert_allclose([r["vAP_m"] for r in rows if r["vAP_m"] is not None],
                    [r["vAP_m"] for r in want if r["vAP_m"] is not None], rtol=1e-12, atol=0)
    vaps = [r["vAP_m"] for r in want if r["vAP_m"] is not None]
    assert got["vAP"]["n_positions"] == len(vaps)
    if vaps:
        assert_allclose(got["vAP"]["max_m"], max(vaps), rtol=1e-12)


@pytest.mark.skipif(_IPA is None, reason="IPA UR10 data not found")
@pytest.mark.parametrize("series", [pytest.param("A", marks=pytest.mark.xdist_group(IPA_GROUP)), "B", "D"])
def test_on_the_ipa_series_the_figures_equal_the_loops(series):
    ms = ipa_series(_IPA / f"Series_{series}")  # Series A imported once with tests/test_io.py's (tests/_cache_g.py)
    keys = direction_keys(ms.q)
    assert np.array_equal(keys, _loop_direction_keys(ms.q))
    groups = commanded_groups(ms)
    resid = ms.position_m - ms.position_m.mean(axis=0)
    got = pose_accuracy(resid, groups, keys)
    _assert_same_positions(got, _loop_pose_accuracy(resid, groups, keys))
    assert max(r["directions"] for r in got["per_position"]) >= (2 if series != "D" else 1)
    cycles = [g for g in _loop_clusters(ms.q, 1e-3) if g.size >= 3]
    out = iso_figures(ms, ms.q, resid, resid)
    if cycles:
        assert out["RP"]["per_group"] == repeatability(resid, cycles)["per_group"]
    else:
        assert "RP" not in out


@pytest.mark.parametrize("seed", range(6))
def test_on_random_inputs_the_figures_equal_the_loops(seed):
    """Random residuals, positions of 1-40 rows with 1-12 directions (arbitrary, negative and repeated keys), groups
    in any order and sharing rows; random configurations with chains of near neighbours for the clusters."""
    rng = np.random.default_rng(seed)
    m = 600
    resid = rng.normal(0, 1e-4, (m, 3)) + rng.normal(0, 1e-3, 3)
    directions = rng.choice(rng.integers(-50, 50, 12), m)
    groups = [np.sort(rng.choice(m, rng.integers(1, 41), replace=False)) for _ in range(80)]
    _assert_same_positions(pose_accuracy(resid, groups, directions), _loop_pose_accuracy(resid, groups, directions))
    Q = rng.uniform(-0.05, 0.05, (m, 3))
    Q[rng.choice(m, 200)] = Q[rng.choice(m, 200)] + rng.uniform(-1e-3, 1e-3, (200, 3))  # near duplicates
    for tol, size in ((1e-3, 1), (1e-3, 2), (1e-3, 3), (5e-3, 2)):
        assert [g.tolist() for g in clusters(Q, tol, size)] == [g.tolist() for g in _loop_clusters(Q, tol, size)]
    assert np.array_equal(direction_keys(Q), _loop_direction_keys(Q))
    assert len(_loop_clusters(Q, 1e-3, 3)) > 0  # the case has cycle groups


def test_empty_inputs():
    assert clusters(np.zeros((0, 6)), 1e-3) == [] and direction_keys(np.zeros((0, 6))).size == 0
    got = pose_accuracy(np.zeros((5, 3)), [], np.zeros(5, int))
    assert got["n_positions"] == 0 and got["AP"]["mean_m"] is None and got["vAP"]["n_positions"] == 0
