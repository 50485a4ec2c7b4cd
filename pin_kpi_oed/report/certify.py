r"""The parts of a certificate that make it one: identity, the uncertainty per the GUM, conformity, the held-out
rows counted, ISO 9283 against the commanded poses.

* **figures with their uncertainty** (:func:`figure_uncertainty`): from the held-out count n — the mean error
  ē ± 2 s/√n; the RMS ± 2 u, u = std(|e|²)/(2 RMS √n) (the RMS² is a mean of n values); the 95th percentile between
  the order statistics a binomial(n, 0.95) puts at ±2 σ of its rank (half that interval's width as U). The
  instrument's own uncertainty of a point adds in quadrature (2 u_instr).
* **conformity** (ISO 14253-1): the stated figure (``--accuracy-figure``, default the 95th percentile) against the
  required accuracy with its U (:func:`~pin_kpi_oed.report.uncertainty.conformity`).
* **the budget**: :func:`~pin_kpi_oed.report.uncertainty.budget` at the working configurations (the model's, or a
  joint-space program given with ``--work``; else at most :data:`BUDGET_ROWS` seeded held-out rows, said so) and the
  expanded uncertainty at every held-out row from the model's σ there (``validate``'s per-axis σ, the one
  ``predict`` prints) with the held term and the temperature: the share of rows within U against the stated coverage.
* **along each working path** (a cell's ``working_paths``, ``report --cell``): the same budget at every sample of the
  path with the cell's TCP (:func:`path_uncertainty`): U's largest value (and where, as arc length) and median, and
  the budget's shares over the samples; with ``--monte-carlo`` its check on each path.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["figure_uncertainty", "uncertainty_section", "held_out_coverage", "conformity_section",
           "commanded_section", "path_uncertainty", "BUDGET_ROWS", "FIGURES"]

#: The most held-out rows the full budget is computed at when the model names no working configurations.
BUDGET_ROWS = 60
#: Accuracy figures a conformity statement can be about: key -> label.
FIGURES = {"p95_m": "95th percentile of the 3-D error", "rms_m": "RMS of the 3-D error",
           "mean_m": "mean 3-D error", "max_m": "largest 3-D error"}


def figure_uncertainty(errors_m: np.ndarray, instrument_u_m: float = 0.0) -> dict:
    """Expanded uncertainties (k = 2, m) of the held-out figures from their count (module docstring)."""
    e = np.sort(np.asarray(errors_m, float))
    n = e.size
    rms = float(np.sqrt(np.mean(e ** 2)))
    ui = 2.0 * float(instrument_u_m)
    u_rms = float(np.std(e ** 2, ddof=1) / (2.0 * max(rms, 1e-300) * np.sqrt(n))) if n > 1 else float("nan")
    half = 2.0 * np.sqrt(n * 0.95 * 0.05)
    lo, hi = int(np.clip(np.floor(0.95 * n - half), 0, n - 1)), int(np.clip(np.ceil(0.95 * n + half), 0, n - 1))
    out = {"mean_m": float(np.hypot(2.0 * np.std(e, ddof=1) / np.sqrt(n), ui)) if n > 1 else float("nan"),
           "rms_m": float(np.hypot(2.0 * u_rms, ui)),
           "p95_m": float(np.hypot(0.5 * (e[hi] - e[lo]), ui)),
           "max_m": None, "n": int(n), "instrument_U_m": ui,
           "note": "k = 2 from the held-out count (mean: 2 s/√n; RMS: from the spread of |e|²; 95th percentile: the "
                   "order statistics ±2 σ of its rank) with the instrument's uncertainty in quadrature; the largest "
                   "error has no uncertainty from its count"}
    return out


def _work_rows(cm: Any, work: Any, ho: Any, seed: int) -> tuple[np.ndarray, str]:
    if work is not None:
        return np.asarray(work, float), "the working configurations given (joint-space program)"
    if cm.q_work is not None and len(cm.q_work):
        return np.asarray(cm.q_work, float), "the model's working configurations"
    rng = np.random.default_rng(seed)
    k = min(BUDGET_ROWS, len(ho.Q))
    pick = np.sort(rng.choice(len(ho.Q), k, replace=False))
    return ho.Q[pick], (f"the model names no working configurations: {k} seeded held-out rows stand for them "
                        f"(seed {seed})")


def held_out_coverage(cm: Any, ho: Any, station: str, tcp_m: np.ndarray, temps: dict | None, seed: int) -> dict:
    """U (k = 2) at every held-out row from the model's σ there (``validate``'s per-axis σ), the held term and the
    temperature, against the rows' errors: the share within U and the coverage the budget states."""
    from pin_kpi_oed.compensation.tool_offset import held_tcp_covariance
    from pin_kpi_oed.report.uncertainty import COVERAGE_FACTOR, ball_coverage, temperature_covariance

    sig = np.asarray(ho.after["sigma_axes_m"], float)
    C = np.einsum("ma,ab->mab", sig ** 2, np.eye(3))
    C = C + held_tcp_covariance(ho.model, station, tcp_m, ho.Q, seed=seed)[0]
    C = C + temperature_covariance(ho.model, ho.Q, station, tcp_m, temps)[0]
    U = COVERAGE_FACTOR * np.sqrt(np.einsum("maa->m", C))
    e = np.asarray(ho.after["errors_m"], float)
    cov = ball_coverage(C, U, n=4000, seed=seed)
    r = np.asarray(ho.after["residuals_m"], float)
    Ua = COVERAGE_FACTOR * np.sqrt(np.einsum("maa->ma", C))
    return {"n": int(e.size), "within_U": float(np.mean(e <= U)), "coverage_stated": float(np.mean(cov)),
            "within_U_axis": float(np.mean(np.abs(r) <= Ua)), "coverage_axis": 0.9545,
            "U_median_m": float(np.median(U)), "U_p95_m": float(np.percentile(U, 95))}


