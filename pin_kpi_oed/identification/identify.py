r"""Parameter identification from measured data (paper eqs. 5–6), with effects, stations and validation.

Identification removes the systematic error TCP(p, q) − TCP(p_true, q) ≠ 0 (eq. 2) as far as the
model can represent it; :func:`validate` measures what remains on held-out data.

Problem
-------
Given m measurements (q_i, η_i) of a :class:`~pin_kpi_oed.data.measurements.MeasurementSet`, taken
from one or more *stations* (tracker placements; the data's ``station`` column), find the
identifiable parameters x = (P_B, θ) minimising the weighted least-squares cost (eqs. 5–6)

.. math::

    \min_x \; \tfrac12 \sum_i \rho\bigl(\lVert f_i(x) \rVert^2\bigr)
      + \tfrac12 \sum_{k \in B} (P_k / \sigma^{\mathrm{prior}}_k)^2,

with the weighted residual of measurement i of station s (position rows, then orientation rows
for a 6-D probe)

.. math::

    f_i^{\mathrm{pos}} = \Sigma_i^{-1}\bigl(h_s(p_s, q_i + \Delta q_i(θ)) + \Delta y_i(θ) - η_i\bigr)
    \quad [\text{m}/\text{m}],\qquad
    f_i^{\mathrm{rot}} = \log_3\bigl(R_{\mathrm{model},i}\, R_{\mathrm{meas},i}^\top\bigr) / σ_{\mathrm{rot}}

(the result reports the opposite sign, measured − model, i.e. ``log3(R_meas R_modelᵀ)``).
``ρ`` is the identity (plain least squares, Levenberg–Marquardt, MINPACK via
:func:`scipy.optimize.least_squares` ``method='lm'``) or a robust loss (``soft_l1``,
``huber``, ``cauchy``; trust-region reflective), which bounds the pull of outliers.

* P: the robot's joint-placement errors (shared by every station), every station's tracker pose,
  and the reflector offset (shared, or per station with ``reflector_per_station``); layout and
  identifiability in :mod:`pin_kpi_oed.identification.problem`. P_B are the identifiable ones
  (:func:`pin_kpi_oed.oed.identifiability.analyse`, convention: set-up parameters kept, robot
  parameters confounded with them held nominal); the others stay at their given value.
* θ: parameters of optional *effects* (``docs/ARCHITECTURE.md``, "Effect interface"):
  joint-angle errors Δq(θ, Q, aux) and additive tracker-frame offsets Δy(θ, Q, aux), composed
  by :func:`pin_kpi_oed.effects.library.predict_with_effects`.

Jacobian (analytic, exact at any x; :class:`~pin_kpi_oed.identification.problem.ResidualModel`):
with J_h = ∂h/∂p from :meth:`~pin_kpi_oed.model.tracker.TrackerModel.jacobian` (right
Jacobians of exp6 included), (v_k, ω_k) the world twist of joint k and p the reflector in the
base frame,

.. math::

    \frac{∂f^{\mathrm{pos}}}{∂P_B} = Σ^{-1} J_h^{\mathrm{pos}},\qquad
    \frac{∂f^{\mathrm{pos}}}{∂θ} = Σ^{-1}\bigl(R_T\,[v_k + ω_k × p]_k\, \tfrac{∂Δq}{∂θ}
        + \tfrac{∂Δy}{∂θ}\bigr),

    \frac{∂f^{\mathrm{rot}}}{∂(P_B, θ)} = σ_{\mathrm{rot}}^{-1}\, J_l^{-1}(φ)\,
        \bigl[J_h^{\mathrm{rot}},\; R_T [ω_k]_k \tfrac{∂Δq}{∂θ}\bigr],

where φ = log3(R_model R_measᵀ), J_l⁻¹ the inverse left Jacobian of SO(3) and
J_h^rot the spatial angular Jacobian of the model orientation. The p-dependence of an
effect's Δy (its ``model, p`` arguments) is neglected in the Jacobian (not in f).

Steps of :func:`identify`
-------------------------
1. **Inputs** (:func:`~pin_kpi_oed.identification.fit_inputs.check_inputs`): joint columns, units, duplicates, weights;
every station
   has at least 3 rows (one row is refused by name).
2. **Start** (:func:`~pin_kpi_oed.identification.tracker_start.start_stations`): the tracker pose of every station is
unknown in practice. It is
   guessed in closed form by point-set registration (Kabsch/Umeyama, no scale) of the nominal
   forward kinematics x_i (base frame) onto the station's measured points y_i (tracker frame)::

       H = Σ_i (x_i − x̄)(y_i − ȳ)ᵀ = U S Vᵀ,   R = V diag(1, 1, det(V Uᵀ)) Uᵀ,   t = ȳ − R x̄

   and, for a 6-D probe, the probe orientation by the chordal mean
   ``R_probe = proj_SO3(Σ_i (R_T R_tool,i)ᵀ R_meas,i)``. Every station is then measured
   through a working :class:`~pin_kpi_oed.model.tracker.TrackerModel` whose nominal tracker
   pose is its guess, so the tracker parameters stay small.
3. **Parameters** (:func:`~pin_kpi_oed.identification.identifiable.identifiable_set`): the structural analysis of one
station lifted to all
   (:meth:`StationLayout.lift <pin_kpi_oed.identification.problem.StationLayout.lift>`); then the
   data checks on the stacked Jacobian: enough equations, every station's rows determine its own
   set-up and add information on the robot beyond it (:func:`~pin_kpi_oed.identification.identifiable.check_stations`),
   every unknown
   determined by the data of all stations together (:func:`~pin_kpi_oed.identification.identifiable.data_rank_check`).
4. **Solve**, **outliers**, **covariance** (:mod:`~pin_kpi_oed.identification.solve`), **TCP uncertainty**, **result**.

``IdentificationResult.model`` and ``.p`` are the first station's working model and raw
parameter vector: ``result.model.predict(result.p, Q)`` reproduces its fit (without effects);
``result.calibrated_model()`` holds every station's set-up, the geometry and the effects
(:class:`~pin_kpi_oed.calibrated.model_file.CalibratedModel`, the model file).

Uncertainty
-----------
C = (FᵀF + P)⁻¹ over x with F = ∂f/∂x at the solution (inlier rows) and P the prior
(:func:`pin_kpi_oed.oed.covariance.param_covariance`); optionally scaled by the reduced χ²
when the weights are only relative (unknown σ). The predicted TCP uncertainty at working
configurations is the calibrated model's at its TCP (:func:`~pin_kpi_oed.calibrated.tcp_sigma.tcp_sigma`, what
``predict --at tcp`` states): the discrepancy, the parameters' C_s = E C_pp Eᵀ (eq. 25) with E = ds/dP_B, and the
joint-placement parameters held at nominal under their tolerance (first station's tracker frame), reported per
configuration as ``sqrt(trace C_s,i)`` (m).

Outliers: measurement i of m is flagged when ``‖f_i‖ > sqrt(χ²_{nh}(1 − α/m)) · s`` with s the
robust (MAD) scale of the weighted residual components, 1.4826 · median |f| (a family-wise test: an
outlier-free fit flags any row with probability about α, however many rows it has). With a robust
loss the sequence is: plain least squares (start), robust fit (f_scale = 3 s unless given),
flag, then plain least squares on the inliers, re-flag, until the flags settle (≤ 3 rounds);
the estimate, its covariance and χ² are those of the final inlier fit (a robust loss alone
still leaves a bias of order f_scale per outlier). With the plain loss, outliers are only
flagged.

Units: SI (m, rad) everywhere; summaries print mm, µm and mrad and say so.

Modules: options (:mod:`~pin_kpi_oed.identification.identify_options`), result
(:mod:`~pin_kpi_oed.identification.identify_result`), input checks
(:mod:`~pin_kpi_oed.identification.fit_inputs`), registration start
(:mod:`~pin_kpi_oed.identification.tracker_start`), identifiable set and data checks
(:mod:`~pin_kpi_oed.identification.identifiable`), solve (:mod:`~pin_kpi_oed.identification.solve`),
held-out validation (:mod:`~pin_kpi_oed.identification.heldout`); every public name is importable
from here too.
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Any
from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.data.tool_header import ToolSpec
from pin_kpi_oed.discrepancy.coverage import JointCoverage
from pin_kpi_oed.errors import InputError, SolverError
from pin_kpi_oed.identification.discrepancy_fit import discrepancy_options, result_discrepancy
from pin_kpi_oed.identification.fit_inputs import (MIN_STATION_ROWS, FitInputs, check_inputs,
                                                   default_station_label)
from pin_kpi_oed.identification.heldout import error_stats, format_validation, validate
from pin_kpi_oed.model.nests import nest_column
from pin_kpi_oed.identification.identifiable import N_EXCITATION, build_problem, identifiable_set
from pin_kpi_oed.identification.identify_options import ROBUST_LOSSES, IdentifyOptions, resolve_options
from pin_kpi_oed.identification.identify_result import IdentificationResult
from pin_kpi_oed.calibrated.model_file import Setup
from pin_kpi_oed.calibrated.tcp_sigma import tcp_sigma
from pin_kpi_oed.identification.quality import robust_loss_reason
from pin_kpi_oed.identification.problem import (ResidualModel, align_data, effect_param_names, predict)
from pin_kpi_oed.identification.solve import fit_covariance, held_term, settle_outliers, solve
from pin_kpi_oed.identification.tool_check import check_tool
from pin_kpi_oed.identification.tracker_start import register_points, start_stations
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.threads import limit_threads

__all__ = [
    "ROBUST_LOSSES",
    "IdentifyOptions",
    "IdentificationResult",
    "ResidualModel",
    "identify",
    "restate_tcp_sigma",
    "working_configurations",
    "validate",
    "format_validation",
    "predict",
    "effect_param_names",
    "register_points",
    "align_data",
    "default_station_label",
    "error_stats",
    "resolve_options",
    "MIN_STATION_ROWS",
    "N_EXCITATION",
]

def _setups(prob: ResidualModel, P: np.ndarray, errors: np.ndarray, inp: FitInputs, data: MeasurementSet
            ) -> dict[str, Setup]:
    """Step 8: every station's fitted set-up (tracker pose, reflector, probe, rows, RMS error in m)."""
    st = prob.stations
    out = {}
    for s, (lab, rows) in enumerate(zip(st.labels, prob.rows)):
        model, p = st.models[s], st.station_p(P, s)
        R_probe = model.probe_R @ pin.exp3(p[model.layout.probe]) if model.pose6d else None
        refl = model.reflector(p)  # the nests move with the fitted offset they share
        out[lab] = Setup(model.tracker_pose(p).homogeneous.copy(), refl, R_probe, int(rows.size),
                         "identify", data.source, float(np.sqrt(np.mean(errors[rows] ** 2))),
                         nests_m=model.nests_m - model.nests_m[0] + refl if model.n_nests > 1 else None)
    return out


