"""The import directions of docs/architecture.md, checked on the source.

Every ``rve`` subpackage may import only the layers the table in docs/architecture.md
allows (module-level and function-level imports alike, found by parsing the source, so a
lazy import that climbs a layer fails too). The one declared exception is the scene
registry: ``rve.config`` looks up a scene's config model there (a data-only module).
Inside a package no two modules import each other, directly or through others (an import
cycle works only by the order of lazy imports). Comments and docstrings give reasons, not
dates: no issue or round numbers and none of the dating phrases of ``DATED`` in ``rve/``,
``workflow/``, ``tests/`` and the Snakefile.
"""
from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1] / "rve"

#: package -> the rve packages it may import (docs/architecture.md, "Layers")
ALLOWED = {
    "__init__": {"process"},
    "io": set(),
    "analytic": set(),
    "fem": {"kernels"},
    "physics": {"fem"},
    "contact": {"fem", "physics"},
    "model": {"fem", "physics", "contact", "kernels"},
    "solvers": {"threads", "kernels"},
    "testing": {"fem"},
    "config": {"io"},
    "fabrics": {"io", "fem", "physics", "contact", "model", "solvers", "config"},
    "scenes": {"io", "analytic", "fem", "physics", "contact", "model", "solvers", "config", "fabrics"},
    "homogenisation": {"io", "fem", "physics", "contact", "model", "solvers", "config", "fabrics"},
    "tables": {"io", "config", "fabrics", "homogenisation"},
    "studies": {"io", "config", "scenes", "analytic"},
    "kernels": {"threads"},
    "threads": set(),
    "process": set(),
    "cli": None,  # the top: anything
}

#: (importing package, imported module) pairs allowed against the table, with the reason
EXCEPTIONS = {
    ("config", "rve.scenes.registry"): "the loader asks the one registry for a scene's config model",
}


