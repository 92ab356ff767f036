"""Factorisation reuse (adaptive modified Newton, ``integrate(jacobian_reuse=...)``) in a
mass-dominated, impact-like SDIRK2 run: does it pay? (issue 10, item 2; docs/time_integration.md
"Factorisation reuse (modified Newton)".)

    python benchmarks/stage_reuse.py [--n 8] [--elements 20] [--steps 40] [--h 5e-4] [--v0 10]
                                     [--repeats 3] [--variants off,on,auto] [--backend NAME]
    python benchmarks/stage_reuse.py --strain [--strain-fabric 2] [--repeats 3]

A real dynamic run: an n × n plain weave of single-fibril yarns (d = 0.3 mm, spacing 1 mm,
crimp amplitude R, the RVE material of configs/rve/plain_weave.yaml, no damping), linear
elements, fibril ends pinned, directors free with a twist gauge, contact on; initial
velocity -v0 e_z (mm/ms) on the centroids of the warp fibrils' nodes within 2 mm of the
centre (|x|, |y| < 2), which drives them into the weft fibrils under them; SDIRK2
(rve.solvers.dirk.integrate, fixed step h, ms, default Newton tolerances).

Variants (each run from the same initial state, interleaved A B C A B C ... so a drifting
machine load hits them alike): ``off`` = full Newton (one factorisation per iteration,
today's default), ``on`` = ``jacobian_reuse=True``, ``auto`` = ``jacobian_reuse="auto"``
(also the measured cost rule). Printed per variant: median wall time and its ratio to
``off`` measured in the same run (``full``: full Newton on ``--backend``, for the ratio at
equal linear solver), Newton iterations, Jacobian evaluations, factorisations,
reused iterations, rejected modified steps, full-Newton stage retries, the contractions and
why factorisations were dropped; then the final-state difference of each variant against
full Newton, next to the difference between full Newton at the default tolerance and at a
100× tighter one (the scale of "equal to the Newton tolerance"), and the same difference
with both runs at the tighter tolerance (it shrinks with the tolerance: the difference is
the tolerance's, not the method's).

``--strain``: the two dynamic phases of one RVE strain step instead (rve.homogenisation.strain,
configs/rve/plain_weave.yaml with ``--strain-fabric`` warp/weft yarns of 10 fibrils each,
12 el/fibril; uniaxial step 1 from the relaxed state, relaxed once by the scene's energy
path and cached under ``--cache``): the driven phase (backward Euler, 2 steps of 5 µs,
loose stage Newton rtol 1e-3, max 8 iterations) and the heavily damped relaxation (2 steps
of 1 ms), the variant's options given to both phases as
``RelaxSettings.integrator_options``. Same table; the final state is the damped phase's.
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def build(n: int, elements: int, v0: float):
    import rve.config.rve  # noqa: F401  (registers the "rve" scene)
    from rve.config.loader import load_config
    from rve.model.contact_model import ContactParams, ContactSystem
    from rve.fabrics import weave
    from rve.model import BeamMaterial, BeamModel, DirichletBC

    cfg = load_config(ROOT / "configs/rve/plain_weave.yaml")
    m, c = cfg.material, cfg.contact
    d = 0.3
    fab = weave("plain", n, n, spacing=1.0, amplitude=d / 2, fibril_diameter=d, rows=(1,))
    mesh = fab.mesh(elements, 1)
    ends = np.array([tg.node(mesh) for tg in fab.end_tags], dtype=np.int64)
    first = mesh.node_offsets[:-1].astype(np.int64)
    mat = BeamMaterial(m.youngs_modulus, m.poisson_ratio, m.density)
    lay0 = BeamModel(mesh, mat).layout
    bcs = [DirichletBC(lay0.dofs("r", ends), 0.0), DirichletBC(lay0.dofs("g1", first, comp=2), 0.0)]
    base = BeamModel(mesh, mat, disk_points=4, bcs=bcs)
    params = ContactParams(penalty=c.penalty, heat_transfer=0.0, conductance=0.0, n_gp=c.n_gp, margin=c.margin,
                           g_eps=c.g_eps, recompute_closest=c.recompute_closest, rebuild_every=1)
    x = np.zeros(base.n)
    base.nodal(x)[:, :9] = fab.initial_state(mesh)
    system = ContactSystem(base, params, x)
    w = np.zeros(base.n)
    X = base.nodal(x)
    warp = np.zeros(mesh.n_nodes, dtype=bool)
    for y in fab.yarns:
        if y.direction == "warp":
            for f in y.fibrils:
                warp[mesh.fibril_nodes(f)] = True
    mid = np.flatnonzero((np.abs(X[:, 0]) < 2.0) & (np.abs(X[:, 1]) < 2.0) & warp)
    w[base.layout.dofs("r", mid, comp=2)] = -float(v0)
    return system, x, w


VARIANTS = {"off": dict(jacobian_reuse=False), "on": dict(jacobian_reuse=True), "auto": dict(jacobian_reuse="auto"),
            # full Newton through the reuse machinery (every factorisation dropped after its
            # iteration): the same linear backend as the reuse variants, for a like-for-like ratio
            "full": dict(jacobian_reuse=True, reuse_contraction=1e-300)}


def _register_pardiso() -> None:
    """Make ``get_backend("pardiso")`` work in this process if the linear layer does not
    register it yet (rve/solvers/pardiso.py is usable as a backend instance)."""
    from rve.solvers import linear

    if "pardiso" in linear.BACKENDS:
        return
    from rve.solvers.backends.pardiso import PardisoFactorization, available

    if not available():
        raise SystemExit("pardiso is not available here")
    linear.register_backend("pardiso", lambda symmetric=True: PardisoFactorization())


def run(system, x0, w0, steps, h, newton_opts=None, **opts):
    from rve.solvers.dirk import integrate, integrator_options

    system.rebuild(x0)  # the same contact map at the start of every run
    t0 = time.perf_counter()
    res = integrate(system, x0, w0, 0.0, steps * h, steps, stages=2, consistent=False, newton_opts=newton_opts,
                    **integrator_options(fixed_step=True, **opts))
    return res, time.perf_counter() - t0


def _rel(a, b) -> float:
    return float(np.linalg.norm(a - b) / max(np.linalg.norm(b), 1e-300))


def strain_phases(cfg, fab, mesh, x_rel, integrate_opts):
    """Driven + damped phases of uniaxial strain step 1 (``strain_step`` up to its static
    solve) with ``integrate_opts`` passed to every ``integrate`` call -> (x, w, stats)."""
    import rve.solvers.relaxation as relaxation
    from rve.homogenisation.strain import _settings, affine_velocity, clamped_ends, mech_system, strain_levels

    sp_ = cfg.strain
    levels = strain_levels(cfg)
    rate = float(levels[1] - levels[0]) / sp_.t_step
    nn = mesh.n_nodes
    x = np.array(x_rel, float).reshape(nn, 9)
    ends, _, _ = clamped_ends(fab, mesh)
    w_aff = affine_velocity(x, "uniaxial", rate)
    opts = dict(integrate_opts)
    sys1 = mech_system(fab, mesh, cfg, sp_.damping, x, end_velocity=w_aff[ends, :3])
    s1 = _settings(sp_.t_step, sp_.stretch_steps, sp_.rebuild_every, sp_.newton_rtol, sp_.newton_max_iter,
                   sp_.static_atol, static=False)
    res1 = relaxation.relax_to_equilibrium(sys1, x.reshape(-1), w_aff.reshape(-1),
                                           dataclasses.replace(s1, integrator_options=opts))
    x1 = res1.x.reshape(nn, 9).copy()
    sys2 = mech_system(fab, mesh, cfg, sp_.relax_damping, x1)
    s2 = _settings(sp_.t_relax, sp_.relax_steps, sp_.rebuild_every, sp_.newton_rtol, sp_.newton_max_iter,
                   sp_.static_atol, static=False)
    res2 = relaxation.relax_to_equilibrium(sys2, x1.reshape(-1), np.zeros(sys2.n),
                                           dataclasses.replace(s2, integrator_options=opts))
    calls = res1.integrations + res2.integrations
    return res2.x, res2.w, calls, (res1.t, res2.t)


class _Summed:
    """The counts of several IntegrationResults, added."""

    def __init__(self, results):
        for k in ("newton_iterations", "jacobian_evaluations", "factorizations", "reuses", "rejected_reuses",
                  "stage_retries", "rejected", "steps"):
            setattr(self, k, int(sum(getattr(r, k) for r in results)))
        self.contractions = [q for r in results for q in r.contractions]
        reasons = {}
        for r in results:
            for k, v in r.refactor_reasons.items():
                reasons[k] = reasons.get(k, 0) + v
        self.refactor_reasons = reasons


def main_strain(a) -> None:
    import rve.config.rve  # noqa: F401  (registers the "rve" scene)
    from rve.config.loader import load_config
    from rve.fabrics.setup import fabric_and_mesh
    from rve.homogenisation.strain import relax_fabric

    n = a.strain_fabric
    cfg = load_config(ROOT / "configs/rve/plain_weave.yaml", [f"fabric.n_warp={n}", f"fabric.n_weft={n}"])
    fab, mesh = fabric_and_mesh(cfg)
    cache = Path(a.cache) / f"strain_relaxed_{n}x{n}_{cfg.mesh.elements}.npy"
    if cache.exists():
        x_rel = np.load(cache)
    else:
        t0 = time.perf_counter()
        x0 = fab.initial_state(mesh)
        x_rel, _, _ = relax_fabric(cfg, fab, mesh, x0)
        cache.parent.mkdir(parents=True, exist_ok=True)
        np.save(cache, x_rel)
        print(f"relaxed the {n}x{n} weave in {time.perf_counter() - t0:.1f} s (cached: {cache})", flush=True)
    names = [v for v in a.variants.split(",") if v]
    load0 = os.getloadavg()
    walls = {v: [] for v in names}
    results = {}
    for rep in range(a.repeats):
        for v in names:
            opts = dict(VARIANTS[v])
            if opts["jacobian_reuse"]:
                opts.update(reuse_contraction=a.contraction, linear_backend=a.backend)
            t0 = time.perf_counter()
            out = strain_phases(cfg, fab, mesh, x_rel, opts)
            walls[v].append(time.perf_counter() - t0)
            results[v] = out
            print(f"  repeat {rep + 1} {v:>4}: {walls[v][-1]:7.2f} s (t reached {out[3]})", flush=True)
    load1 = os.getloadavg()
    n_fib = fab.n_fibrils if hasattr(fab, "n_fibrils") else "?"
    print(f"# strain step 1 (uniaxial) dynamic phases, {n}x{n} plain weave ({n_fib} fibrils), "
          f"{cfg.mesh.elements} el/fibril, {x_rel.size} dofs; driven: BE {cfg.strain.stretch_steps} x "
          f"{cfg.strain.t_step / cfg.strain.stretch_steps:g} ms, damped: BE {cfg.strain.relax_steps} x "
          f"{cfg.strain.t_relax / cfg.strain.relax_steps:g} ms; Newton rtol {cfg.strain.newton_rtol}, max "
          f"{cfg.strain.newton_max_iter}; load average {load0[0]:.2f} -> {load1[0]:.2f} on {os.cpu_count()} cores")
    t_ref = float(np.median(walls["off"])) if "off" in walls else None
    print(f"{'variant':>7} {'wall med':>9} {'ratio':>6} {'its':>5} {'jac':>5} {'fact':>5} {'reused':>6} {'rej':>4} "
          f"{'retry':>5} {'cuts':>4} {'theta med':>9} {'theta max':>9}  dropped because")
    for v in names:
        r = _Summed(results[v][2])
        wm = float(np.median(walls[v]))
        th = (f"{np.median(r.contractions):9.2e} {np.max(r.contractions):9.2e}" if r.contractions
              else f"{'(quadr.)':>9} {'-':>9}")
        print(f"{v:>7} {wm:9.2f} {(t_ref / wm if t_ref else float('nan')):6.2f} {r.newton_iterations:5d} "
              f"{r.jacobian_evaluations:5d} {r.factorizations:5d} {r.reuses:6d} {r.rejected_reuses:4d} "
              f"{r.stage_retries:5d} {r.rejected:4d} {th}  {r.refactor_reasons}")
    print("(ratio = median wall of 'off' / median wall of the variant: > 1 means faster)")
    if "off" in results:
        xr = results["off"][0]
        for v in names:
            if v != "off":
                print(f"   {v:>4} vs off, state after the damped phase: x {_rel(results[v][0], xr):.1e} (relative), "
                      f"max |dx| {np.abs(results[v][0] - xr).max():.1e} mm")
        # the difference is the loose stage tolerance's: both at a 1e5x tighter rtol
        tight = load_config(ROOT / "configs/rve/plain_weave.yaml",
                            [f"fabric.n_warp={n}", f"fabric.n_weft={n}", "strain.newton_rtol=1e-8",
                             "strain.newton_max_iter=40"])
        t_off = strain_phases(tight, fab, mesh, x_rel, dict(VARIANTS["off"]))
        for v in names:
            if v != "off":
                t_v = strain_phases(tight, fab, mesh, x_rel, dict(VARIANTS[v]))
                print(f"   {v:>4} vs off, both with stage rtol 1e-8: x {_rel(t_v[0], t_off[0]):.1e} (relative), "
                      f"max |dx| {np.abs(t_v[0] - t_off[0]).max():.1e} mm; off(rtol 1e-3) vs off(1e-8): "
                      f"max |dx| {np.abs(xr - t_off[0]).max():.1e} mm")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=8)
    ap.add_argument("--elements", type=int, default=20)
    ap.add_argument("--steps", type=int, default=40)
    ap.add_argument("--h", type=float, default=5e-4)
    ap.add_argument("--v0", type=float, default=10.0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--variants", default="off,on,auto")
    ap.add_argument("--backend", default=None, help="linear_backend of the reuse variants (get_backend name)")
    ap.add_argument("--contraction", type=float, default=0.5)
    ap.add_argument("--strain", action="store_true", help="the dynamic phases of an RVE strain step instead")
    ap.add_argument("--strain-fabric", type=int, default=2, help="warp (= weft) yarns of the strain-step weave")
    ap.add_argument("--cache", default=str(ROOT / "results" / "bench_cache"))
    a = ap.parse_args(argv)
    if a.backend == "pardiso":
        _register_pardiso()
    if a.strain:
        return main_strain(a)
    names = [v for v in a.variants.split(",") if v]
    system, x0, w0 = build(a.n, a.elements, a.v0)
    load0 = os.getloadavg()
    walls = {v: [] for v in names}
    results = {}
    for rep in range(a.repeats):
        for v in names:
            opts = dict(VARIANTS[v])
            if opts["jacobian_reuse"]:
                opts.setdefault("reuse_contraction", a.contraction)
                opts.update(linear_backend=a.backend)
            res, wall = run(system, x0, w0, a.steps, a.h, **opts)
            walls[v].append(wall)
            results[v] = res
            print(f"  repeat {rep + 1} {v:>4}: {wall:7.2f} s", flush=True)
    tight_opts = dict(atol=1e-12, rtol=1e-14)
    tight, _ = run(system, x0, w0, a.steps, a.h, newton_opts=tight_opts)
    tight_reuse = {v: run(system, x0, w0, a.steps, a.h, newton_opts=tight_opts, linear_backend=a.backend,
                          **VARIANTS[v])[0] for v in names if v != "off"}
    load1 = os.getloadavg()
    print(f"# {a.n}x{a.n} single-fibril plain weave, {a.elements} el/fibril, n={system.n} dofs, SDIRK2, h={a.h:g} ms, "
          f"{a.steps} steps ({2 * a.steps} stage solves), v0={a.v0:g} mm/ms, reuse threshold {a.contraction}, "
          f"backend {a.backend or 'default'}; load average {load0[0]:.2f} -> {load1[0]:.2f} on {os.cpu_count()} cores")
    ref = results.get("off")
    t_ref = float(np.median(walls["off"])) if "off" in walls else None
    print(f"{'variant':>7} {'wall med':>9} {'ratio':>6} {'its':>5} {'jac':>5} {'fact':>5} {'reused':>6} {'rej':>4} "
          f"{'retry':>5} {'theta med':>9} {'theta max':>9}  dropped because")
    for v in names:
        r = results[v]
        wm = float(np.median(walls[v]))
        th = (f"{np.median(r.contractions):9.2e} {np.max(r.contractions):9.2e}" if r.contractions
              else f"{'(quadr.)':>9} {'-':>9}")
        print(f"{v:>7} {wm:9.2f} {(t_ref / wm if t_ref else float('nan')):6.2f} {r.newton_iterations:5d} "
              f"{r.jacobian_evaluations:5d} {r.factorizations:5d} {r.reuses:6d} {r.rejected_reuses:4d} "
              f"{r.stage_retries:5d} {th}  {r.refactor_reasons}")
    print("(ratio = median wall of 'off' / median wall of the variant: > 1 means faster)")
    if ref is not None:
        print(f"final state vs full Newton (relative 2-norm): tolerance scale |off(default tol) - off(100x tighter)|: "
              f"x {_rel(ref.x, tight.x):.1e}, w {_rel(ref.w, tight.w):.1e}")
        for v in names:
            if v != "off":
                r = results[v]
                rt = tight_reuse[v]
                print(f"   {v:>4} vs off: x {_rel(r.x, ref.x):.1e}, w {_rel(r.w, ref.w):.1e}; both at the 100x tighter "
                      f"tolerance: x {_rel(rt.x, tight.x):.1e}, w {_rel(rt.w, tight.w):.1e} (shrinks with the tolerance)")


if __name__ == "__main__":
    main()
