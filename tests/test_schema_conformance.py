"""The compiled schema predicate (validation/conformance.py) says yes only where ``jsonschema`` finds no error, and
a refused document, descended by ``jsonschema`` only where the predicate refuses, gets the message of the full
descent: every verdict and message equals the plain ``jsonschema`` path's (the check as it was before the
predicate, the reference here), for shipped cells and a design file with one bad value at many places (the model
file's battery: tests/test_model_file_checks.py, whose reference takes the plain path too)."""

from __future__ import annotations

import copy
import json
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest
import yaml

from pin_kpi_oed.cell.cell import CELL_DIR
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.validation import schema as schema_module
from pin_kpi_oed.validation.conformance import compile_schema

#: one bad value of every kind a hand-edited file holds
BAD = {"text": "x", "true": True, "null": None, "negative": -1.5, "empty-list": [], "list": [1.0, "a"],
       "object": {"zz": 1}}


def _places(d: Any, path: tuple = ()) -> Iterator[tuple]:
    """Every place of a document: each key of a mapping, the first and last entry of a list (paths of keys)."""
    if isinstance(d, dict):
        for k, v in d.items():
            yield path + (k,)
            yield from _places(v, path + (k,))
    elif isinstance(d, list) and d:
        for i in sorted({0, len(d) - 1}):
            yield path + (i,)
            yield from _places(d[i], path + (i,))


def _battery(good: dict, n: int, seed: int = 0) -> list[dict]:
    """``good``, then ``good`` with one place set to one bad value (``n`` of them drawn, every kind of value at every
    depth alike), and with an unknown key at every mapping.

    A seeded draw of ``n`` (place, value) pairs, not all of them: the reference's full descent costs milliseconds per
    document; the variety of the messages reached is asserted by the test."""
    out = [good]
    rng = np.random.default_rng(seed)
    combos = [(p, v) for p in _places(good) for v in BAD.values()]
    for k in sorted(rng.choice(len(combos), size=min(n, len(combos)), replace=False)):
        place, value = combos[k]
        d = copy.deepcopy(good)
        _get(d, place[:-1])[place[-1]] = copy.deepcopy(value)
        out.append(d)
    for place in [()] + [p for p in _places(good) if isinstance(_get(good, p), dict)]:
        d = copy.deepcopy(good)
        _get(d, place)["unknown_key"] = 1.0
        out.append(d)
    return out


def _get(d: Any, place: tuple) -> Any:
    for k in place:
        d = d[k]
    return d


def _verdicts(check: Callable[[Any, str], None], docs: list[dict]) -> list[str]:
    out = []
    for d in docs:
        try:
            check(d, "f.yaml")
            out.append("ok")
        except InputError as exc:
            out.append(str(exc))
    return out


def _cell(name: str) -> dict:
    return yaml.safe_load((CELL_DIR / f"{name}.yaml").read_text())


def _design() -> dict:
    rng = np.random.default_rng(0)
    return {"robot": "kr15", "tracker_T_base": np.eye(4).tolist(), "reflector_m": [0.0, 0.0, 0.1],
            "tcp_m": [0.0, 0.0, 0.0], "noise": {"sigma_xyz_m": 1e-5}, "q_work": rng.uniform(-1, 1, (2, 6)).tolist(),
            "designs": [{"criterion": "kpi", "q_meas": rng.uniform(-1, 1, (2, 6)).tolist(),
                         "cov_s_m2": np.eye(3).tolist()}], "measurements": 4, "seed": 0}


CASES = {"cell kr15_seam": (lambda: _cell("kr15_seam"), schema_module.validate_cell_dict, schema_module.CELL_SCHEMA),
         "cell ur10": (lambda: _cell("ur10"), schema_module.validate_cell_dict, schema_module.CELL_SCHEMA),
         "design": (_design, schema_module.validate_design_dict, schema_module.DESIGN_SCHEMA)}


@pytest.mark.parametrize("case", sorted(CASES))
def test_compiled_predicate_and_pruned_descent_give_jsonschemas_verdicts(case, monkeypatch):
    make, check, schema = CASES[case]
    docs = _battery(make(), n=40)
    fast = _verdicts(check, docs)
    accepted = [schema_module.conforms(d, schema) for d in docs]
    monkeypatch.setattr(schema_module, "conforms", lambda instance, sub: False)  # the full jsonschema descent
    slow = _verdicts(check, docs)
    plain = _verdicts(lambda d, src: schema_module._validate(d, schema, src, "x"), docs)  # the schema alone
    assert fast == slow
    assert fast[0] == "ok" and accepted[0]  # the good document takes the fast path
    assert all(a <= (p == "ok") for a, p in zip(accepted, plain))  # sound: no yes where jsonschema says no
    assert accepted == [p == "ok" for p in plain]  # and exact here: what the schema lets through takes the fast path
    assert len({s for s in slow if s != "ok"}) > 20  # the battery reaches many messages


def test_the_predicate_leaves_other_number_types_and_unknown_keywords_to_jsonschema():
    """A NumPy number under a numeric keyword, or a keyword the compiler does not know, is never accepted (False:
    jsonschema decides); plain numbers are judged as jsonschema compares them."""
    minimum = compile_schema({"type": "number", "minimum": 0})
    assert minimum(0) and minimum(2.5) and not minimum(-1e-9) and not minimum(True) and not minimum("1")
    assert not compile_schema({"minimum": 0})(np.float32(1.0)) and compile_schema({"minimum": 0})("text")
    assert not compile_schema({"type": "string", "pattern": "^a"})("abc")
    integer = compile_schema({"type": "integer"})
    assert integer(3) and integer(3.0) and not integer(3.5) and not integer(False)
    closed = compile_schema({"type": "object", "additionalProperties": False, "properties": {"a": {"type": "null"}}})
    assert closed({"a": None}) and not closed({"a": 0}) and not closed({"b": None}) and closed({})
    assert json.dumps(schema_module.CELL_SCHEMA)  # the compiled schemas are plain JSON
