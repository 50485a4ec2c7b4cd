r"""The TCP position's expanded uncertainty (GUM): its budget, its coverage and its Monte-Carlo check.

At a configuration q the error of the calibrated model's TCP position, as a measurement with the certificate's
tracker would show it (measured − predicted, tracker frame of the station), has the covariance

    C(q) = C_tracker + C_parameters + C_discrepancy + C_held + C_temperature     (m², 3 × 3)

* **tracker**: the instrument's standard uncertainty of one point (the lab file's ``instrument.uncertainty_m``,
  else the noise model's σ), isotropic, never above the model's white level per axis (it is part of it);
* **discrepancy**: the Gaussian process's posterior variance at q and the rest of the white level (robot
  repeatability and what the model leaves unexplained);
* **parameters**: the rest of the model's own predictive covariance
  (:func:`~pin_kpi_oed.calibrated.prediction_sigma.predictive_covariance`, the one σ every predicting command
  reports): the parameters' error propagated to q (with a white discrepancy's joint-angle errors);
* **parameters no measurement determines** (held at nominal): their tolerance propagated to the TCP through what
  the fit absorbed (:func:`~pin_kpi_oed.compensation.tool_offset.held_tcp_covariance`; zero at the measured point);
* **temperature**: without a thermal effect in the model, a uniform expansion α ΔT of the arm about its base
  (displacement α ΔT · p(q), p the TCP in the base frame), ΔT rectangular within ±a, a the largest difference of the
  rows' temperatures from the calibration's mean: u = α a / √3 along p(q); α = :data:`THERMAL_EXPANSION_PER_K`.

The first three are the model's σ at the measured point (the reflector), the held term moves it to the TCP (as
``compensate`` states a TCP's σ). The combined standard uncertainty of the 3-D position is u_c = √tr C, the expanded
uncertainty U = k u_c with k = 2; each contribution's share is tr C_i / tr C. The probability that the 3-D error
lies within U under N(0, C) (:func:`ball_coverage`) is stated beside it: 95.4 % for an error along one axis,
98.9 % for an isotropic one. Per axis, U_a = 2 √C_aa covers 95.4 %.

:func:`monte_carlo` draws the parameters from their covariance (each draw through the model's Jacobian at the
rows) and the discrepancy jointly over the rows from its Gaussian-process posterior and white level, and compares
the spread with the budget's parameter, discrepancy and tracker terms (which it must equal: the budget takes its
parameter term as the rest of the model's predictive covariance, so the check is that the parts add up).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["COVERAGE_FACTOR", "THERMAL_EXPANSION_PER_K", "CONTRIBUTIONS", "budget", "ball_coverage",
           "monte_carlo", "linear_draws", "discrepancy_draws", "conformity", "budget_summary",
           "temperature_covariance"]

#: The coverage factor of the expanded uncertainty.
COVERAGE_FACTOR = 2.0
#: Linear expansion of the arm's links per kelvin (aluminium; steel arms ≈ 11.5e-6 /K), 1/K.
THERMAL_EXPANSION_PER_K = 23e-6
#: The budget's contributions, in the order printed: (key, label).
CONTRIBUTIONS = (("tracker", "tracker noise"), ("parameters", "parameters"),
                 ("discrepancy", "discrepancy (unmodelled, repeatability)"),
                 ("held", "parameters no measurement determines (held at nominal)"), ("temperature", "temperature"))


def _model_parts(cm: Any, Q: np.ndarray, label: str, chunk: int = 150) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(total, discrepancy posterior, white) per row (m, 3, 3) m², tracker frame of station ``label``."""
    from pin_kpi_oed.calibrated.prediction_sigma import predictive_covariance

    m = len(Q)
    st = cm.setups[label]
    R = st.tracker_T_base[:3, :3]
    s2 = st.sigma_scale ** 2
    tot, post, white = np.zeros((m, 3, 3)), np.zeros((m, 3, 3)), np.zeros((m, 3, 3))
    d = cm.discrepancy
    for a in range(0, m, chunk):
        rows = slice(a, a + chunk)
        Y, C = predictive_covariance(cm, Q[rows], None, label)
        k = len(Y)
        tot[rows] = C.reshape(k, 3, k, 3)[np.arange(k), :, np.arange(k), :]
        if d is None:
            white[rows] = np.einsum("na,ab->nab", np.asarray(cm.noise.sigma(Y[:, :3]), float).reshape(k, 3) ** 2,
                                    np.eye(3)) * s2
        else:
            kp = np.diag(d.posterior_covariance(Q[rows]))
            post[rows] = s2 * np.einsum("n,ia,a,ja->nij", kp, R, np.asarray(d.scale_m, float) ** 2, R)
            white[rows] = s2 * (R * np.asarray(d.noise_var_m2, float)) @ R.T
    return tot, post, white


