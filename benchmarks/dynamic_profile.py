"""Per-phase profile of the dynamic fabric scenes at full size over a truncated run
(docs/engine.md "Dynamic scenes: profile and levers").

    python benchmarks/dynamic_profile.py impact  [--steps 30] [--skip 14] [--relaxed PATH] [--opt KEY=VALUE ...]
    python benchmarks/dynamic_profile.py induced [--steps 100] [--orientation B2] [--opt KEY=VALUE ...]

``impact``: the thesis 32 x 32 weave and projectile (configs/scenes/impact.yaml) from its
relaxed state (``--relaxed``: an npz written by ``rve.scenes.impact.load_or_relax``, relaxed
and saved there if missing or for another config), ``--skip + --steps`` steps of the nominal
0.5 µs; the per-step figures are also given for the last ``--steps`` steps alone (the
projectile is on the fabric there: the gap of 0.2 mm closes after about 14 steps).
``induced``: configs/scenes/induced_deformation.yaml, one orientation, the first ``--steps``
of its 3000 steps of 5 µs.

``--baseline TREE``: the same profile run first in a fresh process on another source tree
(``PYTHONPATH=TREE``, its configs, e.g. today's main), then on this one; printed as the ratio of the CPU
per step and of each phase (this tree / baseline).

``--opt KEY=VALUE``: scene integrator options (``rve.solvers.dirk.integrator_options`` flat
names, e.g. ``jacobian_reuse=false``, ``predictor_degree=0``); ``--set``: config overrides.

One BLAS/OpenMP/MKL thread unless the environment says otherwise, as in the Snakefile's
jobs (a multi-threaded OpenBLAS on the shared 2-core machine made every vector norm of the
stage Newton cost ~9 ms). Printed: wall and CPU (process) seconds of the solve, and per phase: contact search/rebuild,
assembly, contact forms, composition, factorisation, linear solves (back substitutions),
the rest of Newton (line search, restriction, stage bookkeeping), thermal post-solve,
balances/output; Newton iterations per stage, Jacobian evaluations, factorisations and
reused iterations per step, why factorisations were dropped, rebuilds (early), rejected
steps. Factorisation and solve seconds are measured by wrapping the factorisation entry
points (``StageFactorisation`` of the modified Newton, ``sparse_solve`` of full Newton).
"""
from __future__ import annotations

import os

for _k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "RVE_PARDISO_THREADS"):   # as the Snakefile's jobs
    os.environ.setdefault(_k, "1")
try:  # the allocator as in the scenes' job bodies (a tree without it: its defaults)
    from rve.process import keep_freed_memory

    keep_freed_memory()
except ImportError:
    pass

import argparse  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from collections import Counter  # noqa: E402

import numpy as np  # noqa: E402

from rve.config.loader import load_config  # noqa: E402
from rve.solvers import newton as newton_mod  # noqa: E402

OUT = ["output.vtk=false", "output.png=false"]


class Probe:
    """Wall seconds of the factorisations and back substitutions, and why held
    factorisations were dropped (wrapping the solver entry points for one run)."""

    def __init__(self):
        self.t = Counter()
        self.n = Counter()
        self.reasons = Counter()
        self._saved = []

    def _wrap(self, owner, name, key, method=False):
        orig = getattr(owner, name)
        probe = self

        def wrapped(*a, **k):
            t0 = time.perf_counter()
            try:
                return orig(*a, **k)
            finally:
                probe.t[key] += time.perf_counter() - t0
                probe.n[key] += 1

        setattr(owner, name, wrapped)
        self._saved.append((owner, name, orig))

    def __enter__(self):
        SF, JR = newton_mod.StageFactorisation, newton_mod.JacobianReuse
        self._wrap(SF, "__init__", "factorize")
        self._wrap(SF, "solve", "solve")
        self._wrap(newton_mod, "sparse_solve", "factorize+solve (full Newton)")
        orig_inv = JR.invalidate
        probe = self

        def invalidate(jr, reason):
            if jr.factor is not None:
                probe.reasons[reason] += 1
            return orig_inv(jr, reason)

        JR.invalidate = invalidate
        self._saved.append((JR, "invalidate", orig_inv))
        return self

    def __exit__(self, *exc):
        for owner, name, orig in reversed(self._saved):
            setattr(owner, name, orig)


