"""The model file's numeric arrays are checked with NumPy: every verdict and message equals the element-by-element
check's (a plain JSON Schema validator on the same schema and a recursive walk for NaN / inf, kept here as the
independent reference), for clean files and for every kind of bad entry in every numeric array."""

from __future__ import annotations

import copy
import math
import time
from typing import Any

import numpy as np
import pytest

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.validation import schema as schema_module
from pin_kpi_oed.validation.schema import MODEL_SCHEMA, validate_model_dict


def _unwrapped(x: Any) -> Any:
    """The schema without its NumPy keyword: what the element-by-element check validates against."""
    if isinstance(x, dict):
        if "numeric_array" in x:
            return _unwrapped(x["numeric_array"]["schema"])
        return {k: _unwrapped(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_unwrapped(v) for v in x]
    return x


def _walk_nonfinite(v: Any, path: str) -> str | None:
    """Reference: path of the first NaN / inf number, walking every entry in Python."""
    if isinstance(v, bool) or v is None or isinstance(v, str):
        return None
    if isinstance(v, (int, float)):
        return None if math.isfinite(v) else path
    if isinstance(v, dict):
        for k, x in v.items():
            hit = _walk_nonfinite(x, f"{path}.{k}" if path else str(k))
            if hit:
                return hit
    if isinstance(v, list):
        for i, x in enumerate(v):
            hit = _walk_nonfinite(x, f"{path}[{i}]")
            if hit:
                return hit
    return None


def _model_dict(n_par: int = 6, n_reg: int = 4, seed: int = 0, n_placements: int = 2) -> dict:
    """A schema-valid model file content (SI units) with every numeric array the schema names.

    By default 6 parameters, 4 registration rows and 2 joint placements: every array keeps several rows and columns,
    so a first and a last entry are distinct places; the 292 corruptions of 12 parameters and 8 rows reached the same
    133 lines of the checks (validation/schema.py) with the same 66 kinds of message as these, at a third more CPU,
    and those with 6 placements (a 6-joint robot's) the same messages but for the placement's index, at a third
    more CPU (the element-by-element reference walks each placement's 16 numbers; the schema does not tie their
    number to the joints')."""
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n_par, n_par)) * 1e-4
    T = np.eye(4)
    T[:3, 3] = [2.0, 0.5, 0.3]
    names = [f"joint_a{k // 6 + 1}.{'t' if k % 6 < 3 else 'r'}{'xyz'[k % 3]}" for k in range(n_par)]
    return {
        "format": "pin_kpi_oed.model/1",
        "robot": {"spec": "kr15", "name": "kr15", "tool_frame": "tool0", "joint_names": [f"joint_a{k}" for k in
                                                                                          range(1, 7)],
                  "nominal_joint_placements": [np.eye(4).tolist() for _ in range(n_placements)]},
        "tcp_m": [0.0, 0.0, 0.1], "pose6d": False,
        "q_work": rng.uniform(-1, 1, (3, 6)).tolist(),
        "geometry": {"joint_placement_errors": {n: float(v) for n, v in zip(names, rng.normal(0, 1e-4, n_par))},
                     "joint_placements": [np.eye(4).tolist() for _ in range(n_placements)],
                     "parameters": {"names": names, "values": rng.normal(0, 1e-4, n_par).tolist(),
                                    "std": np.sqrt(np.diag(A @ A.T)).tolist(), "units": ["m"] * n_par,
                                    "covariance": (A @ A.T).tolist(),
                                    "held": {"names": ["h1", "h2"], "sigma": [1e-4, 2e-4],
                                             "absorption": rng.normal(size=(n_par, 2)).tolist()}}},
        "effects": [{"name": "joint_compliance", "kind": "JointCompliance", "options": {},
                     "param_names": ["c2", "c3"], "theta": [1e-6, 2e-6], "unit": "rad/Nm"}],
        "stations": {"tr": {"tracker_T_base": T.tolist(), "reflector_m": [0.05, 0.03, 0.08], "n_rows": 10,
                            "registered_q_rad": rng.uniform(-1, 1, (n_reg, 6)).tolist()}},
        "default_station": "tr",
        "noise": {"sigma_xyz_m": [1e-5, 1e-5, 1e-5], "range_a_m": None, "range_b": 0.0},
        "fit": {}, "history": [],
    }


