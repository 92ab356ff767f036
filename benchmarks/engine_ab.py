"""A/B of whole processes against today's pre-engine main (issue 10 acceptance figures).

    python benchmarks/engine_ab.py relax 12 [--runs 3] [--baseline /work/baseline]
        [--baseline-python /work/venv_base/bin/python] [--env RVE_LINEAR_BACKEND=superlu ...]
    python benchmarks/engine_ab.py relax 30 --runs 1
    python benchmarks/engine_ab.py strain STATE.nc        # one strain step (uniaxial 1, default config)
    python benchmarks/engine_ab.py --worker relax 12 OUT.npy [--profile FILE.txt]
    python benchmarks/engine_ab.py paths A.npy.history.json B.npy.history.json   # two paths step by step

Every run is a fresh process: the baseline tree with its own interpreter (``--baseline``,
``--baseline-python``: today's main, SuperLU and numpy kernels) and this tree with the
current interpreter, alternated (base, new, base, new, ...) so that both see the same
machine load. Per process: wall time (launch to exit), CPU time (user + system of that
process alone, ``os.wait4``), peak RSS, and what the worker prints (energy, overlap,
stability, iterations, factorisations). Printed: medians per side, the ratios base / new
of wall and CPU time (of the medians, and the median and range of the run-by-run ratios of
the alternated runs, which hold when the machine's speed drifts), and the relative energy difference and max |x_new - x_base| of the
final states. ``--variant "NAME=K=V;K=V"`` adds a further side: this tree with the given
environment (e.g. ``"superlu=RVE_LINEAR_BACKEND=superlu;RVE_KERNELS=numpy"``).

The relaxation is configs/scenes/plain_weave_relax.yaml with ``mesh.elements = N`` (at 12
the coarse stage is the run itself; at 30 the shipped mesh sequencing 12 -> 30); the
worker uses only the API both trees share (``load_config``, ``fabric_relax.solve``).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
STRAIN_CONFIG = "configs/rve/plain_weave.yaml"


def worker(kind: str, arg: str, out_npy: str, profile: str = "") -> dict:
    t_start = time.perf_counter()
    prof = None
    if profile:
        import pyinstrument

        prof = pyinstrument.Profiler(interval=0.005)
        prof.start()
    from rve.config import load_config

    eps = float(os.environ.get("RVE_AB_PERTURB", "0") or 0)  # perturb the coarse minimum (mm), path test
    if eps:
        from rve.fabrics import relaxation as _rx

        _coarse = _rx._coarse_stage

        def _perturbed(cfg, system):
            x, cres, dofs = _coarse(cfg, system)
            return x + eps * np.random.default_rng(1).uniform(-1.0, 1.0, x.size), cres, dofs

        _rx._coarse_stage = _perturbed
    rec = {"kind": kind, "arg": arg}
    if kind == "relax":
        from rve.scenes import fabric_relax

        cfg = load_config(str(Path.cwd() / "configs/scenes/plain_weave_relax.yaml"), [f"mesh.elements={int(arg)}"])
        t0 = time.perf_counter()
        res = fabric_relax.solve(cfg)
        if isinstance(res, dict):  # today's main: the summary with the state under "_state"
            s, x = res, np.asarray(res["_state"]["x"], float)
        else:
            s, x = res.summary, np.asarray(res.state["x"], float)
        stages = [h for h in s["history"] if h.get("method") == "minimize_energy"]
        rec.update(energy_mJ=float(s["energy_mJ"]), max_overlap_over_R=float(s["max_overlap_over_R"]),
                   negative_pivots=int(s["negative_pivots"]), stable=bool(s["stable"]),
                   converged=bool(s["static_converged"]), iterations=int(s["static_newton_iterations"]),
                   factorizations=int(sum(h.get("factorizations", 0) for h in stages)),
                   stage_its=[int(h.get("newton_iterations", 0)) for h in stages],
                   stage_energies=[float(h["energies"][-1]) for h in stages if h.get("energies")])
        Path(str(out_npy) + ".history.json").write_text(json.dumps(
            [{k: h.get(k) for k in ("mesh_elements", "onset_over_R", "energies", "residuals", "sigmas", "steps",
                                    "factorizations", "analyses", "linear_backend")} for h in stages]))
    else:
        from rve.homogenisation.strain import strain_step
        from rve.solvers.static import StaticProblem

        import rve.config.rve  # noqa: F401  (registers the RVE config with load_config)

        try:
            from rve.fabrics.setup import fabric_and_mesh
        except ImportError:
            from rve.homogenisation.strain import build_fabric as fabric_and_mesh  # today's main
        try:
            from rve.solvers.linear import factor_inertia
        except ImportError:  # the pre-redesign baseline tree
            from rve.contact.relax import factor_inertia
        from rve.homogenisation.checkpoint import load_state

        cfg = load_config(str(Path.cwd() / STRAIN_CONFIG), ["mesh.elements=12"])  # the 12-element step measured since round 3
        fab, mesh = fabric_and_mesh(cfg)
        st = load_state(arg)
        t0 = time.perf_counter()
        xs, system, info = strain_step(cfg, fab, mesh, st.x, st.origin, "uniaxial", 1)
        x = np.asarray(xs, float).reshape(-1)
        prob = StaticProblem(system, x, np.zeros(system.n), 0.0)
        _, J = prob(prob.u0())
        _, neg = factor_inertia(J)
        rec.update(energy_mJ=float(system.energy(x)),
                   max_overlap_over_R=float(system.contact_state(x)["max_overlap_over_R"]),
                   negative_pivots=int(neg), stable=bool(neg == 0), converged=bool(info.get("converged")))
    rec["solve_s"] = time.perf_counter() - t0
    rec["setup_s"] = t0 - t_start
    if prof is not None:
        prof.stop()
        Path(profile).write_text(prof.output_text(unicode=False, color=False, show_all=False))
    np.save(out_npy, x)
    return rec


def compare_paths(file_a: str, file_b: str) -> None:
    """Step-by-step energies of two runs' minimiser stages (the ``.history.json`` files the
    worker writes): per stage the iterations, the first accepted iteration at which the
    energies differ by more than 1e-14 ... 1e-3 relative, and the energies around there."""
    ha, hb = json.loads(Path(file_a).read_text()), json.loads(Path(file_b).read_text())
    for k, (a, b) in enumerate(zip(ha, hb)):
        ea, eb = np.asarray(a["energies"]), np.asarray(b["energies"])
        m = min(ea.size, eb.size)
        rel = np.abs(ea[:m] - eb[:m]) / np.abs(ea[:m])
        first = {t: (int(np.argmax(rel > t)) if np.any(rel > t) else None) for t in (1e-14, 1e-12, 1e-9, 1e-6, 1e-3)}
        print(f"stage {k + 1} ({a.get('mesh_elements')} el, onset {a.get('onset_over_R')} R): iterations "
              f"{ea.size - 1} vs {eb.size - 1}, final energies {ea[-1]:.12e} vs {eb[-1]:.12e} mJ "
              f"(rel {abs(ea[-1] - eb[-1]) / abs(ea[-1]):.1e}); max rel. difference on the common iterations "
              f"{rel.max():.1e}; first iteration above " + ", ".join(f"{t:.0e}: {v}" for t, v in first.items()))
        if first[1e-14] is not None:
            i0 = first[1e-14]
            show = sorted({i for i in (i0 - 1, i0, i0 + 1, i0 + 5, i0 + 10, i0 + 20, i0 + 40, i0 + 80, m - 1)
                           if 0 <= i < m})
            for i in show:
                sa, sb = (a["sigmas"][i - 1], b["sigmas"][i - 1]) if i else (0.0, 0.0)
                print(f"    it {i:4d}: {ea[i]:.15e} {eb[i]:.15e}  rel {rel[i]:.1e}  sigma {sa:.3g} / {sb:.3g}")


def run_one(python: str, tree: Path, kind: str, arg: str, out_npy: Path, env_extra: dict) -> dict:
    env = dict(os.environ)
    for k in ("MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS"):
        env.setdefault(k, "1")
    env.update(env_extra)
    env["PYTHONPATH"] = str(tree)
    cmd = [python, str(Path(__file__).resolve()), "--worker", kind, str(arg), str(out_npy)]
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, cwd=str(tree), env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    out, err = p.communicate()
    wall = time.perf_counter() - t0
    # per-process rusage (communicate() reaped it: use the children's delta instead)
    if p.returncode != 0:
        return {"error": (err.strip().splitlines() or ["?"])[-1], "wall_s": wall}
    rec = json.loads(out.strip().splitlines()[-1])
    rec["wall_s"] = wall
    return rec


def run_timed(python, tree, kind, arg, out_npy, env_extra):
    import resource

    ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    rec = run_one(python, tree, kind, arg, out_npy, env_extra)
    ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    rec["cpu_s"] = (ru1.ru_utime - ru0.ru_utime) + (ru1.ru_stime - ru0.ru_stime)
    return rec


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] == "--worker":
        prof = ""
        if "--profile" in argv:
            i = argv.index("--profile")
            prof = argv[i + 1]
            argv = argv[:i] + argv[i + 2:]
        rec = worker(argv[1], argv[2], argv[3], prof)
        import resource

        rec["rss_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
        print(json.dumps(rec))
        return
    if argv and argv[0] == "paths":
        compare_paths(argv[1], argv[2])
        return
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("kind", choices=("relax", "strain"))
    ap.add_argument("arg", help="elements per fibril (relax) or the relaxed state file (strain)")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--baseline", default="/work/baseline")
    ap.add_argument("--baseline-python", default="/work/venv_base/bin/python")
    ap.add_argument("--variant", action="append", default=[], help="NAME=K=V;K=V: this tree with that environment")
    ap.add_argument("--no-baseline", action="store_true")
    ap.add_argument("--out", default=str(ROOT / "results/engine/ab"))
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    arg = str(Path(a.arg).resolve()) if a.kind == "strain" else a.arg
    sides = [] if a.no_baseline else [("base", a.baseline_python, Path(a.baseline), {})]
    sides.append(("new", sys.executable, ROOT, {}))
    for v in a.variant:
        name, _, rest = v.partition("=")
        env = dict(kv.split("=", 1) for kv in rest.split(";") if kv)
        sides.append((name, sys.executable, ROOT, env))
    recs = {s[0]: [] for s in sides}
    xs = {}
    for k in range(a.runs):
        for name, py, tree, env in sides:
            npy = out / f"{a.kind}_{Path(arg).stem}_{name}_{k}.npy"
            r = run_timed(py, tree, a.kind, arg, npy, env)
            recs[name].append(r)
            if "error" not in r:
                xs[name, k] = np.load(npy)
            print(f"  {name} run {k + 1}: " + (f"wall {r['wall_s']:.1f} s cpu {r['cpu_s']:.1f} s rss "
                  f"{r['rss_mib']:.0f} MiB E={r['energy_mJ']:.12f} ovl/R={r['max_overlap_over_R']:.4f} "
                  f"neg={r['negative_pivots']} its={r.get('iterations')} fact={r.get('factorizations')} "
                  f"stages={r.get('stage_its')} load={os.getloadavg()[0]:.1f}"
                  if "error" not in r else f"error {r['error']}"), flush=True)
    ref = sides[0][0]
    good = lambda n: [r for r in recs[n] if "error" not in r]  # noqa: E731
    med = lambda n, key: float(np.median([r[key] for r in good(n)])) if good(n) else float("nan")  # noqa: E731
    print(f"\n{a.kind} {a.arg}: medians of {a.runs} interleaved runs (ratio = {ref} / side)")
    for name, *_ in sides:
        g = good(name)
        if not g:
            print(f"{name:<10} no successful run")
            continue
        E0 = good(ref)[0]["energy_mJ"] if good(ref) else float("nan")
        x0 = xs.get((ref, 0))
        dx = float(np.abs(xs[name, 0] - x0).max()) if x0 is not None and (name, 0) in xs else float("nan")
        pairs = [a["wall_s"] / b["wall_s"] for a, b in zip(recs[ref], recs[name]) if "error" not in a and "error" not in b]
        print(f"{name:<10} wall {med(name, 'wall_s'):8.1f} s ({med(ref, 'wall_s') / med(name, 'wall_s'):.2f}x; "
              f"run by run {ref}/{name}: median {float(np.median(pairs)):.2f}x, {min(pairs):.2f}-{max(pairs):.2f})  "
              f"cpu {med(name, 'cpu_s'):8.1f} s ({med(ref, 'cpu_s') / med(name, 'cpu_s'):.2f}x)  "
              f"peak RSS {max(r['rss_mib'] for r in g):6.0f} MiB  E {g[0]['energy_mJ']:.12f} mJ "
              f"(dE/E {abs(g[0]['energy_mJ'] - E0) / abs(E0):.1e})  |dx| {dx:.1e}  "
              f"ovl/R {g[0]['max_overlap_over_R']:.4f} neg {g[0]['negative_pivots']}  "
              f"walls {[round(r['wall_s'], 1) for r in g]} cpus {[round(r['cpu_s'], 1) for r in g]}")
    if a.json:
        Path(a.json).write_text(json.dumps(recs, indent=1))


if __name__ == "__main__":
    main()
