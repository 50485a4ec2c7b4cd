"""Option checks of every command, run before any work (``cli/app.py`` calls :func:`check_args`).

Each rule names the option, the allowed range and the unit; zero and negative values are refused
rather than replaced by defaults (``--measurements 0`` never silently designs 60 poses).
The rules are a table per command (:data:`RULES`); output and input paths of each command are in
:data:`OUTPUTS`, :data:`INPUTS` and :data:`FOLDERS`, checked by :func:`~pin_kpi_oed.validation.paths.check_outputs`.
"""

from __future__ import annotations

import argparse
import math
import re
from pathlib import Path
from typing import Any
from collections.abc import Callable, Sequence

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.validation.paths import check_figure_suffix, check_outputs

__all__ = ["join_negative_values", "check_args", "RULES", "OUTPUTS", "INPUTS", "FOLDERS", "FIGURES", "floats",
           "check_discrepancy_options", "check_ignored_options", "IGNORED", "check_tool_length"]


def floats(text: Any, what: str) -> list[float]:
    """Comma-separated numbers of an option (SI units).

    Raises:
        InputError: text that is not a number, or not finite, naming the option.
    """
    out = []
    for s in str(text).replace(" ", "").split(","):
        if s == "":
            continue
        try:
            v = float(s)
        except ValueError:
            raise InputError(f"{what}: '{s}' is not a number (in '{text}')") from None
        if not math.isfinite(v):
            raise InputError(f"{what}: {s} is not finite")
        out.append(v)
    if not out:
        raise InputError(f"{what}: expected comma-separated numbers, got '{text}'")
    return out


def _int_at_least(lo: int) -> Callable[[str, Any], None]:
    def rule(opt: str, v: Any) -> None:
        if v is not None and v < lo:
            raise InputError(f"{opt}: must be >= {lo}, got {v}")
    return rule


def _nonneg_float(opt: str, v: Any) -> None:
    if v is not None and any(x < 0 for x in floats(v, opt)):
        raise InputError(f"{opt}: must be >= 0, got {v}")


def _positive_float(opt: str, v: Any) -> None:
    if v is not None and not (math.isfinite(float(v)) and float(v) > 0):
        raise InputError(f"{opt}: must be positive and finite, got {v}")


def _open_unit(opt: str, v: Any) -> None:
    if v is not None and not (0 < float(v) < 1):
        raise InputError(f"{opt}: must be in (0, 1), got {v}")


def _sigma_m(opt: str, v: Any) -> None:
    if v is not None:
        from pin_kpi_oed.validation.units import check_sigma_m  # NumPy: only when the option is given

        check_sigma_m(floats(v, opt), opt)


def _sigma_rad(opt: str, v: Any) -> None:
    if v is not None:
        from pin_kpi_oed.validation.units import check_sigma_rad

        check_sigma_rad(floats(v, opt), opt)


def _offset(opt: str, v: Any) -> None:
    if v is not None:
        from pin_kpi_oed.validation.units import MAX_TOOL_OFFSET_M, check_offset_m

        a = floats(v, opt)
        if len(a) != 3:
            raise InputError(f"{opt}: expected x,y,z (m), got '{v}'")
        check_offset_m(a, MAX_TOOL_OFFSET_M, opt)


def _range(unit: str) -> Callable[[str, Any], None]:
    def rule(opt: str, v: Any) -> None:
        if v is None:
            return
        a = floats(v, opt)
        if len(a) != 2 or a[0] > a[1]:
            raise InputError(f"{opt}: expected LOW,HIGH ({unit}) with LOW <= HIGH, got '{v}'")
    return rule


#: the plausible range of a cell's temperature (°C); beyond it, K or °F was meant
TEMPERATURE_RANGE_C = (-50.0, 100.0)


def _temperature(opt: str, v: Any) -> None:
    """LOW,HIGH in °C, LOW <= HIGH, within :data:`TEMPERATURE_RANGE_C`."""
    if v is None:
        return
    _range("°C")(opt, v)
    lo, hi = TEMPERATURE_RANGE_C
    bad = [x for x in floats(v, opt) if not lo <= x <= hi]
    if bad:
        raise InputError(f"{opt}: {bad[0]:g} °C is outside [{lo:g}, {hi:g}] °C: give the temperature in °C "
                         f"({bad[0]:g} K would be {bad[0] - 273.15:g} °C)")


