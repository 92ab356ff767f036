"""The plain-weave relaxation (configs/scenes/plain_weave_relax.yaml) with the chord, the
curve and the smooth contact geometry: wall time, whether every stage converged (and why not), the relaxed
energy, the final residual and contact statistics (docs/contact.md "Contact on the centroid
curve"). One run per geometry; minutes at 30 el/fibril.

Usage: nice -n 10 python benchmarks/contact_relax_compare.py [elements ...] [--geometry G ...]
(default 12 elements; every geometry). Wall and CPU time (all threads; on a shared machine the
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


def main(argv=None) -> None:
    args = list(argv if argv is not None else sys.argv[1:])
    geometries = ["chord", "curve", "smooth"]
    if "--geometry" in args:
        k = args.index("--geometry")
        geometries, args = args[k + 1:], args[:k]
    els = [int(a) for a in args] or [12]
    for el in els:
        out = {g: run(g, el) for g in geometries}
        ref = geometries[-1]
        for g in geometries[:-1]:
            a, b = out[g], out[ref]
            print(f"  {el} el {g} / {ref}: wall {a['wall'] / b['wall']:.2f}, CPU {a['cpu'] / b['cpu']:.2f}, "
                  f"Newton iterations "
                  f"{a['iterations'] / max(b['iterations'], 1):.2f}, energy {a['energy'] / b['energy']:.4f}, "
                  f"total normal force {a['force'] / b['force']:.4f}", flush=True)


if __name__ == "__main__":
    main()