def temperature_covariance(cm: Any, Q: np.ndarray, label: str, tcp_m: np.ndarray, temps: dict | None
                           ) -> tuple[np.ndarray, dict]:
    """(m, 3, 3) m² tracker frame and its note: the temperature's term of the budget (module docstring; none when the
    model has a thermal effect or ``temps`` is None)."""
    m = len(Q)
    if any(e.name == "thermal_expansion" for e in cm.effects):
        return np.zeros((m, 3, 3)), {"note": "the model's thermal effect compensates the temperature"}
    if not temps or temps.get("mean_c") is None:
        return np.zeros((m, 3, 3)), {"note": "the rows carry no temperature: not evaluated"}
    a = float(temps["half_range_k"])
    u = THERMAL_EXPANSION_PER_K * a / np.sqrt(3.0)
    R = cm.setups[label].tracker_T_base[:3, :3]
    P = np.array([cm.robot.oMtool(q).act(np.asarray(tcp_m, float)) for q in Q]) @ R.T
    return u ** 2 * np.einsum("ma,mb->mab", P, P), {
        "note": f"uniform expansion {THERMAL_EXPANSION_PER_K * 1e6:g} µm/m/K about the base, ΔT within ±{a:.2f} K "
                f"of the calibration's mean {temps['mean_c']:.2f} °C (rectangular)", "half_range_k": a}


def budget(cm: Any, Q: np.ndarray, station: str | None = None, *, tcp_m: np.ndarray | None = None,
           instrument_u_m: float | None = None, temperatures: dict | None = None, seed: int = 0) -> dict:
    """The uncertainty budget of the TCP position at configurations Q (module docstring).

    Args:
        cm: the calibrated model.
        Q: configurations (m, n) rad / m, checked.
        station: the station whose set-up the rows belong to (default: the model's).
        tcp_m: the TCP in the tool frame (m; default the model's ``default_tcp_m``).
        instrument_u_m: the tracker's standard uncertainty of a point (m); None: the noise model's σ.
        temperatures: ``{"mean_c": calibration mean °C, "half_range_k": a K}`` or None (no temperature).
        seed: seed of the coverage draws and of a held term solved on seeded configurations.

    Returns:
        ``cov`` (key -> (m, 3, 3) m²), ``total`` (m, 3, 3), ``u_c_m`` (m,), ``U_m`` (m,) (k = 2), ``U_axis_m``
        (m, 3), ``coverage`` (m,) probability of the 3-D error within U, ``share`` (key -> mean share),
        ``notes`` (key -> text), ``tcp_m``.
    """
    from pin_kpi_oed.compensation.tool_offset import held_tcp_covariance

    Q = np.atleast_2d(np.asarray(Q, float))
    label = cm.station(station)
    tcp = cm.default_tcp_m if tcp_m is None else np.asarray(tcp_m, float).reshape(3)
    tot, post, white = _model_parts(cm, Q, label)
    if instrument_u_m is None:
        Y = cm.predict(Q, station=label)[:, :3]
        u2 = np.asarray(cm.noise.sigma(Y), float).reshape(len(Q), 3) ** 2
        src = "the noise model's σ"
    else:
        u2 = np.full((len(Q), 3), float(instrument_u_m) ** 2)
        src = "the instrument's stated uncertainty"
    wd = np.einsum("maa->ma", white)
    trk = np.einsum("ma,ab->mab", np.minimum(u2, wd), np.eye(3))
    held = held_tcp_covariance(cm, label, tcp, Q, seed=seed)[0]
    temp, tnote = temperature_covariance(cm, Q, label, tcp, temperatures)
    cov = {"tracker": trk, "parameters": tot - post - white, "discrepancy": post + white - trk, "held": held,
           "temperature": temp}
    total = sum(cov.values())
    tr = np.einsum("maa->m", total)
    u_c = np.sqrt(np.maximum(tr, 0.0))
    U = COVERAGE_FACTOR * u_c
    notes = {"tracker": src, "temperature": tnote["note"],
             "held": "zero: the TCP is the measured point" if not np.any(held) else
             "their tolerance through what the fit absorbed",
             "parameters": "the model's predictive covariance less the discrepancy and the white level",
             "discrepancy": "posterior variance + white level less the tracker's part"}
    return {"cov": cov, "total": total, "u_c_m": u_c, "U_m": U,
            "U_axis_m": COVERAGE_FACTOR * np.sqrt(np.maximum(np.einsum("maa->ma", total), 0.0)),
            "coverage": ball_coverage(total, U, seed=seed),
            "share": {k: float(np.mean(np.einsum("maa->m", c) / np.maximum(tr, 1e-300))) for k, c in cov.items()},
            "notes": notes, "tcp_m": tcp.tolist(), "station": label}


