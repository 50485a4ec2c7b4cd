"""The trust map (predicted σ over configurations of use, measured coverage) and the honest ellipsoids of the viewer:
the figure's σ is predict_with_sigma's, extrapolated rows are marked and counted, ``predict --figure`` checks its
path before any work; ``design --model`` writes each design's honest C_s and ``view`` draws it (larger than the
paper's), old design files keep the paper's."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pin_kpi_oed import NoiseModel, TrackerModel, load_robot
from pin_kpi_oed.cli.app import main
from pin_kpi_oed.data.measurements import write_measurements
from pin_kpi_oed.design.design_file import load_design
from pin_kpi_oed.discrepancy import Discrepancy, DiscrepancyOptions, JointKernel
from pin_kpi_oed.discrepancy.coverage import JointCoverage
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.identification.identify import identify
from pin_kpi_oed.calibrated.model_file import load_model_file
from pin_kpi_oed.simulation.simulator import default_tracker_pose, simulate
from pin_kpi_oed.viz.ellipsoids import confidence_ellipsoid
from pin_kpi_oed.viz.scene import SceneOptions, build_scene
from pin_kpi_oed.viz.trust_map import plot_trust_map, trust_map, trust_map_title


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    """A UR10 model file with an exact discrepancy trained on 40 configurations (shoulder pan within ±1 rad), and
    30 rows of use: 15 at the training configurations, 15 with the pan at 2.8 rad (outside the coverage)."""
    robot = load_robot("ur10")
    model = TrackerModel(robot, tracker_T_base=default_tracker_pose(robot), reflector_m=np.array([0.03, 0.02, 0.08]),
                         noise=NoiseModel(sigma_xyz_m=(1e-5,) * 3))
    data = simulate(model, robot.random_q(np.random.default_rng(1), 60), np.zeros(model.n_params), seed=2)
    cm = identify(model, data, discrepancy=DiscrepancyOptions(mode="none")).calibrated_model()
    rng = np.random.default_rng(3)
    Z = robot.random_q(rng, 40)
    Z[:, 0] = rng.uniform(-1.0, 1.0, 40)
    cm.discrepancy = Discrepancy("exact", list(robot.joint_names), np.array([2e-4, 1e-4, 1.5e-4]), np.zeros(3), 0.02,
                                 JointKernel(0.8, np.full(6, 1.3), np.full(6, 0.2), np.full(6, 0.4)), Z,
                                 0.3 * rng.standard_normal((40, 3)), coverage=JointCoverage.from_training(Z), n_rows=40)
    folder = tmp_path_factory.mktemp("trust")
    cm.save(folder / "m.json")
    Q = np.vstack([Z[:15], Z[15:30]])
    Q[15:, 0] = 2.8
    use = simulate(model, Q, np.zeros(model.n_params), seed=4)
    write_measurements(use, folder / "use.csv")
    return load_model_file(folder / "m.json"), Q, folder


def test_trust_map_draws_the_sigma_of_predict(calibrated, tmp_path):
    cm, Q, _ = calibrated
    out = tmp_path / "trust.png"
    tm = plot_trust_map(cm, Q, out=out)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and not list(tmp_path.glob(".*.tmp"))
    Y, sig, extra = cm.predict_with_sigma(Q)
    assert np.allclose(tm.sigma_m, np.linalg.norm(sig, axis=1), rtol=1e-12) and np.allclose(tm.sigma_xyz_m, sig)
    T = cm.setups[cm.station()].tracker_T_base
    assert np.allclose(tm.positions_base_m @ T[:3, :3].T + T[:3, 3], Y, atol=1e-12)   # base frame
    # the extrapolated rows: flagged, counted in the legend, and the coloured values are the σ in mm
    assert np.array_equal(tm.extrapolation, extra) and tm.n_extrapolated == 15 and not extra[:15].any()
    ax = tm.figure.axes[0]
    texts = [t.get_text() for t in ax.get_legend().get_texts()]
    assert any("extrapolation" in t and "(15 rows)" in t for t in texts), texts
    assert any(t.startswith("measured (training)") and "40 rows" in t for t in texts), texts
    drawn = np.concatenate([np.asarray(c.get_array()) for c in ax.collections if c.get_array() is not None])
    assert np.allclose(np.sort(drawn), np.sort(tm.sigma_m * 1e3))
    assert tm.figure.axes[-1].get_ylabel() == "predicted σ (mm)"
    assert np.median(tm.sigma_m[15:]) > np.median(tm.sigma_m[:15])          # σ grows outside the coverage


def test_cli_predict_figure_and_bad_paths(calibrated, tmp_path, capsys):
    _, _, folder = calibrated
    base = ["predict", "--model", str(folder / "m.json"), "--data", str(folder / "use.csv")]
    pred, fig = tmp_path / "pred.csv", tmp_path / "trust.png"
    assert main(base + ["--out", str(pred), "--figure", str(fig)]) == 0
    assert "15 of 30 rows outside the measured coverage" in capsys.readouterr().out
    assert fig.read_bytes()[:4] == b"\x89PNG" and pred.exists()
    for bad, needle in [(tmp_path / "missing" / "t.png", "does not exist"), (tmp_path, "is a folder"),
                        (folder / "use.csv", "is the input"), (tmp_path / "p2.csv", "is also --out")]:
        out = tmp_path / "p2.csv"
        assert main(base + ["--out", str(out), "--figure", str(bad)]) == 2
        err = capsys.readouterr().err
        assert "--figure" in err and needle in err and len(err.strip().splitlines()) == 1, err
        assert not out.exists() and not (tmp_path / "missing").exists()


def test_design_with_model_writes_honest_blocks_and_the_viewer_draws_them(calibrated, tmp_path, capsys):
    """A design with a model file writes each design's honest C_s block; the viewer draws it (and the paper's).
    The optimisation starts from the heuristic design (``--start random``): what is asserted holds for any poses (a
    C_s block and its trace, the discrepancy widening every ellipsoid), and the pool start cost two thirds of the
    design's CPU."""
    _, _, folder = calibrated
    d = tmp_path / "d.json"
    assert main(["design", "--cell", "ur10", "--model", str(folder / "m.json"), "--criteria", "random,kpi",
                 "--measurements", "20", "--starts", "1", "--max-iter", "5", "--start", "random", "--json", str(d),
                 "--quiet"]) == 0
    capsys.readouterr()
    doc = json.loads(d.read_text())
    t = len(doc["q_work"])
    for e in doc["designs"]:
        C = np.asarray(e["discrepancy"]["cov_s_m2"])
        assert C.shape == (3 * t, 3 * t)
        assert np.trace(C) == pytest.approx(e["discrepancy"]["trace_cs_m2"], rel=1e-6)   # a rotation keeps it
    df = load_design(d)
    assert all(e.cov_s_honest_m2 is not None for e in df.designs)
    Rw = df.world_T_tracker.rotation
    honest = build_scene(df, SceneOptions(animate=False, ghosts=False))
    paper = build_scene(df, SceneOptions(animate=False, ghosts=False, sigma="paper"))
    assert honest.sigma == "honest" and paper.sigma == "paper"
    assert "discrepancy included" in honest.legend_html() and "tracker noise only" in paper.legend_html()
    by = {e.criterion: e for e in df.designs}
    for vh, vp in zip(honest.ellipsoids, paper.ellipsoids):
        e, j = by[vh.design], vh.work_index
        blk = slice(3 * j, 3 * j + 3)
        assert np.allclose(vh.radii_m, confidence_ellipsoid(Rw @ e.cov_s_honest_m2[blk, blk] @ Rw.T)[0])
        assert np.allclose(vp.radii_m, confidence_ellipsoid(Rw @ e.cov_s_m2[blk, blk] @ Rw.T)[0])
        assert vh.radii_m.max() > vp.radii_m.max()
    # an old design file (no honest blocks): the paper's C_s, and --sigma honest is refused in one line
    for e in doc["designs"]:
        del e["discrepancy"]
    old = tmp_path / "old.json"
    old.write_text(json.dumps(doc))
    assert build_scene(load_design(old), SceneOptions(animate=False, ghosts=False)).sigma == "paper"
    with pytest.raises(InputError, match="sigma='honest'"):
        build_scene(load_design(old), SceneOptions(animate=False, ghosts=False, sigma="honest"))
    page = tmp_path / "v.html"
    assert main(["view", str(old), "--sigma", "honest", "--html", str(page), "--no-open", "--no-ghosts"]) == 2
    assert "--sigma honest" in capsys.readouterr().err and not page.exists()
    assert main(["view", str(d), "--sigma", "both", "--html", str(page), "--no-open"]) == 2
    assert "--sigma: must be honest or paper" in capsys.readouterr().err and not page.exists()
    assert main(["view", str(d), "--html", str(page), "--no-open", "--no-ghosts"]) == 0
    assert "discrepancy included" in capsys.readouterr().out and page.exists()


def test_the_title_says_what_the_sigma_holds(calibrated, tmp_path):
    """A Gaussian-process model says so; a white level alone or no block is never called 'discrepancy included'.
    The three titles are :func:`trust_map_title`'s; one figure is drawn, to see that it carries that title (the
    drawing does not depend on the discrepancy's kind)."""
    import dataclasses

    cm, Q, _ = calibrated
    white = Discrepancy("white", list(cm.robot.joint_names), np.full(3, 1e-4), np.zeros(3), 1.0, n_rows=40)
    titles = {}
    for tag, d in (("gp", cm.discrepancy), ("white", white), ("none", None)):
        model = dataclasses.replace(cm, discrepancy=d)
        titles[tag] = trust_map_title(model, trust_map(model, Q[:5]))
    drawn = plot_trust_map(dataclasses.replace(cm, discrepancy=white), Q[:5], out=tmp_path / "white.png")
    assert drawn.figure._suptitle.get_text() == titles["white"]
    assert "Gaussian-process discrepancy (exact, 40 rows)" in titles["gp"]
    assert "white residual level; no correlated discrepancy" in titles["white"]
    assert "no discrepancy (noise-only model)" in titles["none"]
    assert not any("discrepancy included" in t for t in titles.values())