def _scheduler(opt: str, v: Any) -> None:
    if v is None or v == "local-dask":
        return
    if not re.fullmatch(r"(tcp|tls|ws|wss|inproc)://[^\s:/]+(:\d{1,5})?/?", str(v)):
        raise InputError(f"{opt}: expected 'local-dask' or a Dask scheduler address tcp://host:port, got '{v}'")


def _fix(opt: str, v: Any) -> None:
    if v is None:
        return
    pats = [s.strip() for s in str(v).split(",") if s.strip()]
    if not pats:
        raise InputError(f"{opt}: give parameter names or globs, e.g. 'reflector.*'")
    if any(p.strip("*?") == "" for p in pats):
        raise InputError(f"{opt} '{v}': would hold every parameter at nominal, leaving nothing to identify; "
                         "name the parameters or groups to hold (e.g. 'reflector.*', 'tracker.*')")


def _finite_at_least(lo: float, unit: str, hi: float | None = None, hint: str = "") -> Callable[[str, Any], None]:
    def rule(opt: str, v: Any) -> None:
        if v is None:
            return
        x = float(v)
        if not math.isfinite(x) or x < lo:
            raise InputError(f"{opt}: must be a finite number >= {lo:g} {unit}, got {v}")
        if hi is not None and x > hi:
            raise InputError(f"{opt}: {x:g} {unit} is more than {hi:g} {unit}{hint}")
    return rule


def _share(opt: str, v: Any) -> None:
    if v is not None and not (math.isfinite(float(v)) and 0 < float(v) <= 1):
        raise InputError(f"{opt}: a share of the URDF speed limits in (0, 1], got {v}")


def _split(opt: str, v: Any) -> None:
    if v is not None and not (math.isfinite(v) and v > 0):
        raise InputError(f"{opt}: a share in (0, 1) or a whole number of rows >= 1, got {v:g}")


def _target_sigma(opt: str, v: Any) -> None:
    """A TCP sigma target in m: between 0.1 µm (below any tracker's resolution) and 5 mm (beyond: mm meant)."""
    if v is None:
        return
    x = float(v)
    if not (math.isfinite(x) and x > 0):
        raise InputError(f"{opt}: must be a positive TCP sigma in m, got {v}")
    if x > TARGET_SIGMA_MAX_M:
        raise InputError(f"{opt}: {x:g} m is more than {TARGET_SIGMA_MAX_M * 1e3:g} mm: give the TCP sigma in m "
                         f"(e.g. {x * 1e-3:g} for {x:g} mm)")
    if x < TARGET_SIGMA_MIN_M:
        raise InputError(f"{opt}: {x:g} m ({x * 1e6:.3g} µm) is below {TARGET_SIGMA_MIN_M * 1e6:g} µm, finer than any "
                         "tracker measures; give the TCP sigma in m (e.g. 3.5e-05 for 35 µm)")


def _radius_rad(opt: str, v: Any) -> None:
    """A joint-space radius in rad: finite, >= 0 and at most π (more is degrees meant)."""
    if v is None:
        return
    x = float(v)
    if not math.isfinite(x) or x < 0:
        raise InputError(f"{opt}: must be a finite radius >= 0 rad, got {v}")
    if x > math.pi:
        raise InputError(f"{opt}: {x:g} rad is more than π rad (180°): give it in rad "
                         f"(e.g. {math.radians(x):.3g} for {x:g}°)")


def _geometry_prior(opt: str, v: Any) -> None:
    """``TRANS_M,ROT_RAD``: two positive sigmas, at most 0.1 m and 0.5 rad (more is mm / degrees meant)."""
    if v is None:
        return
    a = floats(v, opt)
    if len(a) != 2 or not (a[0] > 0 and a[1] > 0):
        raise InputError(f"{opt}: expected two positive sigmas TRANS_M,ROT_RAD (m, rad), got '{v}'")
    if a[0] > GEOMETRY_PRIOR_MAX_M:
        raise InputError(f"{opt}: translation sigma {a[0]:g} m is more than {GEOMETRY_PRIOR_MAX_M:g} m: give it in m "
                         f"(e.g. {a[0] * 1e-3:g} for {a[0]:g} mm)")
    if a[1] > GEOMETRY_PRIOR_MAX_RAD:
        raise InputError(f"{opt}: rotation sigma {a[1]:g} rad is more than {GEOMETRY_PRIOR_MAX_RAD:g} rad: give it in "
                         f"rad (e.g. {math.radians(a[1]):.3g} for {a[1]:g}°)")


