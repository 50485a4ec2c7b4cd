"""The Monte-Carlo draws of the certificates and of the joint-angle level, batched, against the per-draw computations
they replaced (each former computation written out here, the same random numbers): CPU time per call and the largest
difference.

* camera certificate (``camera_monte_carlo``): the TCP of 2000 drawn robots (eye-in-hand UR5 of the camera tests,
  two working configurations) through ``model.kpi`` one draw at a time against ``sensor_points`` in one pass;
* GUM budget (``monte_carlo``): the parameters' draws D F z (82 path samples, 30 parameters, 2000 draws) as one
  three-operand contraction against ``linear_draws`` (D F formed once); the discrepancy's L z against
  ``discrepancy_draws``;
* joint-angle level (``fit_joint_angle``): the leave-one-pose-out density of 30 poses, one group at a time against
  ``loo_log_density`` (the groups of one size together).

Run: ``python -m benchmarks monte_carlo_draws``.
"""

from __future__ import annotations

import numpy as np  # imported first, as user scripts do  # noqa: I001

import time

import pinocchio as pin

from pin_kpi_oed.discrepancy.joint_angle import loo_log_density
from pin_kpi_oed.model.camera import Board, CameraModel, Intrinsics
from pin_kpi_oed.model.robot import load_robot
from pin_kpi_oed.report.uncertainty import discrepancy_draws, linear_draws


def _cpu(f, repeat: int = 3) -> tuple[float, object]:
    """(the smallest CPU time of ``repeat`` calls (s), the last result)."""
    best, out = np.inf, None
    for _ in range(repeat):
        t = time.process_time()
        out = f()
        best = min(best, time.process_time() - t)
    return best, out


def _line(what: str, old: float, new: float, diff: float, unit: str) -> None:
    print(f"{what}: former {old * 1e3:.1f} ms, batched {new * 1e3:.1f} ms ({old / max(new, 1e-9):.0f}x); "
          f"largest difference {diff:.1e} {unit}")


def _camera() -> None:
    intr = Intrinsics(1200.0, 1210.0, 640.0, 512.0, np.array([-0.1, 0.05, 1e-3, -5e-4, 0.01]))
    cam = CameraModel(load_robot("ur5"), intr, Board(6, 8, 0.025), mode="eye_in_hand",
                      camera_pose=pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, 0.3), np.array([0.05, 0.0, 0.03])),
                      board_pose=pin.SE3(np.eye(3), np.array([0.4125, 0.0375, 0.0])).inverse(),
                      tcp_m=np.array([0.0, 0.0, 0.15]))
    Q = np.array([[0.0, -1.57, 1.57, -1.57, -1.57, 0.0], [0.2, -1.4, 1.5, -1.7, -1.5, 0.3]])
    P = np.random.default_rng(0).normal(scale=1e-3, size=(2000, cam.n_params))
    old, a = _cpu(lambda: np.array([cam.kpi(p, Q) for p in P]), 1)
    new, b = _cpu(lambda: cam.sensor_points(P, Q, cam.tcp_m))
    _line("camera TCP of 2000 drawn robots", old, new, float(np.abs(np.asarray(a) - np.asarray(b)).max()), "m")


def _gum() -> None:
    rng = np.random.default_rng(1)
    D = rng.standard_normal((82, 3, 30)) * 1e-3
    B = rng.standard_normal((30, 30))
    C = B @ B.T
    w, V = np.linalg.eigh(C)
    F = V * np.sqrt(np.maximum(w, 0.0))
    old, a = _cpu(lambda: np.einsum("map,pk,nk->nma", D, F, np.random.default_rng(2).standard_normal((2000, 30))))
    new, b = _cpu(lambda: linear_draws(D, C, 2000, np.random.default_rng(2)))
    _line("GUM parameter draws (2000 x 82 rows)", old, new,
          float(np.abs(np.asarray(a) - np.asarray(b)).max() / np.abs(np.asarray(a)).max()), "relative")
    K = np.exp(-0.5 * (np.arange(82)[:, None] - np.arange(82)[None]) ** 2 / 25.0)
    Lk = np.linalg.cholesky(K + 1e-12 * np.eye(82))

    def former():
        g = np.random.default_rng(3)
        return np.einsum("ij,nja->nia", Lk, g.standard_normal((2000, 82, 3))) * 1e-5 \
            + g.standard_normal((2000, 82, 3)) * 1e-6

    old, a = _cpu(former)
    new, b = _cpu(lambda: discrepancy_draws(K, 1e-5, 1e-12, 2000, np.random.default_rng(3)))
    _line("GUM discrepancy draws (2000 x 82 rows)", old, new,
          float(np.abs(np.asarray(a) - np.asarray(b)).max() / np.abs(np.asarray(a)).max()), "relative")


def per_group_loo_log_density(Sigma: np.ndarray, Fs: np.ndarray, r: np.ndarray, groups: np.ndarray) -> np.ndarray:
    """The former ``loo_log_density``: one pose group at a time (the reference the batched one is checked against,
    here and in tests/test_joint_angle_sigma.py). Args as ``loo_log_density``; a group whose left-out covariance is
    not positive definite is −inf."""
    k = len(r)
    H = Fs @ np.linalg.pinv(Fs, rcond=1e-12)
    M = np.eye(k) - H
    out = []
    for g in np.unique(groups):
        idx = (3 * np.flatnonzero(groups == g)[:, None] + np.arange(3)).reshape(-1)
        B = np.linalg.pinv(np.eye(idx.size) - H[np.ix_(idx, idx)], rcond=1e-10)
        A, e = B @ M[idx, :], B @ r[idx]
        C = A @ Sigma @ A.T
        C = 0.5 * (C + C.T) + 1e-12 * np.trace(C) / idx.size * np.eye(idx.size)
        sign, logdet = np.linalg.slogdet(C)
        out.append(-np.inf if sign <= 0 else
                   -0.5 * (float(e @ np.linalg.solve(C, e)) + logdet + idx.size * np.log(2.0 * np.pi)))
    return np.array(out)


def _loo() -> None:
    rng = np.random.default_rng(4)
    n = 30
    Fs = rng.standard_normal((3 * n, 18))
    L = rng.standard_normal((3 * n, 3 * n))
    Sigma = L @ L.T / (3 * n) + 0.1 * np.eye(3 * n)
    r = rng.standard_normal(3 * n)
    groups = np.arange(n)

    old, a = _cpu(lambda: per_group_loo_log_density(Sigma, Fs, r, groups), 10)
    new, b = _cpu(lambda: loo_log_density(Sigma, Fs, r, groups), 10)
    _line("leave-one-pose-out density of 30 poses", old, new,
          float(np.abs(np.asarray(a) - np.asarray(b)).max() / np.abs(np.asarray(a)).max()), "relative")


def main() -> None:
    """Print the figures (module docstring)."""
    from pin_kpi_oed.threads import limited_threads

    with limited_threads():
        _camera()
        _gum()
        _loo()


if __name__ == "__main__":
    main()
