"""The camera check on images the calibration did not see: the statistic's law under no change, by Monte-Carlo over
calibrations of one true robot (not the package's model: every joint placement, the hand-eye transform and the board
off nominal), each from 6 images of its own noise, checked on 4 new images."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.data.corner_measurements import CornerSet
from pin_kpi_oed.identification.camera_fit import fit_camera
from pin_kpi_oed.identification.camera_identify import CameraIdentification, identify_camera
from pin_kpi_oed.simulation.camera_sim import camera_truth, simulate_corners
from pin_kpi_oed.upkeep.camera_check import check_camera, prediction_covariance
from tests.camera_cell import EXAMPLE


@pytest.fixture(scope="module")
def draws():
    """Per noise draw: the check's statistic per dof, the plain Σ r²/σ² per dof (no parameter error), the verdict."""
    cell = load_cell(str(EXAMPLE))
    model = cell.measurement_model()
    names = list(model.robot.joint_names)
    p_true = camera_truth(model, seed=0)
    Q = model.views(6, seed=1, around=cell.q_work)
    Qc = model.views(4, seed=2, around=cell.q_work)
    first = identify_camera(model, CornerSet.from_arrays([f"p{i}" for i in range(6)], Q,
                                                         simulate_corners(model, Q, p_true, [], seed=100), names),
                            device=cell.camera.to_dict())
    out = []
    for s in range(10):
        uv = simulate_corners(model, Q, p_true, [], seed=200 + s)
        fit = fit_camera(model, Q, uv, first.fit.base, p_ref=first.fit.p)
        cm = CameraIdentification(model, fit, first.labels, Q, uv, first.held, device=first.device).calibrated_model()
        uvc = simulate_corners(model, Qc, p_true, [], seed=300 + s)
        c = check_camera(cm, CornerSet.from_arrays([f"c{i}" for i in range(4)], Qc, uvc, names))
        out.append((c.chi2_fixed / c.dof_fixed, c.rms_px ** 2 / model.sigma_px ** 2, c.verdict))
    return out, model, cm, Qc


def test_the_statistic_follows_its_chi2_law_on_images_the_calibration_did_not_see(draws):
    out, *_ = draws
    t = np.array([o[0] for o in out])
    plain = np.array([o[1] for o in out])
    assert 0.85 < np.mean(t) < 1.2, t  # E[T0 / n] = 1 when S is the residuals' covariance
    # without the fitted parameters' error (S = I) a calibration of 6 images would fail every check
    assert np.min(plain) > 3, plain
    assert sum(o[2] == "holds" for o in out) >= 8


def test_prediction_covariance_is_the_identity_plus_the_parameters_part(draws):
    _, model, cm, Qc = draws
    from pin_kpi_oed.identification.camera_identify import camera_model_of

    m, p = camera_model_of(cm)
    F = m.weighted_jacobian(p, Qc).reshape(-1, m.n_params)
    S = prediction_covariance(cm, m, F)
    assert S.shape == (F.shape[0],) * 2 and np.allclose(S, S.T)
    w = np.linalg.eigvalsh(S)
    assert w.min() > 1 - 1e-9 and w.max() > 10  # I plus a positive semi-definite part that is not small
    no_cov = SimpleNamespace(fit=cm.fit, parameters={**cm.parameters, "covariance": 0 * cm.parameters["covariance"],
                                                     "held": None})
    assert np.allclose(prediction_covariance(no_cov, m, F), np.eye(F.shape[0]))