def path_uncertainty(model: Any, station: str, path: Any, tcp_m: np.ndarray, *, instrument_u_m: float | None = None,
                     temps: dict | None = None, seed: int = 0, mc_draws: int = 0) -> dict:
    """The TCP's expanded uncertainty (k = 2) along one working path (module docstring).

    Args:
        model: the calibrated model (registered to ``station``); station: the set-up the budget is stated in.
        path: a :class:`~pin_kpi_oed.cell.paths.WorkingPath` (``name``, samples ``Q`` (S, n) rad / m, ``s_m`` (S,) m).
        tcp_m: the cell's TCP in the tool frame (3,) m.
        instrument_u_m, temps, seed: as :func:`~pin_kpi_oed.report.uncertainty.budget`.
        mc_draws: draws of the Monte-Carlo check on the path's samples (0: none).

    Returns:
        ``name``, ``n``, ``U_max_m``, ``s_at_max_m`` (arc length of the largest U, m), ``U_median_m``, ``U_m``
        (per sample, m), ``budget`` (:func:`~pin_kpi_oed.report.uncertainty.budget_summary`), with ``mc_draws``
        ``monte_carlo`` (median ratio sampled / budget and its 5–95 % range).
    """
    from pin_kpi_oed.report.uncertainty import budget, budget_summary, monte_carlo

    Q = np.asarray(path.Q, float)
    bud = budget(model, Q, station, tcp_m=tcp_m, instrument_u_m=instrument_u_m, temperatures=temps, seed=seed)
    U = np.asarray(bud["U_m"], float)
    out = {"name": path.name, "n": int(len(Q)), "U_max_m": float(U.max()),
           "s_at_max_m": float(np.asarray(path.s_m, float)[int(np.argmax(U))]), "U_median_m": float(np.median(U)),
           "U_m": U.tolist(), "budget": budget_summary(bud)}
    if mc_draws:
        mc = monte_carlo(model, Q, bud, n=mc_draws, seed=seed)
        out["monte_carlo"] = {"n": mc["n"], "median_ratio": mc["median_ratio"],
                              "ratio_p5": float(np.percentile(mc["ratio"], 5)),
                              "ratio_p95": float(np.percentile(mc["ratio"], 95))}
    return out


def uncertainty_section(cm: Any, ho: Any, *, work: Any = None, instrument_u_m: float | None = None,
                        temps: dict | None = None, seed: int = 0, mc_draws: int = 0, cell: Any = None) -> dict:
    """The certificate's uncertainty section (module docstring): the budget at the working configurations, the
    held-out rows against U, along the ``cell``'s working paths, and (``mc_draws`` > 0) the Monte-Carlo check of the
    budget."""
    from pin_kpi_oed.report.uncertainty import budget, budget_summary, monte_carlo

    station = ho.station or cm.station(None)
    Qw, where = _work_rows(cm, work, ho, seed)
    tcp = cm.default_tcp_m
    bud = budget(ho.model, Qw, station, tcp_m=tcp, instrument_u_m=instrument_u_m, temperatures=temps, seed=seed)
    out = {"where": where, "budget": budget_summary(bud),
           "per_configuration": [{"U_m": float(u), "coverage": float(c), "U_axis_m": ua.tolist()}
                                 for u, c, ua in zip(bud["U_m"], bud["coverage"], bud["U_axis_m"])],
           "held_out": held_out_coverage(cm, ho, station, tcp, temps, seed)}
    if cell is None or not getattr(cell, "paths", None):
        out["paths"] = ("no cell with working paths was given (report --cell): U along a path is not stated"
                        if cell is None else f"cell {cell.name} has no working paths: U along a path is not stated")
    else:
        out["paths"] = [path_uncertainty(ho.model, station, pth, np.asarray(cell.tcp_m, float),
                                         instrument_u_m=instrument_u_m, temps=temps, seed=seed, mc_draws=mc_draws)
                        for pth in cell.paths]
    if mc_draws:
        mc = monte_carlo(ho.model, Qw, bud, n=mc_draws, seed=seed)
        out["monte_carlo"] = {"n": mc["n"], "median_ratio": mc["median_ratio"],
                              "ratio_p5": float(np.percentile(mc["ratio"], 5)),
                              "ratio_p95": float(np.percentile(mc["ratio"], 95))}
    return out


