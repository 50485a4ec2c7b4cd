"""The faster paths of the design stack give the numbers of the plain ones.

``Chain.frames`` multiplies by the constant joint placements once over all configurations, remembers its last result
and leaves out the twists when not asked; ``Chain.tool_pose`` walks the chain without keeping the joint frames; the
incidence row without gradient reads the tool pose only; ``∂J/∂q`` computes only the joint pairs that enter it. Each
is checked here against the per-configuration code it replaced (kept below as the reference), to 1e-12 relative (on
the package's NumPy/OpenBLAS the numbers are bit for bit the same: ``pin-kpi-oed demo`` writes the same design file).

The measurement model's hot path: ``cross3`` (no axis moves), the device-frame Jacobian written through one view, ∂Y/∂q
computed on first read, the right Jacobian from ``pin.Jexp6`` of the vectors and one chain shared by the models of one
robot are checked bit for bit against the code they replaced (``python -m benchmarks.kinematics_calls`` prints a digest
of every call's numbers to compare two versions of the package).
"""

from __future__ import annotations

import gc

import numpy as np
import pinocchio as pin
import pytest

from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.cell.collision import CollisionModel
from pin_kpi_oed.model.kinematics import Chain, cross3, placement_jacobian, point_velocity, revolute_mask, skew
from pin_kpi_oed.model.robot import load_robot
from pin_kpi_oed.model.tracker import TrackerModel

REL = 1e-12