class StepClock:
    """Wall time at every accepted step (wraps a recorder class's ``on_step``)."""

    def __init__(self, recorder_cls):
        self.cls, self.times, self.its = recorder_cls, [], []

    def __enter__(self):
        orig = self.cls.on_step
        self._orig = orig
        clock = self

        def on_step(rec, t, x, w, info):
            out = orig(rec, t, x, w, info)
            clock.times.append(time.perf_counter())
            clock.its.append((list(info.stage_iterations), info.factorizations, info.jacobians))
            return out

        self.cls.on_step = on_step
        self.t0 = time.perf_counter()
        return self

    def __exit__(self, *exc):
        self.cls.on_step = self._orig


def _value(text: str):
    low = text.lower()
    if low in ("true", "false"):
        return low == "true"
    try:
        return int(text)
    except ValueError:
        try:
            return float(text)
        except ValueError:
            return text


def parse_opts(items) -> dict:
    return {k: _value(v) for k, v in (s.split("=", 1) for s in items or [])}


def run_impact(a, opts: dict) -> dict:
    from rve.scenes import impact
    from rve.scenes.impact.record import ImpactRecorder

    cfg = load_config(a.config or "configs/scenes/impact.yaml", OUT + (a.set or []))
    x0, rinfo = impact.load_or_relax(cfg, a.relaxed)
    n = a.skip + a.steps
    h = cfg.time.t_end / impact.scene.nominal_steps(cfg)
    with Probe() as probe, StepClock(ImpactRecorder) as clock:
        c0, w0 = time.process_time(), time.perf_counter()
        s = impact.solve(cfg, x_start=x0, relax_info=rinfo, record=False, t_end=n * h, steps=n,
                         integrator_options=opts).summary
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    w = s["wall_time_s"]
    phases = {"contact search/rebuild": w["contact_search"], "assembly (fabric beams)": w["assembly_fabric"],
              "contact forms (fabric)": w["contact_fabric"], "contact (sphere)": w["contact_sphere"],
              "composition": w["compose"], "thermal post-solve": w["temperature"],
              "balances/output": w["balances"] + w.get("checkpoint", 0.0)}
    return _report("impact", s, phases, w["linear_solve_and_newton"], probe, clock, cpu, wall, a.skip)


def run_induced(a, opts: dict) -> dict:
    from rve.scenes import induced
    from rve.scenes.induced.record import InducedRecorder

    cfg = load_config(a.config or "configs/scenes/induced_deformation.yaml",
                      OUT + ["time.adaptive.enabled=false", f"field.orientation={a.orientation}"] + (a.set or []))
    h = cfg.time.t_end / cfg.time.steps
    with Probe() as probe, StepClock(InducedRecorder) as clock:
        c0, w0 = time.process_time(), time.perf_counter()
        s = induced.solve(cfg, record=False, t_end=a.steps * h, steps=a.steps, integrator_options=opts).summary
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    w = s["wall_time_s"]
    search = w["rebuild"]
    phases = {"contact search/rebuild": search, "assembly (beams)": w["assembly"],
              "contact forms": w["contact"] - search, "thermal post-solve": w["thermal_post"],
              "balances/output": w["balances"]}
    rest = w["linear_solves_and_other"] - search
    return _report("induced", s, phases, rest, probe, clock, cpu, wall, 0)