def _check_effects_determined(effects: Sequence[Any], data: MeasurementSet) -> None:
    """Refuse an effect the data cannot determine (its ``check`` note: e.g. thermal expansion from a constant
    temperature, which the link lengths absorb) instead of fitting it.

    Raises:
        InputError: one line naming the file, the effect and why.
    """
    for eff in effects:
        note = eff.check(data) if hasattr(eff, "check") else None
        if note:
            why = note.replace(f"{eff.name}: skipped, ", "")
            raise InputError(f"{data.source or 'data'}: effect {eff.name} is not determined by the data: {why}; "
                             "leave it out of the effects (parameter 'effects')")


def _result_tool(model: TrackerModel, data: MeasurementSet) -> ToolSpec | None:
    """The tool a result keeps: the data's header, its missing TCP and working configurations filled from the tool
    the model was declared with (``model.tool``: a cell's), or the model's alone."""
    dt, mt = data.tool, getattr(model, "tool", None)
    if dt is None or mt is None:
        return dt if mt is None else mt
    return replace(dt, tcp_m=mt.tcp_m if dt.tcp_m is None else dt.tcp_m,
                   q_work=mt.q_work if dt.q_work is None else dt.q_work,
                   source=dt.source if dt.tcp_m is not None and dt.q_work is not None else
                   f"{dt.source}, {mt.source}")


