"""Every ``rve`` name the benchmark and workflow scripts import exists in the package.

The scripts are not imported by the suite (they run long studies), so a module moved by a
redesign can leave them broken unnoticed: ``benchmarks/engine_matrices.py`` imported
``rve.contact.system`` and ``rve.homogenisation.strain.build_fabric`` for two rounds after
both had moved. Imports in an ``except ImportError`` branch are fallbacks for an older tree
(``benchmarks/engine_ab.py`` runs today's main too) and are not checked.
"""
from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = sorted([*ROOT.glob("benchmarks/*.py"), *ROOT.glob("workflow/scripts/*.py")])


def _fallback_nodes(tree) -> set[int]:
    """ids of the nodes inside ``except ImportError`` (or ``ModuleNotFoundError``) branches."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Try):
            for h in node.handlers:
                names = [h.type] if not isinstance(h.type, ast.Tuple) else list(h.type.elts)
                if any(isinstance(n, ast.Name) and n.id in ("ImportError", "ModuleNotFoundError") for n in names):
                    out.update(id(sub) for stmt in h.body for sub in ast.walk(stmt))
    return out


def _rve_imports(path: Path):
    tree = ast.parse(path.read_text())
    skip = _fallback_nodes(tree)
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module and node.module.split(".")[0] == "rve":
            for alias in node.names:
                yield node.lineno, node.module, alias.name
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == "rve":
                    yield node.lineno, alias.name, None


def test_there_are_scripts_to_check():
    assert len(SCRIPTS) > 10


@pytest.mark.parametrize("path", SCRIPTS, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_script_imports_resolve(path):
    missing = []
    for line, module, name in _rve_imports(path):
        try:
            mod = importlib.import_module(module)
        except ImportError as exc:
            missing.append(f"line {line}: {module} ({exc})")
            continue
        if name not in (None, "*") and not hasattr(mod, name):
            try:
                importlib.import_module(f"{module}.{name}")
            except ImportError:
                missing.append(f"line {line}: {module} has no {name}")
    assert not missing, f"{path.relative_to(ROOT)}: " + "; ".join(missing)
