"""The package reads as its pipeline: nothing upstream imports from downstream (docs/ARCHITECTURE.md)."""

from __future__ import annotations

import ast
from pathlib import Path

#: Upstream to downstream, as drawn in docs/ARCHITECTURE.md.
ORDER = ["errors", "progress", "threads", "validation", "data", "results", "model", "effects", "discrepancy", "oed", "cell", "design",
         "program", "identification", "diagnosis", "studies", "viz", "cli"]
PKG = Path(__file__).resolve().parents[1] / "pin_kpi_oed"


def _runtime_imports(tree: ast.AST):
    """(line, module) of every pin_kpi_oed import, lazy ones included, except under ``if TYPE_CHECKING:``."""
    skip: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            skip.update(id(n) for b in node.body for n in ast.walk(b))
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("pin_kpi_oed."):
            yield node.lineno, node.module
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("pin_kpi_oed."):
                    yield node.lineno, a.name


def test_nothing_upstream_imports_downstream() -> None:
    rank = {name: i for i, name in enumerate(ORDER)}
    tops = {p.stem if p.is_file() else p.name for p in PKG.iterdir() if not p.name.startswith(("_", "."))}
    assert tops - {"cells"} <= set(rank) | {"py"}, f"a top-level module missing from ORDER: {sorted(tops - set(rank))}"
    bad = []
    for f in PKG.rglob("*.py"):
        top = f.relative_to(PKG).with_suffix("").parts[0]
        if top not in rank:
            continue
        for line, mod in _runtime_imports(ast.parse(f.read_text())):
            other = mod.split(".")[1]
            if other in rank and rank[other] > rank[top]:
                bad.append(f"{f.relative_to(PKG)}:{line} ({top}) imports {mod}")
    assert not bad, "upstream imports downstream:\n" + "\n".join(bad)