def _report(tag, s, phases, newton_rest, probe, clock, cpu, wall, skip) -> dict:
    fac = probe.t["factorize"] + probe.t["factorize+solve (full Newton)"]
    sol = probe.t["solve"]
    phases = dict(phases)
    phases["factorisation"] = fac
    phases["linear solves"] = sol
    phases["Newton rest"] = newton_rest - fac - sol
    steps = max(1, s["steps_accepted"])
    its = [sum(i[0]) for i in clock.its]
    stage_n = sum(len(i[0]) for i in clock.its)
    jac = sum(i[2] for i in clock.its)
    fz = sum(i[1] for i in clock.its)
    times = np.diff([clock.t0] + clock.times)
    late = times[skip:] if skip < len(times) else times
    out = {"wall_s": wall, "cpu_s": cpu, "steps": s["steps_accepted"], "rejected": s["steps_rejected"],
           "newton_its_per_stage": sum(its) / max(1, stage_n), "jacobians_per_step": jac / steps,
           "factorizations_per_step": fz / steps, "rebuilds": s["contact_rebuilds"], "early": s["extra_rebuilds"],
           "refactor_reasons": dict(probe.reasons), "phases_s": phases,
           "wall_per_step_ms": 1e3 * wall / steps, "wall_per_step_late_ms": 1e3 * float(np.mean(late)),
           "cpu_per_step_ms": 1e3 * cpu / steps}
    print(f"[{tag}] {s['steps_accepted']} steps ({s['steps_rejected']} rejected): wall {wall:.2f} s, CPU {cpu:.2f} s; "
          f"per step wall {out['wall_per_step_ms']:.0f} ms, CPU {out['cpu_per_step_ms']:.0f} ms; last "
          f"{len(late)} steps {out['wall_per_step_late_ms']:.0f} ms wall per step")
    print(f"[{tag}] Newton its/stage {out['newton_its_per_stage']:.2f}, Jacobians/step {out['jacobians_per_step']:.2f}, "
          f"factorisations/step {out['factorizations_per_step']:.2f}; rebuilds {s['contact_rebuilds']} "
          f"(+{s['extra_rebuilds']} early); refactor reasons {dict(probe.reasons)}")
    tot = sum(phases.values())
    print(f"[{tag}] phases (wall s, % of the phases): " + ", ".join(
        f"{k} {v:.2f} ({100 * v / max(tot, 1e-300):.0f} %)" for k, v in phases.items()))
    return out


def run_baseline(tree: str) -> dict:
    """The figures of this script's run (same arguments, without ``--baseline``) on ``tree``."""
    argv = list(sys.argv[1:])
    i = argv.index("--baseline")
    del argv[i:i + 2]
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "baseline.json")
        env = dict(os.environ, PYTHONPATH=os.path.abspath(tree))
        print(f"[baseline] PYTHONPATH={env['PYTHONPATH']}", flush=True)
        # in the baseline tree: its configs (a scene config may name options that tree lacks)
        subprocess.run([sys.executable, os.path.abspath(__file__)] + argv + ["--json", path], env=env, check=True,
                       cwd=os.path.abspath(tree))
        with open(path) as fh:
            return json.load(fh)


def _print_ratio(base: dict, out: dict) -> None:
    print(f"[ratio] this tree / baseline: CPU per step {out['cpu_per_step_ms']:.0f} / "
          f"{base['cpu_per_step_ms']:.0f} ms = {out['cpu_per_step_ms'] / base['cpu_per_step_ms']:.3f}; wall per "
          f"step {out['wall_per_step_ms']:.0f} / {base['wall_per_step_ms']:.0f} ms = "
          f"{out['wall_per_step_ms'] / base['wall_per_step_ms']:.3f}")
    print("[ratio] phases (wall s, this tree / baseline): " + ", ".join(
        f"{k} {v:.2f} / {base['phases_s'][k]:.2f} = {v / max(base['phases_s'][k], 1e-300):.2f}"
        for k, v in out["phases_s"].items() if k in base["phases_s"]))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene", choices=["impact", "induced"])
    ap.add_argument("--steps", type=int, default=None)
    ap.add_argument("--skip", type=int, default=14, help="impact: steps before the measured window")
    ap.add_argument("--orientation", default="B2")
    ap.add_argument("--relaxed", default="/tmp/rve_impact_relaxed_full.npz")
    ap.add_argument("--config", default=None)
    ap.add_argument("--set", nargs="*", default=[], help="config overrides KEY=VALUE")
    ap.add_argument("--opt", nargs="*", default=[], help="integrator options KEY=VALUE")
    ap.add_argument("--json", default=None, help="also write the figures to this file")
    ap.add_argument("--baseline", default=None, help="another source tree profiled first (ratio printed)")
    a = ap.parse_args()
    if a.steps is None:
        a.steps = 30 if a.scene == "impact" else 100
    opts = parse_opts(a.opt)
    base = run_baseline(a.baseline) if a.baseline else None
    print(f"[this tree] {os.path.dirname(os.path.dirname(os.path.abspath(__import__('rve').__file__)))}", flush=True)
    out = (run_impact if a.scene == "impact" else run_induced)(a, opts)
    out["options"] = opts
    if base is not None:
        _print_ratio(base, out)
        out["baseline"] = base
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(out, fh, indent=1, default=float)


if __name__ == "__main__":
    main()
