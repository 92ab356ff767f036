"""Benchmark of the induced-deformation scene (issue 11; docs/induced_deformation.md).

Per orientation: dofs, steps accepted/rejected, Newton iterations per stage, linear solves,
factorisations and Jacobian evaluations (modified Newton: newton.jacobian_reuse), wall time
split (assembly, contact, linear solves + other, T post-solve, balances), CPU time, peak
memory (ru_maxrss of the process); the post vs monolithic temperature path (``--repeat``
interleaved pairs: CPU and wall medians, their ratio, and max |T_post - T_mono| / max T);
and the balance-error convergence with the step size on a short horizon (orders).

    python benchmarks/induced_deformation.py [--steps 40] [--t-end 0.2] [--orientations B1,B2,B3]
        [--reduced] [--study-t 0.05] [--study-steps 10,20,40]

``--ab [CASES]`` runs only the interleaved A/B of the temperature path (docs/induced_deformation.md
"Temperature path"): per case ``orientation:t_end_ms:steps`` (default B2 0.1 ms / 20 steps,
before contact, and B3 0.5 ms / 100 steps, contact from ~0.3 ms; full size unless
``--reduced``), after one warm-up run of each path, ``--pairs`` rounds of the three paths
``post`` (the T post-solve with its reuse), ``post-former`` (``post_reuse=False``: a fresh
direct solve per stage with contact, numpy Joule, scalar_jump) and ``monolithic``, the order
reversed every round; prints CPU and wall medians, the T post-solve phase alone
(``wall_time_s.thermal_post``), max |T - T_mono| / max T, and the peak memory of one
untimed run per path (tracemalloc, Python + numpy allocations). ``--original REV`` adds the
path ``post-original``: ``rve/scenes/induced_balances.py`` of the git revision REV (read with
``git show``) in place of the current one, for the before/after of the T post-solve.

    python benchmarks/induced_deformation.py --ab [B2:0.1:20,B3:0.5:100] [--pairs 2] [--original REV]

``--contact-check [B3:0.5:100]``: whether the contact heat-transfer matrix must follow every
stage (``contact_check``).
"""
import argparse
import json
import os
import resource
import time

import numpy as np

from rve.config.loader import load_config
from rve.scenes.induced import solve

AB_PATHS = {"post": dict(mode="post"), "post-former": dict(mode="post", post_reuse=False),
            "monolithic": dict(mode="monolithic")}


def _original_balances(rev):
    """``rve/scenes/induced_balances.py`` of git revision ``rev`` as a module of this package."""
    import subprocess
    import types

    src = subprocess.run(["git", "show", f"{rev}:rve/scenes/induced_balances.py"], check=True,
                         capture_output=True, text=True).stdout
    mod = types.ModuleType(f"rve.scenes._induced_balances_{rev}")
    mod.__package__ = "rve.scenes"
    exec(compile(src, f"{rev}:rve/scenes/induced_balances.py", "exec"), mod.__dict__)
    if not hasattr(mod.ThermalOperators, "active_pairs"):  # the scene's on_step asks for it: the
        def active_pairs(self, x):                         # original on_step's own call, no memo
            term = self.system.term
            return term.active_pairs(x) if term.map is not None else np.zeros(0, np.int64)
        mod.ThermalOperators.active_pairs = active_pairs
    return mod


def _solve_path(cfg, name, t_end, steps, original=None, **kw):
    """``solve`` on path ``name``; ``post-original`` swaps in the original module's classes."""
    if name != "post-original":
        return solve(cfg, t_end=t_end, steps=steps, record=False, **AB_PATHS[name], **kw)
    import rve.scenes.induced.scene as scene

    keep = scene.ThermalOperators, scene.ThermalPostSolver
    scene.ThermalOperators = original.ThermalOperators
    scene.ThermalPostSolver = lambda ops, tab, T_fixed=0.0, reuse=True: original.ThermalPostSolver(ops, tab, T_fixed)
    try:
        return solve(cfg, t_end=t_end, steps=steps, record=False, mode="post", **kw)
    finally:
        scene.ThermalOperators, scene.ThermalPostSolver = keep