def _close(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal to 1e-12 relative to the larger magnitude of the two arrays (1 for arrays of zeros)."""
    scale = max(np.abs(a).max(initial=0.0), np.abs(b).max(initial=0.0), 1.0)
    return a.shape == b.shape and bool(np.abs(a - b).max(initial=0.0) <= REL * scale)


def _reference_frames(chain: Chain, Q: np.ndarray, placements=None) -> dict:
    """The per-configuration loop ``Chain.frames`` replaced: every product per configuration, twists always."""
    M = chain.placements if placements is None else placements
    m, n = Q.shape
    R, t = np.empty((m, n + 1, 3, 3)), np.empty((m, n + 1, 3))
    R_A, t_A = np.empty((m, n, 3, 3)), np.empty((m, n, 3))
    V, W = np.zeros((m, n, 3)), np.zeros((m, n, 3))
    R[:, 0], t[:, 0] = np.eye(3), 0.0
    Rc, tc = np.broadcast_to(np.eye(3), (m, 3, 3)), np.zeros((m, 3))
    K = skew(chain.ang)
    for k in range(n):
        tc = tc + Rc @ M[k].translation
        Rc = Rc @ M[k].rotation
        R_A[:, k], t_A[:, k] = Rc, tc
        if chain.revolute[k]:
            w = Rc @ chain.ang[k]
            W[:, k], V[:, k] = w, -np.cross(w, tc)
            s, c = np.sin(Q[:, k])[:, None, None], np.cos(Q[:, k])[:, None, None]
            Rc = Rc @ (np.eye(3) + s * K[k] + (1.0 - c) * (K[k] @ K[k]))
        else:
            u = Rc @ chain.lin[k]
            V[:, k] = u
            tc = tc + u * Q[:, k:k + 1]
        R[:, k + 1], t[:, k + 1] = Rc, tc
    return {"R": R, "t": t, "R_A": R_A, "t_A": t_A, "V": V, "W": W}


def _perturbed(chain: Chain, seed: int) -> list[pin.SE3]:
    rng = np.random.default_rng(seed)
    return [M * pin.exp6(rng.normal(0.0, 1e-3, 6)) for M in chain.placements]


@pytest.mark.parametrize("name", ["kr15", "kr15_track", "panda"])
def test_frames_equal_the_per_configuration_products(name: str) -> None:
    """Frames, frames before motion and twists of revolute and prismatic chains (kr15_track: a linear track first),
    one to 300 configurations, nominal and perturbed placements: the reference loop's numbers."""
    robot = load_robot(name)
    rng = np.random.default_rng(3)
    for m in (1, 7, 300):
        Q = rng.uniform(robot.q_lower, robot.q_upper, (m, robot.nq))
        for placements in (None, _perturbed(Chain.from_robot(robot), m)):
            chain = Chain.from_robot(robot)  # nothing remembered
            ref = _reference_frames(chain, Q, placements)
            fr = chain.frames(Q, placements)
            for key, value in ref.items():
                assert _close(getattr(fr, key), value), (name, m, key)
            bare = Chain.from_robot(robot).frames(Q, placements, twists=False)
            for key in ("R", "t", "R_A", "t_A"):
                assert _close(getattr(bare, key), ref[key]), (name, m, key, "without twists")
            assert not bare.V.any() and not bare.W.any(), "twists not asked for are not computed"


def test_frames_are_remembered_by_value_read_only_and_twists_on_demand() -> None:
    """The same configurations and placement values give the remembered result (read-only, shared); other
    placements or configurations are computed anew; a call asking for twists after one without them computes them."""
    robot = load_robot("kr15")
    chain = Chain.from_robot(robot)
    Q = np.random.default_rng(5).uniform(robot.q_lower, robot.q_upper, (20, robot.nq))
    bare = chain.frames(Q, twists=False)
    assert not bare.W.any()
    full = chain.frames(Q)
    assert full is not bare and _close(full.W, _reference_frames(chain, Q)["W"]) and full.W.any()
    assert chain.frames(Q.copy(), [M.copy() for M in chain.placements]) is full, "equal values: remembered"
    assert chain.frames(Q, twists=False) is full, "remembered twists serve a call without them"
    with pytest.raises(ValueError):
        full.R[0, 0, 0, 0] = 1.0
    moved = chain.frames(Q, _perturbed(chain, 1))
    assert moved is not full and not np.array_equal(moved.t, full.t)
    Q2 = Q.copy()
    Q2[3, 2] += 1e-9
    again = chain.frames(Q2)
    assert again is not full and not np.array_equal(again.t[3], full.t[3]) and np.array_equal(again.t[4], full.t[4])


@pytest.mark.parametrize("name", ["ur5", "kr15_track"])
def test_tool_pose_is_the_tool_point_of_the_full_chain(name: str) -> None:
    """``tool_pose`` (no joint frames kept) gives ``tool_point``'s point and tool rotation, one point or one per
    configuration, nominal and perturbed placements, computed afresh or from the remembered frames."""
    robot = load_robot(name)
    rng = np.random.default_rng(7)
    Q = rng.uniform(robot.q_lower, robot.q_upper, (50, robot.nq))
    for placements in (None, _perturbed(Chain.from_robot(robot), 2)):
        for point in (np.array([0.01, -0.02, 0.05]), rng.normal(0.0, 0.05, (50, 3))):
            kin = Chain.from_robot(robot).tool_point(Q, point, placements)
            fresh = Chain.from_robot(robot)
            P, R = fresh.tool_pose(Q, point, placements)
            assert _close(P, kin.p) and _close(R, kin.R_tool)
            fresh.frames(Q, placements)  # now from the remembered frames
            P2, R2 = fresh.tool_pose(Q, point, placements)
            assert _close(P2, kin.p) and _close(R2, kin.R_tool)


def test_incidence_without_gradient_is_the_value_with_it() -> None:
    """cos β read from the tool pose alone equals the value computed with its gradient, at nominal and perturbed
    parameters (the rejection sampler's first stage and the optimiser's row decide alike)."""
    cell = load_cell("kr15")
    rng = np.random.default_rng(11)
    Q = rng.uniform(cell.q_lower, cell.q_upper, (40, cell.q_lower.size))
    for p in (np.zeros(cell.tracker_model().n_params), rng.normal(0.0, 1e-4, cell.tracker_model().n_params)):
        c = cell.tracker_model().incidence_cos(p, Q)
        c_grad, _ = cell.tracker_model().incidence_cos(p, Q, with_grad=True)
        assert _close(c, c_grad)


def _reference_dJ(model, p: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """∂J/∂q of the reflector rows by the masked products over every joint pair (the code the pair list replaced)."""
    kin = model.kinematics(p, Q, model.points(p))
    m, n = Q.shape
    blk = placement_jacobian(kin)
    Wsk = skew(np.moveaxis(kin.twist[:, 3:, :], 1, 2))
    Pdsk = skew(np.moveaxis(point_velocity(kin), 1, 2))
    before = np.tril(np.ones((n, n), bool), -1)
    D = (Wsk[:, None] @ blk[:, :, None]) * before[None, :, :, None, None]
    D[..., 3:] -= (Pdsk[:, None] @ kin.R_A[:, :, None]) * ~before[None, :, :, None, None]
    return np.moveaxis(D, (1, 2, 3, 4), (2, 4, 1, 3)).reshape(m, 3, 6 * n, n)


def test_dJ_dq_equals_the_masked_products_over_every_joint_pair() -> None:
    """The joint-placement columns of ∂J/∂q (tracker frame) from the pairs that enter it equal the products over all
    pairs masked by joint order, rotated into the tracker frame."""
    cell = load_cell("kr15")
    model = cell.tracker_model()
    p = np.zeros(model.n_params)
    Q = np.random.default_rng(13).uniform(cell.q_lower, cell.q_upper, (30, cell.q_lower.size))
    _, _, dJ, _ = model.jacobian_dq(p, Q)
    nj = 6 * model.layout.n_joints
    RT = model.tracker_pose(p).rotation
    ref = np.einsum("ab,mbjk->majk", RT, _reference_dJ(model, p, Q))
    assert _close(dJ[:, :3, :nj, :], ref)
    assert np.abs(ref).max() > 0.1, "the reference is not all zeros"


def test_collision_model_shares_the_measurement_models_remembered_frames() -> None:
    """The constraint rows and the incidence row at the same configurations read one chain's frames."""
    cell = load_cell("kr15")
    coll = CollisionModel(cell)
    assert coll.fk is coll.model.chain
    Q = np.random.default_rng(17).uniform(cell.q_lower, cell.q_upper, (10, cell.q_lower.size))
    coll.evaluate(Q, with_grad=True)
    remembered = coll.fk.frames(Q)
    kin = coll.model.kinematics(np.zeros(coll.model.n_params), Q, coll.model.reflector_m)
    assert kin.R_A is remembered.R_A, "the measurement model's kinematics used the frames the rows computed"


def test_banded_pair_gradients_are_the_full_ones_on_the_near_pairs() -> None:
    """With a band, the pair rows' gradients are computed only for the pairs near at some configuration: on the near
    rows they equal the gradients of the run without a band (1e-12), elsewhere they are zero."""
    cell = load_cell("kr15")
    coll = CollisionModel(cell)
    rng = np.random.default_rng(19)
    Q = rng.uniform(cell.q_lower, cell.q_upper, (25, cell.q_lower.size))
    g_full, G_full = coll.evaluate(Q, backend="geometry")
    band = 0.05
    g_band, G_band = coll.evaluate(Q, backend="geometry", band=band)
    pair = coll.info.kind == 0
    gp = g_full[:, pair]
    near = gp <= gp.min(axis=1, keepdims=True) + band
    assert 0 < near.sum() < near.size and np.array_equal(g_band, g_full)
    assert _close(G_band[:, pair][near], G_full[:, pair][near]) and np.abs(G_full[:, pair][near]).max() > 0.01
    assert not G_band[:, pair][~near].any()


def test_cross3_is_numpys_cross_bit_for_bit() -> None:
    """``cross3`` (components by basic indexing into one preallocated result) returns ``np.cross``'s numbers bit
    for bit, for single vectors, rows, broadcast operands and the components on a middle axis."""
    rng = np.random.default_rng(23)
    cases = [((3,), (3,), -1), ((5, 3), (5, 3), -1), ((5, 3), (3,), -1), ((3,), (5, 3), -1), ((2, 4, 3), (4, 3), -1),
             ((4, 3, 6), (4, 3, 1), 1), ((4, 3, 6), (3, 1), -2), ((4, 3, 6), (4, 3, 6), 1), ((7, 6, 3), (7, 6, 3), -1)]
    for sa, sb, axis in cases:
        a, b = rng.normal(size=sa), rng.normal(size=sb)
        ref = np.cross(a, b, axis=axis)
        out = cross3(a, b, axis)
        assert out.shape == ref.shape and np.array_equal(out, ref), (sa, sb, axis)
        assert np.abs(ref).max() > 0.1


def _reference_sensor_jacobian(model, p: np.ndarray, Q: np.ndarray, point: np.ndarray, offset_group) -> np.ndarray:
    """The device-frame Jacobian of a tool point assembled as ``sensor_point`` did before it wrote the joint blocks
    through one reshaped view: a slice per joint and the device-frame columns concatenated."""
    L = model.layout
    kin = model.kinematics(p, Q, point)
    T = model.sensor_pose(p)
    m, n = kin.p.shape[0], L.n_joints
    J = np.zeros((m, 3, model.n_params))
    blk = placement_jacobian(kin)
    for k in range(n):
        J[:, :, L.joint_slice(k)] = blk[:, k]
    J[:, :, L.group_slice(model.frame_group)] = np.concatenate([np.broadcast_to(np.eye(3), (m, 3, 3)),
                                                               -skew(kin.p)], axis=-1)
    if offset_group is not None:
        J[:, :, L.group_slice(offset_group)] = kin.R_tool
    return T.rotation @ J


@pytest.mark.parametrize("name", ["kr15", "kr15_track"])
def test_sensor_point_jacobian_and_lazy_velocity_are_the_former_numbers(name: str) -> None:
    """``sensor_point``'s Jacobian equals the former per-joint assembly bit for bit; ∂Y/∂q computed on first read
    (∂J/∂q not asked for) equals the one computed with ∂J/∂q bit for bit, after the device pose it was computed
    from has been freed."""
    robot = load_robot(name)
    rng = np.random.default_rng(29)
    model = TrackerModel(robot, tracker_T_base=pin.SE3(pin.rpy.rpyToMatrix(0.1, -0.2, 0.3), np.array([2.0, 0.4, 0.1])),
                         reflector_m=np.array([0.02, -0.01, 0.08]))
    gc.freeze()  # what lived before is left out of the collections below (a test worker's whole heap: ~0.4 s each)
    try:
        for m in (1, 12):
            Q = rng.uniform(robot.q_lower, robot.q_upper, (m, robot.nq))
            p = rng.normal(0.0, 1e-3, model.n_params)
            for offset_group in (None, "reflector"):
                point = model.points(p)
                sp = model.sensor_point(p, Q, point, offset_group)
                assert sp.dJ is None
                assert np.array_equal(sp.J, _reference_sensor_jacobian(model, p, Q, point, offset_group))
                gc.collect()  # every object made since the freeze
                _ = [np.full((3, 3), 7.0) for _ in range(100)]  # reuse freed memory
                full = model.sensor_point(p, Q, point, offset_group, with_dq=True)
                assert (np.array_equal(sp.Ydq, full.Ydq) and np.array_equal(sp.J, full.J)
                        and np.abs(sp.Ydq).max() > 0.1)
    finally:
        gc.unfreeze()


def test_shared_chain_is_one_per_model_and_placements() -> None:
    """Two measurement models of one robot read one chain (the joint axes read from Pinocchio once) that computes
    what a chain of its own computes; after the robot's joint placements change, a new model gets a chain with the
    new placements, and a chain's joint types come from its axes as ``revolute_mask`` says."""
    robot = load_robot("kr15_track")
    a, b = TrackerModel(robot), TrackerModel(robot)
    assert a.chain is b.chain is Chain.shared(robot)
    assert np.array_equal(a.chain.revolute, revolute_mask(robot.model, robot.joint_ids))
    assert not a.chain.revolute.all() and a.chain.revolute.any()
    Q = np.random.default_rng(31).uniform(robot.q_lower, robot.q_upper, (5, robot.nq))
    own = Chain.from_robot(robot).frames(Q)
    assert np.array_equal(a.chain.frames(Q).t, own.t) and np.array_equal(a.chain.frames(Q).V, own.V)
    j = robot.joint_ids[2]
    M = robot.model.jointPlacements[j].copy()  # this test's own robot (load_robot builds a new one per call)
    robot.model.jointPlacements[j] = pin.SE3(M.rotation, M.translation + np.array([0.0, 0.0, 0.01]))
    c = TrackerModel(robot)
    assert c.chain is not a.chain
    assert np.array_equal(c.chain.placements[2].translation, M.translation + np.array([0.0, 0.0, 0.01]))
    assert not np.array_equal(c.chain.frames(Q).t, own.t)


def test_right_jacobian_is_the_one_of_the_motions() -> None:
    """The block-diagonal right Jacobian from ``pin.Jexp6`` of the parameter vectors equals the one from
    ``pin.Jexp6`` of their ``pin.Motion`` (the former code) bit for bit, with a 6-DoF probe's rotation group."""
    model = TrackerModel(load_robot("kr15"), pose6d=True)
    p = np.random.default_rng(37).normal(0.0, 0.05, model.n_params)
    L = model.layout
    ref = np.eye(model.n_params)
    for k in range(L.n_joints):
        s = L.joint_slice(k)
        ref[s, s] = pin.Jexp6(pin.Motion(p[s]))
    ref[L.tracker, L.tracker] = pin.Jexp6(pin.Motion(p[L.tracker]))
    ref[L.probe, L.probe] = pin.Jexp3(p[L.probe])
    Jr = model.right_jacobian(p)
    assert np.array_equal(Jr, ref) and np.abs(Jr - np.eye(model.n_params)).max() > 1e-3
    assert np.array_equal(model.right_jacobian(np.zeros(model.n_params)), np.eye(model.n_params))


@pytest.mark.parametrize("pose6d", [False, True])
def test_jacobians_at_the_nominal_model_are_the_products_by_the_identity(pose6d: bool) -> None:
    """At p = 0 the Jacobians skip the product by the right Jacobian (the identity): their numbers are those of the
    product ``J @ I`` bit for bit (a zero of either sign becomes +0.0 in both), on a pool of real configurations;
    away from p = 0 the product is made."""
    model = TrackerModel(load_robot("kr15"), tracker_T_base=pin.SE3(pin.rpy.rpyToMatrix(0.1, -0.2, 0.3),
                                                                      np.array([2.0, 0.5, 0.1])),
                         reflector_m=np.array([0.01, 0.02, 0.1]), tcp_m=np.array([0.0, 0.01, 0.15]), pose6d=pose6d)
    Q = model.robot.random_q(np.random.default_rng(41), 40)
    zero, eye = np.zeros(model.n_params), np.eye(model.n_params)
    J = model.jacobian_dq(zero, Q)[1]  # the tangent-coordinate Jacobian (no product at p = 0)
    signed = J.copy()
    signed[:, :, 0] = -0.0  # zeros of both signs
    E = model.sensor_point(zero, Q, model.tcp_m).J
    for a, b in ((model.jacobian(zero, Q), J @ eye), (model.at_parameters(signed, zero), signed @ eye),
                 (model.kpi_jacobian(zero, Q), (E @ eye).reshape(-1, eye.shape[0]))):
        assert a.shape == b.shape and a.tobytes() == b.tobytes()
    assert not np.signbit(model.at_parameters(signed, zero)[:, :, 0]).any()
    p = np.random.default_rng(43).normal(0.0, 1e-3, model.n_params)
    assert np.array_equal(model.at_parameters(J, p), J @ model.right_jacobian(p))