def _compensate_frame(opt: str, v: Any) -> None:
    """``compensate --frame``: ``tracker`` or ``base``; ``cell`` (which named the station's tracker frame, not a cell
    file's frame) refused, saying which to use."""
    if v == "cell":
        raise InputError(f"{opt} cell: ambiguous (it meant the tracker frame of the station, not the cell file's "
                         f"frame): give {opt} tracker for targets in the tracker frame, {opt} base for the robot base "
                         "frame")


#: the range of a TCP sigma target (m): 0.1 µm .. 5 mm
TARGET_SIGMA_MIN_M, TARGET_SIGMA_MAX_M = 1e-7, 5e-3
#: the largest sigmas of a joint-placement prior: 0.1 m, 0.5 rad
GEOMETRY_PRIOR_MAX_M, GEOMETRY_PRIOR_MAX_RAD = 0.1, 0.5
_SEED = {"seed": _int_at_least(0)}
#: command -> {argparse dest: rule(option name, value)}
#: check's TCP tolerance (m): positive, at most 10 mm (a value in mm is refused)
_TOLERANCE = _finite_at_least(1e-9, "m", 0.01, ": give the tolerance in m (e.g. 1e-4 for 0.1 mm)")

#: a length along the tool axis (m): at most 5 m (a value in mm is refused)
_TOOL_LENGTH = _finite_at_least(0.0, "m", 5.0, ": give the length along the tool axis in m (e.g. 0.2 for 200 mm)")

RULES: dict[str, dict[str, Callable[[str, Any], None]]] = {
    "info": {**_SEED, "reflector": _offset},
    "demo": dict(_SEED),
    "design": {**_SEED, "measurements": _int_at_least(1), "starts": _int_at_least(1), "max_iter": _int_at_least(1),
               "pool_size": _int_at_least(1), "target_sigma": _target_sigma, "work_radius": _radius_rad,
               "work_samples": _int_at_least(0),
               "clearance_margin": _finite_at_least(0.0, "m", 0.5, ": give the clearance margin in m (e.g. 0.02 for "
                                                                    "20 mm)"),
               "incidence_margin": _finite_at_least(0.0, "deg", 89.0), "iso_side": _positive_float},
    "simulate": {**_SEED, "n": _int_at_least(1), "n_test": _int_at_least(0), "noise": _sigma_m,
                 "sigma_rot": _sigma_rad, "tol_translation": _nonneg_float, "tol_rotation": _nonneg_float,
                 "tol_reflector": _nonneg_float, "temperature": _temperature, "reflector": _offset},
    "identify": {**_SEED, "register_rows": _int_at_least(1), "max_nfev": _int_at_least(1), "sigma": _sigma_m,
                 "sigma_rot": _sigma_rad, "fix": _fix, "reflector": _offset, "geometry_prior": _geometry_prior},
    "import-ipa": {**_SEED, "split": _split},
    "diagnose": {**_SEED, "register_rows": _int_at_least(1), "kfold": _int_at_least(2), "sigma": _sigma_m,
                 "alpha": _open_unit, "reflector": _offset},
    "view": {"scale": _positive_float, "level": _open_unit},
    "export": {**_SEED, "dwell": _finite_at_least(0.0, "s", 3600.0, " (a wait at each measurement point, in s)"),
               "margin": _finite_at_least(0.0, "m", 0.5, ": give the move clearance margin in m (e.g. 0.01 for 10 mm)"),
               "speed_override": _share},
    "compensate": {**_SEED, "tcp": _offset, "tool_length": _TOOL_LENGTH, "frame": _compensate_frame},
    "export-model": {"tcp": _offset},
    "predict": {"tool_length": _TOOL_LENGTH},
    "check": {**_SEED, "alpha": _open_unit, "tolerance": _TOLERANCE, "measurements": _int_at_least(3),
              "pool_size": _int_at_least(3)},
    "monitor": {"alpha": _open_unit, "tolerance": _TOLERANCE, "every": _int_at_least(3), "poll": _positive_float,
                "idle": _positive_float},
    "report": {**_SEED, "register_rows": _int_at_least(3)},
    "study": {**_SEED, "measurements": _int_at_least(9), "seeds": _int_at_least(1), "arms": _int_at_least(1),
              "starts": _int_at_least(1), "workers": _int_at_least(1), "scheduler": _scheduler},
}

