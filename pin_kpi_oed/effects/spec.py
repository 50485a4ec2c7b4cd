"""Effects as plain data, for the model file: :func:`effect_spec` describes an effect (its registry name and
``options()``, a :class:`~pin_kpi_oed.effects.base.SubsetEffect` as its base and the kept parameters, a
:class:`~pin_kpi_oed.effects.joint_angle.JointAngleTable` with its knots in rad) and :func:`effect_from_spec` rebuilds
it, checking that the parameter names are the stored ones."""

from __future__ import annotations

from typing import Any
from collections.abc import Sequence

import numpy as np

from pin_kpi_oed.data.atomic import to_jsonable
from pin_kpi_oed.effects.library import ALL_EFFECT_NAMES, JointAngleTable, SubsetEffect, effect_class
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.robot import Robot

__all__ = ["effect_spec", "effect_from_spec"]


def _joint_names(effect: Any, idx: Sequence[int] | np.ndarray) -> list[str]:
    return [effect.robot.joint_names[int(j)] for j in idx]


def _known_class(name: Any) -> Any:
    """The registered effect class of ``name`` (default or opt-in), or None."""
    if str(name) not in ALL_EFFECT_NAMES:
        return None
    return effect_class(str(name))


def effect_spec(effect: Any) -> dict:
    """Plain description of an effect from which :func:`effect_from_spec` rebuilds it.

    Raises:
        InputError: the effect is not of the library and has no ``options()``.
    """
    if isinstance(effect, SubsetEffect):
        return {"name": effect.name, "kind": "subset", "base": effect_spec(effect.base),
                "keep": [int(k) for k in effect.keep], "param_names": list(effect.param_names())}
    if isinstance(effect, JointAngleTable):
        opts = {"joints": _joint_names(effect, effect.joints), "knots": [np.asarray(k, float) for k in effect.knots]}
        return {"name": effect.name, "kind": "joint_angle_table", "options": to_jsonable(opts),
                "param_names": list(effect.param_names())}
    name = getattr(effect, "name", type(effect).__name__)
    cls = _known_class(name)
    if callable(getattr(effect, "options", None)) and cls is not None and isinstance(effect, cls):
        opts = effect.options()
    else:
        raise InputError(f"effect '{name}' ({type(effect).__name__}) cannot be stored in a model file: it is not an "
                         "effect of pin_kpi_oed.effects.library (or has no options() method)")
    return {"name": name, "kind": name, "options": to_jsonable(opts), "param_names": list(effect.param_names())}


def effect_from_spec(spec: dict, robot: Robot, where: str = "model file") -> Any:
    """Rebuild an effect from :func:`effect_spec` output (its parameter names are checked).

    Raises:
        InputError: an unknown kind, bad options, or parameter names that differ from the stored ones.
    """
    kind = spec.get("kind")
    eff: Any
    try:
        if kind == "subset":
            eff = SubsetEffect(effect_from_spec(spec["base"], robot, where), [int(k) for k in spec["keep"]])
        elif kind == "joint_angle_table":
            o = spec["options"]
            knots = [np.asarray(k, float) for k in o["knots"]]
            eff = JointAngleTable(robot, o["joints"], [k[0] for k in knots], [k[-1] for k in knots],
                                  step_rad=max(min(float(k[1] - k[0]) for k in knots), 1e-12))
            eff.knots = knots
        elif _known_class(kind) is not None:
            opts = dict(spec.get("options") or {})
            for key in ("pairs", "terms"):  # JSON lists back to the tuples the constructors take
                if opts.get(key) is not None:
                    opts[key] = [tuple(t) for t in opts[key]]
            eff = _known_class(kind)(robot, **opts)
        else:
            raise InputError(f"{where}: effect '{spec.get('name')}': unknown kind '{kind}' (known: "
                             f"{', '.join(list(ALL_EFFECT_NAMES) + ['joint_angle_table', 'subset'])})")
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise InputError(f"{where}: effect '{spec.get('name')}': bad options ({exc})") from None
    names = list(eff.param_names())
    if "param_names" in spec and names != list(spec["param_names"]):
        raise InputError(f"{where}: effect '{spec.get('name')}' rebuilt with parameters {names[:3]}... but the file "
                         f"lists {list(spec['param_names'])[:3]}...; the file does not match this version")
    return eff
