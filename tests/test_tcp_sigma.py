"""The TCP's σ with the parameters held at nominal: the formula against Monte-Carlo fits and finite differences."""

from __future__ import annotations

import numpy as np
import pytest

from pin_kpi_oed.simulation.simulator import default_tracker_pose
from pin_kpi_oed.model.noise import NoiseModel
from pin_kpi_oed.model.robot import load_robot
from pin_kpi_oed.model.tolerances import Tolerances, held_columns
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.oed.covariance import held_absorption, held_covariance, tcp_covariances
from pin_kpi_oed.oed.identifiability import analyse

NOISE_M = 1e-4


@pytest.fixture(scope="module")
def ur3():
    """A UR3 measured at a reflector off the flange axis, its TCP 0.15 m out; 30 measured, 4 working poses."""
    rb = load_robot("ur3")
    model = TrackerModel(rb, tracker_T_base=default_tracker_pose(rb), reflector_m=np.array([0.03, 0.0, 0.02]),
                         tcp_m=np.array([0.0, 0.01, 0.15]), noise=NoiseModel(sigma_xyz_m=(NOISE_M,) * 3))
    B = analyse(model, Q=rb.random_q(np.random.default_rng(1), 60)).base
    N = held_columns(model, B)
    rng = np.random.default_rng(2)
    return model, B, N, rb.random_q(rng, 30), rb.random_q(rng, 4)


def test_held_columns_are_what_the_reflector_cannot_see(ur3):
    model, B, N, _, _ = ur3
    names = {model.layout.names[i] for i in N}
    assert {"wrist_3_joint.tz", "wrist_3_joint.rz", "shoulder_pan_joint.tx"} <= names
    assert not names & {model.layout.names[i] for i in B}


def test_tcp_covariance_matches_monte_carlo_fits(ur3):
    """Truths with every held parameter drawn from its tolerance, the identified ones at random, the tracker's
    noise: the fitted model's TCP error (nonlinear kinematics, Gauss-Newton fit over the identified parameters)
    has the covariance E_B C_p E_Bᵀ + G Σ_N Gᵀ, within a few %; without the held term the σ is far too small.
    The 1500 robots go through the kinematics together (``sensor_points``: each draw's reflector in the tracker
    frame, ``predict``, and its TCP, ``kpi``, to 1e-12 m, asserted on the first draws), each with its own fit."""
    model, B, N, Q, Qw = ur3
    p0 = np.zeros(model.n_params)
    F = model.weighted_jacobian(p0, Q).reshape(-1, model.n_params)
    E = model.kpi_jacobian(p0, Qw)
    s_all = Tolerances().sigma_vector(model)
    C_p, C_s, C_h = tcp_covariances(F[:, B], F[:, N], E[:, B], E[:, N], s_all[N])
    sB = np.where(s_all[B] > 0, s_all[B], 1e-3)
    rng = np.random.default_rng(3)
    n = 1500
    P, noise = np.zeros((n, model.n_params)), np.empty((n, len(Q), 3))
    for k in range(n):  # the truths and their noise, drawn in turn
        P[k, B] = rng.normal(size=B.size) * sB
        P[k, N] = rng.normal(size=N.size) * s_all[N]
        noise[k] = rng.normal(size=(len(Q), 3)) * NOISE_M

    def predict(Pk):  # each row's reflector positions in the tracker frame, (k, m, 3)
        return model.sensor_points(Pk, Q, np.array([model.reflector(p) for p in Pk]))

    y = predict(P) + noise
    assert np.abs(y[:3] - noise[:3] - [model.predict(p, Q) for p in P[:3]]).max() < 1e-12
    ph = np.zeros_like(P)
    for _ in range(2):  # Gauss-Newton with the Jacobian frozen at the nominal model, every draw's fit at once
        ph[:, B] += ((y - predict(ph)) / NOISE_M).reshape(n, -1) @ F[:, B] @ C_p.T
    err = (model.sensor_points(ph, Qw, model.tcp_m) - model.sensor_points(P, Qw, model.tcp_m)).reshape(n, -1)
    assert np.abs(err[:3] - [(model.kpi(a, Qw) - model.kpi(b, Qw)).ravel() for a, b in zip(ph[:3], P[:3])]).max() \
        < 1e-12
    sq = np.sum(err ** 2, axis=1)
    ratio = sq.mean() / np.trace(C_s)
    se = sq.std() / np.sqrt(n) / sq.mean()
    assert se < 0.04
    assert abs(ratio - 1.0) < max(3 * se, 0.03), (ratio, se)
    per = np.einsum("kia,kia->i", err.reshape(n, 4, 3), err.reshape(n, 4, 3)) / n
    pred = np.einsum("iaia->i", C_s.reshape(4, 3, 4, 3))
    assert np.all(np.abs(per / pred - 1.0) < 0.12), per / pred
    assert np.trace(C_h) > 0.5 * np.trace(C_s)  # the held part is no small correction here


def test_held_term_vanishes_at_the_reflector_and_in_the_tracker_frame(ur3):
    """At the reflector itself G = 0 (a held direction is absorbed exactly), and joint 1's placement (held for the
    tracker pose) moves no point in the tracker frame."""
    model, B, N, Q, Qw = ur3
    p0 = np.zeros(model.n_params)
    F = model.weighted_jacobian(p0, Q).reshape(-1, model.n_params)
    A = held_absorption(F[:, B], F[:, N])
    at_r = TrackerModel(model.robot, tracker_T_base=model.tracker_T_base, reflector_m=model.reflector_m,
                        tcp_m=model.reflector_m, noise=model.noise)
    E = at_r.jacobian(p0, Qw)[:, :3].reshape(-1, model.n_params)
    G, C = held_covariance(E[:, B], E[:, N], A, Tolerances().sigma_vector(model)[N])
    assert np.max(np.abs(G)) < 1e-9 * max(1.0, np.max(np.abs(E)))
    Et = model.kpi_jacobian(p0, Qw)
    G2, _ = held_covariance(Et[:, B], Et[:, N], A, np.ones(N.size))
    base = [k for k, i in enumerate(N) if model.layout.names[i].startswith("shoulder_pan_joint.")]
    assert np.max(np.abs(G2[:, base])) < 1e-9
    # the last joint's offset along its axis moves the TCP by itself at every working configuration
    along = np.linalg.norm(G2.reshape(4, 3, -1), axis=1)
    assert np.any(np.all(np.abs(along - 1.0) < 1e-6, axis=0))


def test_held_term_does_not_depend_on_the_design(ur3):
    """A structural dependency is absorbed the same by every design: the held term equals at two designs and its
    finite-difference derivative w.r.t. a measured configuration is zero."""
    model, B, N, Q, Qw = ur3
    p0 = np.zeros(model.n_params)
    E = model.kpi_jacobian(p0, Qw)
    s = Tolerances().sigma_vector(model)[N]

    def held_trace(Qm):
        F = model.weighted_jacobian(p0, Qm).reshape(-1, model.n_params)
        return np.trace(held_covariance(E[:, B], E[:, N], held_absorption(F[:, B], F[:, N]), s)[1])

    t0 = held_trace(Q)
    t1 = held_trace(model.robot.random_q(np.random.default_rng(9), 25))
    assert abs(t1 / t0 - 1.0) < 1e-6
    Qh = Q.copy()
    Qh[3, 2] += 1e-5
    assert abs(held_trace(Qh) - t0) / 1e-5 < 1e-6 * t0