#: the numeric arrays of a model file: (path, levels of lists)
ARRAYS = [("robot/nominal_joint_placements", 3), ("geometry/joint_placements", 3), ("q_work", 2),
          ("geometry/parameters/values", 1), ("geometry/parameters/std", 1), ("geometry/parameters/covariance", 2),
          ("geometry/parameters/held/sigma", 1), ("geometry/parameters/held/absorption", 2),
          ("effects/0/theta", 1), ("stations/tr/registered_q_rad", 2)]


def _at(d: dict, path: str) -> tuple[Any, Any]:
    *head, last = path.split("/")
    o: Any = d
    for k in head:
        o = o[int(k)] if isinstance(o, list) else o[k]
    return o, (int(last) if isinstance(o, list) else last)


def _corruptions() -> list[tuple[str, dict]]:
    """(label, model dict) with one bad entry or one bad array each."""
    out = []
    good = _model_dict()
    for path, ndim in ARRAYS:
        entries = {"text": "x", "bool": True, "false": False, "null": None, "nan": float("nan"),
                   "inf": float("-inf"), "deeper": [1.0], "dict": {"v": 1}, "negative": -1e-3, "int": 0}
        for tag, value in entries.items():
            for where in (0, -1):
                d = copy.deepcopy(good)
                o, k = _at(d, path)
                leaf = o[k]
                for _ in range(ndim - 1):
                    leaf = leaf[where]
                leaf[where] = value
                out.append((f"{path} entry {where} {tag}", d))
        wholes = {"text": "diag(1e-8)", "empty": [], "nested-empty": [[]], "dict": {}, "null": None, "number": 1.0,
                  "flat": [0.1, 0.2], "bool-row": [True, False]}
        for tag, value in wholes.items():
            d = copy.deepcopy(good)
            o, k = _at(d, path)
            o[k] = value
            out.append((f"{path} = {tag}", d))
        if ndim >= 2:
            for tag in ("longer", "shorter"):
                d = copy.deepcopy(good)
                o, k = _at(d, path)
                row = o[k][-1]
                row.append(copy.deepcopy(row[0])) if tag == "longer" else row.pop()
                out.append((f"{path} last row {tag}", d))
    return out


def _verdict(d: dict) -> str:
    try:
        validate_model_dict(d, "m.json")
    except InputError as exc:
        return str(exc)
    return "ok"


@pytest.fixture
def element_by_element(monkeypatch):
    """Switch the check to the reference: a plain JSON Schema validator on every document and part (no compiled
    predicate accepts first, none prunes) and the recursive NaN walk."""
    import jsonschema

    def use() -> None:
        plain = jsonschema.Draft202012Validator(_unwrapped(MODEL_SCHEMA))
        monkeypatch.setattr(schema_module, "_VALIDATORS", {id(MODEL_SCHEMA): plain})
        monkeypatch.setattr(schema_module, "conforms", lambda instance, schema: False)
        monkeypatch.setattr(schema_module, "_first_nonfinite", _walk_nonfinite)
    return use


def test_numpy_checks_give_the_element_by_element_messages(element_by_element):
    cases = _corruptions()
    fast = {label: _verdict(d) for label, d in cases}
    good = _verdict(_model_dict())
    element_by_element()
    slow = {label: _verdict(d) for label, d in cases}
    assert good == "ok" == _verdict(_model_dict())
    assert fast == slow
    refused = [v for v in fast.values() if v != "ok"]
    assert len(refused) > 0.8 * len(cases) and len(set(refused)) > 60  # the battery reaches many message paths
    assert all(v.startswith("m.json: ") and "\n" not in v for v in refused)
    assert fast["stations/tr/registered_q_rad entry -1 bool"] == slow["stations/tr/registered_q_rad entry -1 bool"] \
        == "m.json: model field stations.tr.registered_q_rad[3][5]: expected a number, got True"
    assert fast["geometry/parameters/covariance entry 0 nan"].startswith(
        "m.json: model field geometry.parameters.covariance[0][0]: not a finite number")


def test_numpy_checks_are_faster_on_a_large_file(element_by_element):
    """A model with a 120-parameter covariance and 2,000 registration rows: the NumPy checks cost a fraction of the
    element-by-element ones (CPU time, best of 3)."""
    d = _model_dict(n_par=120, n_reg=2000, n_placements=6)

    def cpu() -> float:
        best = math.inf
        for _ in range(3):
            t0 = time.process_time()
            validate_model_dict(d, "m.json")
            best = min(best, time.process_time() - t0)
        return best

    validate_model_dict(d, "m.json")
    fast = cpu()
    element_by_element()
    validate_model_dict(d, "m.json")
    assert fast < 0.2 * cpu()
