"""``identify --discrepancy`` with a camera: ``on`` refused in one line naming the reason, ``auto`` (the default)
and ``none`` say that a camera's model has no Gaussian-process discrepancy and what its σ carries instead: the
parameters' covariance at the residual level. A cell stating 0.12 px of pixel noise on images with 0.2 px: the TCP σ
at the residual level is the σ of the same fit with the noise stated right."""

from __future__ import annotations

import numpy as np
import pytest

from pin_kpi_oed.calibrated.model_file import load_model_file
from pin_kpi_oed.calibrated.tcp_sigma import tcp_sigma
from pin_kpi_oed.cell.cell import load_cell
from tests.camera_cell import CAMERA_CELL, camera_cell
from tests.cli_run import run_cli


#: the tests sharing the module fixture ``fits``: on one worker under ``--dist loadgroup``, computed once
GROUP = "test_camera_discrepancy_fits"


@pytest.fixture(scope="module")
def fits(tmp_path_factory):
    """Images of 0.2 px noise identified with the noise stated right and stated 0.12 px (auto, none)."""
    d = tmp_path_factory.mktemp("camera_discrepancy")
    right = camera_cell(d, "right.yaml")
    low = camera_cell(d, "low.yaml", camera={**CAMERA_CELL["camera"], "sigma_px": 0.12})
    rc, _, err = run_cli("simulate", "--cell", right, "--n", 12, "--out", d / "c.csv", "--seed", 2)
    assert rc == 0, err
    runs = {}
    for name, cell, extra in (("right", right, ()), ("auto", low, ()), ("none", low, ("--discrepancy", "none"))):
        runs[name] = run_cli("identify", "--data", d / "c.csv", "--cell", cell, "--model-out", d / f"{name}.json",
                             *extra)
        assert runs[name][0] == 0, runs[name][2]
    return d, low, runs


@pytest.mark.xdist_group(GROUP)
def test_on_is_refused_in_one_line_naming_the_reason(fits):
    d, low, _ = fits
    rc, out, err = run_cli("identify", "--data", d / "c.csv", "--cell", low, "--discrepancy", "on",
                           "--model-out", d / "on.json")
    assert rc == 2 and len(err.strip().splitlines()) == 1 and not (d / "on.json").exists()
    assert "--discrepancy on: not for camera measurements" in err and "board corners' pixels" in err


@pytest.mark.xdist_group(GROUP)
def test_auto_says_no_gaussian_process_and_the_residual_level(fits):
    _, _, runs = fits
    out = runs["auto"][1]
    chi2 = float(out.split("reduced chi2 ")[1].split(",")[0])
    assert 2.0 < chi2 < 4.0  # (0.2 / 0.12)² = 2.8
    assert "discrepancy (auto): none for a camera" in out
    assert f"the parameters' covariance scaled by the fit's reduced chi2 {chi2:.2f}" in out
    assert "discrepancy (none): none for a camera" in runs["none"][1]
    assert "discrepancy (auto): none for a camera" in runs["right"][1]


@pytest.mark.xdist_group(GROUP)
def test_the_tcp_sigma_at_the_residual_level_is_the_sigma_with_the_noise_stated_right(fits):
    d, low, _ = fits
    q = load_cell(str(low)).q_work
    sig, cms = {}, {}
    for name in ("right", "auto", "none"):
        cm = cms[name] = load_model_file(d / f"{name}.json")
        assert cm.discrepancy is None
        ts = tcp_sigma(cm, q)
        sig[name] = np.sqrt(np.maximum(ts.sigma_m ** 2 - ts.held_sigma_m ** 2, 0.0))  # the fitted parameters' part
    assert np.allclose(sig["auto"], sig["none"], rtol=1e-9)
    assert np.allclose(sig["auto"], sig["right"], rtol=0.15), sig
    # the scaling is what makes it so: the covariance the fit states at 0.12 px is (0.12 / 0.2)² of the right one
    std = {k: np.asarray(cms[k].parameters["std"]) for k in ("right", "auto")}
    assert np.median(std["auto"] / std["right"]) == pytest.approx(0.6, rel=0.05)
