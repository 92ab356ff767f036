"""The import directions of docs/architecture.md, checked on the source.

Every ``rve`` subpackage may import only the layers the table in docs/architecture.md
allows (module-level and function-level imports alike, found by parsing the source, so a
lazy import that climbs a layer fails too). The one declared exception is the scene
registry: ``rve.config`` looks up a scene's config model there (a data-only module).
"""
from __future__ import annotations

import ast
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
    pkg = list(path.relative_to(ROOT.parent).with_suffix("").parts)
    if pkg[-1] == "__init__":
        pkg = pkg[:-1]
    else:
        pkg = pkg[:-1]
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