def contact_check(a, ov):
    """Does the contact heat-transfer matrix have to follow every stage? One post run of the
    case with two extra T chains on the same stage states, by dense solves of the stage
    equations: K_c per stage (the exact stage equations) and K_c frozen at the step's end
    state for both stages. Prints max |T_post - T_chain| / max T over the run and at t_end."""
    import rve.scenes.induced.scene as scene
    from rve.scenes.thermal_post import ThermalPostSolver

    def dense_step(ops, tab, T0, stages, t0, h, x_ref=None):
        M, K = ops.M.toarray(), ops.K.toarray()
        fr, fx = ops.free, ops.fixed
        Fs, T = [], None
        for i, (x, w) in enumerate(stages):
            ha = h * tab.A[i, i]
            Kc = ops.contact(x if x_ref is None else x_ref).toarray()
            Q = ops.joule_now(x, w, t0 + tab.c[i] * h)
            rhs = M @ T0 + ha * Q - sum(h * tab.A[i, j] * Fs[j] for j in range(i))
            A = M + ha * (K + Kc)
            T = np.zeros(ops.n)
            T[fx] = T0[fx]
            T[fr] = np.linalg.solve(A[np.ix_(fr, fr)], rhs[fr] - A[np.ix_(fr, fx)] @ T[fx])
            Fs.append((K + Kc) @ T - Q)
        return T

    class Chains(ThermalPostSolver):
        last = None

        def __init__(self, *args, **kw):
            super().__init__(*args, **kw)
            self.T_exact = self.T_frozen = None
            self.dev = {"exact": 0.0, "frozen": 0.0}
            Chains.last = self

        def step(self, T0, stages, t0, h):
            T = super().step(T0, stages, t0, h)
            self.T_exact = dense_step(self.ops, self.tab, T0 if self.T_exact is None else self.T_exact,
                                      stages, t0, h)
            self.T_frozen = dense_step(self.ops, self.tab, T0 if self.T_frozen is None else self.T_frozen,
                                       stages, t0, h, stages[-1][0])
            m = max(np.abs(T).max(), 1e-300)
            for k, v in (("exact", self.T_exact), ("frozen", self.T_frozen)):
                self.dev[k] = max(self.dev[k], float(np.abs(T - v).max() / m))
            return T

    o, t_end, steps = a.contact_check.split(":")
    cfg = load_config(a.config, ["time.adaptive.enabled=false"] + ov + [f"field.orientation={o}"])
    keep = scene.ThermalPostSolver
    scene.ThermalPostSolver = Chains
    try:
        r = solve(cfg, t_end=float(t_end), steps=int(steps), record=False, mode="post")
    finally:
        scene.ThermalPostSolver = keep
    c, T = Chains.last, r.state["T"]
    s = r.summary
    print(f"[{o} {t_end} ms, {steps} steps] max active pairs {s['contact_active_pairs_max']}, refinement solves "
          f"{s['thermal_post_refinements']}, fallbacks {s['thermal_post_fallbacks']}")
    for k, v in (("K_c per stage (dense)", c.T_exact), ("K_c frozen at the step end", c.T_frozen)):
        key = "exact" if v is c.T_exact else "frozen"
        print(f"  post vs {k}: max over the run {c.dev[key]:.2e}, at t_end {np.abs(T - v).max() / T.max():.2e}")


