"""Interleaved whole-scene A/B of the dynamic scenes' stage-matrix backend, in this process
(docs/engine.md "Unsymmetric stage matrices").

    python benchmarks/engine_scene_ab.py impact [--start 60 --steps 20 --rounds 2] [--reduced]
    python benchmarks/engine_scene_ab.py induced [--steps 100 --rounds 3]
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
from _harness import ROOT  # noqa: E402


# ----------------------------------------------------------------------------- scene A/B
def _state_diff(a: dict, b: dict) -> dict:
    """max |a - b| / max |a| of the final states' arrays (x, w, T)."""
    out = {}
    for k in ("x", "w", "T"):
        if k in a and k in b:
            va, vb = np.asarray(a[k], float), np.asarray(b[k], float)
            out[k] = float(np.abs(va - vb).max() / max(np.abs(va).max(), 1e-300))
    return out


class _Timers:
    """Calls and wall time of the factorisation backends' phases (wrapped methods), reset per run."""

    def __init__(self):
        from rve.solvers.backends.pruned import PrunedSuperLU
        from rve.solvers import linear
        from rve.solvers.backends import pardiso

        self.t, self.n = {}, {}
        targets = [(pardiso.PardisoFactorization, "analyse", "pardiso_analyse"),
                   (pardiso.PardisoFactorization, "factorize", "pardiso_factorize"),
                   (pardiso.PardisoFactorization, "solve", "pardiso_solve"),
                   (PrunedSuperLU, "_factorize", "superlu_pruned_factorize"),
                   (PrunedSuperLU, "solve", "superlu_pruned_solve"),
                   (linear.SuperLUBackend, "_factorize", "superlu_factorize"),
                   (linear.SuperLUBackend, "solve", "superlu_solve")]
        for owner, attr, key in targets:
            self._wrap(owner, attr, key)

    def _wrap(self, owner, attr, key):
        fn = owner.__dict__[attr]
        timers = self

        def timed(*a, **k):
            t0 = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                timers.t[key] = timers.t.get(key, 0.0) + time.perf_counter() - t0
                timers.n[key] = timers.n.get(key, 0) + 1

        setattr(owner, attr, timed)

    def reset(self):
        self.t, self.n = {}, {}

    def summary(self) -> str:
        # pardiso_factorize includes the analyses it triggers; printed as is
        return ", ".join(f"{k} {self.n[k]}x {self.t[k]:.1f} s" for k in sorted(self.t))


