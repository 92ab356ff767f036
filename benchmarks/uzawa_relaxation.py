"""Relaxed Uzawa updates against the plain ones (docs/contact.md "Relaxed updates when the
loop cycles"): the pipeline's jobs of a run (``relax_job``, ``strain_job``) from its stored
states, each job in a fresh process once with the shipped loop (relaxed updates once it
cycles) and once with the plain updates (``rve.solvers.augmented.RELAXATION = 1``), the two
alternating, ``--runs`` times each.

    nice -n 10 python benchmarks/uzawa_relaxation.py STATES [--run imperfect_18]
        [--jobs relax uniaxial:2 shear:2] [--runs 1] [--work DIR]

STATES: the run's stored states (``initial.nc``, ``relaxed.nc``, ``{mode}_{NN}.nc``; a job
``mode:N`` starts from step N - 1's state, ``relax`` from ``initial.nc``). Prints per job
and variant the median CPU and wall time, the Uzawa updates and solves, whether the
tolerance was met, the largest overlap left (over R), the update from which the updates
were relaxed, and the x+ face force; then per job the CPU ratio relaxed / plain, the
difference of the two states' x+ face forces, and the peak RSS.

A worker: ``python benchmarks/uzawa_relaxation.py --worker SPEC.json JOB STATES OUT RELAXATION``.
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
from _harness import interleave, median, peak, pipeline_spec, run_json, worker_env  # noqa: E402


def _al_info(solver: dict) -> dict:
    """The Uzawa loop's record of a stored state's solver info (a strain step keeps it under
    ``static``, the relaxation at the top)."""
    return (solver.get("static") or {}).get("augmented_lagrangian") or solver.get("augmented_lagrangian") or {}


def worker(spec_file: str, job: str, states: str, out_dir: str, relaxation: float) -> None:
    """One job from the stored states with ``RELAXATION = relaxation``; one JSON line."""
    import rve.solvers.augmented as augmented
    from rve.homogenisation.checkpoint import load_state
    from rve.homogenisation.jobs import BASE_COMBO, relax_job, strain_job

    augmented.RELAXATION = float(relaxation)
    spec = json.loads(Path(spec_file).read_text())
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    t0, c0 = time.perf_counter(), time.process_time()
    if job == "relax":
        out = out_dir / "relaxed.nc"
        relax_job(Path(states) / "initial.nc", out, out_dir / "relaxed.log", spec, BASE_COMBO)
    else:
        mode, step = job.split(":")
        step = int(step)
        prev = Path(states) / ("relaxed.nc" if step == 1 else f"{mode}_{step - 1:02d}.nc")
        out = out_dir / f"{mode}_{step:02d}.nc"
        strain_job(prev, out, out_dir / f"{mode}_{step:02d}.log", spec, BASE_COMBO, mode, step)
    rec = {"job_wall_s": time.perf_counter() - t0, "job_cpu_s": time.process_time() - c0}
    st = load_state(out)
    al = _al_info(st.solver or {})
    rec.update(updates=al.get("updates"), solves=al.get("solves"), met=al.get("met"),
               overlap=al.get("max_penetration_over_R"), relaxed_from=al.get("relaxed_from"))
    if st.reaction_force:
        rec["reaction_x+"] = [float(v) for v in st.reaction_force.get("x+", [])[:2]]
    print(json.dumps(rec, default=float))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("states", nargs="?")
    ap.add_argument("--run", default="imperfect_18", help="a run of configs/pipeline.yaml")
    ap.add_argument("--jobs", nargs="+", default=["relax", "uniaxial:2", "shear:2"])
    ap.add_argument("--runs", type=int, default=1)
    ap.add_argument("--work", help="directory of the workers' states (default: a temporary one)")
    ap.add_argument("--worker", nargs=5, metavar=("SPEC", "JOB", "STATES", "OUT", "RELAXATION"))
    a = ap.parse_args()
    if a.worker:
        spec, job, states, out, relaxation = a.worker
        return worker(spec, job, states, out, float(relaxation)) or 0
    if not a.states:
        ap.error("STATES is required")
    work = Path(a.work or tempfile.mkdtemp(prefix="uzawa_relaxation_"))
    work.mkdir(parents=True, exist_ok=True)
    spec_file = work / "spec.json"
    spec_file.write_text(json.dumps(pipeline_spec(a.run)))
    variants = {"relaxed": 0.5, "plain": 1.0}
    print(f"run {a.run}, states {a.states}, {a.runs} run(s) per job and variant; work {work}")
    for job in a.jobs:
        def side(name, job=job):
            def run(i):
                out = work / f"{job.replace(':', '_')}_{name}_{i}"
                return run_json([sys.executable, __file__, "--worker", str(spec_file), job, a.states, str(out),
                                 str(variants[name])], env=worker_env())
            return run
        recs = interleave({name: side(name) for name in variants}, a.runs)
        last, cpu = {}, {}
        for name in variants:
            ok = [r for r in recs[name] if "error" not in r]
            if not ok:
                print(f"{job:12s} {name:8s}: failed: {recs[name][-1].get('error')}")
                continue
            last[name], cpu[name] = ok[-1], median(ok, "job_cpu_s")
            r = ok[-1]
            print(f"{job:12s} {name:8s}: CPU {cpu[name]:8.1f} s, wall {median(ok, 'job_wall_s'):8.1f} s; updates "
                  f"{r['updates']}, solves {r['solves']}, met {r['met']}, overlap {r['overlap']:.2e} R, relaxed "
                  f"from {r['relaxed_from']}, x+ force {r.get('reaction_x+')}")
        if len(last) == 2:
            fa, fb = (np.asarray(last[n].get("reaction_x+") or [np.nan]) for n in variants)
            print(f"{job:12s} CPU ratio relaxed / plain {cpu['relaxed'] / cpu['plain']:.2f}; x+ force difference "
                  f"{np.max(np.abs(fa - fb)):.2e} N of {np.max(np.abs(fb)):.4f} N; peak RSS "
                  f"{max(peak(recs[n], 'process_rss_mib') for n in variants):.0f} MiB", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
