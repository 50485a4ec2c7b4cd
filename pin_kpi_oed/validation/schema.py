"""Typed schemas (JSON Schema, checked with ``jsonschema``) of cell, design and model files.

:func:`validate_cell_dict` and :func:`validate_design_dict` run before the readers
(:func:`pin_kpi_oed.cell.cell.cell_from_dict`, :func:`pin_kpi_oed.design.design_file.load_design`)
and refuse, in one line naming the file and the field path:

* unknown keys at every level, nested blocks included (``noise: {sigma_xyz: ...}``),
* text where a number belongs (``measurements: sixty``), lists of the wrong length,
* ragged arrays, a design file that is not an object;

then the unit-plausibility checks of :mod:`pin_kpi_oed.validation.units` (a noise sigma of 1 m,
degrees under a ``_rad`` key). :func:`validate_model_dict` does the same for calibrated model files
(``identify --model-out``; read by :func:`pin_kpi_oed.calibrated.model_file.load_model_file`): every
field typed, numbers finite and in range, the parameter covariance square, symmetric and positive
semi-definite; the optional ``discrepancy`` block is left to its own reader. The model file's numeric arrays
(placements, covariances, configurations, effect parameters) are checked with NumPy (nesting, shape, number type,
range, finiteness) and only an array that fails goes through the element-by-element check, which names the first
bad entry: the messages are those of the element-by-element check, at a fraction of its cost.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from itertools import chain
from typing import Any

import numpy as np

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.validation.conformance import compile_schema, pruned
from pin_kpi_oed.validation.units import MAX_TOOL_OFFSET_M, check_sigma_m, check_sigma_rad

__all__ = ["CELL_SCHEMA", "DESIGN_SCHEMA", "MODEL_SCHEMA", "validate_cell_dict", "validate_design_dict",
           "validate_model_dict", "check_covariance", "conforms"]

#: largest plausible distance of the robot base or the tracker from the cell origin (m)
MAX_CELL_M = 200.0

_NUM = {"type": "number"}
_VEC3 = {"type": "array", "items": _NUM, "minItems": 3, "maxItems": 3}
_NUMS = {"type": "array", "items": _NUM, "minItems": 1}
_MATRIX = {"type": "array", "items": _NUMS, "minItems": 1}
_POSE = {"type": "object", "additionalProperties": False,
         "properties": {"xyz_m": _VEC3, "rpy_rad": _VEC3, "rpy_deg": _VEC3}}
_NOISE = {"type": "object", "additionalProperties": False,
          "properties": {"sigma_xyz_m": {"anyOf": [_NUM, {"type": "array", "items": _NUM, "minItems": 1,
                                                          "maxItems": 3}]},
                         "range_a_m": {"type": ["number", "null"]}, "range_b": _NUM, "sigma_rot_rad": _NUM}}
_CAPSULE = {"type": "object", "additionalProperties": False, "required": ["name", "a_m", "b_m", "radius_m"],
            "properties": {"name": {"type": "string"}, "link": {"type": "string"}, "a_m": _VEC3, "b_m": _VEC3,
                           "radius_m": {"type": "number", "minimum": 0}}}
_HALF = {"type": "object", "additionalProperties": False, "required": ["name", "normal", "offset_m"],
         "properties": {"name": {"type": "string"}, "normal": _VEC3, "offset_m": _NUM}}

_ENVIRONMENT = {"type": "object", "additionalProperties": False, "required": ["name"],
                "properties": {"name": {"type": "string"}, "mesh": {"type": "string"}, "urdf": {"type": "string"},
                               "box": {"type": "object", "additionalProperties": False, "required": ["size_m"],
                                       "properties": {"size_m": _VEC3}},
                               "cylinder": {"type": "object", "additionalProperties": False,
                                            "required": ["radius_m", "length_m"],
                                            "properties": {"radius_m": {"type": "number", "exclusiveMinimum": 0},
                                                           "length_m": {"type": "number", "exclusiveMinimum": 0}}},
                               "sphere": {"type": "object", "additionalProperties": False, "required": ["radius_m"],
                                          "properties": {"radius_m": {"type": "number", "exclusiveMinimum": 0}}},
                               "pose": _POSE,
                               "scale": {"anyOf": [{"type": "number", "exclusiveMinimum": 0},
                                                   {"type": "array", "items": {"type": "number", "exclusiveMinimum": 0},
                                                    "minItems": 3, "maxItems": 3}]},
                               "max_radius_m": {"type": "number", "exclusiveMinimum": 0},
                               "max_capsules": {"type": "integer", "minimum": 1}}}
_TARGET = {"type": "object", "additionalProperties": False, "required": ["xyz_m"],
           "properties": {"xyz_m": _VEC3, "rpy_rad": _VEC3, "rpy_deg": _VEC3, "seed_rad": _NUMS, "seed_deg": _NUMS}}

#: schema of a cell YAML file (see :mod:`pin_kpi_oed.cell.cell`)
CELL_SCHEMA: dict[str, Any] = {
    "type": "object", "additionalProperties": False, "required": ["robot"],
    "properties": {
        "name": {"type": "string"}, "description": {"type": "string"}, "robot": {"type": "string"},
        "kinematics": {"type": "string"}, "tool_frame": {"type": ["string", "null"]}, "base": _POSE, "tracker": _POSE,
        "reflector_m": _VEC3, "nests_m": {"type": ["array", "null"], "items": _VEC3, "minItems": 1},
        "tcp_m": _VEC3, "noise": _NOISE,
        "camera": {"type": "object"}, "board": {"type": "object"},  # read by pin_kpi_oed.cell.camera_setup
        "joint_bounds": {"type": "object", "additionalProperties": False,
                         "properties": {k: _NUMS for k in ("lower_rad", "upper_rad", "lower_deg", "upper_deg")}},
        "robot_capsules": {"anyOf": [{"enum": ["urdf", "urdf_visual"]}, {"type": "null"},
                                     {"type": "array", "items": _CAPSULE}]},
        "extra_capsules": {"type": ["array", "null"], "items": _CAPSULE},
        "obstacles": {"type": ["object", "null"], "additionalProperties": False,
                      "properties": {"capsules": {"type": ["array", "null"], "items": _CAPSULE},
                                     "half_spaces": {"type": ["array", "null"], "items": _HALF}}},
        "skip_pairs": {"type": ["array", "null"],
                       "items": {"type": "array", "items": {"type": "string"}, "minItems": 2, "maxItems": 2}},
        "beam": {"type": ["object", "null"], "additionalProperties": False,
                 "properties": {"radius_m": {"type": "number", "minimum": 0},
                                "skip": {"type": ["array", "null"], "items": {"type": "string"}}}},
        "incidence_max_deg": {"type": "number", "exclusiveMinimum": 0, "maximum": 180},
        "clearance_m": {"type": "number", "minimum": 0},
        "working_configurations_rad": {"anyOf": [_NUMS, _MATRIX]},
        "working_configurations_deg": {"anyOf": [_NUMS, _MATRIX]},
        "measurements": {"type": "integer", "minimum": 1},
        "max_random_tries": {"type": "integer", "minimum": 1},
        "environment": {"type": ["array", "null"], "items": _ENVIRONMENT},
        "working_targets": {"type": ["array", "null"], "items": _TARGET},
        "working_paths": {"type": ["array", "null"], "items": {"type": "object"}},
        "orientation_length_m": _NUM,
    },
}

_SQUARE = {"type": "array", "items": _NUMS}
#: schema of a design JSON file (``design --json``; hand-edited files are checked against it)
DESIGN_SCHEMA: dict[str, Any] = {
    "type": "object",
    "properties": {
        "robot": {"anyOf": [{"type": "string"}, {"type": "object"}]},
        "tracker_T_base": {"type": "array", "items": {"type": "array", "items": _NUM, "minItems": 4, "maxItems": 4},
                           "minItems": 4, "maxItems": 4},
        "reflector_m": _VEC3, "tcp_m": _VEC3, "noise": _NOISE,
        "q_work": {"anyOf": [_NUMS, _MATRIX]}, "q_meas": _MATRIX,
        "designs": {"type": "array",
                    "items": {"type": "object",
                              "properties": {"criterion": {"type": "string"}, "q_meas": _MATRIX,
                                             "cov_s_m2": _SQUARE}}},
        "measurements": {"type": "integer", "minimum": 1},
        "seed": {"type": "integer", "minimum": 0},
    },
}


def _path(err: Any) -> str:
    out = ""
    for p in err.absolute_path:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out or "(top level)"


def _message(err: Any) -> str:
    v = err.validator
    if v == "additionalProperties":
        extra = sorted(set(err.instance) - set(err.schema.get("properties", {})))
        known = ", ".join(sorted(err.schema.get("properties", {})))
        return f"unknown field(s) {', '.join(map(str, extra))} (known here: {known})"
    if v == "type":
        t = err.validator_value
        t = " or ".join(t) if isinstance(t, list) else t
        art = {"number": "a ", "string": "a ", "integer": "an ", "object": "an ", "array": "an "}.get(t, "")
        return f"expected {art}{t}, " \
               f"got {err.instance!r:.60}"
    if v in ("minItems", "maxItems"):
        return f"wrong number of entries ({len(err.instance)}; {v} {err.validator_value})"
    if v == "required":
        return err.message.replace("is a required property", "missing (required field)")
    if v in ("anyOf", "oneOf"):
        return f"invalid value {err.instance!r:.60} (expected numbers / a list of numbers)"
    return err.message.splitlines()[0][:160]


def _clean_array(v: Any, ndim: int) -> np.ndarray | None:
    """``v`` as a float array when it is exactly ``ndim`` levels of JSON lists, rectangular, of numbers (int or float,
    not bool: JSON's ``true`` is no number); else None (the caller then checks ``v`` element by element)."""
    if type(v) is not list:
        return None
    level: Any = v
    for _ in range(ndim - 1):
        if not set(map(type, level)) <= {list}:
            return None
        level = list(chain.from_iterable(level))
    if not set(map(type, level)) <= {int, float}:
        return None
    try:
        a = np.array(v, dtype=float)
    except (ValueError, TypeError, OverflowError):  # ragged, or an integer beyond a float
        return None
    return a if a.ndim == ndim else None


def _numeric_array(validator: Any, spec: dict, instance: Any, schema: dict) -> Any:
    """The schema keyword ``numeric_array``: passes a clean array (:func:`_clean_array`) of the stated shape and range
    at once; anything else is checked against ``spec["schema"]`` element by element (the same errors, paths and
    messages as that schema alone gives)."""
    if not _clean_passes(spec, instance):
        yield from validator.descend(instance, spec["schema"])


def _clean_passes(spec: dict, instance: Any) -> bool:
    """Whether ``instance`` passes the ``numeric_array`` keyword ``spec`` at once: ``null`` where nullable, or a clean
    array (:func:`_clean_array`) of the stated shape and range."""
    if spec.get("nullable") and instance is None:
        return True
    a = _clean_array(instance, spec["ndim"])
    return a is not None and all(want is None or n == want for n, want in zip(a.shape, spec.get("shape") or a.shape)) \
        and (not spec.get("nonempty") or min(a.shape) >= 1) \
        and (spec.get("minimum") is None or bool(np.all(a >= spec["minimum"])))


def _numeric_array_check(spec: dict) -> Callable[[Any], bool]:
    """The ``numeric_array`` keyword as a predicate of :func:`~pin_kpi_oed.validation.conformance.compile_schema`."""
    each = compile_schema(spec["schema"])
    return lambda x: _clean_passes(spec, x) or each(x)


def _numeric(schema: dict, ndim: int, shape: tuple | None = None, nonempty: bool = False,
             minimum: float | None = None, nullable: bool = False) -> dict:
    """``schema`` (an array of ``ndim`` levels of numbers) checked with NumPy first (:func:`_numeric_array`).

    Args:
        schema: the element-by-element schema; the NumPy check passes only what it passes.
        ndim: levels of lists; shape: the required length per level (None: any), or None.
        nonempty: every level has at least one entry; minimum: the smallest number allowed, or None.
        nullable: ``null`` passes too.

    Returns:
        The schema with the ``numeric_array`` keyword.
    """
    return {"numeric_array": {"schema": schema, "ndim": ndim, "shape": shape, "nonempty": nonempty,
                              "minimum": minimum, "nullable": nullable}}


_VALIDATORS: dict[int, Any] = {}
#: id of a schema -> (the schema, kept alive so that its id stays its own; its predicate)
_CONFORMS: dict[int, tuple[Any, Callable[[Any], bool]]] = {}


def conforms(instance: Any, schema: Any) -> bool:
    """Whether ``instance`` passes ``schema`` by its compiled predicate (:mod:`~pin_kpi_oed.validation.conformance`,
    made once per schema), True only where ``jsonschema`` finds no error.

    Args:
        instance: a parsed document or a part of it.
        schema: one of this module's schemas or a part of it.

    Returns:
        True: valid; False: ask ``jsonschema`` (the document may still be valid).
    """
    hit = _CONFORMS.get(id(schema))
    if hit is None or hit[0] is not schema:
        hit = _CONFORMS[id(schema)] = (schema, compile_schema(schema, _numeric_array_check))
    return hit[1](instance)


def _validate(d: Any, schema: dict, source: str, what: str) -> None:
    """Refuse ``d`` with the first error ``jsonschema`` finds against ``schema``. A document the compiled predicate
    accepts has none (:func:`conforms`); a refused one is descended by ``jsonschema`` only where the predicate
    refuses (:func:`~pin_kpi_oed.validation.conformance.pruned`): the same errors, in the same order.

    Raises:
        InputError: ``<source>: <what> field <path>: <message>``.
    """
    if conforms(d, schema):
        return
    import jsonschema

    validator = _VALIDATORS.get(id(schema))
    if validator is None:  # built once per schema (a few ms each)
        cls = jsonschema.validators.extend(jsonschema.Draft202012Validator, {"numeric_array": _numeric_array})
        validator = _VALIDATORS[id(schema)] = cls(schema)
    errors = sorted(validator.evolve(schema=pruned(d, validator.schema, conforms)).iter_errors(d),
                    key=lambda e: (len(list(e.absolute_path)), list(map(str, e.path))))
    if errors:
        e = errors[0]
        deepest = jsonschema.exceptions.best_match([e]) if e.context else e
        if deepest is not e and deepest.validator in ("additionalProperties", "type"):
            e = deepest
        where = f"{source}: " if source else ""
        raise InputError(f"{where}{what} field {_path(e)}: {_message(e)}")


def _ragged(v: Any) -> bool:
    return isinstance(v, list) and bool(v) and isinstance(v[0], list) and len({len(r) if isinstance(r, list) else -1
                                                                        for r in v}) > 1


def validate_cell_dict(d: Any, source: str = "") -> None:
    """Check a parsed cell mapping against :data:`CELL_SCHEMA` and the shared unit guards.

    Args:
        d: the parsed YAML mapping.
        source: file name for the message.

    Raises:
        InputError: the first violation, naming the file, the field path, the value and the unit.
    """
    where = f"{source}: " if source else ""
    if not isinstance(d, dict):
        raise InputError(f"{where}expected a YAML mapping at the top level, got {type(d).__name__}")
    _validate(d, CELL_SCHEMA, source, "cell")
    noise = d.get("noise") or {}
    if "sigma_xyz_m" in noise:
        check_sigma_m(noise["sigma_xyz_m"], f"{where}noise.sigma_xyz_m")
    if "sigma_rot_rad" in noise:
        check_sigma_rad(noise["sigma_rot_rad"], f"{where}noise.sigma_rot_rad")
    for key in ("working_configurations_rad", "working_configurations_deg"):
        if _ragged(d.get(key)):
            raise InputError(f"{where}{key}: rows of different lengths (ragged)")
    jb = d.get("joint_bounds") or {}
    for key in ("lower_rad", "upper_rad"):
        if key in jb:
            a = np.abs(np.asarray(jb[key], float))
            if np.any(a > 4 * math.pi) and np.all(a[a > 4 * math.pi] <= 1080):
                x = float(np.asarray(jb[key], float)[np.argmax(a)])
                raise InputError(f"{where}joint_bounds.{key}: {x:g} rad ({math.degrees(x):.0f}°) is beyond ±4π: "
                                 f"the values look like degrees; use joint_bounds.{key[:-4]}_deg or convert to rad")
    for key, limit in (("reflector_m", MAX_TOOL_OFFSET_M), ("tcp_m", MAX_TOOL_OFFSET_M)):
        if key in d and float(np.linalg.norm(np.asarray(d[key], float))) > limit:
            raise InputError(f"{where}{key}: {float(np.linalg.norm(np.asarray(d[key], float))):.4g} m from the tool "
                             f"frame, more than {limit:g} m: the values look like mm; give them in m")
    for i, x in enumerate(d.get("nests_m") or []):
        if float(np.linalg.norm(np.asarray(x, float))) > MAX_TOOL_OFFSET_M:
            raise InputError(f"{where}nests_m[{i}]: {float(np.linalg.norm(np.asarray(x, float))):.4g} m from the tool "
                             f"frame, more than {MAX_TOOL_OFFSET_M:g} m: the values look like mm; give them in m")
    for key in ("base", "tracker"):
        xyz = (d.get(key) or {}).get("xyz_m")
        if xyz is not None and float(np.linalg.norm(np.asarray(xyz, float))) > MAX_CELL_M:
            raise InputError(f"{where}{key}.xyz_m: {float(np.linalg.norm(np.asarray(xyz, float))):.4g} m from the "
                             f"cell origin, more than {MAX_CELL_M:g} m: the values look like mm; give them in m")
    wr = d.get("working_configurations_rad")
    if wr is not None and not _ragged(wr):
        a = np.abs(np.asarray(wr, float))
        if np.any(a > 4 * math.pi):
            raise InputError(f"{where}working_configurations_rad: {float(a.max()):g} rad is beyond ±4π: the values "
                             "look like degrees; use working_configurations_deg")


def validate_design_dict(d: Any, source: str = "") -> None:
    """Check a parsed design JSON against :data:`DESIGN_SCHEMA` (hand-edited files: lists, ragged arrays, text).

    Raises:
        InputError: the first violation, naming the file and the field path.
    """
    where = f"{source}: " if source else ""
    if not isinstance(d, dict):
        raise InputError(f"{where}expected a JSON object at the top level (a design file), got {type(d).__name__}")
    _validate(d, DESIGN_SCHEMA, source, "design")
    checks = [("q_meas", d.get("q_meas")), ("q_work", d.get("q_work"))]
    for i, e in enumerate(d.get("designs") or []):
        checks += [(f"designs[{i}].q_meas", e.get("q_meas")), (f"designs[{i}].cov_s_m2", e.get("cov_s_m2"))]
    for name, v in checks:
        if _ragged(v):
            raise InputError(f"{where}{name}: rows of different lengths (ragged array)")
    if isinstance(d.get("noise"), dict) and "sigma_xyz_m" in d["noise"]:
        check_sigma_m(d["noise"]["sigma_xyz_m"], f"{where}noise.sigma_xyz_m")


_MAT4 = {"type": "array", "items": {"type": "array", "items": _NUM, "minItems": 4, "maxItems": 4},
         "minItems": 4, "maxItems": 4}
_MAT3 = {"type": "array", "items": {"type": "array", "items": _NUM, "minItems": 3, "maxItems": 3},
         "minItems": 3, "maxItems": 3}
_STRS = {"type": "array", "items": {"type": "string"}}
_NUMBERS = _numeric({"type": "array", "items": _NUM}, 1)
_SIGMAS = _numeric({"type": "array", "items": {"type": "number", "minimum": 0}}, 1, minimum=0.0)
_ROWS = _numeric({"type": "array", "items": {"type": "array", "items": _NUM}}, 2)
_PLACEMENTS = _numeric({"type": "array", "items": _MAT4}, 3, (None, 4, 4))
_CONFIGURATIONS = _numeric({"type": "array", "minItems": 1, "items": {"type": "array", "items": _NUM, "minItems": 1}},
                           2, nonempty=True)
_EFFECT = {"type": "object", "required": ["kind"],
           "properties": {"name": {"type": "string"}, "kind": {"type": "string"},
                          "options": {"type": ["object", "null"]}, "param_names": _STRS,
                          "theta": _NUMBERS, "unit": {"type": ["string", "array", "null"]},
                          "base": {"type": "object"}, "keep": {"type": "array", "items": {"type": "integer",
                                                                                             "minimum": 0}}}}
_STATION = {"type": "object", "additionalProperties": False, "required": ["tracker_T_base", "reflector_m"],
            "properties": {"tracker_T_base": _MAT4, "reflector_m": _VEC3,
                           "nests_m": {"type": ["array", "null"], "items": _VEC3, "minItems": 1},
                           "probe_R": {"anyOf": [_MAT3, {"type": "null"}]},
                           "n_rows": {"type": "integer", "minimum": 0}, "fitted_by": {"type": "string"},
                           "source": {"type": "string"}, "rms_m": {"type": ["number", "null"], "minimum": 0},
                           "sigma_scale": {"type": "number", "minimum": 1},
                           "registered_q_rad": _CONFIGURATIONS}}
_HELD = {"type": ["object", "null"], "additionalProperties": False,
         "properties": {"names": _STRS, "sigma": _SIGMAS, "absorption": _ROWS}}
_PARAMETERS = {"type": ["object", "null"], "additionalProperties": False,
               "properties": {"names": _STRS, "values": _NUMBERS, "std": _SIGMAS, "units": _STRS,
                              "covariance": _numeric({"anyOf": [{"type": "array", "items": {
                                  "type": "array", "items": _NUM}}, {"type": "null"}]}, 2, nullable=True),
                              "held": _HELD}}
#: schema of a calibrated model file (``pin_kpi_oed.model/1``; see :mod:`pin_kpi_oed.calibrated.model_file`)
MODEL_SCHEMA: dict[str, Any] = {
    "type": "object", "additionalProperties": False, "required": ["format", "robot", "geometry", "stations"],
    "properties": {
        "format": {"type": "string"},
        "robot": {"type": "object", "additionalProperties": False,
                  "properties": {"spec": {"type": "string"}, "name": {"type": "string"},
                                 "urdf_path": {"type": "string"}, "tool_frame": {"type": ["string", "null"]},
                                 "joint_names": _STRS, "nominal_joint_placements": _PLACEMENTS,
                                 "kinematics": {"type": "object"}}},
        "tcp_m": _VEC3, "pose6d": {"type": "boolean"},
        "tool_source": {"type": "string"},
        "q_work": _CONFIGURATIONS,
        "geometry": {"type": "object", "additionalProperties": False, "required": ["joint_placement_errors"],
                     "properties": {"joint_placement_errors": {"type": "object", "additionalProperties": _NUM},
                                    "joint_placements": _PLACEMENTS, "parameters": _PARAMETERS}},
        "effects": {"type": ["array", "null"], "items": _EFFECT},
        "stations": {"type": "object", "minProperties": 1, "additionalProperties": _STATION},
        "default_station": {"type": ["string", "null"]},
        "noise": _NOISE,
        "fit": {"type": ["object", "null"]},
        "history": {"type": ["array", "null"], "items": {"type": "object"}},
        "discrepancy": {"type": ["object", "null"]},  # validated by its own reader
        "coverage": {"type": ["object", "null"]},  # validated by its own reader (JointCoverage.from_dict)
    },
}

#: largest plausible joint-placement error: translation (m), rotation (rad)
MAX_PLACEMENT_ERROR = {"t": 0.5, "r": math.pi / 2}


def _first_nonfinite(v: Any, path: str) -> str | None:
    """Path of the first NaN / inf number in a nested list / dict, or None."""
    if isinstance(v, bool) or v is None or isinstance(v, str):
        return None
    if isinstance(v, (int, float)):
        return None if math.isfinite(v) else path
    if isinstance(v, dict):
        for k, x in v.items():
            if not _passes(x):
                hit = _first_nonfinite(x, f"{path}.{k}" if path else str(k))
                if hit:
                    return hit
    if isinstance(v, list):
        ndim, x0 = 1, v[0] if v else None
        while type(x0) is list:  # the depth of the first entry's nesting: a clean array of that depth at once
            ndim, x0 = ndim + 1, x0[0] if x0 else None
        a = _clean_array(v, ndim)
        if a is not None:
            bad = np.argwhere(~np.isfinite(a))
            return None if not len(bad) else path + "".join(f"[{int(i)}]" for i in bad[0])
        for i, x in enumerate(v):
            if not _passes(x):
                hit = _first_nonfinite(x, f"{path}[{i}]")
                if hit:
                    return hit
    return None


def _passes(x: Any) -> bool:
    """A leaf :func:`_first_nonfinite` passes at once (text, ``null``, a boolean, a finite float): the common entries
    of a mapping or a list, judged without a call of the walk (False: walk it)."""
    t = type(x)
    return t is str or x is None or t is bool or (t is float and math.isfinite(x))


def check_covariance(C: Any, what: str, n: int | None = None) -> np.ndarray:
    """A covariance matrix: square (n × n), finite, symmetric, positive semi-definite and not zero.

    Args:
        C: the matrix (nested lists or array).
        what: the file and field, for the message.
        n: the expected size (the number of parameter names), or None.

    Returns:
        The matrix as a float array.

    Raises:
        InputError: naming ``what`` and what is wrong (the most negative eigenvalue when not PSD).
    """
    try:
        A = np.asarray(C, float)
    except (TypeError, ValueError):
        raise InputError(f"{what}: expected a square matrix of numbers") from None
    if A.ndim != 2 or A.shape[0] != A.shape[1] or (n is not None and A.shape[0] != n):
        raise InputError(f"{what}: expected a square {n if n is not None else 'k'} x "
                         f"{n if n is not None else 'k'} matrix, got shape {A.shape}")
    if not np.all(np.isfinite(A)):
        raise InputError(f"{what}: contains NaN or inf")
    scale = float(np.max(np.abs(A))) if A.size else 0.0
    if scale == 0.0:
        raise InputError(f"{what}: all zero: not a covariance of a fit (it would claim exact parameters)")
    if np.max(np.abs(A - A.T)) > 1e-8 * scale:
        i, j = np.unravel_index(int(np.argmax(np.abs(A - A.T))), A.shape)
        raise InputError(f"{what}: not symmetric (entry [{i}][{j}] = {A[i, j]:.6g}, [{j}][{i}] = {A[j, i]:.6g})")
    w = np.linalg.eigvalsh(0.5 * (A + A.T))
    if w[0] < -1e-9 * scale or np.any(np.diag(A) < 0):
        raise InputError(f"{what}: not positive semi-definite (smallest eigenvalue {w[0]:.3g}, largest {w[-1]:.3g}): "
                         "not a covariance")
    return A


def validate_model_dict(d: Any, source: str = "model file") -> None:
    """Check a parsed model file against :data:`MODEL_SCHEMA`, then numbers and covariances.

    Args:
        d: the parsed JSON (its ``format`` already checked).
        source: the file name for the messages.

    Raises:
        InputError: the first violation, naming the file, the field path, the value and the unit or range.
    """
    where = f"{source}: " if source else ""
    if not isinstance(d, dict):
        raise InputError(f"{where}expected a JSON object at the top level (a model file), got {type(d).__name__}")
    _validate(d, MODEL_SCHEMA, source, "model")
    for key in ("robot", "tcp_m", "q_work", "geometry", "effects", "stations", "noise"):
        hit = _first_nonfinite(d.get(key), key)
        if hit:
            raise InputError(f"{where}model field {hit}: not a finite number (NaN or inf)")
    if "tcp_m" in d and float(np.linalg.norm(d["tcp_m"])) > MAX_TOOL_OFFSET_M:
        raise InputError(f"{where}model field tcp_m: {float(np.linalg.norm(d['tcp_m'])):.4g} m from the tool frame, "
                         f"more than {MAX_TOOL_OFFSET_M:g} m: give it in m")
    for name, v in d["geometry"]["joint_placement_errors"].items():
        kind = str(name).rsplit(".", 1)[-1][:1]
        lim = MAX_PLACEMENT_ERROR.get(kind)
        if lim is not None and abs(v) > lim:
            unit = "m" if kind == "t" else "rad"
            raise InputError(f"{where}model field geometry.joint_placement_errors.{name}: {v:g} {unit} is beyond "
                             f"±{lim:.3g} {unit}: not a calibration error (units: m, rad)")
    for label, st in d["stations"].items():
        refl = float(np.linalg.norm(st["reflector_m"]))
        if refl > MAX_TOOL_OFFSET_M:
            raise InputError(f"{where}model field stations.{label}.reflector_m: {refl:.4g} m from the tool frame, "
                             f"more than {MAX_TOOL_OFFSET_M:g} m: give it in m")
        xyz = float(np.linalg.norm(np.asarray(st["tracker_T_base"], float)[:3, 3]))
        if xyz > MAX_CELL_M:
            raise InputError(f"{where}model field stations.{label}.tracker_T_base: the base is {xyz:.4g} m from the "
                             f"tracker, more than {MAX_CELL_M:g} m: give it in m")
    noise = d.get("noise") or {}
    if "sigma_xyz_m" in noise:
        check_sigma_m(noise["sigma_xyz_m"], f"{where}model field noise.sigma_xyz_m")
    if noise.get("sigma_rot_rad") is not None:
        check_sigma_rad(noise["sigma_rot_rad"], f"{where}model field noise.sigma_rot_rad")
    if noise.get("range_a_m") is not None:
        check_sigma_m(noise["range_a_m"], f"{where}model field noise.range_a_m")
    if noise.get("range_b") is not None and not (0 <= noise["range_b"] < 1e-2):
        raise InputError(f"{where}model field noise.range_b: {noise['range_b']:g} must be in [0, 0.01) "
                         "(m of noise per m of distance)")
    par = d["geometry"].get("parameters") or {}
    names = par.get("names")
    for key in ("values", "std", "units"):
        if names is not None and par.get(key) is not None and len(par[key]) != len(names):
            raise InputError(f"{where}model field geometry.parameters.{key}: {len(par[key])} entries for "
                             f"{len(names)} names")
    if par.get("covariance") is not None:
        if _ragged(par["covariance"]):
            raise InputError(f"{where}model field geometry.parameters.covariance: rows of different lengths (ragged)")
        check_covariance(par["covariance"], f"{where}model field geometry.parameters.covariance",
                         len(names) if names is not None else None)
    held = par.get("held") or {}
    if held:
        if _ragged(held.get("absorption")):
            raise InputError(f"{where}model field geometry.parameters.held.absorption: rows of different lengths "
                             "(ragged)")
        k, rows = len(held.get("names") or []), np.asarray(held.get("absorption") or [], float)
        if len(held.get("sigma") or []) != k or (k and rows.shape != (len(names or []), k)):
            raise InputError(f"{where}model field geometry.parameters.held: {k} names, "
                             f"{len(held.get('sigma') or [])} sigma and an absorption of shape {rows.shape}; "
                             f"expected ({len(names or [])}, {k}) (one row per parameter name)")