def ball_coverage(C: np.ndarray, U: np.ndarray, n: int = 20000, seed: int = 0) -> np.ndarray:
    """P(‖e‖ ≤ U_i) for e ~ N(0, C_i), per row, by seeded draws (n per row; standard error ≤ 0.4 %)."""
    rng = np.random.default_rng(seed)
    z2 = rng.standard_normal((n, 3)) ** 2
    C = np.asarray(C, float).reshape(-1, 3, 3)
    W = np.maximum(np.linalg.eigh(0.5 * (C + np.swapaxes(C, 1, 2)))[0], 0.0)  # (rows, 3): each row's eigenvalues
    out = np.empty(len(C))
    for i, (w, Ui) in enumerate(zip(W, np.asarray(U, float))):
        out[i] = float(np.mean(z2 @ w <= Ui ** 2))
    return out


def _parameter_draws(cm: Any, Q: np.ndarray, label: str, n: int, rng: np.random.Generator) -> np.ndarray | None:
    """(n, m, 3) tracker-frame prediction errors with parameters drawn from the covariance the model's σ uses (a
    Gaussian-process model's least-squares one inside the training's coverage and, outside it (everywhere for a white
    discrepancy), its universal-kriging one with the kriging correction −K_WQ Σ⁻¹F, the parts of
    ``Discrepancy.parametric_covariance``; the fit's
    χ²-scaled one of a noise-only model), each draw propagated through the model's Jacobian at the rows: the fitted
    covariance holds directions of several centiradians (confounded parameters) whose first-order effects cancel,
    which the non-linear model does not reproduce. At a station registered later each draw is registered again
    (:func:`_reregistered`) and every draw is scaled by the station's σ factor."""
    from pin_kpi_oed.calibrated.prediction_sigma import robot_parameter_covariance

    model, p = cm.station_model(label)
    L = model.layout
    d = cm.discrepancy
    st = cm.setups[label]
    if d is None:
        _, names, C = robot_parameter_covariance(cm, label)
        if C is None:
            return None
        fit = cm.fit or {}
        chi2 = fit.get("chi2_reduced")
        if not fit.get("covariance_scaled") and chi2 is not None and np.isfinite(chi2):
            C = C * max(1.0, float(chi2))
        cols = [L.names.index(n_) for n_ in names]
        return linear_draws(model.jacobian(p, Q)[:, :3, :][:, :, cols], C, n, rng)
    if d.param_cov is None and d.param_cov_ls is None:
        return None
    cols = [L.names.index(n_) for n_ in d.param_names]
    own = label in d.param_stations and st.fitted_by == "identify"
    if own:
        cols += list(range(L.tracker.start, L.tracker.stop)) + list(range(L.reflector.start, L.reflector.stop))
    J = _reregistered(cm, label, Q, cols) if not own else model.jacobian(p, Q)[:, :3, :][:, :, cols]
    R = st.tracker_T_base[:3, :3]
    inside = ~np.asarray(d.extrapolation(Q), bool) if d.kind != "white" else np.zeros(len(Q), bool)
    out = np.zeros((n, len(Q), 3))
    for mask, ins in ((inside, True), (~inside, False)):
        C = d.param_cov_ls if (ins or d.param_cov is None) and d.param_cov_ls is not None else d.param_cov
        if not mask.any() or C is None:
            continue
        D = np.zeros((int(mask.sum()), 3, C.shape[0]))
        k = min(len(cols), C.shape[0])
        D[:, :, :k] = J[mask][:, :, :k]
        if d.Bn is not None and C is d.param_cov:
            D -= np.einsum("ab,mbp->map", R, np.einsum("mz,zbp->mbp", d.kernel(Q[mask], d.Z), d.Bn))
        out[:, mask] = linear_draws(D, C, n, rng)
    return st.sigma_scale * out


