"""Lazy re-exports for the package's ``__init__`` files: a name is imported on first use.

``import pin_kpi_oed`` stays as cheap as the robot model it needs; ``pin_kpi_oed.identify``
imports the identification modules (SciPy, ...) only when it is first looked up.
"""

from __future__ import annotations

import importlib
from typing import Any
from collections.abc import Callable


def lazy_exports(namespace: dict[str, Any], exports: dict[str, str]) -> tuple[Callable[[str], Any], Callable[[], list]]:
    """``(__getattr__, __dir__)`` of a package that re-exports ``exports`` = {name: module} lazily.

    Args:
        namespace: the package's ``globals()`` (a looked-up name is cached there).
        exports: public name -> absolute module path that defines it.
    """
    package = namespace["__name__"]

    def __getattr__(name: str) -> Any:
        try:
            where = exports[name]
        except KeyError:
            raise AttributeError(f"module '{package}' has no attribute '{name}'") from None
        value = getattr(importlib.import_module(where), name)
        namespace[name] = value
        return value

    def __dir__() -> list:
        return sorted(set(namespace) | set(exports))

    return __getattr__, __dir__
