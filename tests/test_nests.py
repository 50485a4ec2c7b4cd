"""Several reflector nests: the nest rows' Jacobian against finite differences, the fit at each row's nest, and a
design that measures the second nest where it lowers the TCP's tr C_s (and not where it does not)."""

from __future__ import annotations

import numpy as np
import pytest

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.noise import NoiseModel
from pin_kpi_oed.model.robot import load_robot
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.simulation.simulator import default_tracker_pose

NESTS = [[0.0, 0.0, 0.0], [0.06, 0.0, 0.05]]  # one on the last joint's axis, one off it


@pytest.fixture(scope="module")
def ur5():
    return load_robot("ur5")


def _model(rb, tcp=(0.0, 0.0, 0.15)):
    return TrackerModel(rb, tracker_T_base=default_tracker_pose(rb), reflector_m=NESTS[0], tcp_m=np.array(tcp),
                        nests_m=NESTS, noise=NoiseModel(sigma_xyz_m=(2.5e-5,) * 3))


def test_nest_rows_jacobian_matches_finite_differences(ur5):
    model = _model(ur5)
    rng = np.random.default_rng(0)
    Q, nest = ur5.random_q(rng, 6), np.array([0, 1, 1, 0, 1, 0])
    mn = model.at_nests(nest)
    p = rng.normal(size=model.n_params) * 1e-3
    J = mn.jacobian(p, Q)
    h = 1e-7
    Jfd = np.stack([(mn.predict(p + h * e, Q) - mn.predict(p - h * e, Q)) / (2 * h)
                    for e in np.eye(model.n_params)], axis=-1)
    assert np.max(np.abs(J - Jfd)) < 1e-6 * np.max(np.abs(J))
    # row i is the point of nest i: the same as a model of that nest alone
    for k in (0, 1):
        one = model.at_nests(np.full(len(Q), k))
        assert np.allclose(mn.predict(p, Q)[nest == k], one.predict(p, Q)[nest == k], atol=1e-12)
    assert not np.allclose(mn.predict(p, Q), model.predict(p, Q))
    # the shared offset moves every nest alike: its columns are the tool's rotation at every row
    _, J2, _, _ = mn.jacobian_dq(p, Q)
    assert np.allclose(J2, J, atol=1e-12)


def test_bad_nests_are_refused_naming_the_field(ur5):
    with pytest.raises(InputError, match="nest 0"):
        TrackerModel(ur5, reflector_m=[0.01, 0, 0], nests_m=NESTS)
    with pytest.raises(InputError, match="nest 2 is not one of the tool's nests 0 … 1"):
        _model(ur5).at_nests([0, 2])


def test_identify_fits_each_row_at_its_nest(ur5):
    """Noise-free rows at two nests, a truth with joint errors: the fit reproduces them to the solver's tolerance,
    the model identifies the last joint's rotation a single nest on its axis cannot see."""
    from pin_kpi_oed.identification.identify import identify
    from pin_kpi_oed.simulation.simulator import random_truth, simulate

    model = _model(ur5)
    rng = np.random.default_rng(1)
    Q = ur5.random_q(rng, 36)
    nest = np.arange(36) % 2
    data = simulate(model, Q, random_truth(model, seed=2), nest=nest, seed=3,
                    noise=NoiseModel(sigma_xyz_m=(1e-9,) * 3))
    assert np.array_equal(data.extra["nest"], nest)
    res = identify(model, data, discrepancy="none")
    assert np.sqrt(np.mean(res.residuals_m ** 2)) < 1e-7
    assert "wrist_3_joint.rx" in res.names


def test_design_measures_the_second_nest_where_it_helps(ur5):
    """TCP 0.15 m out on the last axis, nest 0 on that axis: its rotations across the axis are held and the
    second nest removes them (tr C_s far lower); with the TCP at nest 0 they move no TCP and the design keeps one
    nest."""
    from pin_kpi_oed.oed.nests import assign_nests, nest_trace

    rng = np.random.default_rng(0)
    Q, Qw = ur5.random_q(rng, 30), ur5.random_q(rng, 4)
    far = assign_nests(_model(ur5), Q, Qw)
    assert set(far.nest.tolist()) == {0, 1}
    assert far.chosen.total_m2 < 0.5 * far.one.total_m2
    assert far.chosen.total_m2 == pytest.approx(nest_trace(_model(ur5), Q, far.nest, Qw).total_m2, rel=1e-12)
    assert "less" in far.line() and "nest 1 at" in far.line()
    near = assign_nests(_model(ur5, tcp=NESTS[0]), Q, Qw)
    assert set(near.nest.tolist()) == {0}
    assert "no other nest lowers it" in near.line()
