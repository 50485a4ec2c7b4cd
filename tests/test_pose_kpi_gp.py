"""The 6-D KPI under model discrepancy (``kpi6_gp``): ``kpi6`` when the discrepancy's kernel level goes to zero, the
orientation rows through the GLS parameter covariance alone, the exact gradient against finite differences, the pool
state's updates against recomputation, and the design in IPOPT and pool selection."""

from __future__ import annotations

import numpy as np
import pytest

from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.design.ipopt import ipopt_options
from pin_kpi_oed.design.optimize import DesignOptions, DesignProblem, run_designs
from pin_kpi_oed.discrepancy.prior import DiscrepancyPrior
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.oed.criteria import get_criterion
from pin_kpi_oed.oed.discrepancy_defaults import default_discrepancy
from pin_kpi_oed.oed.discrepancy_kpi import DiscrepancyDesignCriterion
from pin_kpi_oed.oed.discrepancy_pool import GreedyState
from pin_kpi_oed.oed.kriging import kpi_gp_value_and_grad, pad_rows
from pin_kpi_oed.oed.pose_kpi_gp import PoseDiscrepancyCriterion

from .fd import fd_rows


@pytest.fixture(scope="module")
def seam():
    return DesignProblem(load_cell("kr15_seam"), collision=False)


def _crit(problem, disc, Q_given=None):
    return PoseDiscrepancyCriterion(problem.model, problem.base, disc, problem.q_work, Q_given=Q_given,
                                    p=problem.p0, length_m=problem.cell.orientation_length_m)


def test_is_kpi6_when_the_discrepancy_level_goes_to_zero(seam):
    """White discrepancy with σ = the tracker's σ: kpi6 exactly; the kernel's level s² → 0 (white σ kept): kpi6 in
    the limit, the gap shrinking with the level."""
    sig = seam.cell.noise.sigma_xyz_m[0]
    assert np.allclose(seam.cell.noise.sigma_xyz_m, sig)
    Q = seam.random_design(20, 3)[0]
    kpi6 = seam.criterion("kpi6").value(Q)
    white = _crit(seam, DiscrepancyPrior(None, np.full(3, sig), 1.0))
    assert white.value(Q) == pytest.approx(kpi6, rel=1e-9)
    kernel = default_discrepancy(6).kernel
    gaps = []
    for w in (1e2, 1e4, 1e6):
        v = _crit(seam, DiscrepancyPrior(kernel, np.full(3, sig / np.sqrt(w)), w)).value(Q)
        gaps.append(abs(v - kpi6) / kpi6)
    assert gaps[0] > gaps[1] > gaps[2]
    assert gaps[2] < 1e-4
    # a real discrepancy costs accuracy
    assert _crit(seam, default_discrepancy(6)).value(Q) > 2 * kpi6


def test_orientation_rows_count_through_the_gls_covariance_alone(seam):
    """t·φ − tr C_s^UK (kpi_gp's position value) = L² Σ_i tr(R_i M⁻¹ R_iᵀ), M the GLS information of the
    correlated rows; it differs from the noise-only (OLS) orientation term."""
    d = default_discrepancy(6)
    Q = seam.random_design(24, 4)[0]
    six = _crit(seam, d)
    pos = DiscrepancyDesignCriterion(seam.model, seam.base, d, seam.q_work, p=seam.p0)
    t, L = len(seam.q_work), seam.cell.orientation_length_m
    J = pos.pool_jacobians(Q)
    G = d.covariance(Q) + d.noise * np.eye(len(Q))
    P = 0.0 if pos.prior_info is None else pos.prior_info
    M = sum(J[:, a].T @ np.linalg.solve(G, J[:, a]) / d.scale_m[a] ** 2 for a in range(3)) + P
    R = seam.model.kpi_rotation_jacobian(seam.p0, seam.q_work)[:, seam.base].reshape(t, 3, -1)
    orient = L ** 2 * np.einsum("tap,pq,taq->", R, np.linalg.inv(M), R)
    assert t * six.value(Q) - pos.value(Q) == pytest.approx(orient, rel=1e-7)
    M_ols = sum(J[:, a].T @ J[:, a] / (d.scale_m[a] ** 2 * d.noise) for a in range(3)) + P
    orient_ols = L ** 2 * np.einsum("tap,pq,taq->", R, np.linalg.inv(M_ols), R)
    assert abs(orient - orient_ols) > 0.05 * orient
    assert six.covariance(Q).shape == (6 * t, 6 * t)
    assert np.trace(six.covariance(Q)) / t == pytest.approx(six.value(Q), rel=1e-9)


