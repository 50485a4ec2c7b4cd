"""Uniform draws of ``numpy.random.default_rng(seed)`` without loading ``numpy.random``.

The identifiability analysis excites the model with configurations drawn uniformly within the joint limits from
``default_rng(seed)``. ``numpy.random`` (its bit generators, ``secrets``, ``hmac``, ...) is the largest import that
``info`` would load for it alone; these few hundred draws are computed here in Python instead, bit for bit the same:
NumPy's ``SeedSequence`` (entropy mixing, state generation), its ``PCG64`` (XSL-RR, 128-bit LCG) and
``Generator.uniform`` (``low + (high - low) * u``, ``u`` the 53 high bits of the next 64-bit output).
``tests/test_seeded_uniform.py`` compares them with NumPy's.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

_M32 = 0xFFFFFFFF
_M64 = (1 << 64) - 1
_M128 = (1 << 128) - 1
_INIT_A, _MULT_A = 0x43B0D7E5, 0x931E8875
_INIT_B, _MULT_B = 0x8B51F9DD, 0x58F38DED
_MIX_L, _MIX_R = 0xCA01F9DD, 0x4973F715
_POOL = 4
_PCG_MULT = 0x2360ED051FC65DA44385DF649FCCF645


def _seed_words(seed: int) -> list[int]:
    """The seed as 32-bit words, least significant first (``SeedSequence``'s entropy of an integer)."""
    words = [seed & _M32]
    seed >>= 32
    while seed:
        words.append(seed & _M32)
        seed >>= 32
    return words


def _pool(entropy: list[int]) -> list[int]:
    """``SeedSequence``'s pool of four 32-bit words mixed from ``entropy``."""
    const = _INIT_A

    def hashmix(value: int) -> int:
        nonlocal const
        value ^= const
        const = (const * _MULT_A) & _M32
        value = (value * const) & _M32
        return value ^ (value >> 16)

    def mix(x: int, y: int) -> int:
        r = (_MIX_L * x - _MIX_R * y) & _M32
        return r ^ (r >> 16)

    pool = [hashmix(entropy[i] if i < len(entropy) else 0) for i in range(_POOL)]
    for src in range(_POOL):
        for dst in range(_POOL):
            if src != dst:
                pool[dst] = mix(pool[dst], hashmix(pool[src]))
    for src in range(_POOL, len(entropy)):
        for dst in range(_POOL):
            pool[dst] = mix(pool[dst], hashmix(entropy[src]))
    return pool


def _state64(pool: list[int], n_words: int) -> list[int]:
    """``SeedSequence.generate_state(n_words, uint64)``."""
    const, out32 = _INIT_B, []
    for i in range(2 * n_words):
        v = pool[i % _POOL] ^ const
        const = (const * _MULT_B) & _M32
        v = (v * const) & _M32
        out32.append(v ^ (v >> 16))
    return [out32[2 * k] | (out32[2 * k + 1] << 32) for k in range(n_words)]


def unit_draws(seed: int, n: int) -> list[float]:
    """The first ``n`` doubles in [0, 1) of ``numpy.random.default_rng(seed).random()``.

    Args:
        seed: a non-negative integer seed.
        n: how many draws.

    Returns:
        The draws, in NumPy's order.

    Raises:
        ValueError: a negative seed (NumPy refuses it too).
    """
    if seed < 0:
        raise ValueError(f"seed must be non-negative, got {seed}")
    s = _state64(_pool(_seed_words(int(seed))), 4)
    init_state, init_seq = (s[0] << 64) | s[1], (s[2] << 64) | s[3]
    inc = ((init_seq << 1) | 1) & _M128
    state = (inc + init_state) & _M128  # srandom: step from 0 (gives inc), add the initial state, step again
    state = (state * _PCG_MULT + inc) & _M128
    out = []
    for _ in range(n):
        state = (state * _PCG_MULT + inc) & _M128
        hi, lo = state >> 64, state & _M64
        x, rot = hi ^ lo, hi >> 58
        u64 = ((x >> rot) | (x << ((64 - rot) & 63))) & _M64
        out.append((u64 >> 11) * (1.0 / 9007199254740992.0))
    return out


def uniform_rows(seed: int, low: Sequence[float] | np.ndarray, high: Sequence[float] | np.ndarray, n: int
                 ) -> np.ndarray:
    """``numpy.random.default_rng(seed).uniform(low, high, size=(n, len(low)))``, bit for bit.

    Args:
        seed: a non-negative integer seed.
        low: lower bounds, one per column (any unit: the draws take it).
        high: upper bounds, one per column.
        n: rows.

    Returns:
        (n, len(low)) draws, row by row as NumPy draws them.

    Raises:
        ValueError: a negative seed.
    """
    lo = np.asarray(low, dtype=float).ravel()
    span = np.asarray(high, dtype=float).ravel() - lo
    u = np.array(unit_draws(seed, n * lo.size), dtype=float).reshape(n, lo.size)
    return lo + span * u
