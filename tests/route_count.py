"""The calibrated model's route through ``check_calibration``: the files it enters and the climbs back up.

``python -m tests.route_count [ROOT]`` (ROOT: a checkout, default this one) prints the route, files and climbs. It
reads the source with ``ast`` (nothing is imported or run) from ``check_calibration``'s parameter ``model`` and follows
the model: a name holding it (``CalibratedModel``), a part of it (``model.robot``) or a container holding it (a class
with a field of either, such as ``CheckRows``: a container does not hide the model), bound through assignments,
return annotations and parameters. A call is followed when an argument or the receiver carries the model and the
callee is a function or method of the package (a class instantiated is not followed into). The bodies of the check's
own modules (``upkeep/check*.py``) are read, in source order, every branch; any other file is entered once per call
(a question, answered there). A climb: control back from a called file in a caller that then calls out again.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

from tests._cache_misc import nodes, parsed

MODEL = "CalibratedModel"
START = ("pin_kpi_oed.upkeep.check", "check_calibration", "model")
BLOCKS = ("body", "orelse", "finalbody", "handlers")
NONE: tuple[str | None, str | None] = (None, None)


class Route:
    """The walk over the modules of one checkout (module docstring)."""

    def __init__(self, root: Path) -> None:
        self.mods = {".".join(f.relative_to(root).with_suffix("").parts).removesuffix(".__init__"):
                     parsed(f.resolve()) for f in sorted((root / "pin_kpi_oed").rglob("*.py"))}
        self.funcs = {(m, n.name): n for m, t in self.mods.items() for n in t.body if isinstance(n, ast.FunctionDef)}
        self.classes = {n.name: (m, n) for m, t in self.mods.items() for n in t.body if isinstance(n, ast.ClassDef)}
        self.imports = {m: {a.asname or a.name: (i.module, a.name) for i in nodes(t)
                            if isinstance(i, ast.ImportFrom) and (i.module or "").startswith("pin_kpi_oed")
                            for a in i.names} for m, t in self.mods.items()}
        self.fields = {c: {s.target.id: self.cls(s.annotation) for s in n.body
                           if isinstance(s, ast.AnnAssign) and isinstance(s.target, ast.Name)}
                       for c, (_, n) in self.classes.items()}
        self.boxes, self.events = set(), []      # events: (module, "call" / "return")
        while more := {c for c, f in self.fields.items() if {MODEL, *self.boxes} & set(f.values())} - self.boxes:
            self.boxes |= more          # a class holding the model, or holding a class that holds it

    def cls(self, ann: ast.expr | None) -> str | None:
        """The first class of the package an annotation names (``X | None``: X; a string annotation too), or None."""
        names = [getattr(n, "id", None) or getattr(n, "value", None) for n in ast.walk(ann)] if ann else []
        return next((n for n in names if isinstance(n, str) and n in self.classes), None)

    def kind(self, c: str | None) -> tuple[str | None, str | None]:     # (class, carries) of a value of class c
        return c, "model" if c == MODEL else "box" if c in self.boxes else None

    def info(self, e: ast.expr, env: dict) -> tuple[str | None, str | None]:
        """(class, carries) of an expression; carries: "model" (the model or a part of it), "box" (holds it), None."""
        if isinstance(e, ast.Name):
            return env.get(e.id, NONE)
        if isinstance(e, ast.Attribute):
            c, k = self.info(e.value, env)
            f = self.fields.get(c or "", {}).get(e.attr)
            return (f, "model") if k == "model" else self.kind(f) if k == "box" else NONE
        parts = [e.body, e.orelse] if isinstance(e, ast.IfExp) else getattr(e, "elts", [])
        if parts:
            return next((i for i in (self.info(x, env) for x in parts) if i[1]), NONE)
        if isinstance(e, ast.Call) and isinstance(e.func, ast.Name) and e.func.id in self.classes:
            return self.kind(e.func.id)             # a class instantiated: holds the model if it is a container
        if isinstance(e, ast.Call) and (t := self.callee(e, env)) is not None:
            return self.kind(self.cls(t[1].returns))
        return NONE

    def callee(self, call: ast.Call, env: dict) -> tuple[str, ast.FunctionDef] | None:
        """(module, definition) of the package function or method a call runs, or None."""
        f, mod = call.func, env["__module__"]
        if isinstance(f, ast.Name):
            where, name = (mod, f.id) if (mod, f.id) in self.funcs else self.imports[mod].get(f.id, ("", ""))
            return (where, self.funcs[(where, name)]) if (where, name) in self.funcs else None
        if isinstance(f, ast.Attribute) and (c := self.info(f.value, env)[0]) in self.classes:
            m, node = self.classes[c]
            return next(((m, n) for n in node.body if isinstance(n, ast.FunctionDef) and n.name == f.attr), None)
        return None

    def walk(self, mod: str, fn: ast.FunctionDef, env: dict, stack: tuple = ()) -> None:
        env = {**env, "__module__": mod}
        for s in self.statements(fn.body):
            for call in self.calls(s):
                self.follow(mod, call, env, stack + (fn.name,))
            value = getattr(s, "value", None) if isinstance(s, (ast.Assign, ast.AnnAssign)) else None
            for t in (getattr(s, "targets", None) or [getattr(s, "target", None)]) if value is not None else []:
                if isinstance(t, ast.Name):
                    env[t.id] = self.info(value, env)
                elif isinstance(t, ast.Tuple) and isinstance(value, ast.Call) and (c := self.callee(value, env)):
                    ret = getattr(c[1].returns, "slice", None)   # tuple[A, B] unpacked
                    for x, a in zip(t.elts, ret.elts if isinstance(ret, ast.Tuple) else []):
                        env[getattr(x, "id", "")] = self.kind(self.cls(a))

    def follow(self, mod: str, call: ast.Call, env: dict, stack: tuple) -> None:
        args = [*call.args, *(k.value for k in call.keywords)]
        recv = [call.func.value] if isinstance(call.func, ast.Attribute) else []
        if not any(self.info(a, env)[1] for a in args + recv) or (t := self.callee(call, env)) is None:
            return
        where, fn = t
        self.events.append((where, "call"))
        if where.startswith(START[0]) and fn.name not in stack:
            params = [*fn.args.posonlyargs, *fn.args.args, *fn.args.kwonlyargs][1 if recv else 0:]
            inner = {"self": self.info(recv[0], env)} if recv else {}
            for p, a in [*zip(params, call.args), *((p, k.value) for k in call.keywords for p in params
                                                     if p.arg == k.arg)]:
                own = self.kind(self.cls(p.annotation))
                inner[p.arg] = own if own[1] else self.info(a, env)
            self.walk(where, fn, inner, stack)
        self.events.append((mod, "return"))

    @staticmethod
    def statements(body: list) -> list:
        """Every statement of a body in source order, those of nested blocks after their head (no nested defs)."""
        out = []
        for s in body:
            if not isinstance(s, (ast.FunctionDef, ast.ClassDef)):
                out += [s, *(x for f in BLOCKS for x in Route.statements(getattr(s, f, None) or []))]
        return out

    @staticmethod
    def calls(s: ast.stmt) -> list[ast.Call]:
        """The calls of a statement's own expressions (not of its nested blocks), inner ones first."""
        nested, out = {id(x) for f in BLOCKS for x in getattr(s, f, None) or []}, []

        def visit(n: ast.AST) -> None:
            for c in ast.iter_child_nodes(n):
                if id(c) not in nested and not isinstance(c, (ast.Lambda, ast.FunctionDef)):
                    visit(c)
            if isinstance(n, ast.Call):
                out.append(n)
        visit(s)
        return out


def route(root: Path) -> tuple[list[str], int]:
    """The modules of the route in call order (consecutive steps in one file merged) and the number of climbs."""
    r = Route(root)
    mod, name, param = START
    r.walk(mod, r.funcs[(mod, name)], {param: (MODEL, "model")})
    steps = [(mod, "start")]
    for e in r.events:
        if e[0] != steps[-1][0]:
            steps.append(e)
    climbs = sum(a[1] == "return" and b[1] == "call" for a, b in zip(steps, steps[1:]))
    return [s[0].removeprefix("pin_kpi_oed.") for s in steps], climbs


if __name__ == "__main__":
    files, climbs = route(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parents[1])
    print(" -> ".join(files), f"files entered: {len(set(files))}; climbs back up: {climbs}", sep="\n")
