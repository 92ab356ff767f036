"""Cost of a static strain-like step with friction against the frictionless one, on a relaxed
RVE state: the affine field of the first strain increment (shear or uniaxial) applied to
every node, the pinned ends exactly on their targets, then the static equilibrium by the
energy minimiser (mu = 0: ``cell_statics.static_minimize``) and with friction from the relaxed
state's history (mu > 0) in ``--substeps`` equal sub-increments of the field (default 1: the
whole increment), each committed, by ``--method potential`` (default:
``rve.solvers.frictional.frictional_solve``, the energy minimiser on the incremental potential
at frozen loads, then Newton on the exact residual) or ``--method newton`` (the residual path
of before: the capped Newton, then pseudo-transient continuation). ``--compare`` solves the
first run's frictional step by the other method too and prints the difference of the two
states and dissipations. Prints per run the wall and CPU times, iterations, the phases
(predictor stages, corrector, fallback: iterations, wall times, the exact residuals), the
stick/slip counts and the peak RSS; then the medians and their ratios (one process,
alternating). ``--log``: the solvers' iterations (``rve.newton``: the corrector's rates).

    nice -n 10 python benchmarks/friction_cost.py RELAXED.nc [--mode shear] [--mu 0.2] [--runs 3]
    nice -n 10 python benchmarks/friction_cost.py --small [--elements 12]   (a 4x4 plain weave, one
        fibril per yarn, relaxed here first)

(The strain steps of the pipeline also have the driven and the damped phases, whose
dynamics are not frictional yet: this measures the static solve only.)
"""
import argparse
import dataclasses
import json
import resource
import time

import numpy as np

from rve.config.rve import RVEConfig
from rve.fabrics.setup import clamped_ends, contact_params, fabric_and_mesh, mechanics_system
from rve.homogenisation.cell_statics import static_minimize
from rve.homogenisation.checkpoint import load_state
from rve.homogenisation.strain import affine_velocity, end_targets
from rve.model.terms.friction import FrictionLaw
from rve.solvers.frictional import frictional_solve
from rve.solvers.minimize import capped_newton
from rve.solvers.static import pseudo_transient_solve


