"""The augmented Lagrangian in the RVE pipeline (docs/contact.md "Augmented Lagrangian in the
RVE pipeline").

(a) ``penalty``: the 2x2 plain-weave cell (pinned and periodic, 6 el/fibril, onset 0.05 R),
relaxed and strained 5 % uniaxially in one step, with the penalty and with the augmented
Lagrangian at P* = 50 and 150 N/mm^2: per run the x+ face force, the largest overlap (true
overlap for AL, over R), the Uzawa updates of the step, and the probes of the strained state
(resistance, Joule temperature); then per enforcement the relative change of each of these
table quantities from P* = 50 to 150 (the penalty part).

(b) ``cost``: the work-precision candidate (configs/rve/plain_weave_periodic.yaml, p = 2,
P* = 150, ``elements`` el/fibril), one uniaxial and one shear step (2.5 %) from the relaxed
state of each enforcement: CPU time of the step with the penalty, with the augmented
Lagrangian of the plain Uzawa loop (``al_penalty_growth: 1``) and with the penalty increase
(default 4; other ``growths`` on the command line), each ``repeats`` times; the median CPU time, its ratio to the penalty's, the Uzawa
updates, the minimiser iterations and the largest overlap.

(c) ``bits``: the penalty default's states (2x2 cell, pinned and periodic, static method
energy and newton: the relaxed state and two 5 % steps of uniaxial and shear) written to an
npz; run it under two trees and compare array by array:

    PYTHONPATH=/work/main python benchmarks/rve_augmented.py bits /tmp/a.npz
    PYTHONPATH=. python benchmarks/rve_augmented.py bits /tmp/b.npz
    python benchmarks/rve_augmented.py compare /tmp/a.npz /tmp/b.npz

Usage: nice -n 10 python benchmarks/rve_augmented.py [penalty|cost|all] [elements] [repeats] [growths]
       (default: all 6 3 1,4; growths: the al_penalty_growth values of the AL rows)
"""
from __future__ import annotations

import statistics
import sys
import time

import numpy as np

from rve.config.rve import RVEConfig
from rve.fabrics.setup import clamp_reactions, fabric_and_mesh
from rve.homogenisation.multipliers import multiplier_record
from rve.homogenisation.probes import solve_probes
from rve.homogenisation.strain import relax_fabric, strain_step
from rve.homogenisation.sweeps import load_run_config


def _overlap(system, x) -> float:
    xf = np.asarray(x, float).reshape(-1)
    return system.max_penetration(xf) if system.augmented else system.contact_state(xf)["max_overlap_over_R"]


def penalty_run(boundary: str, enforcement: str, penalty: float, tol: float = 1e-4) -> dict:
    t0 = time.perf_counter()
    cfg = RVEConfig(scene="rve", boundary=boundary, fabric={"kind": "plain", "rows": [1]}, mesh={"elements": 6},
                    contact={"onset": 0.05, "enforcement": enforcement, "penalty": penalty, "al_tolerance": tol},
                    strain={"total": 0.05, "steps": 1})
    fab, mesh = fabric_and_mesh(cfg)
    x0, sys0, info0 = relax_fabric(cfg, fab, mesh, fab.initial_state(mesh))
    x, system, info = strain_step(cfg, fab, mesh, x0, x0, "uniaxial", 1, multipliers=multiplier_record(sys0))
    reac = info.get("reaction_force") or clamp_reactions(fab, system, x)
    probes = solve_probes(cfg, fab, mesh, x, multipliers=multiplier_record(system))
    al = info["static"].get("augmented_lagrangian", {})
    out = {"force_N": float(reac["x+"][0])}
    for name, r in sorted(probes.items()):
        out[f"R_{name}_ohm"] = float(r.resistance)
        out[f"Tmax_{name}_K"] = float(r.temperature_max)
    print(f"{boundary:8s} {enforcement:20s} P* {penalty:5.0f}: converged {info0['converged']}/{info['converged']}, "
          + ", ".join(f"{k} {v:.9g}" for k, v in out.items())
          + f", max overlap {_overlap(system, x):.2e} R, step updates {al.get('updates', '-')}, "
            f"wall {time.perf_counter() - t0:.1f} s", flush=True)
    return out


def penalty_part() -> None:
    for boundary in ("pinned", "periodic"):
        for enforcement in ("penalty", "augmented_lagrangian"):
            f = {p: penalty_run(boundary, enforcement, p) for p in (50.0, 150.0)}
            print(f"{boundary:8s} {enforcement:20s} |q(150)/q(50) - 1|: "
                  + ", ".join(f"{k} {abs(f[150.0][k] / f[50.0][k] - 1.0):.2e}" for k in f[50.0]), flush=True)


