"""The energy minimiser's regularisation schedule on the pipeline's own strain steps: how many
trial steps it rejects and what a step costs, with the schedule of ``rve.solvers.minimize``
(``current``) and with the variants below, each in a fresh process on the same input state.

A side runs ``rve.homogenisation.jobs.strain_job`` for ``--mode`` step ``--step`` of a run of
``configs/pipeline.yaml`` (default ``work_precision_default``, the periodic 2 x 2 candidate)
from ``--state`` (the stored state of the step before) with ``_next_sigma`` replaced by the
variant, and prints the wall and CPU time, the accepted iterations, rejections and
factorisations summed over the step's minimiser runs, the converged residual and the face
forces; then the table of the sides and each one's ratio to ``current``.

    nice -n 10 python benchmarks/minimizer_schedule.py --state STATES/uniaxial_01.nc --mode uniaxial --step 2
        [--variants current gentle memory] [--run work_precision_default]

Variants (sigma after an accepted step; the rejection and indefiniteness rules are unchanged):
* ``current``: the shipped rule;
* ``gentle``: after a good full step sigma falls by 3 (ratio > 0.75) or 2 (ratio > 0.5), and
  follows |F|^2 only once the residual contracts by 4 or more per iteration (Newton's basin);
* ``memory``: the shipped rule, but not below a quarter of the last sigma at which a trial
  was rejected (that memory fades by 4 per accepted iteration, as the indefiniteness one).
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import ROOT, interleave, run_json, worker_env  # noqa: E402

VARIANTS = ("current", "gentle", "memory")


def _gentle(sigma, backtracked, ratio, alpha, sig_floor, sig_neg, contraction):
    sigma_used = sigma
    if backtracked:
        return max(2.0 * sigma, sig_floor)
    if ratio > 0.5 and alpha == 1.0:
        sigma = max(sigma / (3.0 if ratio > 0.75 else 2.0), 2.0 * sig_neg)
        if ratio > 0.75 and contraction < 0.25:
            sigma = min(sigma, sigma_used * contraction ** 2)
        return 0.0 if sigma <= sig_floor else sigma
    if ratio < 0.25:
        return max(4.0 * sigma, sig_floor)
    if alpha < 1.0:
        return max(2.0 * sigma, sig_floor)
    return sigma


def _install(variant: str, counts: dict) -> None:
    import rve.solvers.minimize as M

    current = M._next_sigma
    memory = {"sigma": 0.0}
    if variant == "gentle":
        M._next_sigma = _gentle
    elif variant == "memory":
        def _memory(sigma, backtracked, ratio, alpha, sig_floor, sig_neg, contraction):
            s = current(sigma, backtracked, ratio, alpha, sig_floor, sig_neg, contraction)
            floor = 0.25 * memory["sigma"]
            memory["sigma"] *= 0.25
            return s if s == 0.0 and floor <= sig_floor else max(s, floor)
        M._next_sigma = _memory
    inner = M._minimize_energy

    def counted(*args, **kwargs):
        xs, ws, out = inner(*args, **kwargs)
        counts["runs"] += 1
        counts["iterations"] += int(out.iterations)
        counts["rejections"] += int(out.rejections)
        counts["factorizations"] += int(out.factorizations)
        if variant == "memory" and out.sigmas:
            memory["sigma"] = 0.0
        return xs, ws, out
    M._minimize_energy = counted
    if variant == "memory":
        log_rejection = M.log.info

        def spy(msg, *a, **k):
            if "rejected" in msg and len(a) >= 5:
                memory["sigma"] = max(memory["sigma"], float(a[-1]) / 4.0)
            return log_rejection(msg, *a, **k)
        M.log.info = spy


def worker(variant: str, spec_file: str, combo: str, state: str, mode: str, step: int, out_dir: str) -> None:
    import logging

    from rve.homogenisation.checkpoint import load_state
    from rve.homogenisation.jobs import strain_job

    logging.getLogger("rve.solvers.minimize").setLevel(logging.INFO)
    counts = {"runs": 0, "iterations": 0, "rejections": 0, "factorizations": 0}
    _install(variant, counts)
    spec = json.loads(Path(spec_file).read_text())
    out = Path(out_dir) / f"{mode}_{step:02d}.nc"
    t0, c0 = time.perf_counter(), time.process_time()
    strain_job(state, out, Path(out_dir) / "strain.log", spec, combo, mode, step)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    st = load_state(out)
    print(json.dumps({"variant": variant, "step_wall_s": wall, "step_cpu_s": cpu, **counts,
                      "converged": bool(st.solver.get("converged")), "residual_N": float(st.solver.get("residual_N")),
                      "reaction_force": _forces(st.reaction_force)}))


def _forces(reaction) -> list:
    """The face forces (periodic cell: a dict by face) or clamp reactions as one flat list."""
    if isinstance(reaction, dict):
        return [float(v) for k in sorted(reaction) for v in np.ravel(reaction[k])]
    return np.asarray(reaction, float).ravel().tolist()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--worker", nargs=4, metavar=("VARIANT", "SPEC", "COMBO", "STATE"))
    ap.add_argument("--out")
    ap.add_argument("--state")
    ap.add_argument("--mode", default="uniaxial")
    ap.add_argument("--step", type=int, default=2)
    ap.add_argument("--run", default="work_precision_default")
    ap.add_argument("--combo", default="base")
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=VARIANTS)
    ap.add_argument("--runs", type=int, default=1)
    a = ap.parse_args()
    if a.worker:
        return worker(*a.worker, a.mode, a.step, a.out)
    spec = yaml.safe_load((ROOT / "configs" / "pipeline.yaml").read_text())["rve"]["runs"][a.run]
    work = Path(tempfile.mkdtemp(prefix="minimizer_schedule_"))
    spec_file = work / "spec.json"
    spec_file.write_text(json.dumps(spec))

    def side(variant):
        def run(k):
            out = work / f"{variant}_{k}"
            out.mkdir()
            return run_json([sys.executable, __file__, "--worker", variant, spec_file, a.combo, a.state, "--mode",
                             a.mode, "--step", a.step, "--out", out], env=worker_env())
        return run

    recs = interleave({v: side(v) for v in a.variants}, a.runs)
    print(f"{a.run} {a.mode} step {a.step} from {a.state}:")
    base = None
    for v, rs in recs.items():
        for r in rs:
            if "error" in r:
                print(f"  {v}: error {r['error']}")
                continue
            f = np.asarray(r["reaction_force"])
            base = base or r
            print(f"  {v:8s} {r['step_wall_s']:7.1f} s wall {r['step_cpu_s']:7.1f} s CPU ({r['step_cpu_s'] / base['step_cpu_s']:.2f}), "
                  f"{r['iterations']} iterations, {r['rejections']} rejected, {r['factorizations']} factorisations in "
                  f"{r['runs']} minimiser runs; converged={r['converged']} |F|={r['residual_N']:.2e} N; "
                  f"face forces differ from the first side's by {np.abs(f - np.asarray(base['reaction_force'])).max():.2e} N "
                  f"(max |f| {np.abs(f).max():.3g} N); peak RSS {r['process_rss_mib']:.0f} MiB")


if __name__ == "__main__":
    main()