#: command -> argparse dests of output files
OUTPUTS = {"evaluate": ["json"], "demo": ["json"], "design": ["json", "curve", "iso9283"],
           "simulate": ["out", "test_out", "truth_json"],
           "identify": ["json", "urdf_out", "model_out"], "import-ipa": ["out", "train", "test"],
           "register": ["model_out", "json"], "predict": ["out", "figure"], "diagnose": ["json", "model_out"],
           "view": ["html"], "export": ["out", "json", "html"], "compensate": ["out", "json"],
           "import-tracker": ["out"], "import-images": ["out"],
           "export-model": ["out"], "report": ["html", "json", "pdf"], "check": ["model_out", "json", "out", "program"],
           "monitor": ["model_out", "json"]}
#: command -> argparse dests of figure outputs (their names end in a format the package writes)
FIGURES = {"design": ["curve"], "predict": ["figure"]}
#: command -> argparse dests of inputs (files or folders; lists allowed); besides these, every other option's
#: value that names an existing file counts as an input (a new input option is protected without being listed)
INPUTS = {"evaluate": ["design"], "design": ["cell", "pool", "given", "given_prior", "model", "reregister"],
          "identify": ["data", "validate", "register_data", "robot", "kinematics", "cell"],
          "simulate": ["robot", "design", "cell", "poses", "truth", "kinematics"], "import-ipa": ["src"],
          "register": ["model", "data", "cell"], "predict": ["model", "data"],
          "diagnose": ["train", "validate", "register_data", "robot", "kinematics", "cell"],
          "view": ["design"], "info": ["robot"], "export": ["design"],
          "compensate": ["model", "targets", "program", "cell"],
          "import-tracker": ["export", "joints", "robot"], "import-images": ["images", "board", "joints"],
          "export-model": ["model"],
          "report": ["model", "train", "validate", "register_data", "kinematics", "cell"],
          "check": ["model", "data", "cell"],
          "monitor": ["model", "data"]}
#: command -> argparse dests of output folders
FOLDERS = {"diagnose": ["figures"], "view": ["figures"], "study": ["out"]}


_POSITIONAL = {"design", "src", "which", "export"}


def _opt(dest: str) -> str:
    return dest.upper() if dest in _POSITIONAL else "--" + dest.replace("_", "-")


def _pairs(args: argparse.Namespace, dests: list[str], existing_only: bool = False) -> list[tuple[str, Any]]:
    out = []
    for d in dests:
        v = getattr(args, d, None)
        if not v or isinstance(v, bool):
            continue
        for x in (v if isinstance(v, list) else [v]):
            if existing_only and not Path(str(x)).exists():
                continue
            out.append((_opt(d), str(x)))
    return out


def check_args(args: argparse.Namespace) -> None:
    """Check the options of ``args.command`` (ranges, units, output paths) before any work.

    Raises:
        InputError: one line naming the option, the value and what is allowed.
    """
    cmd = getattr(args, "command", None)
    for dest, rule in RULES.get(cmd, {}).items():
        if hasattr(args, dest):
            rule(_opt(dest), getattr(args, dest))
    if cmd == "simulate" and getattr(args, "test_out", None) and not getattr(args, "n_test", 0):
        raise InputError("--test-out: needs --n-test N (N >= 1 held-out measurements); nothing would be written")
    if cmd == "identify" and getattr(args, "validate", None):
        for d in getattr(args, "data", None) or []:
            if Path(d).exists() and Path(args.validate).exists() and Path(d).resolve() == Path(args.validate).resolve():
                raise InputError(f"--validate {args.validate}: is also --data; held-out data must not be training "
                                 "data")
    if cmd == "diagnose" and getattr(args, "validate", None):
        for d in getattr(args, "train", None) or []:
            if Path(d).exists() and Path(args.validate).exists() and Path(d).resolve() == Path(args.validate).resolve():
                raise InputError(f"--validate {args.validate}: is also --train; held-out data must not be training "
                                 "data")
    if cmd == "check":
        _check_design_sizes(args)
    check_ignored_options(args)
    outputs = _pairs(args, OUTPUTS.get(cmd, []))
    files_of = getattr(args, "output_files", None)  # a command whose option writes several files (KRL: .src + .dat)
    if callable(files_of):
        extra = files_of(args)
        opts = {o for o, _ in extra}
        outputs = list(extra) + [o for o in outputs if o[0] not in opts]
    check_outputs(outputs, _inputs(args, cmd), _pairs(args, FOLDERS.get(cmd, [])))
    for opt, path in _pairs(args, FIGURES.get(cmd, [])):
        check_figure_suffix(opt, path)


