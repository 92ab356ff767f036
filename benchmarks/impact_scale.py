"""The cost model of the impact scene over its size (docs/scale.md): 8 x 8, 16 x 16 and
32 x 32 yarns at the thesis's yarn pitch and element length, a short run each.

The sizes keep the full scene's pitch (50.8 mm / 32 yarns), element length (80 elements
per 50.8 mm) and projectile-to-fabric ratio (radius 18 mm at 32 yarns), so n yarns a side
carry n x (2.5 n) elements: dofs ~ n^2. Each size runs in a fresh process: the relaxation,
then ``--steps`` impact steps of 0.5 us (the projectile starts 0.2 mm above the fabric, so a
short run has the fabric's own contacts, not the sphere's). Per size it prints dofs,
stored entries of the stage matrix, and per step: assembly (fabric forms, contact forms,
sphere contact, composition), factorisations (count, seconds each), back-solves (count,
ms each) and the whole stage solve (Newton with everything in it); peak RSS; then the
growth exponents fitted (least squares of log cost against log dofs) and the costs
extrapolated to 128 x 128 yarns.

    nice -n 10 python benchmarks/impact_scale.py                 # 8, 16, 32; 10 steps each
    nice -n 10 python benchmarks/impact_scale.py --sizes 8 16 --steps 5
"""
from __future__ import annotations

import argparse
import json
import math
import resource
import subprocess
import sys
import time

import numpy as np

PITCH_MM = 50.8 / 32
ELEMENTS_PER_YARN_AT_32 = 80
PROJECTILE_RADIUS_AT_32_MM = 18.0


def overrides(n: int) -> list[str]:
    return [f"geometry.n_warp={n}", f"geometry.n_weft={n}", f"geometry.span={PITCH_MM * n:.6g} mm",
            f"mesh.elements={round(ELEMENTS_PER_YARN_AT_32 * n / 32)}",
            f"projectile.radius={PROJECTILE_RADIUS_AT_32_MM * n / 32:.6g} mm",
            "output.vtk=false", "output.png=false"]


def child(n: int, steps: int) -> dict:
    """One size: the relaxation and ``steps`` steps, with the linear solver's calls timed."""
    from rve.config.loader import load_config
    from rve.scenes import impact
    from rve.solvers.backends.pruned import PardisoOrPruned

    calls = {"factorize": [], "solve": [], "nnz": 0}
    factorize, solve = PardisoOrPruned.factorize, PardisoOrPruned.solve

    def timed_factorize(self, A, *args, **kwargs):
        t0 = time.perf_counter()
        out = factorize(self, A, *args, **kwargs)
        calls["factorize"].append(time.perf_counter() - t0)
        calls["nnz"] = max(calls["nnz"], int(A.nnz))
        return out

    def timed_solve(self, b):
        t0 = time.perf_counter()
        out = solve(self, b)
        calls["solve"].append(time.perf_counter() - t0)
        return out

    PardisoOrPruned.factorize, PardisoOrPruned.solve = timed_factorize, timed_solve
    cfg = load_config("configs/scenes/impact.yaml", overrides(n))
    t0 = time.perf_counter()
    x, rinfo = impact.relax(cfg)
    t_relax = time.perf_counter() - t0
    relax_calls = {k: len(calls[k]) for k in ("factorize", "solve")}
    s = impact.solve(cfg, x_start=x, relax_info=rinfo, record=False, t_end=5e-4 * steps, steps=steps).summary
    w = s["wall_time_s"]
    fac, sol = calls["factorize"][relax_calls["factorize"]:], calls["solve"][relax_calls["solve"]:]
    k = max(1, s["steps_accepted"])
    return {"n": n, "dofs": int(s["dofs"]["total"]), "nnz": calls["nnz"], "steps": s["steps_accepted"],
            "rejected": s["steps_rejected"], "relax_s": t_relax,
            "assembly_s": (w["assembly_fabric"] + w["contact_fabric"] + w["contact_sphere"] + w["compose"]) / k,
            "factorizations": len(fac), "factorize_s": float(np.median(fac)) if fac else math.nan,
            "factorize_per_step_s": sum(fac) / k, "solves": len(sol),
            "solve_ms": 1e3 * float(np.median(sol)) if sol else math.nan, "solve_per_step_s": sum(sol) / k,
            "stage_solve_per_step_s": w["linear_solve_and_newton"] / k, "step_s": w["total"] / k,
            "contact_pairs_max": s["contact_pairs_max"],
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def fit(rows: list[dict], key: str) -> tuple[float, float]:
    """Exponent p and prefactor c of cost = c dofs^p, least squares in logs."""
    d = np.log([r["dofs"] for r in rows])
    y = np.log([r[key] for r in rows])
    p, logc = np.polyfit(d, y, 1)
    return float(p), float(math.exp(logc))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[8, 16, 32])
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--child", type=int, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child:
        print(json.dumps(child(a.child, a.steps)))
        return 0
    rows = []
    print(f"{'yarns':>7} {'dofs':>7} {'nnz':>9} {'steps':>5} {'relax s':>8} {'assembly s/step':>15} "
          f"{'factorise s (count)':>20} {'fact. s/step':>12} {'back-solve ms (count)':>22} {'stage solve s/step':>18} "
          f"{'step s':>7} {'pairs':>6} {'RSS MB':>7}")
    for n in a.sizes:
        proc = subprocess.run([sys.executable, __file__, "--child", str(n), "--steps", str(a.steps)],
                              capture_output=True, text=True)
        if proc.returncode:
            print(f"{n}x{n}: failed\n{proc.stderr[-2000:]}")
            return 1
        r = json.loads(proc.stdout.strip().splitlines()[-1])
        rows.append(r)
        print(f"{n:>3}x{n:<3} {r['dofs']:7d} {r['nnz']:9d} {r['steps']:5d} {r['relax_s']:8.1f} {r['assembly_s']:15.3f} "
              f"{r['factorize_s']:13.3f} ({r['factorizations']:3d}) {r['factorize_per_step_s']:12.3f} "
              f"{r['solve_ms']:14.2f} ({r['solves']:4d}) {r['stage_solve_per_step_s']:18.3f} {r['step_s']:7.3f} "
              f"{r['contact_pairs_max']:6d} {r['peak_rss_mb']:7.0f}", flush=True)
    if len(rows) < 2:
        return 0
    big = rows[-1]["dofs"] * (128 / rows[-1]["n"]) ** 2
    print(f"growth exponents, cost ~ dofs^p (fitted over {len(rows)} sizes); extrapolated to 128x128 "
          f"({big:,.0f} dofs at the same pitch and element length):")
    for key, what in (("nnz", "stored entries"), ("assembly_s", "assembly s/step"), ("factorize_s", "one factorisation s"),
                      ("solve_ms", "one back-solve ms"), ("stage_solve_per_step_s", "stage solve s/step"),
                      ("step_s", "step s"), ("peak_rss_mb", "peak RSS MB")):
        p, c = fit(rows, key)
        print(f"  {what:<22} p = {p:5.2f}   at 128x128: {c * big ** p:12.4g}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