def _gate(result: IdentificationResult, model: TrackerModel, opts: IdentifyOptions) -> None:
    """The fit-quality gate of ``opts.on_poor_fit``: flag (``result.fit_quality``), raise, or ignore."""
    if opts.on_poor_fit == "ignore":
        return
    from pin_kpi_oed.identification.quality import assess_fit
    result.fit_quality = assess_fit(result, nominal_reflector_m=model.reflector_m)
    if result.fit_quality.poor and opts.on_poor_fit == "raise":
        raise SolverError(f"{result.source or 'data'}: {result.fit_quality.line()} (on_poor_fit='flag' to keep it)")


@limit_threads
def identify(model: TrackerModel, data: MeasurementSet, options: IdentifyOptions | None = None, *,
             effects: Sequence[Any] = (), **overrides: Any) -> IdentificationResult:
    r"""Identify the robot's geometric parameters (and effect parameters θ) from measurements.

    Weighted nonlinear least squares (eqs. 5–6) over the identifiable parameters, by
    Levenberg–Marquardt with the analytic Jacobian (or trust-region reflective with a robust
    loss), from the nominal model and a closed-form registration of every station's tracker pose
    (steps: see the module docstring).

    Args:
        model: measurement model: robot, nominal reflector in the tool frame, noise (weights),
            TCP point, layout (``fixed`` parameters held at their value, ``prior_sigma``). Its
            ``tracker_T_base`` is only used when ``register`` is False or the tracker is fixed.
        data: the measurements (joint columns named as the robot's joints; SI units); a
            ``station`` column makes each station's rows share one tracker pose.
        options: :class:`IdentifyOptions` (default: the defaults).
        effects: objects of the Effect interface (``docs/ARCHITECTURE.md``); their θ are
            identified jointly (start at 0).
        **overrides: fields of :class:`IdentifyOptions` given by name (``loss="soft_l1"``,
            ``setup_only=True``, ...); they replace those of ``options``.

    Returns:
        The :class:`IdentificationResult`.

    Raises:
        InputError: missing joint columns, NaN, degrees or mm instead of rad or m, duplicate
            rows, an unknown loss or option, a station with fewer than 3 rows.
        IdentifiabilityError: fewer equations than unknowns, a station whose rows determine
            nothing beyond its own set-up, or configurations that do not determine a parameter.
        SolverError: no convergence, or the fitted model does not reach the data.
    """
    t_start = time.perf_counter()
    opts = IdentifyOptions.resolve(options, overrides)
    check_tool(model.robot, model.tcp_m, data)
    inp = check_inputs(model, data, opts)
    _check_effects_determined(effects, data)
    Qw = working_configurations(model.robot, data, opts.Q_work, inp.Q)  # checked before the fit
    result, plain = _fit(model, data, inp, effects, replace(opts, loss="linear") if opts.loss == "auto" else opts,
                         t_start)
    why = robust_loss_reason(result) if opts.loss == "auto" else ""
    if why:  # the robust fit starts from the plain fit just made (the same problem and start)
        result, _ = _fit(model, data, inp, effects, replace(opts, loss="soft_l1"), t_start, plain)
        result.loss_decision = (f"{why}: refitted with the robust loss soft_l1 (--loss linear, loss='linear', "
                                "keeps the plain fit)")
    result.coverage = JointCoverage.from_training(inp.Q, opts.seed, model.robot.periodic_joints)
    result.discrepancy = result_discrepancy(result, data, discrepancy_options(opts.discrepancy, opts.seed), inp.Q)
    if opts.tcp_sigma:
        _state_tcp_sigma(result, Qw, data)  # the σ at the TCP, held parameters' term included (step 10)
    _gate(result, model, opts)
    result.time_s = time.perf_counter() - t_start
    return result


