"""A camera's joint-angle error level from its images (identification/camera_joint_noise.py): the restricted
likelihood against its dense form, the estimate and the parameters' sandwich covariance against Monte-Carlo, the
K-fold decision (on only when the images ask for it), and the term the TCP σ adds (its joint Jacobian against finite
differences, a bad model-file field refused)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from pin_kpi_oed.calibrated.tcp_sigma import joint_angle_covariance, tcp_sigma
from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.data.corner_measurements import CornerSet
from pin_kpi_oed.effects.library import parse_effects_spec
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.identification.camera_identify import identify_camera
from pin_kpi_oed.identification.camera_joint_noise import RemlBlocks as Blocks, joint_noise, reml_levels

from pin_kpi_oed.simulation.camera_sim import camera_truth, simulate_corners
from pin_kpi_oed.upkeep.camera_check import check_camera
from tests.camera_cell import EXAMPLE


def _synthetic(seed: int, s_true: np.ndarray, noise_var: float = 1.0, m: int = 40, rows: int = 30, b: int = 8):
    """A linear camera-like problem: m images of ``rows`` rows, b fitted parameters, d joints, r = ε + B δ
    (β = 0: the REML and the residuals do not depend on it)."""
    rng = np.random.default_rng(seed)
    d = s_true.size
    img = np.repeat(np.arange(m), rows)
    F = rng.normal(size=(m * rows, b))
    B = rng.normal(size=(m * rows, d)) * 300.0  # 300 σ_px per rad: a µrad-level error shows at the pixel level
    r = np.sqrt(noise_var) * rng.normal(size=m * rows)
    r += np.einsum("nd,nd->n", B, (rng.normal(size=(m, d)) * s_true)[img])
    return F, B, r, img, m


def _dense_reml(F, B, r, img, noise_var, s):
    """The restricted log-likelihood on an orthonormal basis N of F's residual space: z = Nᵀr ~ N(0, NᵀVN)."""
    Bs = B * s
    V = np.where(img[:, None] == img[None, :], Bs @ Bs.T, 0.0) + noise_var * np.eye(len(r))
    Qf, _ = np.linalg.qr(F, mode="complete")
    N = Qf[:, F.shape[1]:]
    S = N.T @ V @ N
    z = N.T @ r
    return -0.5 * (np.linalg.slogdet(S)[1] + z @ np.linalg.solve(S, z))


def test_the_woodbury_restricted_likelihood_is_the_dense_one():
    F, B, r, img, m = _synthetic(0, np.array([2e-3, 1e-3, 0.0]), m=12, rows=10, b=5)
    bl = Blocks(F, B, r, img, m)
    a, b = (1.3, np.array([1e-3, 3e-3, 5e-4])), (0.9, np.array([4e-3, 0.0, 2e-3]))
    # equal up to a constant independent of (σ², s): differences agree
    assert bl.loglik(*a) - bl.loglik(*b) == pytest.approx(_dense_reml(F, B, r, img, *a) - _dense_reml(F, B, r, img, *b),
                                                         rel=1e-8, abs=1e-8)


def test_reml_recovers_the_joint_levels_and_the_sandwich_matches_monte_carlo():
    s_true = np.array([3e-3, 0.0, 1.5e-3])
    est = np.array([reml_levels(*_synthetic(k, s_true)).sigma_rad
                    for k in range(12)])
    assert np.median(est[:, 0]) == pytest.approx(3e-3, rel=0.25)
    assert np.median(est[:, 2]) == pytest.approx(1.5e-3, rel=0.3)
    assert np.median(est[:, 1]) < 0.5e-3
    # the parameters' covariance the decision stores is the least-squares estimate's covariance under that error
    F, B, r, img, m = _synthetic(0, s_true)
    jn = joint_noise(F, B, r, img, m, np.zeros((F.shape[1],) * 2), chi2_reduced=1.0)
    assert jn.used
    rng = np.random.default_rng(5)
    betas = []
    for _ in range(400):
        y = rng.normal(size=len(r)) * np.sqrt(jn.noise_var)
        y += np.einsum("nd,nd->n", B, (rng.normal(size=(m, 3)) * jn.sigma_rad)[img])
        betas.append(np.linalg.lstsq(F, y, rcond=None)[0])
    mc = np.cov(np.array(betas).T)
    assert np.diag(mc) == pytest.approx(np.diag(jn.covariance), rel=0.2)
    white = np.linalg.inv(F.T @ F)
    assert np.all(np.diag(jn.covariance) > 2 * np.diag(white))  # the white level alone would understate it


def test_the_term_switches_on_only_when_the_data_ask_for_it():
    zero = np.zeros((8, 8))
    off = joint_noise(*_synthetic(1, np.zeros(3)), zero, chi2_reduced=1.0)
    on = joint_noise(*_synthetic(1, np.array([2e-3, 0.0, 0.0])), zero, chi2_reduced=1.0)
    assert not off.used and np.all(off.sigma_rad == 0) and "no joint-angle term" in off.reason
    assert on.used and on.lr > on.lr_critical and on.heldout_gain > 0


#: the tests sharing the module fixture ``cameras``: on one worker under ``--dist loadgroup``, computed once
GROUP = "test_camera_joint_noise_cameras"