def _reregistered(cm: Any, label: str, Q: np.ndarray, cols: list[int]) -> np.ndarray:
    """(m, 3, len(cols)) the tracker-frame Jacobian of the error left at Q after a set-up registered on the station's
    registration rows Z absorbed what it can of a parameter error: J_q − G_q (G_Zᵀ G_Z)⁺ G_Zᵀ J_Z, with the station
    model's own Jacobians (tracker pose and reflector columns G, unit-norm, directions below 1 % of the largest
    singular value left out); Z the rows the model file records, else the training's coverage rows."""
    model, p = cm.station_model(label)
    L = model.layout
    J = model.jacobian(p, Q)[:, :3, :]
    Z = cm.setups[label].registered_q_rad
    if Z is None or len(Z) < 3:
        cov = cm.discrepancy.coverage if cm.discrepancy is not None else None
        Z = None if cov is None else cov.Z
    if Z is None:
        return J[:, :, cols]
    sc = list(range(L.tracker.start, L.tracker.stop)) + list(range(L.reflector.start, L.reflector.stop))
    Jz = model.jacobian(p, np.asarray(Z, float))[:, :3, :]
    Gz = Jz[:, :, sc].reshape(-1, len(sc))
    norms = np.linalg.norm(Gz, axis=0)
    norms[norms == 0] = 1.0
    B, *_ = np.linalg.lstsq(Gz / norms, Jz[:, :, cols].reshape(-1, len(cols)), rcond=1e-2)
    return J[:, :, cols] - np.einsum("mak,kr->mar", J[:, :, sc] / norms, B)


