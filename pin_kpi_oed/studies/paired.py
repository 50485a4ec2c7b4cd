r"""The one paired comparison of the package's studies and benchmarks: method a against method b on the same
splits (seeds, robots), smaller is better.

A headline is the **paired median** of the per-pair ratios, with the **sign test**: over n pairs with w wins of a
(a < b), l losses and the ties left out, the two-sided exact binomial p of w in w + l at ½. The Wilcoxon
signed-rank p and the change of the means stand beside it, never alone: a ratio of means is carried by the few
pairs where one method fails (a random design that barely identifies the robot), the median and the sign test
are not.

.. math::

    \mathrm{change} = \operatorname{median}_i (a_i / b_i) - 1,\qquad
    p_{\mathrm{sign}} = \min\bigl(1,\; 2\, P[X \le \min(w, l)]\bigr),\; X \sim \mathrm{Bin}(w + l, 1/2).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from pin_kpi_oed.errors import InputError

__all__ = ["paired_comparison", "paired_text"]


def paired_comparison(a: Sequence[float], b: Sequence[float]) -> dict:
    """Paired comparison of ``a`` against ``b`` (same pairs, smaller is better).

    Args:
        a, b: the two methods' values on the same n pairs (any positive unit, e.g. m).

    Returns:
        dict: ``n``; ``median_a``, ``median_b``; ``change_median`` (median of a_i / b_i − 1; the headline);
        ``wins_a``, ``losses_a``, ``ties``; ``p_sign`` (two-sided exact sign test, ties left out; 1.0 without a
        decided pair); ``p_wilcoxon`` (two-sided signed-rank; 1.0 when every pair is equal); ``mean_a``,
        ``mean_b`` and ``change_mean`` (the change of the means, beside the median only).

    Raises:
        InputError: the two differ in length, are empty, or a value of b is not positive.
    """
    from scipy.stats import binomtest, wilcoxon

    x, y = np.asarray(a, float), np.asarray(b, float)
    if x.shape != y.shape or x.size == 0:
        raise InputError(f"paired comparison: {x.size} and {y.size} values (the same pairs, at least one)")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y)) and np.all(y > 0)):
        raise InputError("paired comparison: values must be finite and the reference's positive")
    diff = x - y
    wins, losses = int(np.sum(diff < 0)), int(np.sum(diff > 0))
    decided = wins + losses
    p_sign = float(binomtest(wins, decided, 0.5).pvalue) if decided else 1.0
    p_w = 1.0 if np.all(diff == 0) else float(wilcoxon(x, y).pvalue)
    return {"n": int(x.size), "median_a": float(np.median(x)), "median_b": float(np.median(y)),
            "change_median": float(np.median(x / y) - 1.0), "wins_a": wins, "losses_a": losses,
            "ties": int(x.size - decided), "p_sign": p_sign, "p_wilcoxon": p_w,
            "mean_a": float(x.mean()), "mean_b": float(y.mean()), "change_mean": float(x.mean() / y.mean() - 1.0)}


def paired_text(c: dict) -> str:
    """One line of a :func:`paired_comparison`: the median change with wins and the sign test, then the rest.

    Example: ``median change -10.0 % (15/20 wins, sign test p = 0.041; Wilcoxon p = 0.0019; mean change -85.6 %)``.
    """
    return (f"median change {c['change_median'] * 100:+.1f} % ({c['wins_a']}/{c['n']} wins, sign test "
            f"p = {c['p_sign']:.2g}; Wilcoxon p = {c['p_wilcoxon']:.2g}; mean change {c['change_mean'] * 100:+.1f} %)")
