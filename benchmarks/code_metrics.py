"""The structural figures of a code review, printed from the source: the dated
comments (the grep of tests/test_architecture.py's ``DATED``), the longest function bodies
of ``rve/``, the import cycles between rve modules, and the duplicated-code pairs when the
``duplicates`` tool is installed.

    python benchmarks/code_metrics.py [--top 10]

A function's body is counted from its first statement after the docstring to its last line
(nested functions count towards the function that holds them).
"""
from __future__ import annotations

import argparse
import ast
import importlib.util
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _architecture():
    spec = importlib.util.spec_from_file_location("_architecture", ROOT / "tests/test_architecture.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def function_lengths(root: Path = ROOT / "rve") -> list:
    """[(body lines, "path:line name")], longest first."""
    rows = []
    for path in sorted(root.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                body = node.body
                first = body[1] if (len(body) > 1 and isinstance(body[0], ast.Expr)
                                    and isinstance(body[0].value, ast.Constant)
                                    and isinstance(body[0].value.value, str)) else body[0]
                rows.append((node.end_lineno - first.lineno + 1,
                             f"{path.relative_to(ROOT)}:{node.lineno} {node.name}"))
    return sorted(rows, reverse=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--top", type=int, default=10)
    a = ap.parse_args(argv)
    arch = _architecture()
    dated = [f"{p.relative_to(ROOT)}:{i}" for p in arch.DATED_FILES if p.exists()
             for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1) if arch.DATED.search(line)]
    print(f"dated comments (rve/, workflow/, tests/, Snakefile): {len(dated)}")
    for d in dated[:20]:
        print(f"  {d}")
    rows = function_lengths()
    print(f"functions in rve/ with a body over 80 lines: {sum(1 for n, _ in rows if n > 80)}")
    for n, where in rows[:a.top]:
        print(f"  {n:4d}  {where}")
    cycles = arch._cycles(arch._module_graph())
    print(f"import cycles between rve modules: {len(cycles)}" + "".join(f"\n  {c}" for c in cycles))
    if shutil.which("duplicates"):
        out = subprocess.run(["duplicates", "--seconds", "60"], cwd=ROOT / "rve", capture_output=True, text=True)
        print("duplicates on rve/: " + (out.stdout.splitlines() or ["?"])[0])
    else:
        print("duplicates on rve/: the duplicates tool is not installed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