@pytest.mark.parametrize("given", [0, 6])
def test_gradient_matches_finite_differences(seam, given):
    """dφ/dQ through J(Q), K_QQ and K_WQ, with and without poses measured before."""
    Q = seam.random_design(16 + given, 5)[0]
    Qg, Q = (Q[:given], Q[given:]) if given else (None, Q)
    crit = _crit(seam, default_discrepancy(6), Q_given=Qg)
    v, g = crit.value_and_grad(Q)
    assert v == pytest.approx(crit.value(Q), rel=1e-12)
    num = fd_rows(crit.value, Q, 4)
    assert np.abs(num - g[:4]).max() <= 1e-5 * np.abs(g[:4]).max()
    assert np.abs(g[:4]).max() > 0


def test_pool_state_with_rows_without_discrepancy_equals_recomputation(seam):
    """GreedyState on the 6t rows (the orientation's kernel rows zero): every candidate's value after additions and
    after a downdate equals t·φ recomputed from scratch; the selection's value is φ of its poses and beats random."""
    d = default_discrepancy(6)
    crit = _crit(seam, d)
    Qp = seam.random_design(50, 8)[0]
    Jp = crit.pool_jacobians(Qp)
    t = len(seam.q_work)

    def direct(idx):
        return crit.value(Qp[idx]) * t
    st = GreedyState(Jp, Qp, crit.E, seam.q_work, d, crit.prior_info, 0.0)
    S = list(range(0, 28, 2))
    for i in S:
        st.add(i)
    ex = np.zeros(len(Qp), bool)
    ex[S] = True
    vals = st.values(ex)
    for j in (1, 7, 31, 49):
        assert vals[j] == pytest.approx(direct(S + [j]), rel=1e-8)
    rest = S[:3] + S[4:]
    among = np.array([S[3], 5, 44])
    assert st.values_without(S[3], among) == pytest.approx([direct(rest + [j]) for j in among], rel=1e-7)
    sel = crit.select(Qp, 14, J_pool=Jp)
    assert sel.value == pytest.approx(crit.value(Qp[sel.indices]), rel=1e-10)
    rng = np.random.default_rng(0)
    assert sel.value < min(crit.value(Qp[rng.choice(len(Qp), 14, replace=False)]) for _ in range(10))
    # the padded kernel rows: zero beyond the working configurations
    Kwq = crit.cross_covariance(Qp[:5])
    assert Kwq.shape == (2 * t, 5) and not Kwq[t:].any() and np.allclose(Kwq[:t], d.covariance(seam.q_work, Qp[:5]))
    assert np.array_equal(pad_rows(Kwq[:t], t), Kwq[:t])
    v0 = kpi_gp_value_and_grad(Jp[:14], crit.E, d.covariance(Qp[:14]), crit.cross_covariance(Qp[:14]),
                               crit.tr_kww, d.scale_m, d.noise, crit.prior_info, grad=False)[0]
    assert v0 / t == pytest.approx(crit.value(Qp[:14]), rel=1e-12)


def test_designs_in_ipopt_and_pool_selection(seam):
    """Registered as a criterion of the configurations: the IPOPT design (started from its pool selection) halves φ
    of the heuristic design; refused with a re-registration and a non-positive length."""
    crit = get_criterion("kpi6_gp")
    assert crit.uses_discrepancy and crit.needs_kpi
    obj = seam.criterion("kpi6_gp")
    assert isinstance(obj, PoseDiscrepancyCriterion)
    assert obj.length_m == seam.cell.orientation_length_m
    rnd, des = run_designs(seam.cell, ["random", "kpi6_gp"], 14, 0,
                           DesignOptions(ipopt=ipopt_options(max_iter=15), pool_size=200), seam)
    assert des.criterion == "kpi6_gp"   # (the problem designs without collision constraints: no feasibility here)
    assert des.value == pytest.approx(obj.value(des.q_meas), rel=1e-9)
    assert des.value < 0.5 * obj.value(rnd.q_meas)
    with pytest.raises(InputError, match="kpi6_gp"):
        PoseDiscrepancyCriterion(seam.model, seam.base, default_discrepancy(6), seam.q_work, p=seam.p0,
                                 Q_register=seam.q_work, length_m=0.2)
    with pytest.raises(InputError, match="orientation_length_m"):
        PoseDiscrepancyCriterion(seam.model, seam.base, default_discrepancy(6), seam.q_work, p=seam.p0,
                                 length_m=0.0)
