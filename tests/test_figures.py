"""Report figures: PNGs written atomically, ellipse geometry, design figures; progress bars."""

from __future__ import annotations

import io
import os

import numpy as np
import pytest

from pin_kpi_oed.design.design_file import load_design
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.viz import figures

from .test_viewer import make_design


def _png_size(path) -> tuple[int, int]:
    from PIL import Image

    with Image.open(path) as im:
        im.verify()
    with Image.open(path) as im:
        return im.size


@pytest.fixture(scope="module")
def design() -> dict:
    return make_design(m=14, cov_for=("random", "param", "kpi"))


def test_ellipse_is_the_shadow_of_the_ellipsoid():
    rng = np.random.default_rng(1)
    A = rng.normal(size=(3, 3))
    C = A @ A.T * 1e-12
    k = 7.814727903251178
    P = figures.ellipse_points(C[:2, :2], k, n=721)
    # every point on the boundary x^T C2^-1 x = k
    q = np.einsum("ni,ij,nj->n", P, np.linalg.inv(C[:2, :2]), P)
    np.testing.assert_allclose(q, k, rtol=1e-9)
    # its extent along x equals that of the 3-D ellipsoid (support function sqrt(k C_xx))
    assert np.abs(P[:, 0]).max() == pytest.approx(np.sqrt(k * C[0, 0]), rel=1e-4)


def test_plots_write_pngs_atomically(tmp_path):
    rng = np.random.default_rng(0)
    covs = {}
    for name, s in (("random", 3.0), ("param", 2.0), ("kpi", 1.0)):
        A = rng.normal(size=(6, 6)) * s * 1e-6
        covs[name] = A @ A.T  # two working configurations
    p1 = figures.plot_ellipsoid_projections(covs, tmp_path / "ell.png", labels={"random": "heuristic"})
    w, h = _png_size(p1)
    assert w > 1000 and h > 700  # 2 rows x 3 planes
    p2 = figures.plot_design_bars({k: float(np.trace(v)) for k, v in covs.items()}, tmp_path / "bars.png", n_work=2)
    p3 = figures.plot_pose_quality({"kpi": np.array([0.01, 0.2, -0.001, np.inf])},
                                   {"kpi": np.array([10.0, 31.0, 5.0, 29.0])}, tmp_path / "poses.png")
    for p in (p2, p3):
        assert _png_size(p)[0] > 500
    # overwrite in place; no temporary file left behind
    before = p2.stat().st_mtime_ns
    figures.plot_design_bars({"random": 2e-12, "kpi": 1e-12}, p2)
    assert p2.stat().st_mtime_ns >= before
    assert sorted(os.listdir(tmp_path)) == ["bars.png", "ell.png", "poses.png"]


def test_failed_write_leaves_the_old_file(tmp_path, monkeypatch):
    target = tmp_path / "bars.png"
    target.write_bytes(b"old")

    def boom(*a, **k):
        raise OSError("disk full")

    monkeypatch.setattr(figures.os, "replace", boom)
    with pytest.raises(OSError, match="disk full"):
        figures.plot_design_bars({"kpi": 1e-12}, target)
    assert target.read_bytes() == b"old" and os.listdir(tmp_path) == ["bars.png"]