#: the most candidate poses ``check design`` draws (each one checked in the cell; a check needs tens of poses)
CHECK_POOL_MAX = 20_000


def _check_design_sizes(args: argparse.Namespace) -> None:
    """``check design``'s ``--measurements`` at most its ``--pool-size``, which is at most :data:`CHECK_POOL_MAX`.

    Raises:
        InputError: naming the option, its value and its limit.
    """
    m, pool = getattr(args, "measurements", None), getattr(args, "pool_size", None)
    if pool is not None and pool > CHECK_POOL_MAX:
        raise InputError(f"--pool-size: {pool} candidate poses is more than {CHECK_POOL_MAX} (each is checked in the "
                         f"cell; a check needs tens of poses): give --pool-size 3..{CHECK_POOL_MAX}")
    if m is not None and pool is not None and m > pool:
        raise InputError(f"--measurements: {m} poses from --pool-size {pool} candidates: give --measurements "
                         f"3..{pool} (or --pool-size up to {CHECK_POOL_MAX})")


def _given(args: argparse.Namespace, opt: str) -> bool:
    """Whether ``opt`` is on the command line (``args.argv``; without it, whether its value is set)."""
    argv = getattr(args, "argv", None)
    if argv is None:
        return bool(getattr(args, opt.lstrip("-").replace("-", "_"), None))
    return any(a == opt or str(a).startswith(opt + "=") for a in argv)


def _effects(args: argparse.Namespace) -> set[str] | None:
    e = getattr(args, "effects", None)
    return None if e is None else {x.strip().split("=")[0] for x in str(e).split(",")}


#: command -> [(option, whether it acts with the other options, what it needs)]: an option that would do nothing
#: is refused, never ignored without a word
IGNORED: dict[str, list[tuple[str, Callable[[argparse.Namespace], bool], str]]] = {
    "identify": [("--urdf-frames", lambda a: bool(getattr(a, "urdf_out", None)),
                  "adds frames to the calibrated URDF: add --urdf-out FILE")],
    "design": [("--iso-side", lambda a: bool(getattr(a, "iso9283", None)),
                "is the side of the ISO 9283 test cube: add --iso9283 PROGRAM")],
    "simulate": [("--sigma-rot", lambda a: bool(getattr(a, "pose6d", False)),
                  "is the orientation noise of --pose6d: add --pose6d")],
    "compensate": [("--position-only", lambda a: bool(getattr(a, "program", None)),
                    "holds a --program's TCP position only (--targets are held as given: leave out rx, ry, rz)")],
    "diagnose": [("--harmonics", lambda a: _effects(a) is None or "transmission_error" in _effects(a),
                  "sets the transmission_error candidate's orders: add transmission_error to --effects"),
                 ("--term-prior", lambda a: _effects(a) is None or bool({"transmission_error", "link_bending"}
                                                                          & _effects(a)),
                  "is a prior on transmission_error / link_bending terms: add one of them to --effects")],
    "export-model": [("--tcp", lambda a: getattr(a, "format", None) == "urdf" and not getattr(a, "no_frames", False),
                      "places the URDF's 'tcp' frame: only with --format urdf and its frames (without --no-frames)"),
                     ("--no-frames", lambda a: getattr(a, "format", None) == "urdf",
                      "leaves the set-up frames out of a URDF; a UR kinematics file has none: only with --format "
                      "urdf")],
    "monitor": [(opt, lambda a: bool(getattr(a, "follow", False)),
                 f"{does} while following a growing file: add --follow") for opt, does in
                (("--poll", "sets the seconds between reads"),
                 ("--idle", "sets the seconds without a new row to stop"))],
}


