"""Cost of a static strain-like step with friction against the frictionless one, on a relaxed
RVE state: the affine field of the first strain increment (shear or uniaxial) applied to
every node, the pinned ends exactly on their targets, then the static equilibrium by the energy minimiser (mu = 0: ``cell_statics.static_minimize``)
and by the frictional residual Newton from the relaxed state's history (mu > 0: the capped
Newton of ``relax_to_equilibrium``, then the commit) in ``--substeps`` equal sub-increments of
the field, each committed (one increment fails to converge on the weave: the slip directions
flip between iterates; see docs/contact.md "Friction"). Prints wall times, Newton iterations
and the median ratio over the runs (one process, alternating).

    nice -n 10 python benchmarks/friction_cost.py RELAXED.nc [--mode shear] [--mu 0.2] [--runs 3]
    nice -n 10 python benchmarks/friction_cost.py --small [--elements 12]   (a 4x4 plain weave, one
        fibril per yarn, relaxed here first)

(The strain steps of the pipeline also have the driven and the damped phases, whose
dynamics are not frictional yet: this measures the static solve only.)
"""
import argparse
import dataclasses
import json
import time

import numpy as np

from rve.config.rve import RVEConfig
from rve.fabrics.setup import clamped_ends, contact_params, fabric_and_mesh, mechanics_system
from rve.homogenisation.cell_statics import static_minimize
from rve.homogenisation.checkpoint import load_state
from rve.homogenisation.strain import affine_velocity, end_targets
from rve.model.terms.friction import FrictionLaw
from rve.solvers.relaxation import RelaxSettings, relax_to_equilibrium


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("state", nargs="?")
    ap.add_argument("--small", action="store_true")
    ap.add_argument("--elements", type=int, default=12)
    ap.add_argument("--substeps", type=int, default=2)
    ap.add_argument("--mode", default="shear")
    ap.add_argument("--mu", type=float, default=0.2)
    ap.add_argument("--runs", type=int, default=3)
    a = ap.parse_args()
    if a.small:
        from rve.fabrics.relaxation import relax

        cfg = RVEConfig(scene="rve", fabric={"kind": "plain", "rows": [1]}, mesh={"elements": a.elements})
        fab, mesh = fabric_and_mesh(cfg)
        relaxed = relax(cfg)
        xr = relaxed.x.reshape(-1, 9)
        origin, label = xr, f"a relaxed 4x4 plain weave ({a.elements} el/fibril, one fibril per yarn)"
    else:
        st = load_state(a.state)
        cfg = RVEConfig.model_validate(st.config)
        fab, mesh = fabric_and_mesh(cfg)
        xr, origin, label = st.x, st.origin, a.state
    x0 = xr.reshape(-1)
    ends, _, _ = clamped_ends(fab, mesh)
    eps = cfg.strain.total / cfg.strain.steps
    x1 = xr + affine_velocity(origin, a.mode, eps)   # the driven phase's field over the step
    x1[ends, :3] = end_targets(origin[ends, :3], a.mode, eps)
    x1 = x1.reshape(-1)

    def frictional(system):
        x, its, ok = xr.copy(), 0, True
        for k in range(1, a.substeps + 1):
            x = x + affine_velocity(origin, a.mode, eps / a.substeps)
            x[ends, :3] = end_targets(origin[ends, :3], a.mode, eps * k / a.substeps)
            out = relax_to_equilibrium(system, x.reshape(-1), np.zeros(system.n), RelaxSettings(
                duration=1.0, steps=1, method="energy", static_atol=atol, static_max_iter=iters))
            x, its, ok = out.x.reshape(xr.shape), its + out.static_newton_iterations, out.static_converged
            if not ok:
                break
        return x.reshape(-1), its, ok
    atol, iters = cfg.strain.static_atol, cfg.strain.static_max_iter
    base = contact_params(cfg.contact, rebuild_every=cfg.strain.rebuild_every, conduction=False)
    times = {"frictionless": [], "friction": []}
    for run in range(a.runs):
        sys0 = mechanics_system(fab, mesh, cfg, base, 0.0, x0)
        t0 = time.perf_counter()
        xa, info = static_minimize(sys0, x1, atol, iters)
        times["frictionless"].append(time.perf_counter() - t0)
        params = dataclasses.replace(base, friction=FrictionLaw(a.mu))
        sys1 = mechanics_system(fab, mesh, cfg, params, 0.0, x0)
        sys1.term.friction.set_families(fab.fibril_direction)
        sys1.term.friction.commit(x0)          # the relaxed state's history: no elastic gap
        t0 = time.perf_counter()
        xf, its, ok = frictional(sys1)
        times["friction"].append(time.perf_counter() - t0)
        pts = sys1.term.friction.points()
        print(json.dumps({"run": run, "frictionless_s": round(times["frictionless"][-1], 2),
                          "frictionless_converged": info["converged"], "frictionless_iterations": info["iterations"],
                          "friction_s": round(times["friction"][-1], 2), "friction_converged": ok,
                          "friction_iterations": its, "substeps": a.substeps,
                          "stick": pts["stick"], "slip": pts["slip"],
                          "max_centroid_difference_mm": float(np.abs((xf - xa).reshape(-1, 9)[:, :3]).max())}))
    m0, m1 = np.median(times["frictionless"]), np.median(times["friction"])
    print(f"{a.mode} step 1 of {label}: {mesh.n_elements} elements, mu = {a.mu}: median static solve "
          f"{m0:.2f} s frictionless (minimiser), {m1:.2f} s with friction (residual Newton, {a.substeps} "
          f"sub-increments): ratio {m1 / m0:.2f}")


if __name__ == "__main__":
    main()