def test_bad_input(tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        figures.plot_design_bars({"kpi": 1e-12}, tmp_path / "missing" / "x.png")
    with pytest.raises(InputError, match="is a directory"):
        figures.plot_design_bars({"kpi": 1e-12}, tmp_path)
    with pytest.raises(InputError, match=r"\(3t, 3t\)"):
        figures.plot_ellipsoid_projections({"kpi": np.eye(4)}, tmp_path / "e.png")
    with pytest.raises(InputError, match="finite"):
        figures.plot_design_bars({"kpi": float("nan")}, tmp_path / "b.png")
    with pytest.raises(InputError, match="unit"):
        figures.plot_ellipsoid_projections({"kpi": np.eye(3)}, tmp_path / "e.png", unit="in")


def test_design_figures_from_a_design_json(design, tmp_path):
    out = figures.design_figures(design, tmp_path, prefix="kr15")
    assert set(out) == {"ellipsoids", "bars", "poses"}
    for p in out.values():
        assert p.parent == tmp_path and p.name.startswith("kr15_") and _png_size(p)[0] > 500
    # what the pose figure shows: the independent check's clearance and the model's incidence ...
    df = load_design(design)
    v = figures.design_figure_data(df)
    for d in df.designs:
        np.testing.assert_allclose(v.clearance_m[d.criterion], df.checker.check(d.q_meas).clearance_m, rtol=0)
        np.testing.assert_allclose(v.incidence_deg[d.criterion], df.checker.check(d.q_meas).incidence_deg, atol=1e-8)
        # ... and the ellipsoids in the cell frame: C_world = R C_tracker R^T (same eigenvalues)
        C = d.cov_s_m2[:3, :3]
        np.testing.assert_allclose(np.linalg.eigvalsh(v.covs_m2[d.criterion][0]), np.linalg.eigvalsh(C), rtol=1e-9)
    assert v.colours == {"random": "#1f77b4", "param": "#9467bd", "kpi": "#2ca02c"}
    # per-pose values given in the file are used as they are
    design["designs"][0]["clearance_m"] = [0.05] * 14
    design["designs"][0]["incidence_deg"] = [12.0] * 14
    v = figures.design_figure_data(load_design(design))
    assert v.clearance_m["random"].tolist() == [0.05] * 14 and v.incidence_deg["random"].tolist() == [12.0] * 14


def test_progress_is_silent_off_a_terminal(monkeypatch, capsys):
    from pin_kpi_oed.progress import enabled, progress

    monkeypatch.delenv("PIN_KPI_OED_PROGRESS", raising=False)
    assert sum(progress(range(5), desc="quiet")) == 10
    with progress(total=3, desc="quiet") as bar:
        bar.update(3)
    cap = capsys.readouterr()
    assert cap.err == "" and cap.out == ""  # pytest's captured stderr is not a TTY

    class Tty(io.StringIO):
        def isatty(self):
            return True

    tty = Tty()
    assert enabled(tty)
    list(progress(range(4), desc="shown", file=tty, mininterval=0))
    assert "shown" in tty.getvalue()
    tty2 = Tty()
    list(progress(range(4), desc="off", file=tty2, disable=True))
    assert tty2.getvalue() == ""
    monkeypatch.setenv("PIN_KPI_OED_PROGRESS", "0")
    assert not enabled(tty)
    monkeypatch.setenv("PIN_KPI_OED_PROGRESS", "1")
    buf = io.StringIO()
    list(progress(range(3), desc="forced", file=buf, mininterval=0))
    assert "forced" in buf.getvalue()


def test_design_figures_show_the_honest_covariance_when_the_file_has_it(design, tmp_path):
    """With every design's C_s with the discrepancy in the file (design --model), the ellipsoids and bars show it
    by default, the paper's on request; a file without it shows the paper's."""
    import copy

    d = copy.deepcopy(design)
    df0 = load_design(d)
    for e, entry in zip(d["designs"], df0.designs):
        e.setdefault("discrepancy", {})["cov_s_m2"] = (9.0 * entry.cov_s_m2).tolist()
    df = load_design(d)
    honest, paper = figures.design_figure_data(df), figures.design_figure_data(df, sigma="paper")
    assert honest.sigma == "honest" and paper.sigma == "paper"
    for e in df.designs:
        assert honest.traces_m2[e.criterion] == pytest.approx(9.0 * paper.traces_m2[e.criterion], rel=1e-9)
        np.testing.assert_allclose(honest.covs_m2[e.criterion], 9.0 * paper.covs_m2[e.criterion], rtol=1e-9)
    assert figures.design_figure_data(df0).sigma == "paper"      # nothing honest in the file: the paper's
    out = figures.design_figures(df, tmp_path, prefix="h")
    assert all(_png_size(p)[0] > 500 for p in out.values())


def _pixels(data: bytes) -> np.ndarray:
    from PIL import Image

    with Image.open(io.BytesIO(data)) as im:
        return np.asarray(im)


def test_png_drawn_once_has_the_pixels_of_savefig():
    """``write_png`` draws a figure once (the layout engine run inside that draw; a tight crop measured before it)
    where ``savefig`` draws it twice: the pixels are those of ``savefig`` at the same dpi, exactly, for a constrained
    figure with a legend, a colour bar and a title, and for one laid out by ``tight_layout`` (the diagnosis figures),
    cropped or not; the figure keeps its dpi and layout engine."""
    from pin_kpi_oed.report.figures import outside_legend

    def constrained():
        rng = np.random.default_rng(4)
        fig = figures.agg_figure(4.0, 2.0)
        ax1, ax2 = fig.subplots(1, 2)
        ax1.plot(rng.normal(size=30).cumsum(), label="walk")
        ax1.legend(loc="best")
        sc = ax2.scatter(*rng.normal(size=(2, 40)), c=rng.random(40), cmap="viridis")
        fig.colorbar(sc, ax=ax2, label="σ (mm)")
        fig.suptitle("both ways")
        return fig

    def tight():
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        rng = np.random.default_rng(5)
        fig = Figure(figsize=(3.0, 2.0))
        FigureCanvasAgg(fig)
        ax = fig.subplots()
        ax.hist(rng.normal(size=200), bins=20, label="rows")
        outside_legend(ax)
        fig.tight_layout()
        return fig

    for make, crop, dpi in ((constrained, False, 120), (tight, True, 90), (tight, False, 110)):
        fig = make()                                  # a fresh figure each way: no draw before the one measured
        engine = fig.get_layout_engine()
        out = io.BytesIO()
        figures.write_png(fig, out, dpi, tight=crop)
        assert fig.dpi == 100 and fig.get_layout_engine() is engine
        ref = io.BytesIO()
        make().savefig(ref, format="png", dpi=dpi, bbox_inches="tight" if crop else None)
        a, b = _pixels(ref.getvalue()), _pixels(out.getvalue())
        assert a.shape == b.shape and np.array_equal(a, b), make.__name__


def test_shade_draws_what_fill_draws():
    """The ellipsoid figure's shaded ellipses (``shade``: the polygon added without updating the data limits) have
    the pixels of ``ax.fill`` with the same colour and opacity, on axes whose limits are set afterwards (as the
    figure sets them)."""
    P = figures.ellipse_points(np.array([[4.0, 1.5], [1.5, 1.0]]), 7.81)

    def draw(use_fill: bool) -> np.ndarray:
        fig = figures.agg_figure(2.5, 2.0)
        ax = fig.subplots()
        if use_fill:
            ax.fill(P[:, 0], P[:, 1], color="#2ca02c", alpha=0.12)
        else:
            figures.shade(ax, P, "#2ca02c", 0.12)
        ax.set_xlim(-7.0, 7.0)
        ax.set_ylim(-7.0, 7.0)
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=120)
        return _pixels(buf.getvalue())

    a, b = draw(True), draw(False)
    assert a.shape == b.shape and np.array_equal(a, b)
    assert (a[..., :3] != 255).any(axis=-1).mean() > 0.05      # the ellipse covers part of the image
