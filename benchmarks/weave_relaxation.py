"""Benchmark: the thesis plain-weave RVE (80 fibrils, 30 elements each) under contact.

Prints dofs, contact pairs, the median time of a contact-map rebuild (search + union
sparsity pattern), of a residual + tangent assembly (base beam terms and contact terms
separately, and in total), of a static-Jacobian restriction, of a linear solve (and of the
minimiser's factorisation with its inertia count) and of an energy evaluation, then
runs the whole relaxation (configs/scenes/plain_weave_relax.yaml) and prints its wall
time, Newton iterations, peak memory, the final overlap, the clamp reactions and the yarn
stack geometry (initial vs relaxed). Targets (2-core machine): rebuild + assembly < 0.1 s,
relaxation < 3 min; the script reports, it does not fail on a slow machine.

    python benchmarks/weave_relaxation.py [--elements 30] [--repeats 5] [--no-relax]
        [--set KEY=VALUE ...] [--out DIR] [--json FILE]
"""
from __future__ import annotations

import argparse
import json
import resource
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _median_time(fn, repeats):
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts))


def _peak_mb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", default=str(ROOT / "configs/scenes/plain_weave_relax.yaml"))
    ap.add_argument("--elements", type=int, default=30)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--no-relax", action="store_true", help="only the per-operation timings")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="config override")
    ap.add_argument("--out", default=None, help="also write the scene outputs (netCDF, VTK, PNG) here")
    ap.add_argument("--json", default=None, help="write the figures as JSON here")
    ap.add_argument("--log", default=None, help="write the solver log (every Newton iteration) to this file")
    args = ap.parse_args(argv)
    if args.log:
        import logging

        logging.basicConfig(level=logging.INFO, filename=args.log, filemode="w",
                            format="%(relativeCreated)9.0f ms %(name)s %(message)s")
        for name in ("rve.newton", "rve.dirk"):
            logging.getLogger(name).setLevel(logging.WARNING)

    import rve.scenes  # noqa: F401  (registers the scene config)
    from rve.config import load_config
    from rve.scenes import fabric_relax
    from rve.solvers.linear import factor_inertia, resolve_backend
    from rve.solvers.linear import sparse_solve
    from rve.solvers.static import StaticProblem

    cfg = load_config(args.config, [f"mesh.elements={args.elements}", *args.set])
    fab, system, x0 = fabric_relax.setup(cfg)
    w0 = np.zeros(system.n)
    n_fixed = len(system.constraints(0.0)[0])
    fig = {"fibrils": int(system.mesh.n_fibrils), "elements_per_fibril": int(args.elements),
           "order": int(system.mesh.order), "dofs": int(system.n), "free_dofs": int(system.n - n_fixed)}
    st = system.contact_state(x0)
    fig["contact_pairs"] = int(st["pairs"])
    fig["active_pairs_initial"] = int(st["active_pairs"])
    fig["union_nnz"] = int(system._u_nnz)
    fig["base_nnz"] = int(system.base.pattern.nnz)
    R = args.repeats
    fig["rebuild_s"] = _median_time(lambda: system.rebuild(x0), R)
    system.evaluate(x0, w0, 0.0)  # warm-up
    fig["assembly_base_s"] = _median_time(lambda: system.base.evaluate(x0, w0, 0.0, True), R)
    fig["assembly_contact_s"] = _median_time(lambda: system.contact_terms(x0, w0, True), R)
    fig["assembly_total_s"] = _median_time(lambda: system.evaluate(x0, w0, 0.0, True), R)
    fig["residual_only_s"] = _median_time(lambda: system.evaluate(x0, w0, 0.0, False), R)
    prob = StaticProblem(system, x0, w0, 0.0)
    u = prob.u0()
    r, J = prob(u)
    fig["static_jacobian_s"] = _median_time(lambda: prob(u), R)  # assembly + restriction (fast path)
    fig["linear_solve_s"] = _median_time(lambda: sparse_solve(J, r), max(1, R // 2))  # analysis reused after the 1st
    fig["factor_inertia_solve_s"] = _median_time(lambda: factor_inertia(J)[0].solve(r), max(1, R // 2))  # fresh
    fig["energy_s"] = _median_time(lambda: system.energy(x0), R)
    fig["rebuild_plus_assembly_s"] = fig["rebuild_s"] + fig["assembly_total_s"]
    fig["peak_memory_mb_setup"] = _peak_mb()
    print(f"plain weave {fig['fibrils']} fibrils x {args.elements} elements (p={fig['order']}): "
          f"{fig['dofs']} dofs ({fig['free_dofs']} free), {fig['contact_pairs']} contact pairs "
          f"({fig['active_pairs_initial']} active at the start), union nnz {fig['union_nnz']} (base {fig['base_nnz']})")
    print(f"  map rebuild (search + union pattern) {fig['rebuild_s'] * 1e3:8.1f} ms")
    print(f"  assembly F+Fx+Fw: base beam {fig['assembly_base_s'] * 1e3:8.1f} ms, contact "
          f"{fig['assembly_contact_s'] * 1e3:8.1f} ms, total (into the union CSR) {fig['assembly_total_s'] * 1e3:8.1f} ms")
    print(f"  residual only {fig['residual_only_s'] * 1e3:8.1f} ms; static Jacobian incl. restriction "
          f"{fig['static_jacobian_s'] * 1e3:8.1f} ms")
    fig["linear_backend"] = resolve_backend()
    print(f"  linear solve ({fig['linear_backend']}; RVE_LINEAR_BACKEND=superlu|pardiso|auto): sparse_solve "
          f"{fig['linear_solve_s'] * 1e3:8.1f} ms; "
          f"factor + inertia + solve (the minimiser's) {fig['factor_inertia_solve_s'] * 1e3:8.1f} ms")
    print(f"  energy (beam + penalty) {fig['energy_s'] * 1e3:8.1f} ms")
    print(f"  rebuild + assembly {fig['rebuild_plus_assembly_s'] * 1e3:8.1f} ms (target < 100 ms)")
    if not args.no_relax:
        t0 = time.perf_counter()
        if args.out:
            from rve.scenes import run_scene

            summary = run_scene(cfg, args.out)
        else:
            summary = fabric_relax.solve(cfg).summary
        wall = time.perf_counter() - t0
        fig["relaxation_wall_s"] = wall
        keys = ("method", "onset_schedule_over_R", "coarse_stage", "static_converged", "dynamic_steps",
                "dynamic_newton_iterations", "static_newton_iterations", "static_residuals", "static_rates",
                "negative_pivots", "stable", "energy_mJ", "map_rebuilds", "initial_max_overlap_over_R",
                "max_overlap_over_R", "active_contact_pairs", "clamp_reactions_N", "stack", "total_contact_force_N",
                "min_det_F", "wall_time_s")
        fig.update({k: summary.get(k) for k in keys})
        fig["stages"] = [{k: h.get(k) for k in ("mesh_elements", "onset_over_R", "converged", "newton_iterations",
                                                "factorizations", "rejections", "map_rebuilds", "wall_s")}
                         for h in summary["history"] if h.get("method") == "minimize_energy"]
        fig["peak_memory_mb"] = _peak_mb()
        print(f"  relaxation wall time {wall:8.1f} s (target < 180 s), method {summary['method']}: "
              f"{summary['static_newton_iterations']} Newton iterations, converged={summary['static_converged']}, "
              f"{summary['map_rebuilds']} map rebuilds on the target mesh")
        for st_ in fig["stages"]:
            print(f"    stage: {st_['mesh_elements']} el/fibril, onset {st_['onset_over_R']:g} R: "
                  f"{st_['newton_iterations']} its, {st_['factorizations']} factorisations, {st_['rejections']} "
                  f"rejected trials, converged={st_['converged']}, at {st_['wall_s']:.1f} s of its mesh's run")
        res_ = summary["static_residuals"][-6:]
        print("  last static residuals |F| (N): " + ", ".join(f"{v:.2e}" for v in res_) + "; observed orders: "
              + ", ".join(f"{v:.2f}" for v in summary["static_rates"][-4:]))
        print(f"  energy {summary.get('energy_mJ', float('nan')):.9f} mJ; negative pivots of the tangent at the "
              f"result: {summary['negative_pivots']} (stable={summary['stable']})")
        print(f"  max overlap / R: initial {summary['initial_max_overlap_over_R']:.4f} -> relaxed "
              f"{summary['max_overlap_over_R']:.4f} (target < 0.05); active pairs {summary['active_contact_pairs']}")
        for side, f in summary["clamp_reactions_N"].items():
            print(f"  clamp force {side}: [{f[0]: .4e} {f[1]: .4e} {f[2]: .4e}] N")
        s0, s1 = summary["stack"].get("initial", {}), summary["stack"].get("relaxed", {})
        if s0:
            print(f"  yarn stacks at the crossings: height {s0['height_mm']:.3f} -> {s1['height_mm']:.3f} mm, width "
                  f"{s0['width_mm']:.3f} -> {s1['width_mm']:.3f} mm, levels {s0['levels_mean']:.2f} -> "
                  f"{s1['levels_mean']:.2f} (histogram relaxed {s1['levels_histogram']}); thickness "
                  f"{s0['thickness_mm']:.3f} -> {s1['thickness_mm']:.3f} mm; rows from the width "
                  f"{s0['rows_from_width']:.2f} -> {s1['rows_from_width']:.2f}")
        print(f"  peak memory (max RSS) {fig['peak_memory_mb']:.0f} MB")
    if args.json:
        Path(args.json).write_text(json.dumps(fig, indent=2, default=float) + "\n")
    return fig


if __name__ == "__main__":
    main(sys.argv[1:])
