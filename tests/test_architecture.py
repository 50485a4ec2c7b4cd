"""The package reads as its pipeline (docs/ARCHITECTURE.md): nothing upstream imports from downstream, no import
circle (lazy imports included), no module over 600 lines, no function over 80 lines, no private name reached across
modules, the check's modules asking the calibrated model through its view of the check rows."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from tests._cache_misc import (PARSED_GROUP, kept_out_of_collections, nodes, parsed, release_after_last_reader,
                               walk)

#: Upstream to downstream, as drawn in docs/ARCHITECTURE.md.
ORDER = ["errors", "progress", "threads", "validation", "data", "results", "model", "effects", "discrepancy", "oed",
         "cell", "simulation", "design", "program", "calibrated", "identification", "compensation", "upkeep",
         "diagnosis", "studies", "viz", "report", "cli"]
PKG = Path(__file__).resolve().parents[1] / "pin_kpi_oed"


#: the tests that read the parsed sources: on one xdist worker, so that each file is parsed once (tests/_cache_misc.py)
shares_trees = pytest.mark.xdist_group(PARSED_GROUP)


@pytest.fixture(scope="module", autouse=True)
def _trees_dropped_after_the_last_reader(request):
    """The package's trees are kept while this module's tests read them, and dropped after its last test unless a
    later module of the session reads them too (tests/test_route_count.py, which then drops them): kept, they made
    every garbage collection of the tests that came after walk their 400,000 objects."""
    yield
    _IMPORTS.clear()
    release_after_last_reader(request)


def _tree(f: Path) -> ast.Module:
    """The parsed source of ``f``, parsed once for all the tests of the session (they only read the trees)."""
    return parsed(f.resolve())


#: id of a tree -> (the tree, kept alive so that its id names it alone; its import statements, each with whether it
#: sits under ``if TYPE_CHECKING:``)
_IMPORTS: dict[int, tuple[ast.AST, list[tuple[ast.Import | ast.ImportFrom, bool]]]] = {}


def _imports(tree: ast.AST) -> list[tuple[ast.Import | ast.ImportFrom, bool]]:
    """Every import statement of ``tree`` in ``ast.walk`` order, with whether it is inside the body of an
    ``if TYPE_CHECKING:`` (listed once per tree: the rules below read them several times)."""
    hit = _IMPORTS.get(id(tree))
    if hit is None or hit[0] is not tree:
        typing_only = {id(n) for node in nodes(tree) if isinstance(node, ast.If)
                       and "TYPE_CHECKING" in ast.unparse(node.test) for b in node.body for n in ast.walk(b)}
        hit = _IMPORTS[id(tree)] = (tree, [(n, id(n) in typing_only) for n in nodes(tree)
                                           if isinstance(n, (ast.Import, ast.ImportFrom))])
    return hit[1]


def _runtime_imports(tree: ast.AST):
    """(line, module) of every pin_kpi_oed import, lazy ones included, except under ``if TYPE_CHECKING:``."""
    for node, typing_only in _imports(tree):
        if typing_only:
            continue
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("pin_kpi_oed."):
            yield node.lineno, node.module
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("pin_kpi_oed."):
                    yield node.lineno, a.name


@shares_trees
def test_nothing_upstream_imports_downstream() -> None:
    rank = {name: i for i, name in enumerate(ORDER)}
    tops = {p.stem if p.is_file() else p.name for p in PKG.iterdir() if not p.name.startswith(("_", "."))}
    assert tops - {"cells"} <= set(rank) | {"py"}, f"a top-level module missing from ORDER: {sorted(tops - set(rank))}"
    bad = []
    for f in PKG.rglob("*.py"):
        top = f.relative_to(PKG).with_suffix("").parts[0]
        if top not in rank:
            continue
        for line, mod in _runtime_imports(_tree(f)):
            other = mod.split(".")[1]
            if other in rank and rank[other] > rank[top]:
                bad.append(f"{f.relative_to(PKG)}:{line} ({top}) imports {mod}")
    assert not bad, "upstream imports downstream:\n" + "\n".join(bad)


#: Largest module (lines) and function (lines, decorators excluded, docstring included).
MAX_MODULE_LINES = 600
MAX_FUNCTION_LINES = 80


def _module_name(f: Path) -> str:
    parts = f.relative_to(PKG.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _import_graph(typing_too: bool = False) -> dict[str, set[str]]:
    """Module -> the pin_kpi_oed modules it imports at run time (lazy imports included, ``if TYPE_CHECKING:``
    only with ``typing_too``; ``from pkg import module`` resolved)."""
    files = {_module_name(f): f for f in PKG.rglob("*.py")}
    graph: dict[str, set[str]] = {m: set() for m in files}
    for m, f in files.items():
        for node, typing_only in _imports(_tree(f)):
            if typing_only and not typing_too:
                continue
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("pin_kpi_oed"):
                targets = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            else:
                continue
            # a package's __init__ is not an edge: importing pkg.mod runs it, but it holds no cycle by itself
            graph[m].update(t for t in targets if t in files and t != m and files[t].name != "__init__.py")
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_cycle_finder_finds_a_circle_through_a_lazy_import() -> None:
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []
    tree = ast.parse("def f():\n    from pin_kpi_oed.cell.cell import Cell\n")
    assert [m for _, m in _runtime_imports(tree)] == ["pin_kpi_oed.cell.cell"]


@shares_trees
def test_no_import_circle() -> None:
    circles = _cycles(_import_graph())
    assert not circles, "import circles (lazy imports included):\n" + "\n".join(" <-> ".join(c) for c in circles)


@shares_trees
def test_no_circle_inside_a_folder_not_even_for_typing() -> None:
    """A type and the functions on it live in one place: no two modules of a folder name each other, not even in
    an ``if TYPE_CHECKING:`` import (a lower module states what it reads as a Protocol instead)."""
    graph = _import_graph(typing_too=True)
    folder = {m: m.rsplit(".", 1)[0] for m in graph}
    inside = {m: {w for w in ws if folder[w] == folder[m]} for m, ws in graph.items()}
    circles = _cycles(inside)
    assert not circles, "circles inside a folder:\n" + "\n".join(" <-> ".join(c) for c in circles)


@shares_trees
def test_no_module_over_600_lines_and_no_function_over_80() -> None:
    long_modules, long_functions = [], []
    for f in sorted(PKG.rglob("*.py")):
        text = f.read_text()
        n = len(text.splitlines())
        if n > MAX_MODULE_LINES:
            long_modules.append(f"{f.relative_to(PKG)}: {n} lines")
        for node in nodes(_tree(f)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                length = node.end_lineno - node.lineno + 1
                if length > MAX_FUNCTION_LINES:
                    long_functions.append(f"{f.relative_to(PKG)}:{node.lineno} {node.name}: {length} lines")
    assert not long_modules, f"modules over {MAX_MODULE_LINES} lines: " + "; ".join(long_modules)
    assert not long_functions, f"functions over {MAX_FUNCTION_LINES} lines: " + "; ".join(long_functions)


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _annotation_nodes(every) -> set[int]:
    """ids of the nodes inside annotations (arguments, returns, annotated assignments) among a tree's nodes
    ``every``: typing may name a library's private class (``argparse._SubParsersAction``), the code may not use it."""
    out: set[int] = set()
    for node in every:
        anns: list[ast.AST | None] = []
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            a = node.args
            anns = [x.annotation for x in a.posonlyargs + a.args + a.kwonlyargs] + [node.returns]
            anns += [a.vararg.annotation if a.vararg else None, a.kwarg.annotation if a.kwarg else None]
        elif isinstance(node, ast.AnnAssign):
            anns = [node.annotation]
        out.update(id(n) for ann in anns if ann is not None for n in ast.walk(ann))
    return out