def linear_draws(D: np.ndarray, C: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """Draws of D β with β ~ N(0, C), the parameters' errors through a linear map (:func:`monte_carlo`'s draws).

    β = F z with F = V √w (C = V w Vᵀ, negative eigenvalues clipped) and z ~ N(0, I): D F is formed once, then one
    matrix product with the n draws z (the numbers of contracting D, F and z in one step, to rounding: ~1e-15
    relative, at a hundredth of its cost).

    Args:
        D: the map, (m, 3, P) (e.g. m per parameter unit); C: the covariance of β, (P, P).
        n: draws; rng: the generator (n · P standard normal numbers are drawn from it).

    Returns:
        (n, m, 3): the draws.
    """
    w, V = np.linalg.eigh(0.5 * (C + C.T))
    F = V * np.sqrt(np.maximum(w, 0.0))
    DF = np.einsum("map,pk->mak", D, F).reshape(-1, F.shape[1])
    return (rng.standard_normal((n, F.shape[1])) @ DF.T).reshape(n, D.shape[0], D.shape[1])


def monte_carlo(cm: Any, Q: np.ndarray, bud: dict, n: int = 2000, seed: int = 0) -> dict:
    """The budget's parameter and discrepancy terms against draws (module docstring).

    Args:
        cm: the calibrated model; Q: the budget's configurations (inside the training's coverage: the model's
            parameter term there is the least-squares one the draws use); bud: :func:`budget` at Q.
        n: draws; seed: their seed.

    Returns:
        ``u_mc_m`` (m,) and ``u_budget_m`` (m,): √tr of the sampled and of the budget's parameter + discrepancy
        covariance; ``ratio`` (m,) their quotient; ``median_ratio``, ``n``.
    """
    rng = np.random.default_rng(seed)
    Q = np.atleast_2d(np.asarray(Q, float))
    label = bud["station"]
    draws = _parameter_draws(cm, Q, label, n, rng)
    var = np.zeros(len(Q)) if draws is None else np.var(draws, axis=0, ddof=1).sum(axis=1)
    d = cm.discrepancy
    st = cm.setups[label]
    R = st.tracker_T_base[:3, :3]
    if d is not None:
        delta = discrepancy_draws(d.posterior_covariance(Q), d.scale_m, d.noise_var_m2, n, rng)
        var = var + st.sigma_scale ** 2 * np.var(delta @ R.T, axis=0, ddof=1).sum(axis=1)
    else:
        var = var + np.einsum("maa->m", bud["cov"]["tracker"] + bud["cov"]["discrepancy"])
    ref = np.einsum("maa->m", bud["cov"]["parameters"] + bud["cov"]["discrepancy"] + bud["cov"]["tracker"])
    u_mc, u_b = np.sqrt(var), np.sqrt(np.maximum(ref, 0.0))
    ratio = u_mc / np.maximum(u_b, 1e-300)
    return {"u_mc_m": u_mc, "u_budget_m": u_b, "ratio": ratio, "median_ratio": float(np.median(ratio)), "n": n}


def discrepancy_draws(K: np.ndarray, scale_m: Any, noise_var_m2: float, n: int, rng: np.random.Generator
                      ) -> np.ndarray:
    """Draws of a Gaussian-process discrepancy at m rows (:func:`monte_carlo`'s): the posterior jointly over the
    rows, L z with K = L Lᵀ (Cholesky, 1e-12 added to the diagonal) and z ~ N(0, I) per axis, scaled per axis, plus
    the white level per row and axis. L z is one batched matrix product (the numbers of the one-step contraction of
    L and z, to rounding: ~1e-16 relative, at a tenth of its cost).

    Args:
        K: the posterior covariance of the unit-scale process at the rows, (m, m); scale_m: its scale per axis, (3,)
            or a number, m; noise_var_m2: the white level's variance, m².
        n: draws; rng: the generator (first the n · m · 3 numbers of z, then as many of the white level).

    Returns:
        (n, m, 3) m: the draws (in the discrepancy's frame, the tracker's).
    """
    K = np.asarray(K, float)
    Lk = np.linalg.cholesky(0.5 * (K + K.T) + 1e-12 * np.eye(len(K)))
    g = Lk @ rng.standard_normal((n, len(K), 3))
    return g * np.asarray(scale_m, float) + rng.standard_normal((n, len(K), 3)) * np.sqrt(noise_var_m2)

def conformity(error_m: float, U_m: float, required_m: float) -> dict:
    """ISO 14253-1 decision rule for a figure against a required accuracy (the maximum permissible error).

    ``conforms`` when figure + U ≤ required, ``does not conform`` when figure − U > required, else
    ``undetermined`` (the figure lies within U of the limit).

    Args:
        error_m: the stated figure (m); U_m: its expanded uncertainty (m, k = 2); required_m: the limit (m).
    """
    if error_m + U_m <= required_m:
        verdict = "conforms"
    elif error_m - U_m > required_m:
        verdict = "does not conform"
    else:
        verdict = "undetermined"
    return {"verdict": verdict, "figure_m": float(error_m), "U_m": float(U_m), "required_m": float(required_m),
            "rule": "ISO 14253-1: conforms when figure + U ≤ limit, does not conform when figure − U > limit, "
                    "undetermined within U of the limit"}


def budget_summary(bud: dict) -> dict:
    """The JSON-ready summary of a budget over its rows: U (median, 95th percentile, max), the mean coverage, each
    contribution's share and u (RMS over the rows), the notes."""
    U = np.asarray(bud["U_m"], float)
    rows = [{"key": k, "label": lab, "share": bud["share"][k],
             "u_rms_m": float(np.sqrt(np.mean(np.einsum("maa->m", bud["cov"][k])).clip(0))),
             "note": bud["notes"].get(k, "")} for k, lab in CONTRIBUTIONS]
    return {"n": int(U.size), "k": COVERAGE_FACTOR, "U_median_m": float(np.median(U)),
            "U_p95_m": float(np.percentile(U, 95)), "U_max_m": float(U.max()), "U_min_m": float(U.min()),
            "coverage_mean": float(np.mean(bud["coverage"])), "contributions": rows, "tcp_m": bud["tcp_m"],
            "station": bud["station"]}