def _short(values, head=4, tail=8):
    """A residual history for printing: all of it, or its head and tail."""
    v = [float(f"{r:.3g}") for r in values]
    return v if len(v) <= head + tail else v[:head] + ["..."] + v[-tail:]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("state", nargs="?")
    ap.add_argument("--small", action="store_true")
    ap.add_argument("--elements", type=int, default=12)
    ap.add_argument("--substeps", type=int, default=1)
    ap.add_argument("--mode", default="shear")
    ap.add_argument("--mu", type=float, default=0.2)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--method", default="potential", choices=["potential", "newton"],
                    help="frictional solve: the potential predictor + Newton corrector (frictional_solve), "
                         "or the capped residual Newton + pseudo-transient of before")
    ap.add_argument("--freeze", default="committed", choices=["committed", "current"])
    ap.add_argument("--load-rtol", type=float, default=0.05)
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--rounds-mode", action="store_true",
                    help="predictor rounds at fixed loads (refrozen between rounds) instead of the loads refrozen "
                         "at every accepted iterate")
    ap.add_argument("--predictor-rtol", type=float, default=1e-4)
    ap.add_argument("--smoothing", type=float, nargs="*", default=[1.0],
                    help="continuation: predictor stages with the cone's corner rounded by these eta, then eta = 0")
    ap.add_argument("--compare", action="store_true",
                    help="also solve every frictional step with the other method and print the difference")
    ap.add_argument("--log", action="store_true",
                    help="log the solvers (rve.newton: the corrector's iterations and rates; the predictor rounds)")
    a = ap.parse_args()
    if a.log:
        import logging
        logging.basicConfig(level=logging.WARNING, format="%(name)s: %(message)s")
        for name in ("rve.newton", "rve.solvers.frictional"):
            logging.getLogger(name).setLevel(logging.INFO)
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

    def frictional(system, method):
        x, its, ok, detail = xr.copy(), 0, True, []
        for k in range(1, a.substeps + 1):
            x = x + affine_velocity(origin, a.mode, eps / a.substeps)
            x[ends, :3] = end_targets(origin[ends, :3], a.mode, eps * k / a.substeps)
            if method == "potential":
                system.rebuild(x.reshape(-1))
                xs, res = frictional_solve(system, x.reshape(-1), 0.0, atol=atol, rtol=1e-12, max_iter=iters,
                                           freeze=a.freeze, load_rtol=a.load_rtol, max_rounds=a.rounds,
                                           refreeze=not a.rounds_mode, predictor_rtol=a.predictor_rtol,
                                           smoothing=a.smoothing)
                if res.converged:
                    system.term.friction.commit(xs)
                detail.append({"rounds": res.rounds, "predictor": res.predictor_iterations,
                               "corrector": res.corrector_iterations, "fallback": res.fallback_iterations,
                               "load_changes": [float(f"{v:.3g}") for v in res.load_changes],
                               "walls_s": [round(v, 2) for v in res.walls],
                               "residuals": _short(res.residuals)})
                x, its, ok = xs.reshape(xr.shape), its + res.iterations, res.converged
            else:
                out = relax_to_equilibrium_old(system, x.reshape(-1))
                x, its, ok = out[0].reshape(xr.shape), its + out[1], out[2]
                detail.append({"iterations": out[1]})
            if not ok:
                break
        return x.reshape(-1), its, ok, detail

    def relax_to_equilibrium_old(system, x):
        """The residual path of before: the capped Newton, then pseudo-transient continuation."""
        system.rebuild(x)
        cap = 0.5 * float(system.params.margin)
        xs, _, res = capped_newton(system, x, 0.0, atol=atol, rtol=1e-12, max_iter=iters, step_cap=cap)
        its = res.iterations
        if not res.converged:
            system.rebuild(xs)
            xs, _, res = pseudo_transient_solve(system, xs, np.zeros(system.n), 0.0, atol=atol, rtol=1e-12,
                                                max_iter=200)
            its += res.iterations
        if res.converged:
            system.term.friction.commit(xs)
        return xs, its, res.converged

    def frictional_system():
        params = dataclasses.replace(base, friction=FrictionLaw(a.mu))
        sys1 = mechanics_system(fab, mesh, cfg, params, 0.0, x0)
        sys1.term.friction.set_families(fab.fibril_direction)
        sys1.term.friction.commit(x0)          # the relaxed state's history: no elastic gap
        return sys1

    atol, iters = cfg.strain.static_atol, cfg.strain.static_max_iter
    base = contact_params(cfg.contact, rebuild_every=cfg.strain.rebuild_every, conduction=False)
    times = {"frictionless": [], "friction": []}
    cpu = {"frictionless": [], "friction": []}
    its_all = {"frictionless": [], "friction": []}
    for run in range(a.runs):
        sys0 = mechanics_system(fab, mesh, cfg, base, 0.0, x0)
        t0, c0 = time.perf_counter(), time.process_time()
        xa, info = static_minimize(sys0, x1, atol, iters)
        times["frictionless"].append(time.perf_counter() - t0)
        cpu["frictionless"].append(time.process_time() - c0)
        its_all["frictionless"].append(info["iterations"])
        sys1 = frictional_system()
        t0, c0 = time.perf_counter(), time.process_time()
        xf, its, ok, detail = frictional(sys1, a.method)
        times["friction"].append(time.perf_counter() - t0)
        cpu["friction"].append(time.process_time() - c0)
        its_all["friction"].append(its)
        pts = sys1.term.friction.points()
        rec = {"run": run, "frictionless_s": round(times["frictionless"][-1], 2),
               "frictionless_cpu_s": round(cpu["frictionless"][-1], 2),
               "frictionless_converged": info["converged"], "frictionless_iterations": info["iterations"],
               "friction_s": round(times["friction"][-1], 2), "friction_cpu_s": round(cpu["friction"][-1], 2),
               "friction_converged": ok, "friction_iterations": its, "method": a.method, "substeps": a.substeps,
               "phases": detail, "stick": pts["stick"], "slip": pts["slip"],
               "max_centroid_difference_mm": float(np.abs((xf - xa).reshape(-1, 9)[:, :3]).max()),
               "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, 1)}
        if a.compare and run == 0:
            other = "newton" if a.method == "potential" else "potential"
            sys2 = frictional_system()
            t0 = time.perf_counter()
            xo, its_o, ok_o, _ = frictional(sys2, other)
            rec["compare"] = {"method": other, "converged": ok_o, "iterations": its_o,
                              "wall_s": round(time.perf_counter() - t0, 2),
                              "max_dof_difference": float(np.abs(xo - xf).max()),
                              "max_centroid_difference_mm": float(np.abs((xo - xf).reshape(-1, 9)[:, :3]).max()),
                              "dissipated_N_mm": [sys1.term.friction.dissipated, sys2.term.friction.dissipated]}
        print(json.dumps(rec), flush=True)
    m0, m1 = np.median(times["frictionless"]), np.median(times["friction"])
    c0_, c1_ = np.median(cpu["frictionless"]), np.median(cpu["friction"])
    print(f"{a.mode} step 1 of {label}: {mesh.n_elements} elements, mu = {a.mu}: median static solve "
          f"{m0:.2f} s wall / {c0_:.2f} s CPU, {np.median(its_all['frictionless']):.0f} iterations frictionless "
          f"(minimiser); {m1:.2f} s wall / {c1_:.2f} s CPU, {np.median(its_all['friction']):.0f} iterations with "
          f"friction ({a.method}, {a.substeps} sub-increments): ratio {m1 / m0:.2f} wall, {c1_ / c0_:.2f} CPU; "
          f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0:.0f} MB")

if __name__ == "__main__":
    main()