def _imports(path: Path):
    """Absolute names of the rve modules imported anywhere in ``path``."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    pkg = list(path.relative_to(ROOT.parent).with_suffix("").parts)[:-1]  # the package the module is in
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = pkg[: len(pkg) - (node.level - 1)]
                full = base + (node.module.split(".") if node.module else [])
            else:
                full = (node.module or "").split(".")
            if full[:1] == ["rve"]:
                names = [".".join(full)]
                if not node.module or node.level:  # "from . import x": x may be a module
                    names += [".".join(full + [a.name]) for a in node.names]
                yield from names
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == "rve":
                    yield a.name


def _package(path: Path) -> str:
    rel = path.relative_to(ROOT)
    return rel.parts[0].removesuffix(".py")


FILES = sorted(ROOT.rglob("*.py"))


@pytest.mark.parametrize("path", FILES, ids=[str(p.relative_to(ROOT)) for p in FILES])
def test_imports_follow_the_layers(path):
    src = _package(path)
    assert src in ALLOWED, f"package rve.{src} is not in docs/architecture.md's layer table"
    allowed = ALLOWED[src]
    if allowed is None:
        return
    bad = []
    for name in _imports(path):
        parts = name.split(".")
        if len(parts) < 2 or parts[1] == src:
            continue
        if parts[1] in allowed or (src, ".".join(parts[:3])) in EXCEPTIONS:
            continue
        bad.append(name)
    assert not bad, f"{path.relative_to(ROOT.parent)} (rve.{src}) imports {sorted(set(bad))}: not allowed by docs/architecture.md"


def test_every_package_init_declares_its_api():
    """Thin ``__init__.py`` files with an explicit ``__all__`` (or a docstring saying the
    package has no re-exports)."""
    for init in sorted(ROOT.rglob("__init__.py")):
        tree = ast.parse(init.read_text(encoding="utf-8"))
        doc = ast.get_docstring(tree)
        has_all = any(isinstance(n, ast.Assign) and any(getattr(t, "id", None) == "__all__" for t in n.targets)
                      for n in tree.body)
        assert doc, f"{init.relative_to(ROOT.parent)} has no docstring"
        assert has_all, f"{init.relative_to(ROOT.parent)} has no __all__"


def _module_graph() -> dict:
    """rve module -> the rve modules it imports (anywhere in its source), package
    ``__init__`` edges from the package's own modules left out (they re-export)."""
    mods = {}
    for path in FILES:
        parts = path.relative_to(ROOT.parent).with_suffix("").parts
        mods[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    graph = {}
    for name, path in mods.items():
        edges = set()
        for imported in _imports(path):
            while imported and imported not in mods:
                imported = imported.rpartition(".")[0]
            if imported and imported != name and not (mods[imported].name == "__init__.py"
                                                      and name.startswith(imported + ".")):
                edges.add(imported)
        graph[name] = edges
    return graph


def _cycles(graph: dict) -> list:
    """The strongly connected components of more than one module (Tarjan, iterative)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            v, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[v] = min(low[v], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    found.append(sorted(comp))
    return found


def test_cycle_finder_finds_a_cycle():
    """The check can fail: a three-module ring and a two-module pair are found, a chain is not."""
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"e"}, "e": {"d"}, "f": {"a"}}
    assert sorted(_cycles(graph)) == [["a", "b", "c"], ["d", "e"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycle():
    cycles = _cycles(_module_graph())
    assert not cycles, f"import cycles (docs/architecture.md): {cycles}"


#: words that date a comment (assembled so that this file does not match itself)
DATED = re.compile("|".join([r"\b[Ii]ssue [0-9]+", r"\b[Rr]ound [0-9]+", "today" + "'s", "former " + "path",
                             "moved " + "here"]))
DATED_FILES = sorted([*ROOT.rglob("*.py"), *(ROOT.parent / "workflow").rglob("*.smk"),
                      *(ROOT.parent / "workflow").rglob("*.py"), *(ROOT.parent / "tests").rglob("*.py"),
                      ROOT.parent / "Snakefile"])


def test_dated_pattern_matches_what_it_must():
    for text in ["(iss" + "ue 15)", "Rou" + "nd 9", "the " + "former " + "path", "today" + "'s main"]:
        assert DATED.search(text), text
    assert not DATED.search("int(round(100 * BAND))")


def test_comments_do_not_date():
    hits = [f"{p.relative_to(ROOT.parent)}:{i}: {line.strip()[:80]}"
            for p in DATED_FILES if p.exists()
            for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1) if DATED.search(line)]
    assert not hits, "comments that date (say why, not when):\n" + "\n".join(hits)


#: functions over the limit, each with the reason it is still long
LONG_FUNCTIONS = {
    "rve/homogenisation/checkpoint.py:write_state": "split with the restructuring of rve/homogenisation",
}
MAX_BODY = 80


def _long_functions(files=None) -> dict:
    """"path:name" -> body lines (first statement after the docstring to the end) of the
    functions over ``MAX_BODY`` lines in ``files`` (default: every rve module)."""
    out = {}
    for path in FILES if files is None else files:
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                body = node.body
                doc = len(body) > 1 and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant) \
                    and isinstance(body[0].value.value, str)
                n = node.end_lineno - (body[1] if doc else body[0]).lineno + 1
                if n > MAX_BODY:
                    rel = path.relative_to(ROOT.parent) if path.is_relative_to(ROOT.parent) else path.name
                    out[f"{rel}:{node.name}"] = n
    return out


def test_long_function_finder_finds_one(tmp_path):
    """The check can fail: a generated 90-line body is found, an 80-line one is not."""
    src = ("def f():\n    'doc'\n" + "".join(f"    x{i} = {i}\n" for i in range(90))
           + "def g():\n" + "".join(f"    y{i} = {i}\n" for i in range(80)))
    (tmp_path / "m.py").write_text(src)
    assert _long_functions([tmp_path / "m.py"]) == {"m.py:f": 90}


def test_no_function_body_over_80_lines():
    long = {k: n for k, n in _long_functions().items() if k not in LONG_FUNCTIONS}
    assert not long, f"function bodies over {MAX_BODY} lines (split them): {long}"
