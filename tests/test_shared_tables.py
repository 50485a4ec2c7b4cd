"""The tables a monitor's checks share (calibrated/shared_tables.py) change no result: a station model's kinematics
from the shared table are the tracker model's bit for bit, a discrepancy's rows are computed once and equal the
Gaussian process's own prediction, and a check inside the tables is the check outside them."""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pytest

from pin_kpi_oed import load_robot
from pin_kpi_oed.calibrated.shared_tables import (RESULT_TABLE_NUMBERS, StationTracker, discrepancy_at,
                                                  posterior_covariance_at, remembered, row_tables)
from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.discrepancy.gp import DiscrepancyOptions
from pin_kpi_oed.discrepancy.fit import fit_discrepancy
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.studies.check_events import simulated_model
from pin_kpi_oed.upkeep.check import check_calibration

SIGMA = 2e-5


@pytest.fixture(scope="module")
def setting():
    rb = load_robot("ur10")
    rng = np.random.default_rng(0)
    model = simulated_model(rb, 0.5 * rng.uniform(rb.q_lower, rb.q_upper, size=(5, rb.nq)), SIGMA, 0)
    Qt = 0.7 * rng.uniform(rb.q_lower, rb.q_upper, size=(120, rb.nq))
    R = 3e-5 * np.sin(2.0 * Qt[:, 1:4]) + SIGMA * rng.standard_normal((120, 3))
    d = fit_discrepancy(Qt, R, list(rb.joint_names), DiscrepancyOptions(mode="on", n_fit=120, starts=(0.1,)),
                        periodic=rb.periodic_joints)
    assert d is not None and d.kind == "exact"
    return rb, dataclasses.replace(model, discrepancy=d), rng


class Counting:
    """A discrepancy that counts the rows it is asked to predict."""

    def __init__(self, d):
        self.d, self.rows = d, 0

    def predict(self, Q, return_var=True):
        self.rows += len(Q)
        return self.d.predict(Q, return_var)


def test_station_kinematics_are_the_tracker_models_bit_for_bit(setting):
    rb, model, rng = setting
    wm, p = model.station_model()
    assert isinstance(wm, StationTracker)
    st = model.setups[model.station()]
    plain = TrackerModel(rb, tracker_T_base=pin.SE3(st.tracker_T_base), reflector_m=st.reflector_m, tcp_m=model.tcp_m,
                         noise=model.noise, layout=wm.layout)
    Q = 0.7 * rng.uniform(rb.q_lower, rb.q_upper, size=(7, rb.nq))
    for step in range(3):           # the set-up moves (a registration's steps), the joints' part stays: table hits
        p[wm.layout.tracker] = 1e-3 * step * np.arange(1, 7)
        assert np.array_equal(wm.predict(p, Q), plain.predict(p, Q))
        assert np.array_equal(wm.jacobian(p, Q), plain.jacobian(p, Q))
    other = p.copy()
    other[3] += 1e-3                # another robot geometry is not taken from the table
    assert np.array_equal(wm.predict(other, Q), plain.predict(other, Q))
    assert not np.array_equal(wm.predict(other, Q), wm.predict(p, Q))
    again, _ = model.station_model()
    assert again.chain is wm.chain                       # the chain is built once per robot
    assert np.array_equal(again.predict(p, Q), plain.predict(p, Q))


def test_discrepancy_rows_are_computed_once_and_equal_the_processes(setting):
    rb, model, rng = setting
    c = Counting(model.discrepancy)
    Q = 0.6 * rng.uniform(rb.q_lower, rb.q_upper, size=(40, rb.nq))
    mean, var = model.discrepancy.predict(Q)
    outside = discrepancy_at(c, Q)
    assert c.rows == 40 and np.array_equal(outside[0], mean) and np.array_equal(outside[1], var)
    with row_tables():
        discrepancy_at(c, Q[:10], return_var=False)      # the mean alone: the variance computed when asked
        first = discrepancy_at(c, Q[:30])
        both = discrepancy_at(c, Q)
        assert c.rows == 40 + 10 + 30 + 10
        assert discrepancy_at(c, Q[5:25], return_var=False)[1] is None and c.rows == 90
    np.testing.assert_allclose(both[0], mean, rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(both[1], var, rtol=1e-12, atol=1e-24)
    assert np.array_equal(first[0], both[0][:30])
    discrepancy_at(c, Q)
    assert c.rows == 130                                 # the tables are emptied at the end


def test_posterior_covariance_from_the_rows_columns_is_the_processes(setting):
    rb, model, rng = setting
    d = model.discrepancy
    Q = 0.6 * rng.uniform(rb.q_lower, rb.q_upper, size=(40, rb.nq))
    with row_tables():
        for window in (Q[:10], Q[:20], Q[10:40], Q[::-1]):     # growing, sliding, reordered windows
            K, ref = posterior_covariance_at(d, window), d.posterior_covariance(window)
            np.testing.assert_allclose(K, ref, rtol=1e-9, atol=1e-12 * np.max(np.abs(ref)))
        white = dataclasses.replace(d, kind="white")
        assert np.array_equal(posterior_covariance_at(white, Q[:5]), np.zeros((5, 5)))


def test_remembered_results_are_copies_and_only_inside_the_tables():
    calls = []

    def compute():
        calls.append(1)
        return np.arange(3.0)

    assert np.array_equal(remembered(("k",), compute), np.arange(3.0)) and len(calls) == 1
    remembered(("k",), compute)
    assert len(calls) == 2
    with row_tables():
        a = remembered(("k",), compute)
        a[0] = 99.0
        assert remembered(("k",), compute)[0] == 0.0 and len(calls) == 3
        big = []
        for _ in range(2):          # a result too large for the table is computed every time
            remembered(("big",), lambda: big.append(1) or np.zeros(RESULT_TABLE_NUMBERS))
        assert len(big) == 2


def test_a_check_inside_the_tables_is_the_check_outside(setting):
    rb, model, rng = setting
    Q = 0.7 * rng.uniform(rb.q_lower, rb.q_upper, size=(30, rb.nq))
    Y = model.predict(Q) + rng.normal(size=(30, 3)) * SIGMA
    rows = MeasurementSet(list(rb.joint_names), Q, Y)
    plain = check_calibration(model, rows, propose=False)
    with row_tables():
        model.predict_with_sigma(Q[:10])                 # rows first predicted in another batch, as a monitor does
        model.predict_with_sigma(Q[10:20])
        shared = check_calibration(model, rows, propose=False)
    assert shared.verdict == plain.verdict and shared.setup_determined == plain.setup_determined
    np.testing.assert_allclose(shared.chi2, plain.chi2, rtol=1e-8)
    np.testing.assert_allclose(shared.tcp_sigma_m, plain.tcp_sigma_m, rtol=1e-10)
    np.testing.assert_allclose(shared.model.setups["check"].tracker_T_base,
                               plain.model.setups["check"].tracker_T_base, rtol=0, atol=1e-12)
