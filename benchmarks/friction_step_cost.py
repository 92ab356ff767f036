"""Cost of the pipeline's strain steps with friction against the same steps without it: the
jobs Snakemake runs (``rve.homogenisation.jobs.strain_job``), on the thesis weave.

A run spec (default: ``plain_weave_friction`` of ``configs/pipeline.yaml``, the thesis plain
weave at 12 elements per fibril on the quasi-static path) is swept over ``friction_coefficient``
in {0, mu}. Each combination's relaxed state is built once (``fabric_job``, ``relax_job``: the
relaxation is frictionless, so both have the same x), or taken from ``--relaxed MU0 MU``.
Then, ``--runs`` rounds, alternating the two sides, each side a fresh process that runs strain
steps 1..``--steps`` of ``--mode`` from its relaxed state, the step chain of the pipeline.
Prints per run and step the wall and CPU time of the step, its iterations and the stick/slip
counts, then per step and over the chain the median wall and CPU times of each side and their
ratios (friction / frictionless), per side and step the x+ face force and the dissipation
so far (what the step ends at), and the peak RSS.

    nice -n 10 python benchmarks/friction_step_cost.py [--mu 0.2] [--mode shear] [--steps 2]
        [--runs 3] [--run plain_weave_friction] [--set KEY=VALUE ...] [--work DIR] [--relaxed MU0.nc MU.nc]

The periodic cell with the augmented Lagrangian (docs/contact.md "Friction with the augmented
Lagrangian and the periodic cell"): ``--run work_precision_geometry --set
strain.follow_branch=false --steps 1 --runs 1``.

``--director-blocks [N ...]``: a side per N (none given: 6), the frictional steps with every
contact pair's blocks widened by its nodes' first N director components
(``pad_director_blocks``: with 6 the sparsity an objective law carried by the - fibril's
directors would have, with 1 that of a law reading one twist combination per node;
docs/contact.md "Objectivity"), printed as its ratio to the frictionless step.

A side's worker: ``python benchmarks/friction_step_cost.py --worker SPEC.json COMBO STATE``.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import (interleave, median, peak, pipeline_spec, relaxed_state, run_json,  # noqa: E402
                      worker_env)


def _spec(run: str, mu: float, extra=()) -> dict:
    spec = pipeline_spec(run, extra)
    spec["sweep"] = {"friction_coefficient": [0.0, float(mu)]}
    return spec


def pad_director_blocks(n_directors: int = 6) -> None:
    """The counterfactual of an objective friction law carried by the - fibril's directors
    (docs/contact.md "Objectivity"): every frictional contact term's blocks widened by the
    first ``n_directors`` director components of its local nodes
    (``ContactTerm.widen_by_directors``; 6: all nine mechanical ones, r, g1, g2; 1: one more
    per node, the sparsity of a law that reads one twist combination per node in a node basis
    aligned with it), the new entries zero, so the same law is solved on the sparsity such a
    law would have."""
    from rve.model.terms import contact as C

    init = C.ContactTerm.__init__

    def padded_init(self, *a, **k):
        init(self, *a, **k)
        if self.friction is not None:
            self.widen_by_directors(n_directors)

    C.ContactTerm.__init__ = padded_init


def worker(spec_file: str, combo: str, state: str, mode: str, steps: int, out_dir: str,
           director_blocks: int = 0) -> None:
    """Steps 1..steps of ``mode`` from ``state``; one JSON line with each step's figures
    (``director_blocks`` > 0: ``pad_director_blocks(director_blocks)`` first)."""
    from rve.homogenisation.checkpoint import load_state
    from rve.homogenisation.jobs import strain_job

    if director_blocks:
        pad_director_blocks(director_blocks)
    spec = json.loads(Path(spec_file).read_text())
    prev, recs = Path(state), []
    for step in range(1, steps + 1):
        out = Path(out_dir) / f"{mode}_{step:02d}.nc"
        t0, c0 = time.perf_counter(), time.process_time()
        strain_job(prev, out, Path(out_dir) / f"{mode}_{step:02d}.log", spec, combo, mode, step)
        rec = {"step": step, "wall_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0}
        st = load_state(out)
        info = st.solver or {}
        rec.update(converged=bool(info.get("converged")), residual_N=float(info.get("residual_N", np.nan)),
                   iterations=sum(int(s.get("iterations", 0)) for s in info.get("substeps", [])) or info.get("iterations"),
                   contact_points=int(st.contact_count))
        fr = info.get("friction") or {}
        rec.update({k: fr[k] for k in ("stick", "slip", "dissipated") if k in fr})
        if st.reaction_force:
            rec["reaction_x+"] = [float(v) for v in st.reaction_force.get("x+", [])[:2]]
        recs.append(rec)
        prev = out
    print(json.dumps({"steps": recs}, default=float))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--worker", nargs=3, metavar=("SPEC", "COMBO", "STATE"))
    ap.add_argument("--out", help="(worker) the directory of its states")
    ap.add_argument("--run", default="plain_weave_friction")
    ap.add_argument("--mu", type=float, default=0.2)
    ap.add_argument("--mode", default="shear")
    ap.add_argument("--steps", type=int, default=2)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--work", help="where the relaxed states and the step states go (default: a temporary dir)")
    ap.add_argument("--algorithm-7-1", action="store_true",
                    help="also time the frictionless steps on the default path (strain.path: algorithm_7_1)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="an override added to the run's (repeatable), e.g. strain.follow_branch=false for a run "
                         "whose config follows the branch, which friction refuses")
    ap.add_argument("--relaxed", nargs=2, metavar=("MU0", "MU"), help="the two relaxed states, if built already")
    ap.add_argument("--director-blocks", type=int, nargs="*", metavar="N",
                    help="also time the frictional steps with every contact pair's blocks widened by the nodes' "
                         "first N director components, a side per N (no N: 6, all; pad_director_blocks, the "
                         "sparsity of a director-carried law)")
    a = ap.parse_args()
    if a.worker:
        return worker(*a.worker, a.mode, a.steps, a.out, (a.director_blocks or [0])[0])
    work = Path(a.work or tempfile.mkdtemp(prefix="friction_step_cost_"))
    work.mkdir(parents=True, exist_ok=True)
    spec = _spec(a.run, a.mu, a.set)
    from rve.homogenisation.sweeps import combo_ids

    c0, c1 = combo_ids(spec)
    states = [Path(p) for p in a.relaxed] if a.relaxed else [relaxed_state(spec, c, work / c) for c in (c0, c1)]
    spec_file = work / "spec.json"
    spec_file.write_text(json.dumps(spec))

    def side(name, spec_path, combo, state):
        def run(k):
            out = work / "runs" / f"{name}_{k}"
            out.mkdir(parents=True, exist_ok=True)
            return run_json([sys.executable, __file__, "--worker", spec_path, combo, state, "--mode", a.mode,
                             "--steps", a.steps, "--out", out], env=worker_env())
        return run

    sides = {"frictionless": side("frictionless", spec_file, c0, states[0]),
             f"mu={a.mu:g}": side(f"mu={a.mu:g}", spec_file, c1, states[1])}
    padded_sides = {}
    for n in ([6] if a.director_blocks == [] else a.director_blocks or []):
        def padded(k, n=n):
            out = work / "runs" / f"director_blocks_{n}_{k}"
            out.mkdir(parents=True, exist_ok=True)
            return run_json([sys.executable, __file__, "--worker", spec_file, c1, states[1], "--mode", a.mode,
                             "--steps", a.steps, "--out", out, "--director-blocks", n], env=worker_env())
        padded_sides[n] = f"mu={a.mu:g}, {n} director components"
        sides[padded_sides[n]] = padded
    if a.algorithm_7_1:
        alg = dict(spec, overrides=[*(spec.get("overrides") or []), "strain.path=algorithm_7_1"])
        (work / "spec_algorithm_7_1.json").write_text(json.dumps(alg))
        sides["frictionless, Algorithm 7.1"] = side("algorithm_7_1", work / "spec_algorithm_7_1.json", c0, states[0])
    recs = interleave(sides, a.runs)
    for name, rs in recs.items():
        for k, r in enumerate(rs):
            for s in r.get("steps", []):
                print(json.dumps({"side": name, "run": k, **s}, default=lambda v: round(float(v), 4)))
            if "error" in r:
                print(json.dumps({"side": name, "run": k, "error": r["error"]}))
    failed = [name for name, rs in recs.items() if rs and all("error" in r for r in rs)]
    if failed:
        for name in failed:
            print(f"{name}: every run failed: {recs[name][0]['error']}", file=sys.stderr)
        return 1
    fl, fr = recs["frictionless"], recs[f"mu={a.mu:g}"]
    alg = recs.get("frictionless, Algorithm 7.1")
    print(f"{a.run}, {a.mode} steps 1..{a.steps}, mu = 0 against mu = {a.mu:g} ({a.runs} runs each, alternating):")
    for step in range(1, a.steps + 1):
        def per(rs, key):
            return float(np.median([r["steps"][step - 1][key] for r in rs if "error" not in r]))
        w0, w1, p0, p1 = per(fl, "wall_s"), per(fr, "wall_s"), per(fl, "cpu_s"), per(fr, "cpu_s")
        print(f"  step {step}: median {w0:.1f} s wall / {p0:.1f} s CPU frictionless, {w1:.1f} s wall / {p1:.1f} s CPU "
              f"with friction: ratio {w1 / w0:.2f} wall, {p1 / p0:.2f} CPU")
    if alg:
        for step in range(1, a.steps + 1):
            w = float(np.median([r["steps"][step - 1]["wall_s"] for r in alg if "error" not in r]))
            p = float(np.median([r["steps"][step - 1]["cpu_s"] for r in alg if "error" not in r]))
            print(f"  step {step} frictionless on the Algorithm 7.1 path (driven + damped phases): median {w:.1f} s "
                  f"wall / {p:.1f} s CPU")
    for n, name in padded_sides.items():
        pad = recs[name]
        for step in range(1, a.steps + 1):
            w = float(np.median([r["steps"][step - 1]["wall_s"] for r in pad if "error" not in r]))
            p = float(np.median([r["steps"][step - 1]["cpu_s"] for r in pad if "error" not in r]))
            w0 = float(np.median([r["steps"][step - 1]["wall_s"] for r in fl if "error" not in r]))
            p0 = float(np.median([r["steps"][step - 1]["cpu_s"] for r in fl if "error" not in r]))
            print(f"  step {step} with friction on {n} director components' blocks: median {w:.1f} s wall / "
                  f"{p:.1f} s CPU: ratio {w / w0:.2f} wall, {p / p0:.2f} CPU to the frictionless step")
    for name, rs in recs.items():   # what the steps end at (the same every run: run 0's)
        ok = [r for r in rs if "error" not in r]
        for s in (ok[0]["steps"] if ok else []):
            fx = s.get("reaction_x+")
            print(f"  {name}, step {s['step']}: x+ face force "
                  + (f"({fx[0]:.5g}, {fx[1]:.5g}) N" if fx else "n/a")
                  + (f", dissipated {s['dissipated']:.6g} N mm so far" if "dissipated" in s else ""))
    for rs in (fl, fr) + ((alg,) if alg else ()):
        for r in rs:
            if "error" not in r:
                r["chain_wall_s"] = sum(s["wall_s"] for s in r["steps"])
                r["chain_cpu_s"] = sum(s["cpu_s"] for s in r["steps"])
    w0, w1 = median(fl, "chain_wall_s"), median(fr, "chain_wall_s")
    p0, p1 = median(fl, "chain_cpu_s"), median(fr, "chain_cpu_s")
    print(f"  the chain: median {w0:.1f} s wall / {p0:.1f} s CPU frictionless, {w1:.1f} s wall / {p1:.1f} s CPU with "
          f"friction: ratio {w1 / w0:.2f} wall, {p1 / p0:.2f} CPU; peak RSS {max(peak(fl, 'process_rss_mib'), peak(fr, 'process_rss_mib')):.0f} MiB")


if __name__ == "__main__":
    sys.exit(main())