@pytest.fixture(scope="module")
def cameras():
    """One true UR5 (every joint placement off, eye-in-hand) seen in 12 images: without an unmodelled effect, and with
    a gear harmonic of 0.5 mrad the geometry lacks."""
    cell = load_cell(str(EXAMPLE))
    model = cell.measurement_model()
    names = list(model.robot.joint_names)
    p_true = camera_truth(model, seed=0)
    Q = model.views(12, seed=1, around=cell.q_work)
    out = {}
    for label, spec in (("plain", None), ("harmonic", "gear_harmonic=5e-4")):
        eff = parse_effects_spec(spec, model.robot, np.random.default_rng(3)) if spec else []
        uv = simulate_corners(model, Q, p_true, eff, seed=2)
        out[label] = identify_camera(model, CornerSet.from_arrays([f"p{i}" for i in range(12)], Q, uv, names),
                                     device=cell.camera.to_dict())
    return out, cell


@pytest.mark.xdist_group(GROUP)
def test_a_camera_calibration_carries_the_term_only_when_its_images_show_joint_errors(cameras):
    out, cell = cameras
    plain, harm = out["plain"], out["harmonic"]
    assert not plain.joint.used and "joint_angle_sigma_rad" not in plain.calibrated_model().fit
    assert harm.joint.used
    cm = harm.calibrated_model()
    assert len(cm.fit["joint_angle_sigma_rad"]) == cm.robot.nq and cm.fit["joint_noise"]["used"]
    Qw = cell.q_work
    with_term = tcp_sigma(cm, Qw)
    without = tcp_sigma(replace(harm, joint=None).calibrated_model(), Qw)
    assert np.all(with_term.sigma_m > without.sigma_m)
    assert "joint-angle errors of" in harm.summary()


@pytest.mark.xdist_group(GROUP)
def test_the_tcp_joint_jacobian_is_the_tcps_finite_difference(cameras):
    out, cell = cameras
    cm = out["harmonic"].calibrated_model()
    q = cell.q_work[:1]
    s = np.zeros(cm.robot.nq)
    s[2] = 1.0  # one joint: the covariance is J[:, 2] J[:, 2]ᵀ
    cm.fit["joint_angle_sigma_rad"] = s.tolist()
    for frame in ("cell", "base"):
        C = joint_angle_covariance(cm, None, cm.tcp_m, q, frame)[0]
        h = 1e-6
        dq = np.zeros_like(q)
        dq[0, 2] = h
        up, down = tcp_sigma(cm, q + dq, frame=frame), tcp_sigma(cm, q - dq, frame=frame)
        fd = (up.position_m - down.position_m)[0] / (2 * h)
        assert C == pytest.approx(np.outer(fd, fd), rel=1e-5, abs=1e-12)


@pytest.mark.xdist_group(GROUP)
def test_a_bad_joint_sigma_field_is_refused_in_one_line(cameras):
    out, cell = cameras
    cm = out["harmonic"].calibrated_model()
    cm.fit["joint_angle_sigma_rad"] = [1e-4, -1.0]
    with pytest.raises(InputError, match="fit.joint_angle_sigma_rad"):
        tcp_sigma(cm, cell.q_work)


@pytest.mark.xdist_group(GROUP)
def test_the_check_holds_on_new_images_of_a_robot_with_joint_errors_its_calibration_showed(cameras):
    """New images of the same true robot (its harmonic included): with the joint-angle part in S the statistic per
    dof is near 1 and every check holds; without it (the white level alone) it is larger and some checks alarm."""
    out, cell = cameras
    model = cell.measurement_model()
    names = list(model.robot.joint_names)
    p_true = camera_truth(model, seed=0)
    eff = parse_effects_spec("gear_harmonic=5e-4", model.robot, np.random.default_rng(3))
    with_term = out["harmonic"].calibrated_model()
    without = replace(out["harmonic"], joint=None).calibrated_model()
    t_with, t_without, verdicts = [], [], []
    for s in range(6):
        Qc = model.views(8, seed=10 + s, around=cell.q_work)
        cs = CornerSet.from_arrays([f"c{i}" for i in range(8)], Qc, simulate_corners(model, Qc, p_true, eff,
                                                                                       seed=20 + s), names)
        a, b = check_camera(with_term, cs), check_camera(without, cs)
        t_with.append(a.chi2_fixed / a.scale / a.dof_fixed)
        t_without.append(b.chi2_fixed / b.scale / b.dof_fixed)
        verdicts.append(a.verdict)
    assert verdicts == ["holds"] * 6
    assert 0.8 < np.mean(t_with) < 1.2
    assert np.mean(t_without) > np.mean(t_with) + 0.05


@pytest.mark.xdist_group(GROUP)
def test_predict_says_what_the_sigma_holds(cameras):
    from pin_kpi_oed.calibrated.prediction_sigma import sigma_contents

    out, _ = cameras
    assert "joint-angle errors the camera's images showed" in sigma_contents(out["harmonic"].calibrated_model())
    assert "joint-angle" not in sigma_contents(out["plain"].calibrated_model())


@pytest.mark.xdist_group(GROUP)
def test_the_term_survives_the_model_file(cameras, tmp_path):
    from pin_kpi_oed.calibrated.model_file import load_model_file

    out, cell = cameras
    cm = out["harmonic"].calibrated_model()
    cm.save(tmp_path / "m.json")
    back = load_model_file(tmp_path / "m.json")
    assert back.fit["joint_angle_sigma_rad"] == pytest.approx(cm.fit["joint_angle_sigma_rad"])
    assert tcp_sigma(back, cell.q_work).covariance_m2 == pytest.approx(tcp_sigma(cm, cell.q_work).covariance_m2,
                                                                       rel=1e-9, abs=1e-15)
