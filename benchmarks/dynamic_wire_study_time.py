"""Wall time of the dynamic-wire time-convergence study (thesis §6.4) and of its reference.

Runs ``rve.studies.dynamic_wire.run_study`` with the default plan (or ``--plan quick``):
the reference (s = 3, N = 1500 fixed steps) and every (s, N) of the series on a pool of
``--workers`` processes (2 by default: the 2-core machine), longest run first. Prints

* the wall time of the whole study (target: < 60 s on the 2-core machine) and of the
  reference run alone, the sum of the per-run wall times (the serial cost) and the
  parallel efficiency;
* per run: s, N, wall time, Newton iterations, iterations per stage, time per stage solve;
* the fitted orders (Table 6.4 analogue);
* the machine load (os.getloadavg) before and after: other processes on the machine make
  every figure slower, so read them with it.

Writes the dataset to ``--out`` (default: a temporary file) when given. Never fails on a
slow machine; it only prints. Run: ``python benchmarks/dynamic_wire_study_time.py``.

``--variants off,on,auto [--repeats 2]``: the whole study once per factorisation-reuse
variant of ``rve.solvers.dirk.integrate`` (``jacobian_reuse`` False / True / "auto";
given to every run as ``run_study(integrator_options={"jacobian_reuse": ...})``),
interleaved (A B C A B C ...); then per variant the median study wall time and its ratio
to ``off`` measured in the same run, the fitted orders, and the largest probe difference
to ``off`` over every (s, N) (docs/time_integration.md "Factorisation reuse").
"""
from __future__ import annotations

import argparse
import os
import time

import numpy as np

from rve.studies.dynamic_wire import PROBE_NAMES, normalise_plan, orders_table, run_study, write_study

QUICK = {"reference": {"stages": 3, "steps": 1500},
         "series": {1: {"steps": [200, 400], "fit": [200, 400]}, 2: {"steps": [50, 100], "fit": [50, 100]},
                    3: {"steps": [25, 50], "fit": [25, 50]}}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--plan", choices=["default", "quick"], default="default")
    ap.add_argument("--out", default=None, help="write the study netCDF here")
    ap.add_argument("--variants", default=None, help="compare factorisation-reuse variants, e.g. off,on,auto")
    ap.add_argument("--repeats", type=int, default=1)
    args = ap.parse_args()
    plan = normalise_plan(QUICK if args.plan == "quick" else None)
    if args.variants:
        return compare(plan, args)
    load0 = os.getloadavg()
    t0 = time.perf_counter()
    ds, timing = run_study(plan, workers=args.workers)
    wall = time.perf_counter() - t0
    load1 = os.getloadavg()
    print(f"machine: {os.cpu_count()} cores; load average before {load0[0]:.2f}, after {load1[0]:.2f}")
    print(f"plan: reference s={plan['reference']['stages']} N={plan['reference']['steps']}; "
          + "; ".join(f"s={s}: N={v['steps']}" for s, v in sorted(plan["series"].items())))
    print(f"study wall time (workers={args.workers}): {wall:8.2f} s   (target < 60 s)")
    print(f"reference run wall time:            {timing['reference_wall_s']:8.2f} s")
    print(f"sum of run wall times (serial cost): {timing['sum_of_run_walls_s']:8.2f} s   "
          f"parallel efficiency {timing['sum_of_run_walls_s'] / (args.workers * wall):.2f}")
    print("\n   s      N   wall (s)   Newton its   its/stage   ms/stage")
    for s in ds.stages.values:
        for n in ds.steps.values:
            wt = float(ds.wall_time.sel(stages=s, steps=n))
            its = float(ds.newton_iterations.sel(stages=s, steps=n))
            if wt == wt:  # not NaN
                print(f"{int(s):4d} {int(n):6d} {wt:10.2f} {its:12.0f} {its / (s * n):11.2f} {1e3 * wt / (s * n):10.2f}")
    ref_n = plan["reference"]["steps"] * plan["reference"]["stages"]
    print(f"{plan['reference']['stages']:4d} {plan['reference']['steps']:6d} {timing['reference_wall_s']:10.2f}"
          f" {'(reference)':>12s} {'':11s} {1e3 * timing['reference_wall_s'] / ref_n:10.2f}")
    print("\nfitted orders:\n" + orders_table(ds))
    if args.out:
        write_study(ds, args.out)
        print(f"wrote {args.out}")


REUSE = {"off": False, "on": True, "auto": "auto"}


def compare(plan, args) -> None:
    names = [v for v in args.variants.split(",") if v]
    load0 = os.getloadavg()
    walls = {v: [] for v in names}
    data = {}
    for rep in range(args.repeats):
        for v in names:
            t0 = time.perf_counter()
            ds, timing = run_study(plan, workers=args.workers, integrator_options={"jacobian_reuse": REUSE[v]})
            walls[v].append(time.perf_counter() - t0)
            data[v] = (ds, timing)
            print(f"  repeat {rep + 1} {v:>4}: study {walls[v][-1]:7.2f} s, "
                  f"sum of runs {timing['sum_of_run_walls_s']:7.2f} s",
                  flush=True)
    load1 = os.getloadavg()
    print(f"machine: {os.cpu_count()} cores; load average before {load0[0]:.2f}, after {load1[0]:.2f}")
    ref = data.get("off")
    t_ref = float(np.median(walls["off"])) if "off" in walls else None
    for v in names:
        ds, timing = data[v]
        wm = float(np.median(walls[v]))
        its = float(np.nansum(ds.newton_iterations.values))
        line = f"\n=== {v}: study wall median {wm:.2f} s"
        if t_ref:
            line += f" (ratio off/{v} {t_ref / wm:.2f})"
        line += f", Newton iterations over the series {its:.0f}"
        if ref is not None and v != "off":
            diffs = {p: float(np.nanmax(np.abs(ds[p].values - ref[0][p].values))) for p in PROBE_NAMES}
            line += ("\nmax probe difference to off over all (s, N): "
                     + ", ".join(f"{k} {d:.1e}" for k, d in diffs.items()))
        print(line)
        print(orders_table(ds))


if __name__ == "__main__":
    main()