#: Standard-library names with a leading underscore that are public, documented API: ``os._exit`` (leave the process
#: without the interpreter's exit path; the command line's entry after an interrupt).
PUBLIC_UNDERSCORE = {"os._exit"}


def _private_reaches(tree: ast.AST, listed=nodes) -> list[tuple[int, str]]:
    """(line, text) of every private name imported from another module (``from m import _x``, ``m._x``) and every
    private attribute read on an object other than ``self`` / ``cls`` (``problem._kpi``); ``listed`` lists a tree's
    nodes (:func:`~tests._cache_misc.nodes`: listed once and kept; :func:`~tests._cache_misc.walk`: not kept)."""
    every = listed(tree)
    reach = [node for node in every if isinstance(node, ast.ImportFrom) or isinstance(node, ast.Attribute)
             and _private(node.attr) and not (isinstance(node.value, ast.Name) and node.value.id in ("self", "cls"))]
    # the annotations' nodes listed only when a private attribute was read (most trees read none)
    skip = _annotation_nodes(every) if any(isinstance(n, ast.Attribute) for n in reach) else set()
    out = []
    for node in reach:
        if isinstance(node, ast.ImportFrom):
            out += [(node.lineno, f"from {node.module} import {a.name}") for a in node.names if _private(a.name)]
        elif id(node) not in skip and ast.unparse(node) not in PUBLIC_UNDERSCORE:
            out.append((node.lineno, ast.unparse(node)))
    return out


def test_private_finder_sees_imports_and_attributes() -> None:
    tree = ast.parse("from pin_kpi_oed.a import _x, y\nimport argparse\n"
                     "def f(p: argparse._SubParsersAction, q) -> None:\n    self._ok = q._bad + argparse._Act\n")
    assert [t for _, t in _private_reaches(tree)] == ["from pin_kpi_oed.a import _x", "q._bad", "argparse._Act"]


@shares_trees
def test_no_private_name_across_modules() -> None:
    bad = [f"{f.relative_to(PKG)}:{line} {text}" for f in sorted(PKG.rglob("*.py"))
           for line, text in _private_reaches(_tree(f))]
    assert not bad, "private names reached across modules:\n" + "\n".join(bad)


