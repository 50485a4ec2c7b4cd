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
from collections.abc import Callable

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.validation.paths import check_outputs
from pin_kpi_oed.validation.units import MAX_TOOL_OFFSET_M, check_offset_m, check_sigma_m, check_sigma_rad

__all__ = ["accept_negative_numbers", "check_args", "RULES", "OUTPUTS", "INPUTS", "FOLDERS", "floats"]


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
        check_sigma_m(floats(v, opt), opt)


def _sigma_rad(opt: str, v: Any) -> None:
    if v is not None:
        check_sigma_rad(floats(v, opt), opt)


def _offset(opt: str, v: Any) -> None:
    if v is not None:
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


_SEED = {"seed": _int_at_least(0)}
#: command -> {argparse dest: rule(option name, value)}
RULES: dict[str, dict[str, Callable[[str, Any], None]]] = {
    "info": {**_SEED, "reflector": _offset},
    "demo": dict(_SEED),
    "design": {**_SEED, "measurements": _int_at_least(1), "starts": _int_at_least(1), "max_iter": _int_at_least(1),
               "pool_size": _int_at_least(1)},
    "simulate": {**_SEED, "n": _int_at_least(1), "n_test": _int_at_least(0), "noise": _sigma_m,
                 "sigma_rot": _sigma_rad, "tol_translation": _nonneg_float, "tol_rotation": _nonneg_float,
                 "tol_reflector": _nonneg_float, "temperature": _range("°C"), "reflector": _offset},
    "identify": {**_SEED, "register_rows": _int_at_least(1), "max_nfev": _int_at_least(1), "sigma": _sigma_m,
                 "sigma_rot": _sigma_rad, "fix": _fix, "reflector": _offset},
    "import-ipa": {**_SEED, "split": _split},
    "diagnose": {**_SEED, "register_rows": _int_at_least(1), "kfold": _int_at_least(2), "sigma": _sigma_m,
                 "alpha": _open_unit, "reflector": _offset},
    "view": {"scale": _positive_float, "level": _open_unit},
    "export": {**_SEED, "dwell": _finite_at_least(0.0, "s", 3600.0, " (a wait at each measurement point, in s)"),
               "margin": _finite_at_least(0.0, "m", 0.5, ": give the move clearance margin in m (e.g. 0.01 for 10 mm)"),
               "speed_override": _share},
    "compensate": {**_SEED, "tcp": _offset}, "export-model": {"tcp": _offset},
    "report": {**_SEED, "register_rows": _int_at_least(3)},
    "study": {**_SEED, "measurements": _int_at_least(9), "seeds": _int_at_least(1), "arms": _int_at_least(1),
              "starts": _int_at_least(1), "workers": _int_at_least(1), "scheduler": _scheduler},
}

#: command -> argparse dests of output files
OUTPUTS = {"evaluate": ["json"], "demo": ["json"], "design": ["json"], "simulate": ["out", "test_out", "truth_json"],
           "identify": ["json", "urdf_out", "model_out"], "import-ipa": ["out", "train", "test"],
           "register": ["model_out", "json"], "predict": ["out", "figure"], "diagnose": ["json"], "view": ["html"],
           "export": ["out", "json", "html"], "compensate": ["out", "json"], "import-tracker": ["out"],
           "export-model": ["out"], "report": ["html", "json", "pdf"]}
#: command -> argparse dests of inputs (files or folders; lists allowed)
INPUTS = {"evaluate": ["design"], "design": ["cell", "pool", "given", "given_prior", "model"],
          "identify": ["data", "validate", "register_data", "robot", "kinematics", "cell"],
          "simulate": ["robot", "design", "cell", "poses", "truth", "kinematics"], "import-ipa": ["src"],
          "register": ["model", "data", "cell"], "predict": ["model", "data"],
          "diagnose": ["train", "validate", "register_data", "robot", "kinematics", "cell"],
          "view": ["design"], "info": ["robot"], "export": ["design"],
          "compensate": ["model", "targets", "program", "cell"],
          "import-tracker": ["export", "joints", "robot"], "export-model": ["model"],
          "report": ["model", "train", "validate", "register_data", "kinematics"]}
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
    outputs = _pairs(args, OUTPUTS.get(cmd, []))
    files_of = getattr(args, "output_files", None)  # a command whose option writes several files (KRL: .src + .dat)
    if callable(files_of):
        extra = files_of(args)
        opts = {o for o, _ in extra}
        outputs = list(extra) + [o for o in outputs if o[0] not in opts]
    check_outputs(outputs, _pairs(args, INPUTS.get(cmd, []), existing_only=True), _pairs(args, FOLDERS.get(cmd, [])))


_NEGATIVE = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?(,.*)?$")


def accept_negative_numbers(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Let ``--sigma -1e-5`` or ``--tracker -1,0,0`` reach the checks (argparse takes them for options).

    Returns:
        ``parser``, with every subparser updated.
    """
    stack = [parser]
    while stack:
        p = stack.pop()
        p._negative_number_matcher = _NEGATIVE
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction):
                stack += list(a.choices.values())
    return parser
