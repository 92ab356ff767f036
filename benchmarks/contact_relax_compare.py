"""The plain-weave relaxation (configs/scenes/plain_weave_relax.yaml) with the chord, the
curve and the smooth contact geometry: wall time, whether every stage converged (and why not), the relaxed
energy, the final residual and contact statistics (docs/contact.md "Contact on the centroid
curve"). One run per geometry; minutes at 30 el/fibril.

Usage: nice -n 10 python benchmarks/contact_relax_compare.py [elements ...] [--geometry G ...]
(default 12 elements; every geometry); with three or more meshes the observed order and the limit
of the energy and the total normal force per geometry (also of an earlier log:
python benchmarks/contact_relax_compare.py --orders LOG). Wall and CPU time (all threads; on a shared machine the
CPU time is the measure of the work). Per stage: where the Newton iterations go (factorisations,
rejections, rebuilds, steps shortened by the cap or the backtracking); per mesh: the ratios of wall
time, iterations, energy and total normal force of each geometry to the last one given. The final
state of each run is saved to
/tmp/contact_relax_<geometry>_<elements>.npy (benchmarks/contact_kink_diagnosis.py reads it).
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from rve.config.loader import load_config
from rve.scenes.fabric_relax import solve

ROOT = Path(__file__).resolve().parents[1]


def run(geometry: str, elements: int) -> None:
    cfg = load_config(ROOT / "configs/scenes/plain_weave_relax.yaml",
                      [f"mesh.elements={elements}", f"contact.geometry={geometry}"])
    t0, c0 = time.perf_counter(), time.process_time()
    res = solve(cfg)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    sm = res.summary
    stages = [(h.get("mesh_elements"), h.get("onset_over_R"), h.get("converged"), h.get("newton_iterations"),
               h.get("reason") or "", _stage_record(h)) for h in sm.get("history", [])]
    st = res.model.contact_state(res.state["x"])
    np.save(f"/tmp/contact_relax_{geometry}_{elements}.npy", np.asarray(res.state["x"], float).reshape(-1))
    print(f"{geometry:6s} {elements} el: wall {wall:.1f} s (CPU {cpu:.1f} s), energy {sm.get('energy_mJ'):.6f} mJ, final |F| "
          f"{sm['static_residuals'][-1]:.2e} N, stable {sm.get('stable')}, total normal force "
          f"{st['total_normal_force']:.3f} N, max overlap {st['max_overlap_over_R']:.4f} R", flush=True)
    for el, onset, conv, its, why, rec in stages:
        print(f"      stage {el} el, onset {onset} R: converged {conv}, {its} Newton iterations {why[:110]}",
              flush=True)
        print(f"        {rec}", flush=True)
    return {"wall": wall, "cpu": cpu, "iterations": sum(s[3] or 0 for s in stages), "energy": sm.get("energy_mJ"),
            "force": st["total_normal_force"]}


def _stage_record(h) -> str:
    """Where a stage's Newton iterations go: the factorisations and the regularised ones,
    the rejected steps, the map rebuilds, the accepted steps shortened by the centroid cap or
    the energy backtracking (alpha < 1), and the iterations from the last shortened step to
    convergence (the quadratic tail)."""
    steps = np.asarray(h.get("steps", []), float)
    sig = np.asarray(h.get("sigmas", []), float)
    short = np.flatnonzero(steps < 1.0)
    tail = steps.size - (short[-1] + 1) if short.size else steps.size
    res = h.get("residuals", [])
    en = h.get("energies", [])
    path = f"; energy {en[0]:.6f} -> {en[-1]:.6f} mJ" if en else ""
    return (f"factorisations {h.get('factorizations')} (indefinite {h.get('indefinite')}), rejections "
            f"{h.get('rejections')}, map rebuilds {h.get('map_rebuilds')}, steps with alpha < 1: {short.size}, "
            f"regularised (sigma > 0): {int((sig > 0).sum())}, full steps after the last short one: {tail}; "
            f"|F| {res[0] if res else float('nan'):.2e} -> {res[-1] if res else float('nan'):.2e} N{path}")


def observed_order(ns, values):
    """Observed order p and limit of ``values`` on three meshes ``ns`` (elements per fibril)
    under ``v(n) = v_inf + C n^-p``: p from the ratio of the two differences (bisection on
    (0, 8]), then v_inf; (nan, nan) when the differences change sign (not in the asymptotic
    range)."""
    n, v = np.asarray(ns, float), np.asarray(values, float)
    q = (v[0] - v[1]) / (v[1] - v[2])
    if not np.isfinite(q) or q <= 0:
        return float("nan"), float("nan")

    def ratio(p):
        return (n[0] ** -p - n[1] ** -p) / (n[1] ** -p - n[2] ** -p) - q

    lo, hi = 1e-6, 8.0
    if ratio(lo) * ratio(hi) > 0:
        return float("nan"), float("nan")
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ratio(lo) * ratio(mid) > 0 else (lo, mid)
    p = 0.5 * (lo + hi)
    C = (v[1] - v[2]) / (n[1] ** -p - n[2] ** -p)
    return p, float(v[2] - C * n[2] ** -p)


def print_orders(results) -> None:
    """Per geometry, on the three finest meshes of ``results`` {(geometry, elements): figures}:
    the relaxed energy and the total normal force, their observed order and the limit."""
    for g in sorted({k[0] for k in results}):
        ns = sorted(el for (gg, el) in results if gg == g)[-3:]
        if len(ns) < 3:
            continue
        for key, unit in (("energy", "mJ"), ("force", "N")):
            vals = [results[(g, el)][key] for el in ns]
            p, lim = observed_order(ns, vals)
            figs = ", ".join(f"{el} el {v:.6g}" for el, v in zip(ns, vals))
            print(f"  {g:6s} {key:6s} ({unit}): {figs}; observed order {p:.2f}, limit {lim:.6g}", flush=True)


def results_of_log(path) -> dict:
    """{(geometry, elements): {"energy", "force"}} of the run lines of an earlier log."""
    import re

    pat = re.compile(r"^(\w+)\s+(\d+) el: wall .*energy ([0-9.eE+-]+) mJ.*total normal force ([0-9.eE+-]+) N")
    out = {}
    for line in Path(path).read_text().splitlines():
        m = pat.match(line)
        if m:
            out[(m.group(1), int(m.group(2)))] = {"energy": float(m.group(3)), "force": float(m.group(4))}
    return out


def main(argv=None) -> None:
    args = list(argv if argv is not None else sys.argv[1:])
    if args and args[0] == "--orders":
        print_orders(results_of_log(args[1]))
        return
    geometries = ["chord", "curve", "smooth"]
    if "--geometry" in args:
        k = args.index("--geometry")
        geometries, args = args[k + 1:], args[:k]
    els = [int(a) for a in args] or [12]
    results = {}
    for el in els:
        out = {g: run(g, el) for g in geometries}
        results.update({(g, el): v for g, v in out.items()})
        ref = geometries[-1]
        for g in geometries[:-1]:
            a, b = out[g], out[ref]
            print(f"  {el} el {g} / {ref}: wall {a['wall'] / b['wall']:.2f}, CPU {a['cpu'] / b['cpu']:.2f}, "
                  f"Newton iterations "
                  f"{a['iterations'] / max(b['iterations'], 1):.2f}, energy {a['energy'] / b['energy']:.4f}, "
                  f"total normal force {a['force'] / b['force']:.4f}", flush=True)
    print_orders(results)


if __name__ == "__main__":
    main()
