"""Benchmark: what the one-equilibrium-path test (``strain.follow_branch``) found and cost,
per run, combination and mode, from the stored strain states and the Snakemake benchmark
files of a results folder (finished or not; docs/table_accuracy.md sections 4 and 5).

    python benchmarks/branch_cost.py [RUN ...] [--results results]

For every combination of every run (default: the runs named ``work_precision*``) and every
mode: the strain steps stored so far, the summed tests that failed (detections), the
branch jumps avoided by following, the limit points left at the step floor, the false
alarms, the step solves (1 per step without a detection), and the summed CPU and wall
seconds of the stored steps' jobs and of the probe jobs.
"""
from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

COUNTS = ("detections", "branch_jumps", "limit_points", "false_alarms", "solves")


def _bench(path: Path) -> tuple:
    try:
        row = list(csv.DictReader(path.open(), delimiter="\t"))[-1]
        return float(row["cpu_time"]), float(row["s"])
    except (OSError, IndexError, KeyError, ValueError):
        return 0.0, 0.0


def _branch(state: Path) -> dict:
    import netCDF4

    with netCDF4.Dataset(state) as ds:
        solver = json.loads(ds.getncattr("solver")) if "solver" in ds.ncattrs() else {}
    return solver.get("branch") or {}


def combo_rows(results: Path, run: str) -> list:
    rows = []
    for combo in sorted(p for p in (results / "rve" / run).glob("*/states") if p.is_dir()):
        cdir = combo.parent
        bench = results / "benchmarks" / "rve" / run / cdir.name
        modes: dict = {}
        for state in sorted(combo.glob("*_[0-9][0-9].nc")):
            mode = state.stem.rsplit("_", 1)[0]
            m = modes.setdefault(mode, {"steps": 0, "cpu_s": 0.0, "wall_s": 0.0, **{k: 0 for k in COUNTS}})
            m["steps"] += 1
            cpu, wall = _bench(bench / "strain" / f"{state.stem}.tsv")
            m["cpu_s"] += cpu
            m["wall_s"] += wall
            b = _branch(state)
            for k in COUNTS:
                m[k] += int(b.get(k) or 0)
        probes = [_bench(p) for p in sorted((bench / "probes").glob("*.tsv"))]
        relax = _bench(bench / "relax.tsv")
        rows.append((cdir.name, modes, len(probes), sum(c for c, _ in probes), relax[0]))
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="*", help="run names (default: every run named work_precision*)")
    ap.add_argument("--results", default="results")
    a = ap.parse_args(argv)
    results = Path(a.results)
    runs = a.runs or sorted(p.name for p in (results / "rve").glob("work_precision*") if p.is_dir()
                            and p.name != "work_precision")
    print("| run | combo | mode | steps | detections | jumps followed | limit points | false alarms | solves | "
          "strain CPU s | strain wall s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for run in runs:
        for combo, modes, n_probes, probe_cpu, relax_cpu in combo_rows(results, run):
            for mode, m in sorted(modes.items()):
                print(f"| {run} | {combo} | {mode} | {m['steps']} | " + " | ".join(str(m[k]) for k in COUNTS)
                      + f" | {m['cpu_s']:.1f} | {m['wall_s']:.0f} |")
            print(f"| {run} | {combo} | relax + {n_probes} probes | | | | | | | {relax_cpu + probe_cpu:.1f} | |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
