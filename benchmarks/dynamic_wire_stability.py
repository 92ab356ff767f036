"""Stability stress test of the dynamic wire: growing step sizes, fixed steps vs step control.

For each SDIRK scheme (s = 1, 2, 3) and a decreasing number of nominal steps N (growing
h = t_max / N), runs the dynamic wire (configs/scenes/dynamic_wire.yaml defaults) twice:

* fixed step (``fixed_step=True``): the first failed stage Newton solve ends the run;
* with step control (cut-and-retry: halve on failure, regrow after successes).

Prints per (s, N): h, whether the fixed-step run finished (and where it failed: time and
reason), whether the controlled run finished, its accepted and rejected steps and the
smallest step, wall times; then per scheme the largest h at which the fixed-step run still
finishes and whether every controlled run finished; and the peak memory of the process.

Never fails on a slow machine; it only prints. Run:
``python benchmarks/dynamic_wire_stability.py [--stages 1 2 3] [--steps 100 50 25 12 6 4 3]
[--set load.field_ramp_time=0]``.
"""
from __future__ import annotations

import argparse
import resource
import time

from rve.scenes.dynamic_wire import solve
from rve.scenes.protocol import SceneFailure
from rve.studies.dynamic_wire import load_scene_config


def peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def attempt(cfg, s, n, fixed):
    t0 = time.perf_counter()
    try:
        out = solve(cfg, stages=s, steps=n, fixed_step=fixed, record=False).summary
        return {"ok": True, "wall": time.perf_counter() - t0, "accepted": out["steps_accepted"],
                "rejected": out["steps_rejected"], "h_min": out["h_min"], "probes": out["probes"]}
    except SceneFailure as exc:
        return {"ok": False, "wall": time.perf_counter() - t0, "t": exc.time, "h": exc.details["h"],
                "reason": exc.details["reason"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default="configs/scenes/dynamic_wire.yaml")
    ap.add_argument("--stages", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--steps", type=int, nargs="+", default=[100, 50, 25, 12, 6, 4, 3])
    ap.add_argument("--set", dest="overrides", action="append", default=[],
                    help="config override, e.g. --set load.field_ramp_time=0 (the thesis's step switch-on)")
    args = ap.parse_args()
    cfg = load_scene_config(args.config, args.overrides)
    t_max = cfg.time.t_max
    print(f"dynamic wire, t_max = {t_max:g} ms, B ramp {cfg.load.field_ramp_time:g} ms; "
          f"N nominal steps, h = t_max / N")
    print(f"{'s':>2} {'N':>5} {'h (ms)':>10} | {'fixed step':<52} | {'step control':<44}")
    summary = {}
    for s in args.stages:
        largest_fixed_ok = None
        all_controlled = True
        for n in sorted(args.steps, reverse=True):
            h = t_max / n
            f = attempt(cfg, s, n, True)
            c = attempt(cfg, s, n, False)
            if f["ok"]:
                largest_fixed_ok = h if largest_fixed_ok is None else max(largest_fixed_ok, h)
                ftxt = f"finished ({f['wall']:.1f} s)"
            else:
                ftxt = f"FAILED at t={f['t']:.3g} h={f['h']:.3g}: {f['reason'][:22]}"
            if c["ok"]:
                ctxt = (f"finished: {c['accepted']} acc, {c['rejected']} rej, "
                        f"h_min={c['h_min']:.2g} ({c['wall']:.1f} s)")
            else:
                all_controlled = False
                ctxt = f"FAILED at t={c['t']:.3g} h={c['h']:.3g}"
            print(f"{s:>2} {n:>5} {h:>10.3g} | {ftxt:<52} | {ctxt:<44}", flush=True)
        summary[s] = (largest_fixed_ok, all_controlled)
    print()
    for s, (hf, allc) in summary.items():
        print(f"s = {s}: largest h with a finished fixed-step run: "
              f"{'none' if hf is None else f'{hf:.3g} ms'}; controlled runs all finished: {allc}")
    print(f"peak memory (ru_maxrss): {peak_mb():.0f} MB")


if __name__ == "__main__":
    main()
