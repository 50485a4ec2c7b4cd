"""A fast yes of a JSON Schema: the schemas of :mod:`pin_kpi_oed.validation.schema` compiled into plain predicates.

``jsonschema`` descends a document keyword by keyword, making a validator and an error context at every level; a
valid cell or model file costs milliseconds of that descent. :func:`compile_schema` turns a schema into one Python
predicate per keyword that answers only "valid or not", with no error objects. It is sound, not complete: it says
``True`` only where ``jsonschema`` (Draft 2020-12 with the ``numeric_array`` keyword) finds no error, and ``False``
wherever it is unsure — an unknown keyword, a number type other than ``int`` / ``float`` under a numeric keyword —,
so that the caller then asks ``jsonschema``, which names the error. :func:`pruned` gives the schema a refused
document needs: every property the predicate accepts replaced by ``True`` (the always-valid schema), so that
``jsonschema`` descends only where the errors are and finds the same errors in the same order.
"""

from __future__ import annotations

import numbers
from collections.abc import Callable
from typing import Any

__all__ = ["compile_schema", "pruned"]

Check = Callable[[Any], bool]
#: the predicate maker of the ``numeric_array`` keyword (its spec -> predicate), or None
NumericArray = Callable[[dict], Check] | None


def _never(x: Any) -> bool:
    return False


def _always(x: Any) -> bool:
    return True


def _plain_number(x: Any) -> bool:
    """An ``int`` or ``float`` (``bool`` is no number): the numbers a YAML or JSON parser makes."""
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _other_number(x: Any) -> bool:
    """A number of another type (NumPy's, ``Decimal``): left to ``jsonschema``."""
    return isinstance(x, numbers.Number) and not isinstance(x, bool) and not isinstance(x, (int, float))


_TYPES: dict[str, Check] = {
    "array": lambda x: isinstance(x, list),
    "boolean": lambda x: isinstance(x, bool),
    "integer": lambda x: not isinstance(x, bool) and (isinstance(x, int) or (isinstance(x, float) and x.is_integer())),
    "null": lambda x: x is None,
    "number": _plain_number,
    "object": lambda x: isinstance(x, dict),
    "string": lambda x: isinstance(x, str),
}


def _bound(test: Callable[[Any], bool]) -> Check:
    """A numeric keyword: checks an ``int`` / ``float``, passes what is no number, is unsure of other numbers."""
    def check(x: Any) -> bool:
        if _plain_number(x):
            return test(x)
        return not _other_number(x)
    return check


def _type(value: Any) -> Check:
    names = value if isinstance(value, list) else [value]
    if not all(n in _TYPES for n in names):
        return _never
    tests = [_TYPES[n] for n in names]
    return tests[0] if len(tests) == 1 else (lambda x: any(t(x) for t in tests))


def _objects(key: str, value: Any, schema: dict, numeric_array: NumericArray) -> Check | None:
    """The object keywords (``properties``, ``additionalProperties``, ``required``, ``minProperties``)."""
    if key == "properties":
        subs = [(k, compile_schema(s, numeric_array)) for k, s in value.items()]
        return lambda x: not isinstance(x, dict) or all(k not in x or f(x[k]) for k, f in subs)
    if key == "additionalProperties":
        if "patternProperties" in schema:
            return _never
        known = set(schema.get("properties", {}))
        if value is False:
            return lambda x: not isinstance(x, dict) or all(k in known for k in x)
        rest = compile_schema(value, numeric_array)
        return lambda x: not isinstance(x, dict) or all(k in known or rest(v) for k, v in x.items())
    if key == "required":
        return lambda x: not isinstance(x, dict) or all(r in x for r in value)
    if key == "minProperties":
        return lambda x: not isinstance(x, dict) or len(x) >= value
    return None


def _arrays(key: str, value: Any, schema: dict, numeric_array: NumericArray) -> Check | None:
    """The array keywords (``items``, ``minItems``, ``maxItems``)."""
    if key == "items":
        if "prefixItems" in schema:
            return _never
        each = compile_schema(value, numeric_array)
        return lambda x: not isinstance(x, list) or all(map(each, x))
    if key == "minItems":
        return lambda x: not isinstance(x, list) or len(x) >= value
    if key == "maxItems":
        return lambda x: not isinstance(x, list) or len(x) <= value
    return None


def _numbers(key: str, value: Any) -> Check | None:
    """The numeric keywords (``minimum``, ``maximum``, ``exclusiveMinimum``), as ``jsonschema`` compares."""
    if key == "minimum":
        return _bound(lambda x: not x < value)
    if key == "maximum":
        return _bound(lambda x: not x > value)
    if key == "exclusiveMinimum":
        return _bound(lambda x: not x <= value)
    return None


def _keyword(key: str, value: Any, schema: dict, numeric_array: NumericArray) -> Check:
    """The predicate of one keyword of ``schema``; ``_never`` for a keyword not known here."""
    if key == "type":
        return _type(value)
    for check in (_objects(key, value, schema, numeric_array), _arrays(key, value, schema, numeric_array),
                  _numbers(key, value)):
        if check is not None:
            return check
    if key == "enum":
        if not all(isinstance(v, str) for v in value):
            return _never
        names = set(value)
        return lambda x: isinstance(x, str) and x in names
    if key == "anyOf":
        alternatives = [compile_schema(s, numeric_array) for s in value]
        return lambda x: any(f(x) for f in alternatives)
    if key == "numeric_array" and numeric_array is not None:
        return numeric_array(value)
    return _never


def compile_schema(schema: Any, numeric_array: NumericArray = None) -> Check:
    """A predicate that is True only for an instance ``jsonschema`` finds valid against ``schema``.

    Args:
        schema: a JSON Schema (dicts, lists, booleans) of the keywords ``type``, ``properties``,
            ``additionalProperties``, ``required``, ``minProperties``, ``items``, ``minItems``, ``maxItems``,
            ``minimum``, ``maximum``, ``exclusiveMinimum``, ``enum`` (of strings), ``anyOf`` and ``numeric_array``;
            any other keyword makes its (sub)schema's predicate always False.
        numeric_array: the predicate maker of the ``numeric_array`` keyword (its spec -> predicate), or None
            (the keyword then always False).

    Returns:
        ``instance -> bool``; False means "ask jsonschema", not necessarily "invalid".
    """
    if schema is True:
        return _always
    if not isinstance(schema, dict):
        return _never
    checks = [_keyword(k, v, schema, numeric_array) for k, v in schema.items()]
    if _never in checks:
        return _never
    if not checks:
        return _always
    if len(checks) == 1:
        return checks[0]
    return lambda x: all(c(x) for c in checks)


def pruned(instance: Any, schema: Any, conforms: Callable[[Any, Any], bool]) -> Any:
    """``schema`` with the subschema of every property of ``instance`` that conforms replaced by ``True``,
    recursively through nested objects' ``properties`` (not into ``anyOf``, ``items`` or ``additionalProperties``:
    their errors are kept whole); the property names stay, so ``additionalProperties`` judges alike.

    Args:
        instance: the document (or a part of it).
        schema: its schema.
        conforms: ``(instance, subschema) -> bool``, True only where the subschema finds no error.

    Returns:
        A schema under which ``jsonschema`` finds the same errors of ``instance``, in the same order.
    """
    if not isinstance(instance, dict) or not isinstance(schema, dict) or "properties" not in schema:
        return schema
    props = {k: (s if k not in instance else True if conforms(instance[k], s) else pruned(instance[k], s, conforms))
             for k, s in schema["properties"].items()}
    return {k: (props if k == "properties" else v) for k, v in schema.items()}
