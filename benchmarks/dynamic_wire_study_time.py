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
"""
from __future__ import annotations

import argparse
import json
import os
import time

from rve.studies.dynamic_wire import DEFAULT_PLAN, normalise_plan, orders_table, run_study, write_study

QUICK = {"reference": {"stages": 3, "steps": 1500},
         "series": {1: {"steps": [200, 400], "fit": [200, 400]}, 2: {"steps": [50, 100], "fit": [50, 100]},
                    3: {"steps": [25, 50], "fit": [25, 50]}}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--plan", choices=["default", "quick"], default="default")
    ap.add_argument("--out", default=None, help="write the study netCDF here")
    args = ap.parse_args()
    plan = normalise_plan(QUICK if args.plan == "quick" else None)
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


if __name__ == "__main__":
    main()
