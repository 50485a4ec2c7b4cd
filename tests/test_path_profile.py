"""The σ profile along a working path: the discrepancy term (kriging C_s per sample), and its figure written by
``view --figures`` with the display units printed."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.design.optimize import DesignProblem
from pin_kpi_oed.design.path_profile import discrepancy_profile, path_profile, path_profiles, profile_lines
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.viz.path_profile_plot import plot_path_profiles
from tests.cli_run import run_cli


@pytest.fixture(scope="module")
def seam_problem():
    return DesignProblem(load_cell("kr15_seam"), collision=False)


def test_discrepancy_profile_is_the_kriging_kpi_per_sample(seam_problem):
    Q = seam_problem.cell.robot.random_q(np.random.default_rng(4), 30)
    Qs = seam_problem.cell.q_path
    gp = discrepancy_profile(seam_problem, Q, Qs)
    v = np.array(gp["sigma_pos_gp_m"])
    # the squares sum to the (unhedged) kpi_path_gp value: tr C_s^UK over the samples
    assert np.sum(v ** 2) == pytest.approx(seam_problem.gp_criterion(Q_work=Qs).value(Q), rel=1e-9)
    # sample 57 alone: the kriging covariance at that configuration
    C = seam_problem.gp_criterion(Q_work=Qs[57:58]).covariance(Q)
    assert v[57] == pytest.approx(np.sqrt(np.trace(C)), rel=1e-9)
    noise_only = np.array(path_profile(seam_problem, Q, Qs, 0.2)["sigma_pos_m"])
    assert np.all(v > noise_only)
    assert gp["worst_sigma_pos_gp_m"] == v.max() and gp["rms_sigma_pos_gp_m"] == pytest.approx(np.sqrt(np.mean(v ** 2)))


def test_profiles_carry_the_discrepancy_only_when_asked(seam_problem):
    class R:
        criterion, q_meas = "random", seam_problem.cell.robot.random_q(np.random.default_rng(5), 25)

    plain = path_profiles(seam_problem, [R()])[0]["paths"][0]
    both = path_profiles(seam_problem, [R()], discrepancy=True)[0]["paths"][0]
    assert "sigma_pos_gp_m" not in plain and len(both["sigma_pos_gp_m"]) == 161
    assert "with the discrepancy TCP sigma RMS" in profile_lines([{"criterion": "random", "paths": [both]}])[0]
    assert "with the discrepancy" not in profile_lines([{"criterion": "random", "paths": [plain]}])[0]


def _profile(name, scale):
    s = np.linspace(0.0, 0.8, 161)
    return {"criterion": name, "paths": [{"name": "seam", "s_m": s.tolist(),
                                          "sigma_pos_m": (scale * (1 + s) * 1e-6).tolist(),
                                          "sigma_rot_rad": (scale * (2 - s) * 1e-6).tolist()}]}


def test_profile_figure_and_its_refusals(tmp_path):
    out = plot_path_profiles([_profile("kpi", 1.0), _profile("kpi_path", 0.9)], tmp_path / "p.png", title="t")
    assert out.stat().st_size > 10_000
    with pytest.raises(InputError, match="no design with a working-path profile"):
        plot_path_profiles([{"criterion": "kpi", "paths": []}], tmp_path / "q.png")
    bad = _profile("kpi", 1.0)
    bad["paths"][0]["sigma_rot_rad"] = bad["paths"][0]["sigma_rot_rad"][:-1]
    with pytest.raises(InputError, match="equally long"):
        plot_path_profiles([bad], tmp_path / "q.png")
    assert not (tmp_path / "q.png").exists()


def test_view_figures_write_the_path_profile_with_its_units(tmp_path):
    from pin_kpi_oed.design.design_writer import write_design
    from pin_kpi_oed.design.runner import DesignSettings, design_run

    run = design_run(load_cell("kr15_seam"), DesignSettings(criteria=("random",), measurements=12, seed=0))
    write_design(tmp_path / "seam.json", run)
    assert json.loads((tmp_path / "seam.json").read_text())["path_profiles"]
    rc, out, err = run_cli("view", tmp_path / "seam.json", "--figures", tmp_path / "figs", "--no-open",
                           "--html", tmp_path / "v.html")
    assert rc == 0, err
    assert (tmp_path / "figs" / "design_path_sigma.png").stat().st_size > 10_000
    assert "design_path_sigma.png (TCP sigma in um and tool orientation sigma in urad" in out
