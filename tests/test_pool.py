"""Pool selection, the approximate-design certificate and the equivalence theorem."""

from __future__ import annotations

import numpy as np
import pytest

from pin_kpi_oed.oed import identifiability as idf
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.oed.pool import approximate_design, detmax, efficiency, exact_phi, select

from .conftest import make_model


@pytest.fixture(scope="module")
def pool():
    model = make_model("kr15")
    ident = idf.analyse(model)
    b = ident.base
    rng = np.random.default_rng(0)
    Q = model.robot.random_q(rng, 300)
    p0 = np.zeros(model.n_params)
    Fp = model.weighted_jacobian(p0, Q)[:, :, b]
    E = model.kpi_jacobian(p0, model.robot.neutral()[None])[:, b]
    return Fp, E


def test_relaxation_satisfies_equivalence_theorem_and_bounds_every_design(pool):
    Fp, E = pool
    ap = approximate_design(Fp, E, tol=1e-3)
    assert ap.max_d_ratio <= 1.0 + 1e-3 + 1e-9
    assert abs(ap.weights.sum() - 1.0) < 1e-12 and (ap.weights >= 0).all()
    assert ap.lower_bound <= ap.phi
    m = 40
    idx = select(Fp, m, E).indices
    rng = np.random.default_rng(1)
    for design in [idx] + [rng.choice(len(Fp), m, replace=False) for _ in range(20)]:
        eff = efficiency(exact_phi(Fp, design, E), ap, m)
        assert 0 < eff <= 1.0  # no m-point design beats the certificate
    assert efficiency(exact_phi(Fp, idx, E), ap, m) > 0.9


@pytest.mark.parametrize("kind", ["kpi", "param", "D"])
def test_selection_no_worse_than_detmax(pool, kind):
    Fp, E = pool
    K = {"kpi": E, "param": np.eye(Fp.shape[-1]), "D": None}[kind]
    m = 40
    idx = select(Fp, m, K).indices
    assert len(set(idx.tolist())) == m
    ours = exact_phi(Fp, idx, K)
    base = np.median([exact_phi(Fp, detmax(Fp, m, K, seed=s), K) for s in range(3)])  # typical DETMAX run
    rnd = exact_phi(Fp, np.random.default_rng(2).choice(len(Fp), m, replace=False), K)
    assert ours <= base + 1e-3 * abs(base)
    assert ours < rnd


def test_too_large_m_is_an_error(pool):
    Fp, E = pool
    with pytest.raises(InputError, match="pool of 300"):
        select(Fp, 301, E)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_selection_and_certificate_against_brute_force_on_a_tiny_pool(seed):
    """14 candidates, 11 chosen: all 364 designs enumerated. The A on C_s and D selections are the global
    optimum; the A on C_p selection within 3 %; no design beats the certified bounds (A: φ*/m, D: φ* − nb log m)."""
    import itertools

    model = make_model("kr15")
    b = idf.analyse(model).base
    rng = np.random.default_rng(seed)
    p0 = np.zeros(model.n_params)
    Fp = model.weighted_jacobian(p0, model.robot.random_q(rng, 14))[:, :, b]
    E = model.kpi_jacobian(p0, model.robot.neutral()[None])[:, b]
    m, nb = 11, b.size
    for kind, K in (("kpi", E), ("D", None), ("param", np.eye(nb))):
        phis = np.array([exact_phi(Fp, np.array(c), K) for c in itertools.combinations(range(14), m)])
        sel = select(Fp, m, K)
        assert sel.phi == pytest.approx(exact_phi(Fp, sel.indices, K), rel=1e-12)
        assert sel.phi <= phis.min() + (0.03 if kind == "param" else 1e-9) * abs(phis.min()), kind
        bound = sel.approx.lower_bound / m if K is not None else sel.approx.lower_bound - nb * np.log(m)
        assert phis.min() >= bound, kind
        assert sel.success and sel.approx.max_d_ratio <= 1 + 1e-3 + 1e-9