def check_ignored_options(args: argparse.Namespace) -> None:
    """Refuse an option that would do nothing with the others given (:data:`IGNORED`).

    Raises:
        InputError: naming the option, what it does and what it needs (or to drop it).
    """
    for opt, acts, needs in IGNORED.get(getattr(args, "command", None), []):
        if _given(args, opt) and not acts(args):
            raise InputError(f"{opt}: {needs}, or drop {opt} (as given it would do nothing)")


def check_tool_length(args: argparse.Namespace, pose6d: bool, model: str) -> None:
    """``--tool-length`` (``predict``, ``compensate``) acts on a 6-D model's orientation σ only: refused, when given, on
    a position-only model (whose file the command has read).

    Args:
        args: the parsed options.
        pose6d: the model predicts orientations.
        model: the model file (for the message).

    Raises:
        InputError: naming the option, why it would do nothing and the fix.
    """
    if _given(args, "--tool-length") and not pose6d:
        raise InputError(f"--tool-length: states a 6-D model's orientation sigma at a length along the tool axis, but "
                         f"--model {model} is a position-only (3-D) model: drop --tool-length (as given it would do "
                         "nothing)")


def check_discrepancy_options(args: argparse.Namespace, gp_criteria: bool, model_discrepancy: bool) -> None:
    """``design``'s options that act only with the discrepancy, refused where they would be ignored without a word.

    Args:
        args: the parsed ``design`` options.
        gp_criteria: a discrepancy-aware criterion (``kpi_gp``, ...) is among ``--criteria``.
        model_discrepancy: ``--model`` holds a discrepancy block.

    Raises:
        InputError: naming the option, why it would do nothing, and what to add or drop.
    """
    model = getattr(args, "model", None)
    fix = ("add a discrepancy-aware criterion (--criteria ...,kpi_gp)" if not model else
           f"--model {model} holds no discrepancy (write one with identify --discrepancy on --model-out), or add "
           "kpi_gp to --criteria")
    if not (gp_criteria or model_discrepancy):
        for dest, does in (("curve", "draws the poses needed with the discrepancy"),
                           ("work_radius", "sets the working region of the discrepancy-aware KPI"),
                           ("work_samples", "sets the working region of the discrepancy-aware KPI"),
                           ("robot_class", "chooses the discrepancy a design assumes")):
            if getattr(args, dest, None) is not None:
                raise InputError(f"{_opt(dest)}: {does}, and this design has none: {fix}; or drop {_opt(dest)}")
    if model_discrepancy and getattr(args, "robot_class", None) is not None:
        raise InputError(f"--robot-class {args.robot_class}: chooses the discrepancy a design assumes without a model "
                         f"file, but --model {model} holds its own (used instead); drop --robot-class")


def _inputs(args: argparse.Namespace, cmd: str | None) -> list[tuple[str, Any]]:
    """The command's declared inputs, and every other option whose value names an existing file."""
    declared = _pairs(args, INPUTS.get(cmd, []), existing_only=True)
    skip = (set(INPUTS.get(cmd, [])) | set(OUTPUTS.get(cmd, [])) | set(FOLDERS.get(cmd, []))
            | {"command", "func", "argv"})  # argv: the whole command line as given (for the files' provenance)
    others = [d for d, v in vars(args).items() if d not in skip and isinstance(v, (str, list))]
    return declared + [(o, p) for o, p in _pairs(args, others, existing_only=True) if Path(p).is_file()]


_NEGATIVE = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?(,.*)?$")


def join_negative_values(argv: Sequence[str]) -> list[str]:
    """Let ``--sigma -1e-5`` or ``--tracker -1,0,0`` reach the checks: argparse takes a value that starts with a
    minus sign for an option, so a long option followed by a negative number (or a comma list starting with one)
    is passed as ``--sigma=-1e-5``.

    Returns:
        The arguments, a long option and its negative value joined by ``=``.
    """
    out: list[str] = []
    args = list(argv)
    i = 0
    while i < len(args):
        a = args[i]
        if (a.startswith("--") and "=" not in a and a != "--" and i + 1 < len(args)
                and _NEGATIVE.match(args[i + 1])):
            out.append(f"{a}={args[i + 1]}")
            i += 2
        else:
            out.append(a)
            i += 1
    return out
