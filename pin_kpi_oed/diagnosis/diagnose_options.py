"""Options of :func:`~pin_kpi_oed.diagnosis.diagnose.diagnose` and their checks (step 0)."""

from __future__ import annotations

from dataclasses import dataclass
from collections.abc import Sequence

from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.effects.library import EFFECT_NAMES, Effect
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.tracker import TrackerModel

__all__ = ["DiagnoseOptions", "check_options", "DEFAULT_CANDIDATES"]


#: The candidates of ``pin-kpi-oed diagnose`` by default: every library effect, plus the transferable
#: terms chosen by sparse K-fold selection (``transmission_error``: Fourier orders of each joint's angle;
#: ``link_bending``: the arm-plane gravity terms). On real arms the transmission terms close most of the
#: gap a geometric calibration leaves (UR10 Series C: docs/results.md), so they are not opt-in there.
DEFAULT_CANDIDATES: tuple[str, ...] = EFFECT_NAMES + ("transmission_error", "link_bending")


@dataclass
class DiagnoseOptions:
    """Knobs of :func:`~pin_kpi_oed.diagnosis.diagnose.diagnose` (SI units).

    Attributes:
        kfold: K-fold cross-validation on the training data alone (K ≥ 2), instead of a validation set.
        effects: candidate effect names or objects (default: all of :data:`EFFECT_NAMES`; the command
            line's default is :data:`DEFAULT_CANDIDATES`, which adds the transferable terms).
        weights: ``auto`` (sigma columns if present, else the noise model), ``data`` or ``noise``.
        alpha: significance level of the gap test and of the effect tests.
        seed: seed of the K-fold split and of the random registration rows.
        max_selected: at most this many effects in forward selection (default: all).
        t_ref_c: reference temperature of ``thermal_expansion`` (°C; default the training mean).
        identify_options: extra keyword arguments (fields of
            :class:`~pin_kpi_oed.identification.identify.IdentifyOptions`) of every identification.
        exact_kfold: re-identify every model on every fold (K+1 fits per model); by default the
            folds' fits are one Gauss-Newton step from the all-data fit (exact to second order,
            K times faster).
        register_rows: transfer mode: the validation data come from another session; re-register
            the set-up on this many seeded random rows of them and score only the others.
        register_data: transfer mode: re-register the set-up on these rows and score every
            validation row.
        harmonics: highest Fourier order (cycles per revolution) of the ``transmission_error``
            candidate; its terms (and those of ``link_bending``) are chosen by sparse forward
            selection on K-fold held-out error (:func:`pin_kpi_oed.diagnosis.selection.select_terms`)
            before they are scored like any other candidate.
        show_progress: False: no progress bars; None: bars on a terminal (steps of the diagnosis,
            the term selection).
        transfer_prior_rad: σ (rad) of a Gaussian prior on the parameters of the selected terms
            (``--term-prior``), in their refit and in every identification that scores them; it
            limits how far a term fitted in one region of joint space extrapolates (None: none).
    """

    kfold: int | None = None
    effects: Sequence[str | Effect] | None = None
    weights: str = "auto"
    alpha: float = 0.01
    seed: int = 0
    max_selected: int | None = None
    t_ref_c: float | None = None
    identify_options: dict | None = None
    exact_kfold: bool = False
    register_rows: int | None = None
    register_data: MeasurementSet | None = None
    harmonics: int = 40
    transfer_prior_rad: float | None = None
    show_progress: bool | None = None

    @classmethod
    def resolve(cls, options: DiagnoseOptions | None, overrides: dict) -> DiagnoseOptions:
        """``options`` (or the defaults) with the keyword ``overrides`` applied.

        Raises:
            InputError: an unknown option name.
        """
        from pin_kpi_oed.identification.identify import resolve_options

        return resolve_options(cls, options, overrides, "diagnose")


def check_joints(model: TrackerModel, data: MeasurementSet, what: str) -> None:
    """Refuse data without a column for every robot joint.

    Raises:
        InputError: missing joint column(s), named with the data's columns.
    """
    missing = [j for j in model.robot.joint_names if j not in data.joint_names]
    if missing:
        raise InputError(f"{data.source or what}: missing joint column(s) {', '.join(missing)} for robot "
                         f"{model.robot.name} (columns: {', '.join(data.joint_names)})")


def check_options(model: TrackerModel, train: MeasurementSet, validate: MeasurementSet | None,
                   opts: DiagnoseOptions) -> None:
    """Step 0: one validation mode, a valid alpha and weights, the joint columns."""
    if (validate is None) == (opts.kfold is None):
        raise InputError("diagnose: give either validation data (parameter 'validate') or a number of folds "
                         "(parameter 'kfold'), not both and not neither")
    if (opts.register_rows is not None or opts.register_data is not None) and validate is None:
        raise InputError("diagnose: register_rows / register_data re-register the set-up on rows of another "
                         "session: they need validation data (parameter 'validate')")
    if opts.register_rows is not None and opts.register_data is not None:
        raise InputError("diagnose: give register_rows or register_data, not both")
    if not 0 < opts.alpha < 1:
        raise InputError(f"diagnose: alpha must be in (0, 1), got {opts.alpha}")
    if opts.weights not in ("auto", "data", "noise"):
        raise InputError(f"diagnose: weights must be auto, data or noise, got '{opts.weights}'")
    check_joints(model, train, "training data")
    for d, what in ((validate, "validation data"), (opts.register_data, "registration data")):
        if d is not None:
            check_joints(model, d, what)