def conformity_section(acc_after: dict, unc: dict, required_m: float | None, figure: str,
                       budget: dict | None = None) -> dict | None:
    """The ISO 14253-1 statement of the held-out figure ``figure`` against ``required_m`` (None without one).

    The held-out figure is the measured point's (the reflector's); the accuracy a user requires is the TCP's. With
    ``budget`` (:func:`~pin_kpi_oed.report.uncertainty.budget_summary` at the working configurations, the TCP's
    U), a U (k = 2) above ``required_m`` there keeps a ``conforms`` of the reflector from standing for the TCP: the
    verdict is then ``undetermined`` and ``at_tcp`` says why (the TCP may lie anywhere within its U).

    Args:
        acc_after: the held-out figures after calibration (m); unc: their expanded uncertainties (m, k = 2);
        required_m: the required accuracy (m) or None;
        figure: which figure (``p95_m``, ``rms_m``, ``mean_m``, ``max_m``);
        budget: the TCP's budget summary (``U_max_m``, ``tcp_m``), or None.

    Returns:
        :func:`~pin_kpi_oed.report.uncertainty.conformity`'s dict with ``figure``, ``figure_label`` and, when the
        TCP's U exceeds the requirement, ``at_tcp`` (the line) and ``tcp_U_max_m`` (m); None without ``required_m``.
    """
    from pin_kpi_oed.report.uncertainty import conformity

    if required_m is None:
        return None
    out = conformity(acc_after[figure], unc[figure], required_m)
    out["figure"] = figure
    out["figure_label"] = FIGURES[figure]
    U_tcp = None if budget is None else budget.get("U_max_m")
    if U_tcp is not None and U_tcp > required_m:
        tcp = ", ".join(f"{v * 1e3:.3g}" for v in budget.get("tcp_m") or [])
        out["tcp_U_max_m"] = float(U_tcp)
        out["at_tcp"] = (f"at the TCP (({tcp}) mm in the tool frame) not shown: its U (k = 2) at the working "
                         f"configurations is up to {U_tcp * 1e3:.3f} mm, above the required {required_m * 1e3:.3f} "
                         "mm (section 'Sigma at the TCP' names what no reflector measurement determines and what "
                         "removes it)")
        if out["verdict"] == "conforms":
            out["verdict"] = "undetermined"
    return out


def commanded_section(test: Any, ho: Any, goal_radius_m: float, commanded_tcp_m: np.ndarray | None) -> dict | None:
    """ISO 9283 against the commanded poses of the scored rows, base frame from the scoring station's set-up; None
    when the rows carry no goals."""
    from pin_kpi_oed.report.iso9283 import commanded_groups
    from pin_kpi_oed.report.iso_commanded import commanded_figures, commanded_positions

    st = ho.model.setups[ho.station]
    x_c = commanded_positions(test, st.tracker_T_base, st.reflector_m, commanded_tcp_m)
    if x_c is None:
        return None
    groups = commanded_groups(test, goal_radius_m) or []
    tcp = "the measured point" if commanded_tcp_m is None else \
        "(" + ", ".join(f"{v * 1e3:.3f}" for v in np.asarray(commanded_tcp_m).reshape(3)) + ") mm in the tool frame"
    frame = (f"base frame registered by station '{ho.station}' (its tracker pose); the goals command {tcp}, "
             f"the measured point is the reflector")
    if not groups:
        return {"frame": frame, "statements": [f"no commanded position was measured twice (goals within "
                                               f"{goal_radius_m * 1e3:g} mm): no AP, RP"]}
    return commanded_figures(test, test.position_m, x_c, ho.Q, groups, frame=frame)
