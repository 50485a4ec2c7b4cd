"""Effects library: analytic derivatives (finite differences), gravity with payload, thermal, spec parser."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from pin_kpi_oed.effects.library import (ALL_EFFECT_NAMES, EFFECT_NAMES, UNOBSERVABLE_NOTES, Backlash, GearHarmonic,
                                         JointCompliance,
                                 JointScale, ThermalExpansion, candidate_effects, effect_jacobian, gravity_torque,
                                 make_effect, parse_effects_spec, predict_with_effects, range_scale_parameters)
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.model.robot import load_robot

from .conftest import make_model


@pytest.fixture(scope="module")
def ur10():
    return load_robot("ur10")


@pytest.fixture(scope="module")
def ur10_model(ur10):
    T = pin.SE3(pin.rpy.rpyToMatrix(0.1, 0.2, 2.0), np.array([3.0, 1.0, -0.5]))
    return TrackerModel(ur10, tracker_T_base=T, reflector_m=np.array([0.05, 0.02, 0.1]))


def _aux(robot, Q, rng, temperature=True, payload=True):
    m = Q.shape[0]
    return MeasurementSet(joint_names=robot.joint_names, q=Q, position_m=np.zeros((m, 3)) + 1.0,
                          temperature_c=20 + 3 * rng.random(m) if temperature else None,
                          payload_kg=2 * rng.random(m) if payload else None)


def test_payload_gravity_matches_pinocchio_point_mass(ur10):
    Q = ur10.random_q(np.random.default_rng(0), 6)
    m2 = ur10.model.copy()
    fr = m2.frames[ur10.tool_frame_id]
    m2.appendBodyToJoint(fr.parentJoint, pin.Inertia(2.5, fr.placement.translation, np.zeros((3, 3))),
                         pin.SE3.Identity())
    d2 = m2.createData()
    ref = np.array([pin.computeGeneralizedGravity(m2, d2, q) for q in Q])
    assert np.allclose(gravity_torque(ur10, Q, 2.5), ref, atol=1e-10)
    # no payload: plain generalized gravity
    d = ur10.model.createData()
    assert np.allclose(gravity_torque(ur10, Q), [pin.computeGeneralizedGravity(ur10.model, d, q) for q in Q])


def test_loaded_joints_ur10(ur10):
    names = JointCompliance(ur10).param_names()
    assert "joint_compliance.shoulder_pan_joint" not in names  # vertical axis carries no gravity torque
    assert "joint_compliance.shoulder_lift_joint" in names and "joint_compliance.elbow_joint" in names
    assert len(JointCompliance(ur10, joints="all").param_names()) == 6
    with pytest.raises(InputError, match="unknown joint"):
        JointCompliance(ur10, joints=["nope"])


def _reference_column(robot, pname: str, Q: np.ndarray) -> np.ndarray:
    """Joint-offset column of one effect parameter, from its NAME alone (independent of the effect code)."""
    import re

    import pinocchio as pin

    eff, joint, *rest = pname.split(".")
    j = robot.joint_names.index(joint)
    col = np.zeros(Q.shape)
    if eff in ("joint_compliance", "backlash"):
        data = robot.model.createData()
        tau = np.array([pin.computeGeneralizedGravity(robot.model, data, q)[j] for q in Q])
        col[:, j] = tau if eff == "joint_compliance" else np.sign(tau)
    elif eff in ("gear_harmonic", "transmission_error"):
        f, order = re.fullmatch(r"(sin|cos)(\d+)", rest[0]).groups()
        col[:, j] = getattr(np, f)(int(order) * Q[:, j])
    elif eff == "joint_scale":
        col[:, j] = Q[:, j]
    elif eff == "link_bending":
        f, angle = re.fullmatch(r"(sin|cos)\((.+)\)", rest[0]).groups()
        phi = sum(Q[:, int(t[1:]) - 1] for t in angle.split("+"))  # "q2+q3": joints 2 and 3 (1-based)
        col[:, j] = getattr(np, f)(phi)
    else:
        raise AssertionError(f"no reference for {pname}")
    return col


@pytest.mark.parametrize("name", [n for n in ALL_EFFECT_NAMES if n not in ("thermal_expansion", "drift")])
def test_joint_offset_basis_matches_closed_form(ur10, name):
    """Each column dQ/dθ_i equals the closed form its parameter name states (catches a wrong basis, which a
    finite-difference check of a linear effect cannot), and dQ = Σ θ_i dQ/dθ_i."""
    rng = np.random.default_rng(1)
    Q = ur10.random_q(rng, 25)
    eff = make_effect(name, ur10)
    names = eff.param_names()
    th = rng.normal(size=len(names)) * 1e-3
    dQ, D = eff.joint_offset(th, Q, None)
    assert D.shape == Q.shape + (len(names),)
    for i, pname in enumerate(names):
        ref = _reference_column(ur10, pname, Q)
        assert np.abs(ref).max() > 0, f"{pname}: reference column is zero, the check would prove nothing"
        assert np.allclose(D[:, :, i], ref, atol=1e-12 * max(1.0, np.abs(ref).max())), pname
    assert np.allclose(dQ, D @ th, atol=1e-15)


def test_joint_offset_values(ur10):
    rng = np.random.default_rng(2)
    Q = ur10.random_q(rng, 10)
    aux = _aux(ur10, Q, rng)
    tau = gravity_torque(ur10, Q, aux.payload_kg)
    c = JointCompliance(ur10)
    th = np.array([1e-6, 2e-6])
    dQ, _ = c.joint_offset(th, Q, aux)
    assert np.allclose(dQ[:, c.joints], tau[:, c.joints] * th)
    assert np.all(dQ[:, 0] == 0)
    b = Backlash(ur10)
    dQ, _ = b.joint_offset(np.array([1e-4, -2e-4]), Q, aux)
    assert np.allclose(np.abs(dQ[:, b.joints]), [1e-4, 2e-4])
    g = GearHarmonic(ur10)
    th = np.zeros(g.n_params)
    th[4:8] = [1e-4, 2e-4, 3e-4, 4e-4]  # shoulder_lift_joint
    dQ, _ = g.joint_offset(th, Q)
    q = Q[:, 1]
    assert np.allclose(dQ[:, 1], 1e-4 * np.sin(q) + 2e-4 * np.cos(q) + 3e-4 * np.sin(2 * q) + 4e-4 * np.cos(2 * q))
    s = JointScale(ur10)
    dQ, _ = s.joint_offset(np.full(6, 1e-3), Q)
    assert np.allclose(dQ, 1e-3 * Q)


def test_thermal_first_order_is_exact_for_scaled_links(ur10, ur10_model):
    """Scaling every placement translation and the tool offset by (1+ε) == the tool offset with α ΔT = ε."""
    rng = np.random.default_rng(3)
    Q = ur10.random_q(rng, 20)
    eps = 2e-4
    v = ThermalExpansion(ur10).direction(Q, ur10_model) * eps
    r2 = load_robot("ur10")
    for j in r2.joint_ids:
        M = r2.model.jointPlacements[j]
        r2.model.jointPlacements[j] = pin.SE3(M.rotation, M.translation * (1 + eps))
    F = r2.model.frames[r2.tool_frame_id]
    F.placement = pin.SE3(F.placement.rotation, F.placement.translation * (1 + eps))
    r2.model.frames[r2.tool_frame_id] = F
    m2 = TrackerModel(r2, tracker_T_base=ur10_model.tracker_T_base, reflector_m=ur10_model.reflector_m)
    p0 = np.zeros(ur10_model.n_params)
    exact = m2.predict(p0, Q) - ur10_model.predict(p0, Q)
    assert np.abs(exact - v).max() < 1e-12
    # tool_offset: α (T - T_ref) times that direction, derivative exact
    aux = _aux(ur10, Q, rng)
    th = ThermalExpansion(ur10, t_ref_c=21.0)
    dY, D = th.tool_offset(np.array([eps]), Q, aux, ur10_model, p0)
    assert np.allclose(dY, (aux.temperature_c - 21.0)[:, None] * v)
    assert np.allclose(D[:, :, 0] * eps, dY)


def test_thermal_needs_temperature(ur10, ur10_model):
    rng = np.random.default_rng(4)
    Q = ur10.random_q(rng, 5)
    aux = _aux(ur10, Q, rng, temperature=False)
    th = ThermalExpansion(ur10)
    assert "temperature" in th.check(aux)
    assert th.check(None) is not None
    with pytest.raises(InputError, match="temperature"):
        th.tool_offset(np.array([1e-5]), Q, aux, ur10_model, np.zeros(ur10_model.n_params))
    const = _aux(ur10, Q, rng)
    const.temperature_c[:] = 21.0
    assert "constant" in th.check(const)
    assert th.check(_aux(ur10, Q, rng)) is None
    assert JointCompliance(ur10).check(aux) is None  # payload optional


def test_combined_effect_jacobian_fd(ur10, ur10_model):
    """∂Y/∂θ = Ydq(Q + ΣdQ) ∂dQ/∂θ + ∂dY/∂θ against central differences of the full prediction."""
    rng = np.random.default_rng(5)
    Q = ur10.random_q(rng, 12)
    aux = _aux(ur10, Q, rng)
    p = rng.normal(size=ur10_model.n_params) * 1e-4
    effs = candidate_effects(ur10)
    thetas = [rng.normal(size=e.n_params) * s for e, s in zip(effs, (1e-6, 1e-4, 1e-4, 2e-5, 1e-4))]
    pairs = list(zip(effs, thetas))
    J = effect_jacobian(ur10_model, p, Q, aux, pairs)
    theta = np.concatenate(thetas)
    sizes = np.cumsum([0] + [e.n_params for e in effs])

    def pred(t):
        parts = [(e, t[sizes[i]:sizes[i + 1]]) for i, e in enumerate(effs)]
        return predict_with_effects(ur10_model, p, Q, aux, parts)[:, :3]

    h = 1e-7
    scale = np.abs(J).max()
    for i in range(theta.size):
        e = np.zeros(theta.size)
        e[i] = h * max(1.0, abs(theta[i]) * 1e3)
        fd = (pred(theta + e) - pred(theta - e)) / (2 * e[i])
        assert np.allclose(fd, J[:, :, i], atol=1e-6 * scale + 1e-9), f"column {i}"


def test_range_scale_is_unobservable(ur10_model):
    """A tracker range-scale error is reproduced exactly by geometric parameters."""
    Q = ur10_model.robot.random_q(np.random.default_rng(6), 30)
    s = 3e-5
    p = range_scale_parameters(ur10_model, s)
    Y0 = ur10_model.predict(np.zeros_like(p), Q)
    assert np.abs(ur10_model.predict(p, Q) - (1 + s) * Y0).max() < 1e-12
    assert any("range" in n and "scal" in n for n in UNOBSERVABLE_NOTES)
    with pytest.raises(InputError, match="range-scale"):
        make_effect("tracker_scale", ur10_model.robot)


def test_parse_effects_spec(ur10):
    out = parse_effects_spec("joint_compliance=2e-6, gear_harmonic=1e-4,thermal_expansion=2.3e-5", ur10, 0)
    assert [e.name for e, _ in out] == ["joint_compliance", "gear_harmonic", "thermal_expansion"]
    c = out[0][1]
    assert np.all((np.abs(c) >= 1e-6) & (np.abs(c) <= 2e-6))
    assert out[2][1].tolist() == [2.3e-5]
    a = parse_effects_spec("gear_harmonic=1e-4", ur10, 7)[0][1]
    b = parse_effects_spec("gear_harmonic=1e-4", ur10, np.random.default_rng(7))[0][1]
    assert np.array_equal(a, b)
    ex = parse_effects_spec("backlash=1e-4:-2e-4", ur10)[0][1]
    assert ex.tolist() == [1e-4, -2e-4]
    assert parse_effects_spec("", ur10) == []
    for bad, msg in (("foo=1", "unknown effect"), ("backlash", "NAME=VALUE"), ("backlash=x", "not a number"),
                     ("backlash=1:2:3", "2 parameters"), ("backlash=1,backlash=2", "twice"),
                     ("backlash=nan", "finite")):
        with pytest.raises(InputError, match=msg):
            parse_effects_spec(bad, ur10)


def test_effects_on_kuka_and_shapes():
    model = make_model("kr15")
    rb = model.robot
    Q = rb.random_q(np.random.default_rng(8), 4)
    for eff in candidate_effects(rb):
        assert eff.n_params == len(eff.param_names(rb)) > 0
        assert eff.to_dict()["name"] == eff.name
        dQ, D = eff.joint_offset(np.zeros(eff.n_params), Q, None if eff.name != "thermal_expansion" else None)
        assert dQ.shape == Q.shape
    with pytest.raises(InputError, match="parameters"):
        JointScale(rb).joint_offset(np.zeros(2), Q)
    bad_aux = MeasurementSet(joint_names=rb.joint_names, q=Q[:2], position_m=np.ones((2, 3)))
    with pytest.raises(InputError, match="rows"):
        JointCompliance(rb).joint_offset(np.zeros(JointCompliance(rb).n_params), Q, bad_aux)


def test_joint_angle_table(ur10):
    from pin_kpi_oed.effects.library import JointAngleTable, SubsetEffect

    rng = np.random.default_rng(9)
    Q = ur10.random_q(rng, 40)
    aux = _aux(ur10, Q, rng)
    t = JointAngleTable.from_data(ur10, aux, step_rad=0.5, joints=ur10.joint_names[:2])
    assert t.name not in EFFECT_NAMES  # opt-in only
    th = rng.normal(size=t.n_params) * 1e-4
    dQ, D = t.joint_offset(th, Q)
    assert np.allclose(dQ, D @ th) and np.all(dQ[:, 2:] == 0)
    # piecewise linear: exact at a knot, linear in between, 0 at the first knot
    kn = t.knots[0]
    Qk = np.tile(Q[:1], (3, 1))
    Qk[:, 0] = [kn[0], kn[2], 0.5 * (kn[2] + kn[3])]
    d, _ = t.joint_offset(th, Qk)
    assert abs(d[0, 0]) < 1e-15 and np.isclose(d[1, 0], th[1]) and np.isclose(d[2, 0], 0.5 * (th[1] + th[2]))
    sub = SubsetEffect(t, [0, 3])
    assert sub.name == t.name and sub.n_params == 2 and len(sub.dropped()) == t.n_params - 2
    d2, D2 = sub.joint_offset(np.array([1e-4, 2e-4]), Q)
    full = np.zeros(t.n_params)
    full[[0, 3]] = [1e-4, 2e-4]
    assert np.allclose(d2, t.joint_offset(full, Q)[0]) and D2.shape[2] == 2


def test_effect_is_an_abstract_base_owning_its_joint_angle_derivative(ur10):
    """Effect cannot be built without param_names; the basis derivative ∂(∂dQ/∂θ)/∂q of the joint-angle effects
    equals central differences; effects without one refuse by name (the continuous design needs it)."""
    from pin_kpi_oed.effects.base import Effect, SubsetEffect
    from pin_kpi_oed.effects.coupled import LinkBending
    from pin_kpi_oed.effects.periodic import TransmissionError

    class NoNames(Effect):
        name = "no_names"

    with pytest.raises(TypeError, match="abstract"):
        NoNames(ur10)
    rng = np.random.default_rng(7)
    Q = ur10.random_q(rng, 5)
    effects = [GearHarmonic(ur10), TransmissionError(ur10, max_order=3),
               LinkBending(ur10, terms=[("elbow_joint", "q2+q3", "cos"), ("shoulder_lift_joint", 0, "sin")]),
               SubsetEffect(GearHarmonic(ur10), [1, 4, 6])]
    h = 1e-6
    for eff in effects:
        dD = eff.joint_offset_dq(Q)
        th = np.zeros(eff.n_params)
        for j in range(ur10.nq):
            E = np.zeros_like(Q)
            E[:, j] = h
            fd = (eff.joint_offset(th, Q + E)[1] - eff.joint_offset(th, Q - E)[1]) / (2 * h)
            assert np.allclose(dD[..., j], fd, atol=1e-7), (eff.name, j)
    with pytest.raises(InputError, match="joint_compliance.*no exact q-derivative"):
        JointCompliance(ur10).joint_offset_dq(Q)