def _candidate(elements: int, enforcement: str, growth: float = 4.0):
    spec = {"scene_config": "configs/rve/plain_weave_periodic.yaml",
            "overrides": ["output.pictures=false", "mesh.order=2", f"mesh.elements={elements}",
                          "contact.penalty=150 N/mm^2", f"contact.enforcement={enforcement}",
                          f"contact.al_penalty_growth={growth}", "relaxation.static_max_iter=600"]}
    return load_run_config(spec)


def cost(elements: int, repeats: int, growths=(1.0, 4.0)) -> None:
    schemes = [("penalty", "penalty", 4.0)] + [
        ("AL plain Uzawa" if g == 1 else f"AL P* growth x{g:g}", "augmented_lagrangian", g) for g in growths]
    relaxed = {}
    for enforcement in ("penalty", "augmented_lagrangian"):
        cfg = _candidate(elements, enforcement)
        fab, mesh = fabric_and_mesh(cfg)
        t0 = time.process_time()
        x0, sys0, info0 = relax_fabric(cfg, fab, mesh, fab.initial_state(mesh))
        al = info0.get("static", {}).get("augmented_lagrangian", {})
        print(f"relaxed ({enforcement}): converged {info0['converged']}, CPU {time.process_time() - t0:.1f} s, "
              f"updates {al.get('updates', '-')}, max overlap {al.get('max_penetration_over_R', float('nan')):.2e} R",
              flush=True)
        relaxed[enforcement] = (fab, mesh, x0, multiplier_record(sys0))
    medians = {}
    for mode in ("uniaxial", "shear"):
        for label, enforcement, growth in schemes:
            cfg = _candidate(elements, enforcement, growth)
            fab, mesh, x0, rec = relaxed[enforcement]
            times = []
            for _ in range(repeats):
                t0 = time.process_time()
                x, system, info = strain_step(cfg, fab, mesh, x0, x0, mode, 1, multipliers=rec)
                times.append(time.process_time() - t0)
            st = info["static"]
            al = st.get("augmented_lagrangian", {})
            med = statistics.median(times)
            medians[mode, label] = med
            ratio = med / medians[mode, "penalty"]
            print(f"{mode:8s} {label:20s}: CPU median {med:7.2f} s of {repeats} (x{ratio:5.1f} the penalty's), "
                  f"converged {info['converged']}, updates {al.get('updates', '-')}, solves {al.get('solves', 1)}, "
                  f"P* {al.get('penalties', '-')}, minimiser iterations per solve "
                  f"{al.get('solve_iterations', [st.get('iterations')])}, "
                  f"max overlap {_overlap(system, x):.2e} R, met {al.get('met', '-')}", flush=True)


def penalty_bits(path: str) -> None:
    out = {}
    for boundary in ("pinned", "periodic"):
        for method in ("energy", "newton"):
            cfg = RVEConfig(scene="rve", boundary=boundary, fabric={"kind": "plain", "rows": [1]},
                            mesh={"elements": 6}, contact={"onset": 0.05},
                            strain={"total": 0.1, "steps": 2, "static_method": method, "modes": ["uniaxial", "shear"]})
            fab, mesh = fabric_and_mesh(cfg)
            x0, _, _ = relax_fabric(cfg, fab, mesh, fab.initial_state(mesh))
            out[f"{boundary}_{method}_relaxed"] = x0
            for mode in ("uniaxial", "shear"):
                x = x0
                for step in (1, 2):
                    x, _, _ = strain_step(cfg, fab, mesh, x, x0, mode, step)
                    out[f"{boundary}_{method}_{mode}_{step}"] = x
    np.savez(path, **out)


def compare_bits(a_path: str, b_path: str) -> None:
    a, b = np.load(a_path), np.load(b_path)
    same = [k for k in a.files if k in b.files and np.array_equal(a[k], b[k])]
    print(f"{len(same)} of {len(a.files)} state arrays bit-identical" +
          ("" if len(same) == len(a.files) else f"; differ: {sorted(set(a.files) - set(same))}"))


def main(argv=None) -> None:
    args = argv if argv is not None else sys.argv[1:]
    what = args[0] if args else "all"
    if what == "bits":
        return penalty_bits(args[1])
    if what == "compare":
        return compare_bits(args[1], args[2])
    elements = int(args[1]) if len(args) > 1 else 6
    repeats = int(args[2]) if len(args) > 2 else 3
    if what in ("penalty", "all"):
        penalty_part()
    if what in ("cost", "all"):
        cost(elements, repeats, tuple(float(g) for g in args[3].split(",")) if len(args) > 3 else (1.0, 4.0))


if __name__ == "__main__":
    main()
