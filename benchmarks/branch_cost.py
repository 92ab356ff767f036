"""Benchmark: what the one-equilibrium-path test (``strain.follow_branch``) found and cost,
per run, combination and mode, from the stored strain states and the Snakemake benchmark
files of a results folder (finished or not; docs/table_accuracy.md sections 4 and 5).

    python benchmarks/branch_cost.py [RUN ...] [--results results]
    nice -n 10 python benchmarks/branch_cost.py --measure STATES [--run plain_weave] [--steps uniaxial:1,2 shear:1]
        [--methods arc_length halving]

For every combination of every run (default: the runs named ``work_precision*``) and every
mode: the strain steps stored so far, the summed tests that failed (detections), the
branch jumps avoided by following, the limit points left at the step floor, the false
alarms, the step solves (1 per step without a detection), and the summed CPU and wall
seconds of the stored steps' jobs and of the probe jobs.

``--measure STATES`` times strain jobs of a run of configs/pipeline.yaml (default: the
default job's ``plain_weave``) from the stored states in the folder STATES (``relaxed.nc``,
``<mode>_<step>.nc``): each listed step from the same stored previous state in a fresh
process, once with ``strain.follow_branch=false`` and once per ``--methods`` with it on
(``halving``: the default; ``halving_floor``: every jump halved down to the floor;
``arc_length``: the continuation),
the sides interleaved; printed per step: wall and CPU seconds, what the test found, and
per method the median over the steps of the wall and the CPU ratio on / off and the ratio
of the summed CPU seconds (CPU is the measure on a shared machine).
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


#: the followed sides of --measure: their overrides
METHODS = {"halving": ["strain.branch_method=halving"],
           "halving_floor": ["strain.branch_method=halving", "strain.branch_persist_ratio=0"],
           "arc_length": ["strain.branch_method=arc_length"]}


def _worker(states: Path, run: str, mode: str, step: int, overrides: list) -> int:
    """One strain step in this process; prints its JSON record."""
    import hashlib
    import time

    import numpy as np
    import yaml

    from rve.fabrics.setup import fabric_and_mesh
    from rve.homogenisation.checkpoint import load_state
    from rve.homogenisation.strain import strain_step
    from rve.homogenisation.sweeps import load_run_config

    spec = yaml.safe_load((Path(__file__).resolve().parents[1] / "configs/pipeline.yaml").read_text())["rve"]["runs"][run]
    spec = dict(spec, overrides=list(spec.get("overrides") or []) + list(overrides))
    cfg = load_run_config(spec)
    fab, mesh = fabric_and_mesh(cfg)
    prev = load_state(states / ("relaxed.nc" if step == 1 else f"{mode}_{step - 1:02d}.nc"))
    t0 = time.perf_counter()
    x, _, info = strain_step(cfg, fab, mesh, prev.x, prev.origin, mode, step, multipliers=prev.multipliers)
    b = info.get("branch") or {}
    a = b.get("arc") or {}
    print(json.dumps({"step_wall_s": time.perf_counter() - t0, "x_sha": hashlib.sha256(np.ascontiguousarray(x)).hexdigest()[:16],
                      "residual_N": info.get("residual_N"), **{k: b.get(k) for k in COUNTS + ("limit_points_passed",)},
                      "kept": b.get("kept"), "arc_steps": a.get("arc_steps"), "arc_folds": a.get("folds"),
                      "arc_converged": a.get("converged"), "arc_reached": ((a.get("path") or [{}])[-1]).get("eps")}))
    return 0


def measure(states: Path, run: str, steps: list, methods: list) -> int:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from _harness import interleave, run_json, worker_env

    import numpy as np

    env = worker_env(RVE_PARDISO_THREADS=1)
    ratios: dict = {m: [] for m in methods}
    cpu_ratios: dict = {m: [] for m in methods}
    sum_cpu: dict = {}
    print("| mode | step | side | wall s | CPU s | detections | limit points | passed | kept | x (sha256) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for mode, step in steps:
        def side(over):
            argv = [sys.executable, __file__, "--worker", str(states), run, mode, str(step), *over]
            return lambda k: run_json(argv, env)
        sides = {"off": side(["strain.follow_branch=false"])}
        for m in methods:
            sides[m] = side(["strain.follow_branch=true", *METHODS[m]])
        recs = interleave(sides, 1)
        stored = states / f"{mode}_{step:02d}.nc"
        if stored.exists():   # the folder's own state of this step: off should be it, bit for bit
            import hashlib

            from rve.homogenisation.checkpoint import load_state

            x = load_state(stored).x
            print(f"| {mode} | {step} | stored | | | | | | | {hashlib.sha256(np.ascontiguousarray(x)).hexdigest()[:16]} |")
        for name, (r,) in recs.items():
            if "error" in r:
                print(f"| {mode} | {step} | {name} | error: {r['error']} |")
                continue
            if r.get("arc_converged") is not None:
                print(f"  continuation ({mode} {step}): converged {r['arc_converged']}, {r['arc_steps']} arc steps, "
                      f"{r['arc_folds']} folds, last point at eps {r['arc_reached']}")
            print(f"| {mode} | {step} | {name} | {r['wall_s']:.1f} | {r['cpu_s']:.1f} | {r.get('detections')} | "
                  f"{r.get('limit_points')} | {r.get('limit_points_passed')} | {r.get('kept')} | {r['x_sha']} |",
                  flush=True)
        for name, (r,) in recs.items():
            sum_cpu[name] = sum_cpu.get(name, 0.0) + (r.get("cpu_s", 0.0) if "error" not in r else float("nan"))
        off = recs["off"][0]
        for m in methods:
            on = recs[m][0]
            if "error" not in on and "error" not in off:
                ratios[m].append(on["wall_s"] / off["wall_s"])
                cpu_ratios[m].append(on["cpu_s"] / off["cpu_s"])
    for m, r in ratios.items():
        c = cpu_ratios[m]
        print(f"{m}: median ratio on/off over {len(r)} steps: wall {np.median(r):.3f} (min {min(r):.3f}, max "
              f"{max(r):.3f}), CPU {np.median(c):.3f} (min {min(c):.3f}, max {max(c):.3f}); summed CPU on/off "
              f"{sum_cpu[m] / sum_cpu['off']:.3f}" if r else f"{m}: no pair measured")
    return 0


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["--worker"]:
        states, run, mode, step, *over = argv[1:]
        return _worker(Path(states), run, mode, int(step), over)
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="*", help="run names (default: every run named work_precision*)")
    ap.add_argument("--results", default="results")
    ap.add_argument("--measure", metavar="STATES", help="time strain jobs on/off from the stored states in STATES")
    ap.add_argument("--run", default="plain_weave", help="the run of configs/pipeline.yaml (--measure)")
    ap.add_argument("--steps", nargs="+", default=["uniaxial:1,2,3", "shear:1,2"], help="mode:step,step,...")
    ap.add_argument("--methods", nargs="+", default=["halving"], choices=list(METHODS),
                    help="the followed sides (halving_floor: halving down to the floor, persist ratio 0)")
    a = ap.parse_args(argv)
    if a.measure:
        steps = [(m, int(k)) for item in a.steps for m, ks in [item.split(":")] for k in ks.split(",")]
        return measure(Path(a.measure), a.run, steps, a.methods)
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
