"""Cost of a stage solve of the dynamic wire with and without the two stage-solve savings.

The variants (``rve.solvers.dirk.DirkStepper``):

* ``predictor_degree``: Newton starts each stage from the previous stage value (0) or from
  the linear (1) or quadratic (2, the default) extrapolation in time of the latest stage
  values;
* ``lazy_jacobian``: the Jacobian is assembled at every Newton point (off) or only where
  another iteration needs it (on, the default).

Each run is the dynamic wire of configs/scenes/dynamic_wire.yaml with fixed steps. The
variants are interleaved (A B C D A B C D ...) so a drifting machine load hits them alike;
the table gives per variant the median wall time, Newton iterations per stage, Jacobian
assemblies and residual-only evaluations per stage, ms per stage, the wall-time ratio to the
baseline (0, off) measured in the same run, and the largest probe difference to the baseline
(the variants only change where Newton starts: differences stay at the Newton tolerance).
First it prints what one model evaluation costs with and without the Jacobian; last, peak
RSS. Run: ``python benchmarks/dirk_stage_cost.py [--repeats 3] [--runs 3:600,3:75,1:150] [--reuse]``
(``--reuse``: the default against factorisation reuse on / auto instead).
"""
from __future__ import annotations

import argparse
import os
import resource
import time

import numpy as np

from rve.scenes.dynamic_wire import setup, solve
from rve.studies.dynamic_wire import PROBE_NAMES, load_scene_config

VARIANTS = {
    "previous value, eager J": dict(predictor_degree=0, lazy_jacobian=False),
    "previous value, lazy J": dict(predictor_degree=0, lazy_jacobian=True),
    "extrapolated, eager J": dict(predictor_degree=2, lazy_jacobian=False),
    "linear extrapolation, lazy J": dict(predictor_degree=1, lazy_jacobian=True),
    "extrapolated, lazy J (default)": dict(predictor_degree=2, lazy_jacobian=True),
}

#: ``--reuse``: the default against factorisation reuse (docs/time_integration.md
#: "Factorisation reuse (modified Newton)"), with the baseline for the ratios
REUSE_VARIANTS = {
    "previous value, eager J": VARIANTS["previous value, eager J"],
    "extrapolated, lazy J (default)": VARIANTS["extrapolated, lazy J (default)"],
    "default + reuse on": dict(predictor_degree=2, lazy_jacobian=True, jacobian_reuse=True),
    "default + reuse auto": dict(predictor_degree=2, lazy_jacobian=True, jacobian_reuse="auto"),
}


def _counting(model_cls):
    """Count full and residual-only evaluations of the model (class-level patch)."""
    counts = {"jacobian": 0, "residual": 0}
    orig = model_cls.evaluate

    def evaluate(self, x, w, t, jacobian=True):
        counts["jacobian" if jacobian else "residual"] += 1
        return orig(self, x, w, t, jacobian)

    model_cls.evaluate = evaluate
    return counts


def evaluation_cost(cfg, repeats: int = 5, calls: int = 200) -> dict:
    """Median wall time (ms) of one model evaluation with and without the Jacobian, at a
    generic state of the dynamic wire (451 dofs)."""
    from rve.scenes.dynamic_wire import initial_state

    model = setup(cfg)
    x, w = initial_state(model)
    w = w + 1e-3 * np.random.default_rng(0).random(model.n)
    out = {}
    for jac in (True, False):
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            for _ in range(calls):
                model.evaluate(x, w, 1e-3, jacobian=jac)
            times.append((time.perf_counter() - t0) / calls)
        out["with Jacobian" if jac else "residual only"] = 1e3 * float(np.median(times))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--runs", default="3:600,3:75,1:150", help="comma-separated s:N")
    ap.add_argument("--reuse", action="store_true", help="compare the default with factorisation reuse on / auto")
    args = ap.parse_args()
    variants = REUSE_VARIANTS if args.reuse else VARIANTS
    cfg = load_scene_config("configs/scenes/dynamic_wire.yaml")
    cost = evaluation_cost(cfg)
    print("one evaluation of the dynamic wire (451 dofs), median of 5 x 200 calls: "
          + ", ".join(f"{k} {v:.2f} ms" for k, v in cost.items()))
    counts = _counting(type(setup(cfg)))
    runs = [tuple(int(v) for v in r.split(":")) for r in args.runs.split(",")]
    load0 = os.getloadavg()[0]
    for s, n in runs:
        rec = {k: {"wall": [], "its": 0, "jac": 0, "res": 0, "probes": None} for k in variants}
        for _ in range(args.repeats):
            for name, opts in variants.items():
                counts.update(jacobian=0, residual=0)
                t0 = time.perf_counter()
                out = solve(cfg, stages=s, steps=n, fixed_step=True, record=False, integrator_options=opts).summary
                rec[name]["wall"].append(time.perf_counter() - t0)
                rec[name].update(its=out["newton_iterations_per_stage"], jac=counts["jacobian"] / (s * n),
                                 res=counts["residual"] / (s * n), probes=out["probes"])
        base = rec["previous value, eager J"]
        print(f"\ns = {s}, N = {n} ({s * n} stage solves), median of {args.repeats}")
        print(f"{'variant':32s} {'wall s':>8s} {'its/stage':>10s} {'J/stage':>8s} {'r/stage':>8s} "
              f"{'ms/stage':>9s} {'ratio':>6s} {'max |dprobe|/|probe|':>21s}")
        for name, r in rec.items():
            wall = float(np.median(r["wall"]))
            ratio = float(np.median(np.array(r["wall"]) / np.array(base["wall"])))
            dp = max(abs(r["probes"][k] - base["probes"][k]) / abs(base["probes"][k]) for k in PROBE_NAMES)
            print(f"{name:32s} {wall:8.2f} {r['its']:10.2f} {r['jac']:8.2f} {r['res']:8.2f} "
                  f"{1e3 * wall / (s * n):9.2f} {ratio:6.2f} {dp:21.1e}")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"\nload average before {load0:.2f}, after {os.getloadavg()[0]:.2f}; peak RSS {peak:.0f} MiB")


if __name__ == "__main__":
    main()
