"""Caches shared by the architecture and route tests (tests/test_architecture.py, tests/test_route_count.py): each
source file parsed once per test process, and each tree's nodes listed once (the tests only read them), until
:func:`release` drops them (the package's trees are about 400,000 objects: while they are kept, every full garbage
collection of the process walks them, which made the tests run after them a tenth to a third slower).

Their tests that read the package's trees are marked ``xdist_group("misc_parsed_sources")``: on one worker, the
package is parsed once for all of them.
"""

from __future__ import annotations

import ast
import contextlib
import functools
import gc
from collections.abc import Iterator
from pathlib import Path
from typing import Any

#: the xdist group of the tests that read the package's parsed source
PARSED_GROUP = "misc_parsed_sources"


@contextlib.contextmanager
def kept_out_of_collections() -> Iterator[None]:
    """No garbage collection while a tree is made: a parse allocates many objects at once, and each pass of the
    collector inside it would scan every tree parsed so far. Nothing is frozen (``gc.freeze`` would also keep the
    unreachable cycles other tests of the process left, e.g. OMPL's objects, which nanobind then reports as leaked
    at exit)."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


@functools.cache
def parsed(path: Path) -> ast.Module:
    """The parsed source of the file ``path`` (an absolute path; parsed on the first call only)."""
    text = Path(path).read_text()
    with kept_out_of_collections():
        return ast.parse(text)


#: id of a tree -> (the tree, kept alive so that its id names it alone; its nodes in ``ast.walk`` order)
_NODES: dict[int, tuple[ast.AST, tuple[ast.AST, ...]]] = {}


def walk(tree: ast.AST) -> list[ast.AST]:
    """Every node of ``tree`` in the order of ``ast.walk`` (breadth first, each node's children in the order of
    ``ast.iter_child_nodes``), listed by one loop over the nodes' fields instead of ``ast.walk``'s three nested
    generators (half the time on the package's trees)."""
    out: list[ast.AST] = [tree]
    AST = ast.AST
    for node in out:  # the list grows while it is read: breadth first
        for name in node._fields:
            value = getattr(node, name, None)
            if isinstance(value, AST):
                out.append(value)
            elif isinstance(value, list):
                out.extend(x for x in value if isinstance(x, AST))
    return out


def nodes(tree: ast.AST) -> tuple[ast.AST, ...]:
    """Every node of ``tree`` in ``ast.walk`` order (:func:`walk`), listed on the first call for that tree."""
    hit = _NODES.get(id(tree))
    if hit is None or hit[0] is not tree:
        with kept_out_of_collections():
            hit = _NODES[id(tree)] = (tree, tuple(walk(tree)))
    return hit[1]


def release() -> None:
    """Drop every tree :func:`parsed` kept and every node list :func:`nodes` kept (a later call parses again)."""
    parsed.cache_clear()
    _NODES.clear()


def read_later(request: Any) -> bool:
    """Whether a test of another module that reads the package's trees (marked ``xdist_group(PARSED_GROUP)``) comes
    after the module of ``request`` in this session's order: the group's tests run on one worker, in that order."""
    items = request.session.items
    here = [i for i, item in enumerate(items) if getattr(item, "module", None) is request.module]
    return any(getattr(item, "module", None) is not request.module and any(m.args[:1] == (PARSED_GROUP,)
                                                          for m in item.iter_markers("xdist_group"))
               for item in items[max(here) + 1:] if here)


def release_after_last_reader(request: Any) -> None:
    """:func:`release` at the end of the module of ``request`` unless a later module reads the trees
    (:func:`read_later`): the last module of the group drops them, the others hand them on."""
    if not read_later(request):
        release()
