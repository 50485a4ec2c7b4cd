"""The identifiability's excitation drawn without ``numpy.random`` is NumPy's, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from pin_kpi_oed.model.robot import load_robot
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.oed.identifiability import excitation
from pin_kpi_oed.oed.seeded_uniform import unit_draws, uniform_rows


@pytest.mark.parametrize("seed", [0, 1, 5, 2**31 - 1, 2**32 - 1, 2**32, 2**64 + 3, 2**130 + 17])
def test_draws_are_numpys_bit_for_bit(seed: int) -> None:
    """One-word, two-word and longer seeds (``SeedSequence``'s pool and its further entropy words)."""
    assert np.array_equal(unit_draws(seed, 64), np.random.default_rng(seed).random(64))
    lo = np.array([-2 * np.pi, -3.1, -1.0, 0.0, 0.2])
    hi = np.array([2 * np.pi, 0.5, 1.0, 1e-3, 3.0])
    assert np.array_equal(uniform_rows(seed, lo, hi, 37), np.random.default_rng(seed).uniform(lo, hi, size=(37, 5)))


def test_excitation_is_random_q_of_default_rng() -> None:
    model = TrackerModel(load_robot("ur5"), reflector_m=np.array([0.05, 0.0, 0.05]))
    for seed in (0, 3):
        want = model.robot.random_q(np.random.default_rng(seed), 200)
        assert np.array_equal(excitation(model, seed=seed), want)


def test_a_negative_seed_is_refused_as_numpy_refuses_it() -> None:
    with pytest.raises(ValueError, match="non-negative"):
        unit_draws(-1, 3)
    with pytest.raises(ValueError):
        np.random.default_rng(-1)
