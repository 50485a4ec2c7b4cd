"""Typed schemas (JSON Schema, checked with ``jsonschema``) of cell files and design files.

:func:`validate_cell_dict` and :func:`validate_design_dict` run before the readers
(:func:`pin_kpi_oed.cell.cell.cell_from_dict`, :func:`pin_kpi_oed.design.design_file.load_design`)
and refuse, in one line naming the file and the field path:

* unknown keys at every level, nested blocks included (``noise: {sigma_xyz: ...}``),
* text where a number belongs (``measurements: sixty``), lists of the wrong length,
* ragged arrays, a design file that is not an object;

then the unit-plausibility checks of :mod:`pin_kpi_oed.validation.units` (a noise sigma of 1 m,
degrees under a ``_rad`` key).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.validation.units import MAX_TOOL_OFFSET_M, check_sigma_m, check_sigma_rad

__all__ = ["CELL_SCHEMA", "DESIGN_SCHEMA", "validate_cell_dict", "validate_design_dict"]

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
        "tool_frame": {"type": ["string", "null"]}, "base": _POSE, "tracker": _POSE, "reflector_m": _VEC3,
        "tcp_m": _VEC3, "noise": _NOISE,
        "joint_bounds": {"type": "object", "additionalProperties": False,
                         "properties": {k: _NUMS for k in ("lower_rad", "upper_rad", "lower_deg", "upper_deg")}},
        "robot_capsules": {"anyOf": [{"enum": ["urdf", "urdf_visual"]}, {"type": "null"}, {"type": "array", "items": _CAPSULE}]},
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
        return f"expected {'a ' if t in ('number', 'integer', 'string', 'object', 'array') else ''}{t}, " \
               f"got {err.instance!r:.60}"
    if v in ("minItems", "maxItems"):
        return f"wrong number of entries ({len(err.instance)}; {v} {err.validator_value})"
    if v == "required":
        return err.message.replace("is a required property", "missing (required field)")
    if v in ("anyOf", "oneOf"):
        return f"invalid value {err.instance!r:.60} (expected numbers / a list of numbers)"
    return err.message.splitlines()[0][:160]


def _validate(d: Any, schema: dict, source: str, what: str) -> None:
    import jsonschema

    validator = jsonschema.Draft202012Validator(schema)
    errors = sorted(validator.iter_errors(d), key=lambda e: (len(list(e.absolute_path)), list(map(str, e.path))))
    if errors:
        e = errors[0]
        deepest = jsonschema.exceptions.best_match([e]) if e.context else e
        if deepest is not e and deepest.validator in ("additionalProperties", "type"):
            e = deepest
        where = f"{source}: " if source else ""
        raise InputError(f"{where}{what} field {_path(e)}: {_message(e)}")


def _ragged(v: Any) -> bool:
    return isinstance(v, list) and v and isinstance(v[0], list) and len({len(r) if isinstance(r, list) else -1
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
