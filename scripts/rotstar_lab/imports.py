"""The package's import graph, read from its source: modules per folder, circles, what a command reaches

SYNOPSIS

    python scripts/rotstar_lab/imports.py rotstar_mrcal --from rotstar_mrcal.cli.detect rotstar_mrcal.cli.report

>>> import os
>>> mods, g = graph(os.path.join(os.path.dirname(__file__), "..", "..", "rotstar_mrcal"))
>>> circles(g)
[]
>>> "rotstar_mrcal.dataset" in reach(g, "rotstar_mrcal.cli.detect")
True

The graph is read with `ast` (nothing is imported): an edge for every import
at run time, at the top of a module or inside a function (`if TYPE_CHECKING:`
blocks left out), resolved to the longest module name it names; importing
a.b.c also imports the packages a and a.b. Names loaded lazily through
`rotstar_mrcal.lazy` (PEP 562) are edges only where some module imports them.
"""

from __future__ import annotations

import argparse
import ast
import collections
import os


def modules(pkgdir: str) -> dict[str, str]:
    """{dotted module name: path} of every .py file under pkgdir"""
    base = os.path.dirname(os.path.abspath(pkgdir))
    out = {}
    for dp, dn, fn in os.walk(os.path.abspath(pkgdir)):
        dn[:] = [d for d in dn if d != "__pycache__"]
        for f in fn:
            if f.endswith(".py"):
                name = os.path.relpath(os.path.join(dp, f), base)[:-3].replace(os.sep, ".")
                out[name.removesuffix(".__init__")] = os.path.join(dp, f)
    return out


def _named(node: ast.AST, pkg: str, mods: dict) -> list[tuple[str, bool]]:
    """[(imported name, at the top of the module)] under node"""
    out = []

    def visit(node, top):
        for ch in ast.iter_child_nodes(node):
            if isinstance(ch, ast.Import):
                out.extend((a.name, top) for a in ch.names)
            elif isinstance(ch, ast.ImportFrom):
                parts = pkg.split(".")
                base = ".".join(parts[: len(parts) - ch.level + 1] + [ch.module or ""]).strip(".") \
                    if ch.level else ch.module or ""
                out.extend(((f"{base}.{a.name}" if f"{base}.{a.name}" in mods else base), top) for a in ch.names)
            elif not (isinstance(ch, ast.If) and "TYPE_CHECKING" in ast.unparse(ch.test)):
                visit(ch, top and not isinstance(ch, (ast.FunctionDef, ast.AsyncFunctionDef)))

    visit(node, True)
    return out


def imports(mod: str, path: str, mods: dict) -> list[tuple[str, bool]]:
    """[(module of this package imported by mod, at the top of mod)]"""
    with open(path) as fh:
        tree = ast.parse(fh.read())
    pkg = mod if path.endswith("__init__.py") else mod.rsplit(".", 1)[0]
    out = []
    for name, top in _named(tree, pkg, mods):
        parts = name.split(".")
        while parts and ".".join(parts) not in mods:
            parts.pop()
        if parts and ".".join(parts) != mod:
            out.append((".".join(parts), top))
    return out


def graph(pkgdir: str) -> tuple[dict, dict[str, set]]:
    """(modules, {module: the modules importing it imports}), packages of an imported module included"""
    mods = modules(pkgdir)
    g = {m: set() for m in mods}
    for m, p in mods.items():
        for t, _ in imports(m, p, mods):
            parts = t.split(".")
            g[m].update(q for q in (".".join(parts[:i]) for i in range(1, len(parts) + 1)) if q in g and q != m)
    return mods, g


def reach(g: dict, start: str) -> set[str]:
    """Every module that importing start imports"""
    seen, todo = set(), [start]
    while todo:
        v = todo.pop()
        if v not in seen:
            seen.add(v)
            todo.extend(g[v])
    return seen


def circles(g: dict) -> list[list[str]]:
    """The groups of modules that import each other (strongly connected, more than one module), sorted"""
    groups, done = [], set()
    for v in sorted(g):
        if v in done:
            continue
        group = sorted(w for w in reach(g, v) if v in reach(g, w))
        done.update(group)
        if len(group) > 1:
            groups.append(group)
    return groups


def folder(m: str) -> str:
    return m.split(".")[1] if m.count(".") >= 2 else "(top)"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("pkgdir", help="the package's folder, e.g. rotstar_mrcal")
    ap.add_argument("--from", dest="starts", nargs="*", default=[], help="modules whose reach to print")
    a = ap.parse_args(argv)
    mods, g = graph(a.pkgdir)
    inner = sum(not top for m, p in mods.items() for _, top in imports(m, p, mods))
    print(f"modules: {len(mods)}, per folder: {dict(sorted(collections.Counter(map(folder, mods)).items()))}")
    print(f"imports inside functions: {inner}")
    cs = circles(g)
    print(f"circles: {len(cs)}" + "".join(f"\n  {c}" for c in cs))
    for s in a.starts:
        r = reach(g, s)
        print(f"reach of {s}: {len(r)} modules, {dict(sorted(collections.Counter(map(folder, r)).items()))}")
    return 1 if cs else 0


if __name__ == "__main__":
    raise SystemExit(main())