def main_scene_ab(scene: str, backends, rounds: int, steps: int, start: int, reduced: bool, json_path=None) -> None:
    """Interleaved whole-scene runs in this process, one per backend and round (the backend
    through ``integrator_options={'linear_backend': ...}``): CPU and wall time medians, the
    ratio to the first backend, factorisations, Newton iterations per stage, balance errors,
    and the final states' max differences to the first backend's.

    ``impact``: configs/scenes/impact.yaml (full size unless ``reduced``); the relaxed state of
    engine_matrices.py (``impact_scene[_reduced]_relaxed.npz``, relaxed here if absent), then
    ``start`` steps of 0.5 us once (pardiso_unsym) to a checkpoint, from which every timed run
    resumes for ``steps`` more (the segment in sphere + fabric contact); the last two stage
    matrices of the preparation are saved as ``impact_deep[_reduced]_<k>``.
    ``induced``: configs/scenes/induced_deformation.yaml B3 full size, ``steps`` steps of 5 us
    from t = 0 (contact from about 0.3 ms)."""
    import shutil
    import tempfile

    sys.path.insert(0, str(ROOT / "benchmarks"))
    from rve.config.loader import load_config

    from rve.solvers import linear
    from rve.solvers.backends import pardiso as _pardiso

    # a benchmark-only variant: mtype 11 analysing the stored pattern (candidate contact pairs
    # included), so that later nonzero patterns of the same contact map lie in it
    linear.register_backend("pardiso_unsym_stored", lambda symmetric=True: _pardiso.PardisoFactorization(
        symmetric=False, analyse_stored=True))
    d = ROOT / "results/engine"
    ov = ["output.vtk=false", "output.png=false"]
    runs = {b: [] for b in backends}
    tmp = Path(tempfile.mkdtemp(prefix="rve_ab_"))
    if scene == "impact":
        from engine_matrices import _hook_stage_matrices, _save

        from rve.scenes import impact
        from rve.scenes.impact.scene import schur_border

        if reduced:
            ov += ["geometry.n_warp=8", "geometry.n_weft=8", "geometry.span=12.7 mm", "mesh.elements=16",
                   "projectile.radius=4.5 mm"]
        tag = "impact_scene_reduced" if reduced else "impact_scene"
        cfg = load_config(ROOT / "configs/scenes/impact.yaml", ov + [f"time.checkpoint_every={start}"])
        state = d / f"{tag}_relaxed.npz"
        if state.exists():
            x0 = np.load(state)["x"]
        else:
            x0, _ = impact.relax(cfg)
            d.mkdir(parents=True, exist_ok=True)
            np.savez(state, x=x0)
        total = start + steps
        t_end = 5e-4 * total
        ck = tmp / "start.npz"
        seen, undo = _hook_stage_matrices(2)
        t0 = time.perf_counter()
        try:
            impact.solve(cfg, x_start=x0, record=False, t_end=t_end, steps=total, checkpoint=ck,
                         stop_after_steps=start, integrator_options={"linear_backend": "pardiso_unsym"})
        except Exception as exc:  # SceneFailure: stopped after `start` steps (the checkpoint is written)
            print(f"  preparation: {exc} ({time.perf_counter() - t0:.0f} s)", flush=True)
        finally:
            undo()
        deep = "impact_deep_reduced" if reduced else "impact_deep"
        for k, (seq, A) in enumerate(seen["last"]):
            _save(d, f"{deep}_{k}", A, {"source": f"impact scene {'reduced' if reduced else 'full size'}, the "
                                                  f"{seq}-th of {seen['count']} stage factorisations of the first "
                                                  f"{start} steps of 0.5 us (row-scaled, restricted)",
                                        "border": schur_border(impact.setup(cfg).system),
                                        "note": f"factorisation {seq}/{seen['count']}"})

        def one(backend):
            c = tmp / f"run_{backend}.npz"
            shutil.copy(ck, c)
            return impact.solve(cfg, x_start=x0, record=False, t_end=t_end, steps=total, checkpoint=c,
                                integrator_options={"linear_backend": backend})
    else:
        from rve.scenes.induced import solve as induced_solve

        cfg = load_config(ROOT / "configs/scenes/induced_deformation.yaml", ov + ["time.adaptive.enabled=false", "field.orientation=B3"])

        def one(backend):
            return induced_solve(cfg, t_end=5e-3 * steps, steps=steps, record=False,
                                 integrator_options={"linear_backend": backend})
    timers = _Timers()
    phases = {}
    for _ in range(max(1, rounds)):
        for b in backends:
            timers.reset()
            c0, w0 = time.process_time(), time.perf_counter()
            r = one(b)
            runs[b].append((r, time.process_time() - c0, time.perf_counter() - w0))
            phases[b] = timers.summary()
            print(f"  {scene} {b}: CPU {runs[b][-1][1]:.1f} s wall {runs[b][-1][2]:.1f} s "
                  f"(load {os.getloadavg()[0]:.1f}); {phases[b]}", flush=True)
    ref = runs[backends[0]][-1][0]
    rec = {}
    cpu0 = float(np.median([c for _, c, _ in runs[backends[0]]]))
    for b in backends:
        r = runs[b][-1][0]
        s = r.summary
        cpu = float(np.median([c for _, c, _ in runs[b]]))
        wall = float(np.median([w for _, _, w in runs[b]]))
        diff = _state_diff(ref.state, r.state)
        rec[b] = {"cpu_s": cpu, "wall_s": wall, "cpu_ratio": cpu0 / cpu, "runs": len(runs[b]),
                  "factorizations": s.get("factorizations"), "newton_per_stage": s.get("newton_iterations_per_stage"),
                  "steps_accepted": s.get("steps_accepted"), "steps_rejected": s.get("steps_rejected"),
                  "balance_errors": s.get("balance_errors"), "state_diff_to_first": diff, "phases": phases.get(b)}
        print(f"[{scene}] {b:<16} CPU {cpu:7.1f} s (ratio {cpu0 / cpu:4.2f})  wall {wall:7.1f} s  "
              f"steps {s.get('steps_accepted')}/{s.get('steps_rejected')} rejected  factorisations "
              f"{s.get('factorizations')}  Newton/stage {s.get('newton_iterations_per_stage'):.2f}  "
              f"max|diff|/max to {backends[0]}: " + " ".join(f"{k} {v:.1e}" for k, v in diff.items()), flush=True)
        print(f"[{scene}] {b:<16} balance errors "
              + json.dumps({k: float(f"{v:.4g}") for k, v in s.get("balance_errors", {}).items()}), flush=True)
    shutil.rmtree(tmp, ignore_errors=True)
    if json_path:
        Path(json_path).write_text(json.dumps(rec, indent=1, default=float))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scene", choices=("impact", "induced"))
    ap.add_argument("--backends", nargs="*", default=None,
                    help="default: impact superlu_pruned pardiso_unsym; induced superlu pardiso")
    ap.add_argument("--rounds", type=int, default=2, help="interleaved rounds")
    ap.add_argument("--steps", type=int, default=20, help="timed steps")
    ap.add_argument("--start", type=int, default=60, help="impact: steps before the timed segment")
    ap.add_argument("--reduced", action="store_true", help="impact: the config header's small version")
    ap.add_argument("--json", default=None, help="also write the records here")
    a = ap.parse_args(argv)
    be = a.backends or (["superlu_pruned", "pardiso_unsym"] if a.scene == "impact" else ["superlu", "pardiso"])
    main_scene_ab(a.scene, be, a.rounds, a.steps, a.start, a.reduced, a.json)


if __name__ == "__main__":
    main()
