"""The augmented Lagrangian in the RVE pipeline (docs/contact.md "Augmented Lagrangian in the
RVE pipeline"): the 2x2 plain-weave cell (pinned and periodic, 6 el/fibril, onset 0.05 R),
relaxed and strained 5 % uniaxially in one step, with the penalty and with the augmented
Lagrangian at P* = 50 and 150 N/mm^2. Prints per run the x+ face force, the largest overlap
(true overlap for AL, over R), the Uzawa updates of the strain step and the wall time, then
the relative change of the force from P* = 50 to 150 per enforcement.

Usage: nice -n 10 python benchmarks/rve_augmented.py [al_tolerance]   (default 1e-4)
"""
from __future__ import annotations

import sys
import time

from rve.fabrics.setup import clamp_reactions, fabric_and_mesh
from rve.config.rve import RVEConfig
from rve.homogenisation.multipliers import multiplier_record
from rve.homogenisation.strain import relax_fabric, strain_step


def run(boundary: str, enforcement: str, penalty: float, tol: float) -> float:
    t0 = time.perf_counter()
    cfg = RVEConfig(scene="rve", boundary=boundary, fabric={"kind": "plain", "rows": [1]}, mesh={"elements": 6},
                    contact={"onset": 0.05, "enforcement": enforcement, "penalty": penalty, "al_tolerance": tol},
                    strain={"total": 0.05, "steps": 1})
    fab, mesh = fabric_and_mesh(cfg)
    x0, sys0, info0 = relax_fabric(cfg, fab, mesh, fab.initial_state(mesh))
    x, system, info = strain_step(cfg, fab, mesh, x0, x0, "uniaxial", 1, multipliers=multiplier_record(sys0))
    reac = info.get("reaction_force") or clamp_reactions(fab, system, x)
    xf = x.reshape(-1)
    overlap = system.max_penetration(xf) if system.augmented else system.contact_state(xf)["max_overlap_over_R"]
    al = info["static"].get("augmented_lagrangian", {})
    fx = float(reac["x+"][0])
    print(f"{boundary:8s} {enforcement:20s} P* {penalty:5.0f}: relax/step converged {info0['converged']}/"
          f"{info['converged']}, F_x+ {fx:.9f} N, max overlap {overlap:.2e} R, step updates "
          f"{al.get('updates', '-')}, wall {time.perf_counter() - t0:.1f} s", flush=True)
    return fx


def main(argv=None) -> None:
    args = argv if argv is not None else sys.argv[1:]
    tol = float(args[0]) if args else 1e-4
    for boundary in ("pinned", "periodic"):
        for enforcement in ("penalty", "augmented_lagrangian"):
            f = {p: run(boundary, enforcement, p, tol) for p in (50.0, 150.0)}
            print(f"{boundary:8s} {enforcement:20s} |F(150)/F(50) - 1| = {abs(f[150.0] / f[50.0] - 1.0):.2e}",
                  flush=True)


if __name__ == "__main__":
    main()