def ab(a, ov):
    """The interleaved A/B of the temperature path (module docstring)."""
    print(f"load: {os.getloadavg()}  (2-core machine; CPU = process_time of the run)")
    original = _original_balances(a.original) if a.original else None
    paths = list(AB_PATHS) + (["post-original"] if original else [])
    for case in a.ab.split(","):
        o, t_end, steps = case.split(":")
        t_end, steps = float(t_end), int(steps)
        cfg = load_config(a.config, ["time.adaptive.enabled=false"] + ov + [f"field.orientation={o}"])
        h = t_end / steps
        for name in paths:  # warm-up: numba caches, imports, first factorisations
            _solve_path(cfg, name, 2 * h, 2, original)
        runs = {k: [] for k in paths}
        names = paths
        for rnd in range(max(2, a.pairs)):
            for name in (names if rnd % 2 == 0 else names[::-1]):
                c0, t0 = time.process_time(), time.perf_counter()
                r = _solve_path(cfg, name, t_end, steps, original)
                runs[name].append((time.process_time() - c0, time.perf_counter() - t0, r))
                s = r.summary
                print(f"  [{o} {t_end} ms] round {rnd} {name:12s} CPU {runs[name][-1][0]:7.2f} s  wall "
                      f"{runs[name][-1][1]:7.2f} s  T post-solve {s['wall_time_s']['thermal_post']:.3f} s  "
                      f"Newton its {s['newton_iterations']}  factorisations {s['factorizations']}  load "
                      f"{os.getloadavg()[0]:.1f}", flush=True)
        peak = {}
        if not a.no_memory:
            for name in ("post", "monolithic"):
                peak[name] = _solve_path(cfg, name, t_end, steps, original,
                                         measure_memory=True).summary["peak_memory_MiB"]
        med = {k: {"cpu": float(np.median([c for c, _, _ in v])), "wall": float(np.median([w for _, w, _ in v])),
                   "tpost": float(np.median([r.summary["wall_time_s"]["thermal_post"] for _, _, r in v]))}
               for k, v in runs.items()}
        Tm = runs["monolithic"][-1][2].state["T"]
        dT = {k: float(np.abs(v[-1][2].state["T"] - Tm).max() / max(np.abs(Tm).max(), 1e-300))
              for k, v in runs.items() if k != "monolithic"}
        s = runs["post"][-1][2].summary
        n_rounds = len(runs["post"])
        print(f"[{o} {t_end} ms, {steps} steps] medians of {n_rounds} interleaved rounds; max active contact pairs "
              f"{s['contact_active_pairs_max']}; T post solves {s['thermal_post_solves']} "
              f"(refinement solves {s['thermal_post_refinements']}, fallbacks {s['thermal_post_fallbacks']})")
        for k in paths:
            m = med[k]
            print(f"  {k:12s} CPU {m['cpu']:7.2f} s  wall {m['wall']:7.2f} s  T post-solve phase {m['tpost']:.3f} s"
                  + (f"  peak {peak[k]:.0f} MiB" if k in peak else "")
                  + (f"  max|T - T_mono|/max T {dT[k]:.1e}" if k in dT else ""))
        mm, mp = med["monolithic"], med["post"]
        print(f"  monolithic / post: CPU {mm['cpu'] / mp['cpu']:.3f}, wall {mm['wall'] / mp['wall']:.3f};  "
              f"T post-solve phase former / now: {med['post-former']['tpost'] / max(mp['tpost'], 1e-12):.2f} "
              f"({med['post-former']['tpost']:.3f} s -> {mp['tpost']:.3f} s)"
              + (f";  original / now: {med['post-original']['tpost'] / max(mp['tpost'], 1e-12):.2f} "
                 f"({med['post-original']['tpost']:.3f} s -> {mp['tpost']:.3f} s); CPU original / now "
                 f"{med['post-original']['cpu'] / mp['cpu']:.3f}" if original else ""))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--config", default="configs/scenes/induced_deformation.yaml")
    ap.add_argument("--t-end", type=float, default=0.1, help="horizon of the cost runs (ms)")
    ap.add_argument("--steps", type=int, default=20, help="steps of the cost runs (thesis h = 5 us: t/0.005)")
    ap.add_argument("--orientations", default="B1,B2,B3")
    ap.add_argument("--reduced", action="store_true", help="2 x 2 yarns, 10 elements (the test case)")
    ap.add_argument("--study-t", type=float, default=0.05)
    ap.add_argument("--study-steps", default="10,20,40")
    ap.add_argument("--skip-monolithic", action="store_true")
    ap.add_argument("--repeat", type=int, default=1, help="interleaved post/monolithic pairs (medians)")
    ap.add_argument("--set", action="append", default=[], help="config override KEY=VALUE (repeatable)")
    ap.add_argument("--ab", nargs="?", const="B2:0.1:20,B3:0.5:100", default=None,
                    help="only the interleaved A/B of the temperature path: cases orientation:t_end_ms:steps")
    ap.add_argument("--pairs", type=int, default=2, help="--ab: interleaved rounds (>= 2)")
    ap.add_argument("--no-memory", action="store_true", help="--ab: skip the tracemalloc runs")
    ap.add_argument("--original", default=None, help="--ab: also the T post-solve of this git revision")
    ap.add_argument("--contact-check", nargs="?", const="B3:0.5:100", default=None,
                    help="only: post vs dense chains with K_c per stage and frozen per step (case o:t:steps)")
    a = ap.parse_args()
    ov = ["output.vtk=false", "output.png=false"] + list(a.set)
    if a.reduced:
        ov += ["geometry.n_warp=2", "geometry.n_weft=2", "geometry.span=5 mm", "geometry.natural_length=6.25 mm",
               "mesh.elements=10"]
    if a.ab or a.contact_check:
        if a.ab:
            ab(a, ov)
        if a.contact_check:
            contact_check(a, ov)
        return
    for o in a.orientations.split(","):
        cfg = load_config(a.config, ["time.adaptive.enabled=false"] + ov + [f"field.orientation={o}"])
        runs = {"post": [], "monolithic": []}
        for _ in range(max(1, a.repeat)):
            for mode in ("post",) + (() if a.skip_monolithic else ("monolithic",)):
                c0, t0 = time.process_time(), time.perf_counter()
                r = solve(cfg, t_end=a.t_end, steps=a.steps, record=False, mode=mode)
                runs[mode].append((r, time.process_time() - c0, time.perf_counter() - t0))
        r, cpu, _ = runs["post"][-1]
        s = r.summary
        wall = {k: round(v, 3) for k, v in s["wall_time_s"].items()}
        print(f"[{o}] dofs {s['dofs']}  steps {s['steps_accepted']} accepted / {s['steps_rejected']} rejected  "
              f"Newton its/stage {s['newton_iterations_per_stage']:.2f}  linear solves {s['linear_solves']}  "
              f"factorisations {s['factorizations']}  Jacobians {s['jacobian_evaluations']}  "
              f"T post solves {s['thermal_post_solves']}  peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB")
        print(f"[{o}] wall {wall}  per step {s['wall_time_s']['total'] / max(1, s['steps_accepted']) * 1e3:.1f} ms"
              f"  CPU {cpu:.2f} s")
        print(f"[{o}] balance errors {json.dumps({k: float(f'{v:.3g}') for k, v in s['balance_errors'].items()})}")
        if runs["monolithic"]:
            rm = runs["monolithic"][-1][0]
            dT = float(np.abs(rm.state["T"] - r.state["T"]).max() / max(np.abs(rm.state["T"]).max(), 1e-300))
            med = {m: (float(np.median([c for _, c, _ in v])), float(np.median([w for _, _, w in v])))
                   for m, v in runs.items()}
            print(f"[{o}] monolithic: dofs {rm.summary['dofs']['total']}  CPU {med['monolithic'][0]:.2f} s vs post "
                  f"{med['post'][0]:.2f} s (ratio {med['monolithic'][0] / med['post'][0]:.2f}); wall "
                  f"{med['monolithic'][1]:.2f} vs {med['post'][1]:.2f} s (ratio {med['monolithic'][1] / med['post'][1]:.2f}; "
                  f"medians of {len(runs['post'])} interleaved pairs)  max|T_post - T_mono|/max T = {dT:.2e}  "
                  f"Newton its/stage {rm.summary['newton_iterations_per_stage']:.2f} vs {s['newton_iterations_per_stage']:.2f}")
    steps = [int(v) for v in a.study_steps.split(",")]
    cfg = load_config(a.config, ["time.adaptive.enabled=false"] + ov + ["field.orientation=B2"])
    errs = {k: [] for k in ("mechanical", "thermal", "total", "charge")}
    for n in steps:
        s = solve(cfg, t_end=a.study_t, steps=n, record=False).summary
        for k in errs:
            errs[k].append(s["balance_errors"][k])
    print(f"balance errors vs h (B2, t = {a.study_t} ms, steps {steps}):")
    for k, e in errs.items():
        e = np.array(e)
        if k == "charge":  # at solver tolerance, no order
            print(f"  {k:10s} " + "  ".join(f"{v:.3e}" for v in e))
            continue
        orders = np.log(e[:-1] / e[1:]) / np.log(np.array(steps[1:]) / np.array(steps[:-1]))
        print(f"  {k:10s} " + "  ".join(f"{v:.3e}" for v in e) + "   orders " + " ".join(f"{v:.2f}" for v in orders))


if __name__ == "__main__":
    main()
