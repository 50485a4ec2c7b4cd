"""The KPI design of a camera calibration whose every pose sees the board: pool selection with its certificate and
IPOPT with the camera's constraints, each pose re-checked independently (OpenCV's re-projection, Coal's rays)."""

from __future__ import annotations

import numpy as np
import pytest

from pin_kpi_oed.cell.camera_view import ViewLimits, camera_cell
from pin_kpi_oed.cell.cell_model import CapsuleSpec, HalfSpace
from pin_kpi_oed.design.camera_design import CameraDesignProblem, design_camera, square_roots
from pin_kpi_oed.design.ipopt import ipopt_options
from pin_kpi_oed.errors import InputError
from tests.camera_setup import Q0, UR5_SKIP, ur5_camera


#: the tests sharing the module fixture ``problem``: on one worker under ``--dist loadgroup``, computed once
GROUP = "test_camera_design_problem"


@pytest.fixture(scope="module")
def problem():
    cam = ur5_camera("eye_in_hand")
    post = CapsuleSpec("post", np.array([0.3, -0.35, 0.0]), np.array([0.3, -0.35, 0.7]), 0.05)
    cell = camera_cell(cam.robot, obstacles=[post], half_spaces=[HalfSpace("table", np.array([0, 0, 1.0]), -0.01)],
                       skip_pairs=UR5_SKIP)
    made = CameraDesignProblem(cell, cam, ViewLimits(margin_px=20.0, max_angle_deg=45.0, near_m=0.2, far_m=1.0),
                               Q0[None])
    # the designs of the tests draw the same seeded pool (60 candidates, seed 0): sampled once, a copy each time
    sample, pools = made.pool, {}

    def pool(size, seed=0, **kw):
        if kw:  # around / spread / max_tries: drawn as asked
            return sample(size, seed, **kw)
        if (size, seed) not in pools:
            pools[size, seed] = sample(size, seed)
        Q, drawn = pools[size, seed]
        return Q.copy(), drawn

    made.pool = pool
    return made


@pytest.mark.xdist_group(GROUP)
def test_ur5_eye_in_hand_design_sees_the_board_at_every_pose(problem):
    """8 poses from a pool of 60 feasible candidates (120 before: the pool and its certificate cost in proportion;
    from 60 IPOPT's 15 iterations end below the selection, so its own poses, not the selection's, are checked)."""
    d = design_camera(problem, 8, seed=0, pool_size=60, ipopt_options=ipopt_options(max_iter=15))
    assert d.Q.shape == (8, 6)
    # the independent check: OpenCV re-projects every corner inside the image, Coal finds every ray clear
    assert np.all(d.check.corners_inside == problem.model.board.n)
    assert np.all(d.check.ray_clearance_m > 0) and np.all(d.check.angle_deg <= 45.0)
    assert np.all((d.check.depth_m >= 0.2) & (d.check.depth_m <= 1.0))
    assert d.success and d.check.ok.all()
    # the certificate: no selection from the pool beats its bound; IPOPT never returns a worse design
    assert d.certificate.lower_bound_trace_cs_m2 <= d.selection_trace_cs_m2 * (1 + 1e-9)
    assert d.trace_cs_m2 <= d.selection_trace_cs_m2 * (1 + 1e-12)
    assert d.ipopt is not None and d.source in ("ipopt", "selection")
    # the selection beats random feasible poses of the same pool on tr C_s (the criterion it minimises)
    Q_pool = d.certificate.Q_pool
    rnd = [problem.trace_cs(Q_pool[np.random.default_rng(s).choice(len(Q_pool), 8, replace=False)])
           for s in range(5)]
    assert d.selection_trace_cs_m2 < min(rnd)


@pytest.mark.xdist_group(GROUP)
def test_square_roots_keep_the_information(problem):
    F = problem.criterion("kpi").jacobians(problem.pool(3, seed=1)[0])
    R = square_roots(F)
    assert R.shape[1] == F.shape[2] < F.shape[1]
    M, MR = np.einsum("nra,nrb->nab", F, F), np.einsum("nra,nrb->nab", R, R)
    assert np.abs(M - MR).max() < 1e-9 * np.abs(M).max()


@pytest.mark.xdist_group(GROUP)
def test_too_few_images_refused(problem):
    with pytest.raises(InputError, match="cannot identify"):
        design_camera(problem, 0)


@pytest.mark.xdist_group(GROUP)
def test_an_efficiency_beyond_the_pools_bound_is_not_stated_and_a_stopped_ipopt_is_noted(problem):
    """The pool's bound covers the designs made of its candidates: a selection's efficiency is stated (≤ 100 %); an
    IPOPT design below the bound (its poses left the pool) gets none, and IPOPT stopped at its iteration limit is
    said to be not converged (as the tracker's design says ``max_iter``)."""
    import dataclasses

    from pin_kpi_oed.design.ipopt import IpoptRun

    d = design_camera(problem, 8, seed=0, pool_size=60, ipopt=False)
    assert d.stated_efficiency == pytest.approx(d.efficiency) and d.efficiency <= 1 + 1e-9
    assert f"efficiency {d.efficiency:.1%} of the pool's bound" in d.message and d.ipopt_note() == ""
    stopped = IpoptRun(Q=d.Q, f=0.5, value=d.trace_cs_m2 / 2.318, success=True, status="max_iter", nit=500,
                       solver_status="Maximum_Iterations_Exceeded")
    off = dataclasses.replace(d, efficiency=2.318, source="ipopt", ipopt=stopped, trace_cs_m2=d.trace_cs_m2 / 2.318)
    assert off.stated_efficiency is None
    assert "no efficiency" in off.efficiency_text() and "231.8" not in off.efficiency_text()
    note = off.ipopt_note()
    assert note.startswith("note: IPOPT not converged: stopped at its iteration limit (500) after 500 iterations")
    assert "raise --max-iter" in note
    done = dataclasses.replace(off, ipopt=dataclasses.replace(stopped, status="converged"))
    assert done.ipopt_note() == ""