def restate_tcp_sigma(result: IdentificationResult, data: MeasurementSet, Q_work: np.ndarray) -> None:
    """Step 10 again, on a result whose discrepancy was set after the fit (the command line fits it on the final
    fit): ``result.tcp_std_m`` and its held part become the calibrated model's own σ at the TCP, what the model file
    gives ``predict --at tcp``, ``check`` and ``report``.

    Args:
        result: the identification result, its ``discrepancy`` final.
        data: the training rows (their median temperature, payload and time for the effects that read them).
        Q_work: where the σ is stated, (t, n) rad / m (the working configurations, else the training poses).
    """
    _state_tcp_sigma(result, np.atleast_2d(np.asarray(Q_work, float)), data)


def working_configurations(robot: Any, data: MeasurementSet, Q_work: np.ndarray | None = None,
                           Q: np.ndarray | None = None) -> np.ndarray:
    """Where ``identify`` states the TCP's σ: ``Q_work``, else the data's tool header's working configurations, else
    the measured configurations.

    Args:
        robot: the robot; data: the training rows; Q_work: the option ``IdentifyOptions.Q_work`` (rad / m) or None;
        Q: the rows' joints in the robot's order if already aligned (default: aligned here).

    Returns:
        (t, n) rad / m.

    Raises:
        InputError: working configurations outside the limits or of the wrong shape.
    """
    if Q_work is not None:
        return robot.check_q(Q_work, "Q_work")
    qw = getattr(data.tool, "q_work", None) if data.tool is not None else None
    if qw is not None and np.shape(qw)[-1:] == (robot.nq,):
        return robot.check_q(np.atleast_2d(np.asarray(qw, float)), "the tool header's working configurations")
    return align_data(robot, data) if Q is None else Q


