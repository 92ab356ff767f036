"""Whole runs per linear-solver backend as fresh processes: the relaxation of the shipped
weave and one RVE strain step (docs/engine.md "Backend choice").

    python benchmarks/engine_whole.py --relax 12 [--runs 3] [--backends superlu pardiso]
    python benchmarks/engine_whole.py --relax 30 --runs 1
    python benchmarks/engine_whole.py --strain-step [--state FILE] [--runs 3]

Whole runs (``--relax N``: the shipped 80-fibril plain weave, configs/scenes/
plain_weave_relax.yaml with ``mesh.elements = N``; at N = 12 its coarse stage is the run
itself, at 30 the shipped mesh sequencing 12 -> 30; ``--strain-step``: one RVE strain
step, ``rve.homogenisation.strain.strain_step``, of configs/rve/plain_weave.yaml (12
el/fibril, the default job's), uniaxial step 1 from a relaxed state file): every run is a
fresh ``python`` process with ``RVE_LINEAR_BACKEND`` set to the backend, the runs
interleaved (superlu, pardiso, ..., superlu, pardiso, ...). Printed per backend: median
process wall time (launch to exit, imports included) and of the solve alone, the ratio
superlu / this (same invocation), peak RSS, Newton iterations, factorisations and
analyses, final energy and its relative difference to superlu's, max overlap / R,
negative pivots of the final tangent (stable), |x - x_superlu|_max, and the split of the
solve time measured by wrapping (factorisation + solve, assembly, contact rebuild,
energy, other). Backends: ``superlu`` (scipy's SuperLU) and ``pardiso`` (the default
"auto" where MKL is present, with the minimiser's ``MinimizeOptions`` defaults). The
PARDISO variants measured against them (nonzero vs stored pattern, analysis growth,
orderings, CNR, two threads, the LDL^T test) are decided; their figures stay in
docs/engine.md and in git. Whole runs get ``RVE_PARDISO_THREADS=1`` unless it is set.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import ROOT, rss_mib as _rss_mib, run_json, worker_env  # noqa: E402


RUN_BACKENDS = ("superlu", "pardiso")
RELAX_CONFIG = ROOT / "configs/scenes/plain_weave_relax.yaml"
STRAIN_CONFIG = ROOT / "configs/rve/plain_weave.yaml"


class _Split:
    """Wall-time accumulators around the hot calls (wrapping costs ~1 us per call)."""

    def __init__(self):
        self.t = {"factorisation": 0.0, "assembly": 0.0, "contact_rebuild": 0.0, "energy": 0.0}
        self.n = {k: 0 for k in self.t}

    def wrap(self, owner, attr, key):
        fn = getattr(owner, attr)

        def timed(*a, **k):
            t0 = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                self.t[key] += time.perf_counter() - t0
                self.n[key] += 1

        setattr(owner, attr, timed)


def _instrument() -> _Split:
    from rve.model import contact_model
    from rve.solvers import minimize, newton, static

    sp_ = _Split()
    cs = contact_model.ContactSystem
    sp_.wrap(cs, "evaluate", "assembly")
    sp_.wrap(cs, "rebuild", "contact_rebuild")
    sp_.wrap(cs, "energy", "energy")
    for mod in (minimize, newton, static):
        for name in ("factor_inertia", "factor_positive_definite", "sparse_solve"):
            if hasattr(mod, name):
                sp_.wrap(mod, name, "factorisation")
    from rve.fabrics import relaxation as fabric_relaxation

    # the stability check (its own reference; wrapping linear's would count the LDL^T of
    # factor_positive_definite twice)
    sp_.wrap(fabric_relaxation, "negative_eigenvalue_count", "factorisation")
    return sp_


def run_worker(kind: str, arg: str, backend: str, out_npz: str) -> dict:
    """One whole run in this process (``RVE_LINEAR_BACKEND`` is already set by the parent)."""
    t_import = time.perf_counter()
    import rve.scenes  # noqa: F401
    split = _instrument()
    rec = {"kind": kind, "arg": arg, "backend": backend, "env": os.environ.get("RVE_LINEAR_BACKEND", "")}
    t0 = time.perf_counter()
    if kind == "relax":
        from rve.config import load_config
        from rve.scenes import fabric_relax

        cfg = load_config(str(RELAX_CONFIG), [f"mesh.elements={int(arg)}"])
        res = fabric_relax.solve(cfg)
        s = res.summary
        x = np.asarray(res.state["x"], float)
        stages = [h for h in s["history"] if h.get("method") == "minimize_energy"]
        rec.update(iterations=int(s["static_newton_iterations"]), converged=bool(s["static_converged"]),
                   factorizations=int(sum(h.get("factorizations", 0) for h in stages)),
                   analyses=int(sum(h.get("analyses", 0) for h in stages)),
                   energy_mJ=float(s["energy_mJ"]), max_overlap_over_R=float(s["max_overlap_over_R"]),
                   negative_pivots=int(s["negative_pivots"]), stable=bool(s["stable"]),
                   stages=[{k: h.get(k) for k in ("mesh_elements", "onset_over_R", "newton_iterations",
                                                  "factorizations", "analyses", "wall_s")} for h in stages])
    else:
        from rve.config import load_config
        from rve.fabrics.setup import fabric_and_mesh
        from rve.homogenisation.checkpoint import load_state
        from rve.homogenisation.strain import strain_step
        from rve.solvers.linear import factor_inertia
        from rve.solvers.static import StaticProblem

        cfg = load_config(str(STRAIN_CONFIG), ["mesh.elements=12"])  # the 12-element step of the default job
        fab, mesh = fabric_and_mesh(cfg)
        st = load_state(arg)
        xs, system, info = strain_step(cfg, fab, mesh, st.x, st.origin, "uniaxial", 1)
        x = np.asarray(xs, float).reshape(-1)
        prob = StaticProblem(system, x, np.zeros(system.n), 0.0)
        _, J = prob(prob.u0())
        _, neg = factor_inertia(J)
        cst = system.contact_state(x)
        rec.update(converged=bool(info.get("converged")), residual_N=float(info.get("residual_N", np.nan)),
                   energy_mJ=float(system.energy(x)), max_overlap_over_R=float(cst["max_overlap_over_R"]),
                   negative_pivots=int(neg), stable=bool(neg == 0),
                   iterations=int(_count(info, "newton_iterations")),
                   factorizations=int(_count(info, "factorizations")),
                   analyses=int(_count(info, "analyses")))
    rec["solve_s"] = time.perf_counter() - t0
    rec["import_s"] = t0 - t_import
    rec["split_s"] = {k: float(v) for k, v in split.t.items()}
    rec["split_s"]["other"] = rec["solve_s"] - sum(split.t.values())
    rec["calls"] = dict(split.n)
    rec["rss_mib"] = _rss_mib()
    np.save(out_npz, x)
    return rec


def _count(info, key) -> int:
    """Sum of ``key`` over a nested info dict."""
    if isinstance(info, dict):
        return sum((v if k == key and isinstance(v, (int, np.integer)) else _count(v, key)) for k, v in info.items())
    if isinstance(info, (list, tuple)):
        return sum(_count(v, key) for v in info)
    return 0


def run_whole(kind: str, arg: str, backend: str, out_npz: Path) -> dict:
    env = worker_env(RVE_LINEAR_BACKEND="superlu" if backend == "superlu" else "pardiso")
    env.setdefault("RVE_PARDISO_THREADS", "1")
    rec = run_json([sys.executable, __file__, "--run-worker", kind, str(arg), backend, str(out_npz)], env)
    return {"backend": backend, **rec} if "error" in rec else rec


def whole_table(title: str, runs: list, xs: dict) -> str:
    by = {}
    for r in runs:
        by.setdefault(r["backend"], []).append(r)
    ok = lambda b: [r for r in by.get(b, []) if "error" not in r]  # noqa: E731
    ref = ok("superlu")
    ref_wall = float(np.median([r["wall_s"] for r in ref])) if ref else float("nan")
    ref_cpu = float(np.median([r["cpu_s"] for r in ref])) if ref else float("nan")
    ref_E = ref[0]["energy_mJ"] if ref else float("nan")
    x_ref = xs.get(("superlu", 0))
    head = (f"{'backend':<13} {'runs':>4} {'wall(med)':>9} {'ratio':>6} {'cpu(med)':>8} {'ratio':>6} {'solve':>8} "
            f"{'RSS MiB':>8} {'its':>5} "
            f"{'fact':>5} {'anal':>5} {'energy mJ':>16} {'dE/E':>8} {'ovl/R':>7} {'neg':>4} {'|dx|max':>8}  "
            f"split of the solve: fact / asm / rebuild / energy / other (s)")
    lines = [title, head, "-" * len(head)]
    for b, recs in by.items():
        good = ok(b)
        for r in recs:
            if "error" in r:
                lines.append(f"{b:<13} error: {r['error']}")
        if not good:
            continue
        wall = float(np.median([r["wall_s"] for r in good]))
        cpu = float(np.median([r["cpu_s"] for r in good]))
        r0 = good[0]
        walls = ", ".join(f"{r['wall_s']:.1f}" for r in good)
        x0 = xs.get((b, 0))
        dx = float(np.abs(x0 - x_ref).max()) if x0 is not None and x_ref is not None else float("nan")
        sp_ = {k: float(np.median([r["split_s"][k] for r in good])) for k in r0["split_s"]}
        lines.append(
            f"{b:<13} {len(good):>4} {wall:>9.1f} {ref_wall / wall:>5.2f}x {cpu:>8.1f} {ref_cpu / cpu:>5.2f}x "
            f"{np.median([r['solve_s'] for r in good]):>8.1f} {max(r['rss_mib'] for r in good):>8.0f} "
            f"{r0['iterations']:>5} {r0['factorizations']:>5} {r0['analyses']:>5} {r0['energy_mJ']:>16.12f} "
            f"{abs(r0['energy_mJ'] - ref_E) / abs(ref_E):>8.1e} {r0['max_overlap_over_R']:>7.4f} "
            f"{r0['negative_pivots']:>4} {dx:>8.1e}  "
            + " / ".join(f"{sp_[k]:.1f}" for k in ("factorisation", "assembly", "contact_rebuild", "energy", "other"))
            + f"   (walls: {walls})")
    lines.append("wall = whole process (launch to exit), median; cpu = its user + system CPU time (the fairer "
                 "figure on a loaded machine); ratio = superlu median / this median (same "
                 "invocation, interleaved); solve = the solve alone (wall); its/fact/anal: Newton iterations, "
                 "factorisations, symbolic analyses of the first run; neg: negative pivots of the final tangent (0 = stable)")
    return "\n".join(lines)


def main_whole(kind: str, arg: str, runs: int, backends, json_path=None, outdir=None) -> None:
    outdir = Path(outdir or ROOT / "results/engine/runs")
    outdir.mkdir(parents=True, exist_ok=True)
    recs, xs = [], {}
    for k in range(runs):
        for b in backends:
            npz = outdir / f"{kind}_{Path(str(arg)).stem}_{b}_{k}.npy"
            r = run_whole(kind, arg, b, npz)
            r["rep"] = k
            recs.append(r)
            if "error" not in r:
                xs[(b, k)] = np.load(npz)
            print(f"  {kind} {arg} {b} run {k + 1}: " + (f"{r['wall_s']:.1f} s (cpu {r['cpu_s']:.1f} s), "
                  f"E = {r['energy_mJ']:.12f} mJ, "
                  f"its {r['iterations']}, fact {r['factorizations']}, anal {r['analyses']}, split "
                  + ", ".join(f"{kk} {v:.1f}" for kk, v in r["split_s"].items()) if "error" not in r
                  else f"error {r['error']}"), file=sys.stderr, flush=True)
    title = (f"relaxation, 80-fibril plain weave, {arg} el/fibril" if kind == "relax" else
             f"strain step (uniaxial 1) of {STRAIN_CONFIG.relative_to(ROOT)} from {arg}")
    print(whole_table(title, recs, xs))
    if json_path:
        Path(json_path).write_text(json.dumps(recs, indent=1, default=float))


def main(argv=None) -> None:
    if argv is None and len(sys.argv) > 1 and sys.argv[1] == "--run-worker":
        print(json.dumps(run_worker(sys.argv[2], sys.argv[3], sys.argv[4], sys.argv[5]), default=float))
        return
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--relax", type=int, default=None, metavar="ELEMENTS",
                    help="whole relaxation runs of the 80-fibril weave at this mesh (12 or 30)")
    ap.add_argument("--strain-step", action="store_true", help="whole runs of one RVE strain step")
    ap.add_argument("--state", default=str(ROOT / "results/engine/relaxed12.nc"),
                    help="relaxed state of configs/rve/plain_weave.yaml for --strain-step")
    ap.add_argument("--runs", type=int, default=3, help="interleaved runs per backend")
    ap.add_argument("--backends", nargs="*", default=["superlu", "pardiso"], choices=RUN_BACKENDS)
    ap.add_argument("--json", default=None, help="also write the records here")
    a = ap.parse_args(argv)
    if a.relax is None and not a.strain_step:
        ap.error("give --relax ELEMENTS or --strain-step")
    kind, arg = ("relax", str(a.relax)) if a.relax is not None else ("strain", a.state)
    main_whole(kind, arg, a.runs, a.backends, a.json)


if __name__ == "__main__":
    main()
