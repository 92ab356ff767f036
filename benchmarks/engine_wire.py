"""The dynamic-wire study (``benchmarks/dynamic_wire_study_time.py``) as interleaved fresh
processes per linear-solver backend and, optionally, against another tree: median study
time, its ratio, peak RSS, and whether the fitted-orders tables are equal (docs/engine.md).

    python benchmarks/engine_wire.py [--runs 3] [--backends superlu pardiso]
        [--baseline /path/to/tree --baseline-python /path/to/tree/.venv/bin/python]
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import ROOT, run_process  # noqa: E402


def _wire_process(python: str, tree: Path, env: dict) -> dict:
    """One fresh process of ``benchmarks/dynamic_wire_study_time.py`` (the default plan) in
    ``tree`` with ``python``: study wall time as the script prints it, the process's wall time
    and peak RSS (the parent process; the study's two worker processes are not included),
    and its fitted-orders table (the lines after "fitted orders")."""
    r = run_process([python, "benchmarks/dynamic_wire_study_time.py"], env, cwd=tree)
    out = r.stdout + r.stderr
    if r.returncode != 0:
        raise RuntimeError(f"dynamic_wire_study_time.py failed in {tree}:\n{out[-2000:]}")
    study = float(next(ln for ln in out.splitlines() if ln.startswith("study wall time")).split(":")[1].split()[0])
    orders = out.split("fitted orders:", 1)[1].strip() if "fitted orders:" in out else ""
    return {"study_s": study, "process_s": r.wall_s, "rss_mib": r.rss_mib, "orders": orders}


def main_wire(runs: int, backends, baseline: str | None, baseline_python: str | None) -> None:
    """The dynamic-wire study (``--wire``): interleaved fresh processes, per side the median
    study wall time, its ratio against the first side (the baseline
    tree when ``--baseline`` is given, else the first backend) and peak RSS; the orders tables must be equal across sides
    (the wire is one fibril: its stage matrices take the kept banded LU whatever
    ``RVE_LINEAR_BACKEND`` says, so the backends should not change a digit)."""
    sides = []
    if baseline:
        sides.append(("baseline", baseline_python or sys.executable, Path(baseline), {}))
    for b in backends:
        sides.append((f"this tree, {b}", sys.executable, ROOT, {"RVE_LINEAR_BACKEND": b}))
    recs = {name: [] for name, *_ in sides}
    for k in range(runs):
        for name, py, tree, extra in sides:
            env = {**os.environ, **extra}
            r = _wire_process(py, tree, env)
            recs[name].append(r)
            print(f"  run {k + 1} {name}: study {r['study_s']:.2f} s, process {r['process_s']:.2f} s, "
                  f"peak RSS {r['rss_mib']:.0f} MiB", file=sys.stderr, flush=True)
    ref = sides[0][0]
    ref_t = float(np.median([r["study_s"] for r in recs[ref]]))
    print(f"dynamic-wire study: medians of {runs} interleaved runs (ratio = {ref} / side)")
    for name, *_ in sides:
        t = float(np.median([r["study_s"] for r in recs[name]]))
        pt = float(np.median([r["process_s"] for r in recs[name]]))
        rss = max(r["rss_mib"] for r in recs[name])
        same = all(r["orders"] == recs[ref][0]["orders"] for r in recs[name])
        print(f"{name:24s} study {t:7.2f} s ({ref_t / t:.2f}x)  process {pt:7.2f} s  peak RSS {rss:5.0f} MiB  "
              f"orders {'identical to ' + ref if same else 'DIFFERENT'}")
    print("fitted orders (" + ref + "):\n" + recs[ref][0]["orders"])


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=3, help="interleaved runs per side")
    ap.add_argument("--backends", nargs="*", default=["superlu", "pardiso"])
    ap.add_argument("--baseline", default=None, help="another tree to compare against")
    ap.add_argument("--baseline-python", default=None, help="the baseline tree's interpreter")
    a = ap.parse_args(argv)
    main_wire(a.runs, a.backends, a.baseline, a.baseline_python)


if __name__ == "__main__":
    main()