def test_benchmarks_and_examples_use_the_public_api() -> None:
    """The benchmarks and examples are users of the package: they import no private name of it and read no private
    attribute (what they need is public, documented API)."""
    root = PKG.parent
    with kept_out_of_collections():  # each tree dropped after its file: no other test reads them
        bad = [f"{f.relative_to(root)}:{line} {text}" for d in ("benchmarks", "examples")
               for f in sorted((root / d).rglob("*.py"))
               for line, text in _private_reaches(ast.parse(f.read_text()), walk)]
    assert not bad, "private names used by benchmarks / examples:\n" + "\n".join(bad)


def _statements(tree: ast.AST) -> list[ast.AST]:
    """Every statement of ``tree`` (and the module, exception handlers and match cases holding them), found without
    entering an expression: a statement (an import among them) sits only in a statement list — a body, ``orelse``,
    ``finalbody``, ``handlers``, ``cases`` —, never inside an expression; a tree's expressions are most of its nodes."""
    out: list[ast.AST] = [tree]
    holders = (ast.stmt, ast.excepthandler, ast.match_case)
    for node in out:  # the list grows while it is read
        for name in node._fields:
            value = getattr(node, name, None)
            if isinstance(value, list):
                out.extend(x for x in value if isinstance(x, holders))
    return out


def test_statement_walk_finds_every_import_the_full_walk_finds() -> None:
    tree = ast.parse("import a\nfrom b import _c\nclass K:\n    from d import e\n    def f(self):\n"
                     "        try:\n            from g import h\n        except ImportError:\n            import i\n"
                     "        else:\n            from j import k\n        finally:\n            import m\n"
                     "        match x:\n            case 1:\n                from n import _o\n"
                     "        with p:\n            for q in r:\n                while s:\n"
                     "                    if t:\n                        import u\n"
                     "                    else:\n                        from v import w\n"
                     "async def y():\n    async with z:\n        import aa\n")
    imports = (ast.Import, ast.ImportFrom)
    full = [n for n in ast.walk(tree) if isinstance(n, imports)]
    assert len(full) == 11 and {id(n) for n in _statements(tree) if isinstance(n, imports)} == {id(n) for n in full}
    this = _tree(Path(__file__))
    assert {id(n) for n in _statements(this) if isinstance(n, imports)} == \
        {id(n) for n in nodes(this) if isinstance(n, imports)}


def test_tests_import_no_private_name_of_the_package() -> None:
    """A test imports what it tests by its public name: no ``from pin_kpi_oed... import _x`` anywhere in tests/
    (an import is a statement: the statements are walked, not the expressions, :func:`_statements`)."""
    root = PKG.parent
    with kept_out_of_collections():  # each tree dropped after its file: no other test reads them
        bad = [f"{f.relative_to(root)}:{node.lineno} from {node.module} import {a.name}"
               for f in sorted((root / "tests").rglob("*.py")) for node in _statements(ast.parse(f.read_text()))
               if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("pin_kpi_oed")
               for a in node.names if _private(a.name)]
    assert not bad, "private names of the package imported by tests:\n" + "\n".join(bad)


#: The check's own modules and what each may import of the layers it asks questions of: the calibrated model through
#: its view of the check rows (and the model's type), the fit only through the registration of a set-up.
CHECK_MODULES = ("upkeep/check.py", "upkeep/check_rows.py", "upkeep/check_poses.py", "upkeep/check_stats.py")
CHECK_MAY_IMPORT = {"pin_kpi_oed.calibrated.model_file", "pin_kpi_oed.calibrated.check_view",
                    "pin_kpi_oed.upkeep.transfer"}


def _check_route_imports(tree: ast.AST) -> set[str]:
    """The calibrated, identification and upkeep modules outside the check that a module imports (lazy included)."""
    check = {"pin_kpi_oed." + m.removesuffix(".py").replace("/", ".") for m in CHECK_MODULES}
    return {mod for _, mod in _runtime_imports(tree)
            if mod.split(".")[1] in ("calibrated", "identification", "upkeep") and mod not in check}


def test_check_route_finder_sees_a_lazy_import_of_the_sigma() -> None:
    tree = ast.parse("from pin_kpi_oed.calibrated.check_view import check_view\n"
                     "def f():\n    from pin_kpi_oed.calibrated.prediction_sigma import predictive_covariance\n")
    assert _check_route_imports(tree) - CHECK_MAY_IMPORT == {"pin_kpi_oed.calibrated.prediction_sigma"}


@shares_trees
def test_the_check_asks_the_calibrated_model_through_its_view() -> None:
    """The check calls down once per question: what the model says on the rows (``calibrated/check_view.py``) and
    the registration of a set-up (``upkeep/transfer.py``); none of its modules reaches into the model's σ, its TCP σ
    or the fit's residual model by itself (that weave is what the view replaced)."""
    bad = {m: sorted(_check_route_imports(_tree(PKG / m)) - CHECK_MAY_IMPORT) for m in CHECK_MODULES}
    assert not any(bad.values()), f"the check reaches past its questions: {bad}"
