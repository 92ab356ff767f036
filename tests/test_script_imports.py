"""Every ``rve`` name the benchmark scripts and the Snakemake rule files import exists in
the package.

Neither is imported by the suite (the scripts run long studies, the rules run under
Snakemake), so a module moved by a redesign can leave them broken unnoticed. The
benchmarks are parsed with ``ast``; the rule files are not Python, so their ``from rve...
import`` lines are read by a regular expression. Imports in an ``except ImportError``
branch are fallbacks for an older tree (``benchmarks/engine_ab.py`` also runs another
commit) and are not checked.
"""
from __future__ import annotations

import ast
import importlib
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = sorted(ROOT.glob("benchmarks/*.py"))
RULES = sorted([ROOT / "Snakefile", *ROOT.glob("workflow/rules/*.smk")])
_RULE_IMPORT = re.compile(r"^\s*from\s+(rve[\w.]*)\s+import\s+([\w, ]+?)(?:\s+as\s+\w+)?\s*(?:#.*)?$", re.M)


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
    assert len(SCRIPTS) > 10 and len(RULES) > 5


def _rule_imports(path: Path):
    text = path.read_text()
    for m in _RULE_IMPORT.finditer(text):
        line = text.count("\n", 0, m.start()) + 1
        for name in m.group(2).split(","):
            yield line, m.group(1), name.split(" as ")[0].strip()


@pytest.mark.parametrize("path", SCRIPTS + RULES, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_script_imports_resolve(path):
    missing = []
    found = _rve_imports(path) if path.suffix == ".py" else _rule_imports(path)
    for line, module, name in found:
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
