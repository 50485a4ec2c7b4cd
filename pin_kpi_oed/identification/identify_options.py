"""Options of :func:`~pin_kpi_oed.identification.identify.identify` and the one keyword-override helper."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any
from collections.abc import Sequence

import numpy as np

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.oed.identifiability import Identifiability

__all__ = ["ROBUST_LOSSES", "IdentifyOptions", "resolve_options"]

#: Loss functions accepted by :func:`identify` (``linear`` = plain least squares).
ROBUST_LOSSES = ("linear", "soft_l1", "huber", "cauchy")

@dataclass
class IdentifyOptions:
    """Knobs of :func:`~pin_kpi_oed.identification.identify.identify` (SI units).

    Attributes:
        p0: raw parameters of the model to start from / hold fixed entries at (default zeros).
        loss: ``auto`` (the default, as on the command line: ``linear``, refitted with ``soft_l1`` when
            :func:`~pin_kpi_oed.identification.quality.robust_loss_reason` finds outliers far beyond the noise, or
            any flagged outlier with the noise level unknown; ``result.loss`` is the loss used and
            ``result.loss_decision`` says why it switched), ``linear`` (Levenberg–Marquardt), ``soft_l1``, ``huber``
            or ``cauchy`` (robust, followed by a plain refit on the inliers; see the module docstring).
        f_scale: robust-loss scale in weighted units; default 3 × the MAD scale of a first
            plain least-squares fit.
        weights: ``auto`` (the data's sigma columns if present, else the noise model),
            ``data`` or ``noise``.
        register: guess the tracker pose (and probe orientation) by point-set registration; skipped
            for the tracker (probe) when one of its parameters is fixed or has a prior, so that
            these refer to ``model.tracker_T_base`` (``model.probe_R``) (one station only).
        use_orientation: use the rx, ry, rz columns (6-D probe) when the data have them.
        setup_only: estimate the set-up parameters only (tracker, reflector, probe): the
            "nominal robot" baseline.
        scale_covariance: multiply the covariance by the reduced χ² (relative weights only).
        Q_work: working configurations of the TCP uncertainty (rad); default the data's tool header's working
            configurations, else the measured ones.
        held_tolerances: the prior of the joint-placement parameters the fit holds at nominal (no reflector
            measurement determines them), a :class:`~pin_kpi_oed.model.tolerances.Tolerances`; default its
            defaults. They enter the TCP's σ (:mod:`pin_kpi_oed.oed.held`).
        ident: a precomputed identifiability analysis of one station's working model (default:
            computed on ``N_EXCITATION`` seeded random configurations).
        outlier_alpha: false-alarm probability of the outlier flag of a whole least-squares fit (family-wise: each
            of the m rows is tested at ``outlier_alpha / m``, so an outlier-free fit flags any row, and ``loss='auto'``
            switches to the robust loss, with about this probability); with a robust loss each row is tested at
            ``outlier_alpha`` (which rows the refit leaves out).
        max_nfev: maximum number of residual evaluations (default 50 × unknowns).
        tol: ftol, xtol and gtol of the solver.
        max_median_error_m: fail if the median position error after the fit exceeds it
            (default 1 % of the robot's reach): the model cannot reach the data.
        raise_on_failure: raise :class:`SolverError` when the solver does not converge.
        seed: seed of the identifiability excitation.
        reflector_per_station: every station has its own reflector offset (and probe orientation).
        station: label of the data's one station when they have no ``station`` column
            (default: the file name without extension).
        effect_prior_rad: σ (rad) of a Gaussian prior θ_i ~ N(0, σ²) on every estimated effect
            parameter in rad (effects with ``unit == "rad"``): one row θ_i / σ in the cost and the
            covariance; it keeps a term the data barely determine (e.g. a harmonic fitted in one
            region of joint space) near zero instead of letting it extrapolate. None: no prior. An
            effect with its own ``prior_rad`` attribute (σ, rad) uses that instead.
        theta0: start values of the effects' θ (one array per effect; default zeros).
        held_effects: ``[(effect, θ), ...]`` applied with their parameters held (not estimated),
            e.g. the transferable effects of an earlier calibration; kept in the result and its model.
        discrepancy: model discrepancy δ(q) fitted to the residuals after the parametric fit
            (:mod:`pin_kpi_oed.discrepancy`): ``auto`` (the default, as on the command line: a Gaussian
            process when the data hold enough distinct poses and it lowers the grouped K-fold held-out error,
            else a white discrepancy at the residual level corrected for the fitted parameters), ``on``, ``none``
            (the paper's noise-only model; its σ still includes the parameter covariance), or
            :class:`~pin_kpi_oed.discrepancy.gp.DiscrepancyOptions` (seeded by ``seed``).
        on_poor_fit: what the fit-quality gate (:func:`~pin_kpi_oed.identification.quality.assess_fit`, run on
            the final fit and its discrepancy) does with a poor verdict: ``flag`` (the default: the verdict is in
            ``result.fit_quality`` and the last line of ``result.summary()``; ``result.fit_quality.poor`` is
            True), ``raise`` (:class:`~pin_kpi_oed.errors.SolverError` with the verdict's line, as the command
            line's exit 2 without ``--accept-poor-fit``) or ``ignore`` (no gate: ``result.fit_quality`` None).
            The command line runs the gate itself, with the validation rows when given.
        tcp_sigma: state the TCP's σ at the working configurations (``result.tcp_std_m``, its held part and each
            held parameter's share: the calibrated model's own, step 10 of the module docstring). False leaves them
            empty, for a caller that states them itself (the command line, once its discrepancy is fitted:
            :func:`~pin_kpi_oed.identification.identify.restate_tcp_sigma`) or never reads them (the diagnosis's
            many fits); the fit and the model it gives are the same.
    """

    p0: np.ndarray | None = None
    loss: str = "auto"
    f_scale: float | None = None
    weights: str = "auto"
    register: bool = True
    use_orientation: bool = True
    setup_only: bool = False
    scale_covariance: bool = False
    Q_work: np.ndarray | None = None
    held_tolerances: Any = None
    ident: Identifiability | None = None
    outlier_alpha: float = 1e-3
    max_nfev: int | None = None
    tol: float = 1e-10
    max_median_error_m: float | None = None
    raise_on_failure: bool = True
    seed: int = 0
    reflector_per_station: bool = False
    station: str | None = None
    effect_prior_rad: float | None = None
    theta0: Sequence[np.ndarray] | None = None
    held_effects: Sequence[tuple[Any, np.ndarray]] = ()
    discrepancy: Any = "auto"
    on_poor_fit: str = "flag"
    tcp_sigma: bool = True

    def __post_init__(self) -> None:
        if self.effect_prior_rad is not None and not (np.isfinite(self.effect_prior_rad)
                                                      and self.effect_prior_rad > 0):
            raise InputError(f"effect_prior_rad must be a positive number of rad, got {self.effect_prior_rad}")
        if self.loss not in ("auto",) + ROBUST_LOSSES:
            raise InputError(f"unknown loss '{self.loss}' (choose from auto, {', '.join(ROBUST_LOSSES)})")
        if self.weights not in ("auto", "data", "noise"):
            raise InputError(f"weights must be auto, data or noise, got '{self.weights}'")
        if self.on_poor_fit not in ("flag", "raise", "ignore"):
            raise InputError(f"on_poor_fit must be flag, raise or ignore, got '{self.on_poor_fit}'")
        if not 0.0 < float(self.outlier_alpha) < 1.0:
            raise InputError(f"outlier_alpha must be in (0, 1), got {self.outlier_alpha}")

    @classmethod
    def resolve(cls, options: IdentifyOptions | None, overrides: dict) -> IdentifyOptions:
        """``options`` (or the defaults) with the keyword ``overrides`` applied (:func:`resolve_options`)."""
        return resolve_options(cls, options, overrides, "identify")


def resolve_options(cls: type, options: Any, overrides: dict, what: str) -> Any:
    """An options dataclass ``options`` (or ``cls()``) with the keyword ``overrides`` applied.

    Raises:
        InputError: an unknown option name (the message lists the known ones).
    """
    known = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(overrides) - known)
    if unknown:
        raise InputError(f"{what}: unknown option(s) {', '.join(unknown)} (options: {', '.join(sorted(known))})")
    return dataclasses.replace(options or cls(), **overrides)
