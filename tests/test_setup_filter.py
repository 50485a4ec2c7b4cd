"""The set-up filter: its drift level estimated from the rows (a simulated random walk of known level is found, a
still set-up is found still), its predictions honest (standardised innovations RMS ≈ 1)."""

from __future__ import annotations

import numpy as np
import pytest

from pin_kpi_oed.upkeep.setup_filter import LEVELS_M_PER_SQRT_S, SetupFilter


def _run(level: float, seed: int, n: int = 1500, dt: float = 30.0, sigma: float = 5e-5, offset_m: float = 0.0):
    """A random walk of the set-up at ``level`` (m/√s) observed through random set-up Jacobians, σ per axis, from a
    set-up ``offset_m`` (m, along x) off the model's."""
    rng = np.random.default_rng(seed)
    L = 2.0
    f = SetupFilter(lever_m=L)
    x = np.r_[offset_m, np.zeros(5)]
    D = np.r_[np.ones(3), np.full(3, 1.0 / L ** 2)]
    z = []
    for i in range(n):
        x = x + rng.standard_normal(6) * np.sqrt(level ** 2 * dt * D)
        p = rng.uniform(-1.5, 1.5, 3)                                      # a point 1-2 m from the tracker
        G = np.hstack([np.eye(3), -np.array([[0, -p[2], p[1]], [p[2], 0, -p[0]], [-p[1], p[0], 0]])])
        s = np.full(3, sigma)
        y = G @ x + rng.standard_normal(3) * s
        f.advance(i * dt)
        mu, C = f.predict(G, s)
        z.append((y - mu) / np.sqrt(np.diag(C)))
        f.update(y, G, s)
    return f, np.asarray(z)


@pytest.mark.parametrize("level", [1e-7, 1e-6])
def test_a_drifting_setup_is_followed_at_its_level(level):
    f, z = _run(level, 0)
    assert level / 3.5 <= f.level_m_per_sqrt_s <= 3.5 * level                # the bank's level nearest the truth
    assert 0.9 < np.sqrt(np.mean(z[300:] ** 2)) < 1.1


def test_a_still_setup_is_found_still_and_outliers_are_not_used():
    f, z = _run(0.0, 1)
    # levels whose drift over the filter's memory (200 rows x 30 s) stays far below σ are alike: at most 1e-7 m/√s
    assert f.level_m_per_sqrt_s <= 1e-7 and 0.9 < np.sqrt(np.mean(z ** 2)) < 1.1
    x0, _ = f.state()
    G = np.hstack([np.eye(3), np.zeros((3, 3))])
    assert f.update(np.full(3, 0.01), G, np.full(3, 5e-5)) is False and f.outliers == 1   # 10 mm off: not used
    assert np.allclose(f.state()[0], x0)
    assert LEVELS_M_PER_SQRT_S[0] == 0.0


@pytest.mark.parametrize("seed", [2, 3, 5])
def test_a_still_setup_off_the_models_is_found_still(seed):
    """A set-up that does not move but sits 40 µm off the model's (its registration's error, a tracker set up again)
    is absorbed by every level's prior alike: not scored as a drift (levels up to 3e-7 m/√s walk 5 µm over the
    rows, far below σ: alike; without the prior 1e-6 m/√s or more, every seed)."""
    f, z = _run(0.0, seed, n=300, dt=1.0, offset_m=4e-5)
    assert f.level_m_per_sqrt_s <= 3e-7 and 0.85 < np.sqrt(np.mean(z ** 2)) < 1.15
    assert f.state()[0][0] == pytest.approx(4e-5, abs=2e-5)


def test_the_banks_update_is_each_levels_kalman_update():
    """Every level of the bank is updated at once; each equals the Kalman update of its own filter written out."""
    rng = np.random.default_rng(4)
    f = SetupFilter(lever_m=2.0)
    for _ in range(5):
        G, sigma, r0 = rng.normal(size=(3, 6)), np.array([4e-5, 5e-5, 6e-5]), rng.normal(size=3) * 5e-5
        f.advance(None)
        x0, P0, ll0 = f.x.copy(), f.P.copy(), f.loglik.copy()
        assert f.update(r0, G, sigma)
        R = np.diag(sigma ** 2)
        for k in range(len(f.levels)):
            S = G @ P0[k] @ G.T + R
            r = r0 - G @ x0[k]
            K = P0[k] @ G.T @ np.linalg.inv(S)
            A = np.eye(6) - K @ G
            np.testing.assert_allclose(f.x[k], x0[k] + K @ r, rtol=1e-10, atol=1e-18)
            np.testing.assert_allclose(f.P[k], A @ P0[k] @ A.T + K @ R @ K.T, rtol=1e-10, atol=1e-30)
            ll = f.forgetting * ll0[k] - 0.5 * (r @ np.linalg.solve(S, r) + np.linalg.slogdet(S)[1]
                                                 + 3 * np.log(2 * np.pi))
            np.testing.assert_allclose(f.loglik[k], ll, rtol=1e-10)