def _state_tcp_sigma(result: IdentificationResult, Qw: np.ndarray, data: MeasurementSet) -> None:
    """Step 10: the TCP's σ at the working configurations, the calibrated model's own
    (:func:`~pin_kpi_oed.calibrated.tcp_sigma.tcp_sigma`: the discrepancy, the parameters and the ones held at
    nominal, first station's tracker frame), so that ``identify`` states what ``predict --at tcp`` gives; the
    effects that read temperature, payload or time take the data's median there."""
    cm = result.calibrated_model()
    aux: dict[str, Any] = {k: np.full(len(Qw), float(np.median(v))) for k in ("temperature_c", "payload_kg", "time_s")
                           if (v := getattr(data, k, None)) is not None}
    work = MeasurementSet(q=Qw, position_m=np.zeros((len(Qw), 3)), joint_names=list(cm.robot.joint_names),
                          **aux) if aux else None
    ts = tcp_sigma(cm, Qw, cm.tcp_m, station=result.stations[0], aux=work)
    result.tcp_std_m, result.tcp_held_m, result.tcp_held_contrib_m = ts.sigma_m, ts.held_sigma_m, ts.held_contrib_m


def _fit(model: TrackerModel, data: MeasurementSet, inp: FitInputs, effects: Sequence[Any], opts: IdentifyOptions,
         t_start: float, plain: tuple[np.ndarray, Any] | None = None) -> tuple[IdentificationResult, Any]:
    """One least-squares fit with ``opts.loss`` (steps 2–6 of the module docstring), before the discrepancy: (the
    result, (start, least-squares result) of a plain fit — ``loss='linear'`` — else None). ``plain``: that of a plain
    fit of the same problem, where a robust loss starts (:func:`~pin_kpi_oed.identification.solve.solve`)."""
    stations, P0, T_init = start_stations(model, data, inp, effects, opts)
    nest = nest_column(data, model.n_nests)
    ident = identifiable_set(stations, opts, (0,) if nest is None else np.unique(nest).tolist())
    prob = build_problem(stations, data, inp, effects, P0, ident, opts)
    x_start = prob.x0()
    solution = solve(prob, opts, plain)
    fw, we, outliers = settle_outliers(prob, solution, opts, inp.src)
    x = solution.x
    rpos, rrot = prob.evaluate(x)
    errors = np.linalg.norm(rpos, axis=1)
    C, std, corr, chi2_red, F = fit_covariance(prob, x, fw, opts)
    P_hat, th_hat = prob.unpack(x)
    Cu = C / chi2_red if opts.scale_covariance and chi2_red > 0 else C
    held = held_term(prob, x, F, Cu, opts.held_tolerances)
    setups = _setups(prob, P_hat, errors, inp, data)
    first = setups[stations.labels[0]]
    sol = solution.sol
    converged = bool(sol.status > 0)
    result = IdentificationResult(
        success=converged, status="converged" if converged else "max_nfev", message=str(sol.message),
        nit=solution.nit, nfev=solution.nfev, solver_status=int(sol.status),
        names=prob.names, values=x.copy(), std=std, covariance=C, correlation=corr,
        p=stations.station_p(P_hat, 0), theta=th_hat, residuals_m=-rpos, residuals_rad=None if rrot is None else -rrot,
        errors_m=errors, weighted_errors=we, outliers=outliers, tcp_std_m=np.zeros(0), held_term=held,
        cost=float(sol.cost),
        chi2_reduced=chi2_red, tracker_T_base=first.tracker_T_base.copy(), tracker_T_base_init=T_init[0],
        reflector_m=first.reflector_m.copy(), probe_R=first.probe_R, model=stations.models[0],
        effects=list(effects), identifiability=ident, loss=opts.loss, f_scale=solution.f_scale,
        covariance_scaled=bool(opts.scale_covariance), sigma_source=inp.sigma_source,
        stations=list(stations.labels), setups=setups, station_models=list(stations.models),
        station_p=[stations.station_p(P_hat, s) for s in range(len(stations.labels))],
        station_rows=list(prob.rows), P=P_hat, param_names=list(stations.layout.names), station_set=stations,
        reflector_per_station=bool(opts.reflector_per_station), source=data.source,
        held=[(e, np.asarray(t, float)) for e, t in opts.held_effects], time_s=time.perf_counter() - t_start,
        tool=_result_tool(model, data), tcp_std_at="training" if opts.Q_work is None else "working")
    return result, ((x_start, sol) if opts.loss == "linear" else None)
