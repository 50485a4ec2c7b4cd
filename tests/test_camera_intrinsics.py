"""The camera's intrinsics as optional parameters: the cell's ``intrinsics_sigma``, their fit and the model file."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest

from pin_kpi_oed.calibrated.tcp_sigma import tcp_sigma
from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.data.corner_measurements import CornerSet
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.identification.camera_identify import camera_model_of, identify_camera
from pin_kpi_oed.model.camera import INTRINSIC_NAMES
from pin_kpi_oed.simulation.camera_sim import CameraTolerances, camera_truth, simulate_corners
from tests.camera_cell import CAMERA_CELL, camera_cell
from tests.cli_run import run_cli

SIGMA = {"fx": 10.0, "fy": 10.0, "cx": 10.0, "cy": 10.0}


def _cell(tmp_path, sigma=SIGMA, name="cam.yaml"):
    cam = copy.deepcopy(CAMERA_CELL["camera"])
    if sigma is not None:
        cam["intrinsics_sigma"] = sigma
    return camera_cell(tmp_path, name, camera=cam)


def test_intrinsics_sigma_estimates_the_named_intrinsics_with_their_prior(tmp_path):
    cell = load_cell(_cell(tmp_path, {"fx": 4.0, "cy": 2.5}))
    model = cell.measurement_model()
    L = model.layout
    assert model.estimate_intrinsics
    g = L.group_slice("intrinsics")
    assert [n.split(".")[1] for n in L.names[g]] == list(INTRINSIC_NAMES)
    prior = dict(zip(INTRINSIC_NAMES, L.prior_sigma[g]))
    fixed = dict(zip(INTRINSIC_NAMES, L.fixed[g]))
    assert prior["fx"] == 4.0 and prior["cy"] == 2.5 and not fixed["fx"] and not fixed["cy"]
    assert all(fixed[n] for n in INTRINSIC_NAMES if n not in ("fx", "cy"))
    # the camera's description (stored in the model file) keeps the field and reads back the same
    assert cell.camera.to_dict()["camera"]["intrinsics_sigma"] == {"fx": 4.0, "cy": 2.5}
    plain = load_cell(_cell(tmp_path, None, "plain.yaml")).measurement_model()
    assert not plain.estimate_intrinsics and "intrinsics_sigma" not in load_cell(
        _cell(tmp_path, None, "plain.yaml")).camera.to_dict()["camera"]


@pytest.mark.parametrize("sigma, says", [
    ({"fx": -1.0}, "intrinsics_sigma.fx: expected a positive finite prior sigma"),
    ({"fx": 0.0}, "intrinsics_sigma.fx: expected a positive finite prior sigma"),
    ({"cx": math.inf}, "intrinsics_sigma.cx: expected a positive finite"),
    ({"k1": math.nan}, "intrinsics_sigma.k1: expected a positive finite"),
    ({"fz": 1.0}, "intrinsics_sigma: unknown field(s) fz"),
    ([1.0, 1.0, 1.0, 1.0], "intrinsics_sigma: expected a mapping from intrinsic name"),
    ({}, "intrinsics_sigma: empty"),
])
def test_bad_intrinsics_sigma_is_one_line_naming_the_file_and_field(tmp_path, sigma, says):
    path = _cell(tmp_path, sigma)
    with pytest.raises(InputError, match=says.replace(".", r"\.").replace("(", r"\(").replace(")", r"\)")):
        load_cell(path)
    rc, out, err = run_cli("info", path)
    assert rc == 2 and len(err.strip().splitlines()) == 1 and str(path) in err and "Traceback" not in err


def test_simulated_truth_draws_intrinsics_only_for_a_model_that_estimates_them(tmp_path):
    model = load_cell(_cell(tmp_path)).measurement_model()
    tol = CameraTolerances(intrinsics=(3.0, 3.0, 3.0, 3.0))
    g = model.layout.group_slice("intrinsics")
    p1, p2 = camera_truth(model, tol, seed=4), camera_truth(model, tol, seed=4)
    assert np.array_equal(p1, p2)  # seeded
    assert np.all(p1[g][:4] != 0.0) and np.all(p1[g][4:] == 0.0)  # distortion known: σ 0
    assert np.all(camera_truth(model, CameraTolerances(), seed=4)[g] == 0.0)
    plain = load_cell(_cell(tmp_path, None, "plain.yaml")).measurement_model()
    with pytest.raises(InputError, match="need a model that estimates them"):
        camera_truth(plain, tol, seed=4)
    with pytest.raises(InputError, match="up to 9 finite sigma"):
        camera_truth(model, CameraTolerances(intrinsics=(-1.0,)), seed=4)


def test_fitted_intrinsics_within_3_sigma_and_reprojection_at_the_noise(tmp_path):
    """True intrinsics a few px off nominal, with fx and fy off in opposite directions (an aspect ratio no pose of
    the camera reproduces): with ``intrinsics_sigma`` the fit recovers them and reprojects at the 0.2 px noise;
    without it the fit cannot absorb them and its reprojection RMS is clearly larger."""
    cell = load_cell(_cell(tmp_path))
    model = cell.measurement_model()
    p_true = camera_truth(model, CameraTolerances(), seed=7)
    g = model.layout.group_slice("intrinsics")
    p_true[g.start:g.start + 4] = [6.0, -6.0, 4.0, -4.0]  # px
    k_true = model.intrinsic_vector(p_true)
    Q = model.views(12, seed=8, around=cell.q_work)
    uv = simulate_corners(model, Q, p_true, seed=9)
    cs = CornerSet.from_arrays([f"pose_{i}" for i in range(len(Q))], Q, uv, list(model.robot.joint_names))

    res = identify_camera(model, cs, seed=1, device=cell.camera.to_dict())
    values, sig = res.fitted_intrinsics()
    assert set(sig) == {"fx", "fy", "cx", "cy"}
    z = np.array([(values[n] - k_true[i]) / sig[n] for i, n in enumerate(("fx", "fy", "cx", "cy"))])
    assert np.all(np.abs(z) < 3.0), z
    assert all(0.0 < s < 2.0 for s in sig.values())  # the images determine them far better than the 10 px prior
    assert 0.17 < res.fit.rms_px < 0.23 and res.fit.chi2_reduced < 1.3
    assert "fitted intrinsics: fx" in res.summary()

    plain = load_cell(_cell(tmp_path, None, "plain.yaml")).measurement_model()
    res0 = identify_camera(plain, cs, seed=1, joint_noise=False)  # its fit's RMS alone, no joint-angle level
    assert res0.fit.rms_px > 1.5 * res.fit.rms_px, (res0.fit.rms_px, res.fit.rms_px)

    # the model file's device block: the fitted intrinsics and their σ; the TCP σ in its usual form
    cm = res.calibrated_model(cell.q_work)
    dev = cm.fit["device"]
    assert dev["fitted_intrinsics"] == pytest.approx(values) and dev["intrinsics_std"] == pytest.approx(sig)
    back, _ = camera_model_of(cm)
    assert back.intrinsics.vector() == pytest.approx(model.intrinsic_vector(res.fit.p))
    ts = tcp_sigma(cm, cell.q_work)
    assert np.isfinite(ts.rms_m) and 0.0 < ts.rms_m < 5e-3
