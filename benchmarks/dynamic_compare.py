"""Same physics? The dynamic scenes with speed levers against the reference options, over a
truncated (or the full) horizon (docs/engine.md "Dynamic scenes: profile and levers").

    python benchmarks/dynamic_compare.py run impact  --steps 60 --out ref.npz [--opt KEY=VALUE ...]
    python benchmarks/dynamic_compare.py run induced --steps 300 --orientation B2 --out ref.npz [--opt ...]
    python benchmarks/dynamic_compare.py diff ref.npz lever.npz [more.npz ...]

``run``: one scene run from t = 0 over ``--steps`` nominal steps (induced: the thesis's fixed
steps, ``time.adaptive.enabled=false``, unless ``--set time.adaptive.enabled=true``) (impact: 0.5 µs from the
relaxed state of ``--relaxed``; induced: 5 µs) with the integrator options ``--opt`` (flat
names of ``rve.solvers.dirk.integrator_options``; none = the scene's defaults) and config
overrides ``--set``; saves the per-step histories (impact: projectile centre-of-mass velocity
and position; induced: the mean and the largest warp deflection; both: the balance errors, the
wall time of every step; induced: the step sizes) and the summary's figures to ``--out``.

``diff``: for each further file against the first (the reference): the largest difference of
the projectile velocity history (mm/ms, and relative to the speed) or of the deflection
histories (mm, and relative to the largest deflection), at the common accepted-step times
(the runs use the same nominal grid), the final values, the balance errors of both, and the
wall per step of both (their ratio; for a timing, interleave runs with farm-bench).

    python benchmarks/dynamic_compare.py results BASE_TREE OTHER_TREE

``results``: the outputs of the Snakemake targets ``impact`` and ``induced_deformation``
(``results/impact/full``, ``results/induced_deformation/B1..B3``) of two source trees (e.g.
after ``benchmarks/dynamic_pipeline.py``): the projectile's centre-of-mass velocity history
(``impact.nc``, every accepted step) and the mean and the largest warp deflection histories
of every orientation (``induced_deformation.nc``, the stored states) at the common times, as
the largest difference (and relative to the speed / the largest deflection), the final
values, and the summaries' balance errors side by side.
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
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from dynamic_profile import OUT, StepClock, parse_opts  # noqa: E402

from rve.config.loader import load_config  # noqa: E402


def run_impact(a, opts):
    from rve.scenes import impact
    from rve.scenes.impact.record import ImpactRecorder

    cfg = load_config(a.config or "configs/scenes/impact.yaml", OUT + (a.set or []))
    x0, rinfo = impact.load_or_relax(cfg, a.relaxed)
    n = a.steps
    h = cfg.time.t_end / impact.scene.nominal_steps(cfg)
    with StepClock(ImpactRecorder) as clock:
        w0, c0 = time.perf_counter(), time.process_time()
        s = impact.solve(cfg, x_start=x0, relax_info=rinfo, record=True, t_end=n * h, steps=n,
                         integrator_options=opts).summary
        wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    ser = s["history"]["series"]
    hist = {"t": np.asarray(ser["t"]), "v_com": np.asarray(ser["v_com"]), "com": np.asarray(ser["com"]),
            "omega": np.asarray(ser["omega"]), "max_T": np.asarray(ser["max_T"])}
    bal = {k: float(v) for k, v in s["balance_errors"].items()}
    return hist, bal, clock, wall, cpu, s


def run_induced(a, opts):
    from rve.scenes import induced
    from rve.scenes.induced.record import InducedRecorder

    cfg = load_config(a.config or "configs/scenes/induced_deformation.yaml",
                      OUT + [f"field.orientation={a.orientation}", "time.store_every=1",
                             "time.adaptive.enabled=false"] + (a.set or []))
    h = cfg.time.t_end / cfg.time.steps
    with StepClock(InducedRecorder) as clock:
        w0, c0 = time.perf_counter(), time.process_time()
        res = induced.solve(cfg, record=True, t_end=a.steps * h, steps=a.steps, integrator_options=opts)
        wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    s = res.summary
    st = s["history"]["stored"]
    base, problem = res.model, induced.setup(cfg)
    warp = np.concatenate([base.mesh.fibril_nodes(f) for f in problem.weave.warp])
    X = np.asarray(st["x"])[:, warp, :3] - problem.x0.reshape(base.mesh.n_nodes, -1)[warp, :3]
    hist = {"t": np.asarray(st["t"]), "mean_deflection": X.mean(axis=1),
            "max_deflection": np.linalg.norm(X, axis=2).max(axis=1),
            "max_T": np.asarray([np.max(T) for T in st["T"]]), "h": np.asarray(s["history"]["h"])}
    bal = {k: float(v) for k, v in s["balance_errors"].items()}
    return hist, bal, clock, wall, cpu, s


def do_run(a):
    opts = parse_opts(a.opt)
    hist, bal, clock, wall, cpu, s = (run_impact if a.scene == "impact" else run_induced)(a, opts)
    step_wall = np.diff([clock.t0] + clock.times)
    meta = {"scene": a.scene, "options": opts, "balances": bal, "wall_s": wall, "cpu_s": cpu,
            "steps": s["steps_accepted"], "rejected": s["steps_rejected"],
            "newton_iterations_per_stage": s["newton_iterations_per_stage"], "factorizations": s["factorizations"],
            "time_control": s.get("time_control", "fixed"), "error_rejections": s.get("steps_rejected_by_error", 0),
            "step_ms": s.get("step_ms", {})}
    np.savez(a.out, meta=np.array(json.dumps(meta, default=float)), step_wall=step_wall, **hist)
    print(f"[{a.scene}] {json.dumps(meta, default=float)}")


def _load(path):
    d = np.load(path, allow_pickle=False)
    return json.loads(str(d["meta"])), {k: d[k] for k in d.files if k != "meta"}


def _common(ta, tb):
    """Indices of the times common to both histories (same nominal grid)."""
    ia, ib = [], []
    j = 0
    for i, t in enumerate(ta):
        while j < len(tb) and tb[j] < t - 1e-12 * max(1.0, abs(t)):
            j += 1
        if j < len(tb) and abs(tb[j] - t) <= 1e-9 * max(1e-9, abs(t)):
            ia.append(i)
            ib.append(j)
    return np.asarray(ia, int), np.asarray(ib, int)


def do_diff(a):
    ref_meta, ref = _load(a.files[0])
    print(f"reference {a.files[0]}: options {ref_meta['options']}, {ref_meta['steps']} steps, "
          f"balances {json.dumps({k: float(f'{v:.3g}') for k, v in ref_meta['balances'].items()})}")
    for f in a.files[1:]:
        meta, hist = _load(f)
        ia, ib = _common(ref["t"], hist["t"])
        print(f"{f}: options {meta['options']}, {meta['steps']} steps ({len(ia)} common times up to "
              f"t = {ref['t'][ia[-1]]:.6g} ms)")
        keys = ("v_com", "com", "omega") if "v_com" in ref else ("mean_deflection", "max_deflection")
        if meta.get("time_control") == "adaptive" or ref_meta.get("time_control") == "adaptive":
            print(f"  time control {ref_meta.get('time_control', 'fixed')} -> {meta.get('time_control', 'fixed')}: "
                  f"steps {ref_meta['steps']} -> {meta['steps']}, rejected {ref_meta['rejected']} -> "
                  f"{meta['rejected']} (by the error estimate {meta.get('error_rejections', 0)}), step ms "
                  f"{json.dumps(meta.get('step_ms', {}))}; wall {ref_meta['wall_s']:.1f} -> {meta['wall_s']:.1f} s "
                  f"(ratio {meta['wall_s'] / ref_meta['wall_s']:.3f}), CPU {ref_meta['cpu_s']:.1f} -> "
                  f"{meta['cpu_s']:.1f} s (ratio {meta['cpu_s'] / ref_meta['cpu_s']:.3f})")
        for k in keys + ("max_T",):
            d = np.abs(np.asarray(hist[k])[ib] - np.asarray(ref[k])[ia])
            scale = float(np.max(np.abs(ref[k][ia]))) or 1.0
            print(f"  {k}: max |difference| {float(d.max()):.3e} ({float(d.max()) / scale:.2e} of max |ref| "
                  f"{scale:.4g}); final ref {np.round(np.atleast_1d(ref[k][ia[-1]]), 7).tolist()} lever "
                  f"{np.round(np.atleast_1d(hist[k][ib[-1]]), 7).tolist()}")
        print("  balances: " + ", ".join(f"{k} {ref_meta['balances'][k]:.3g} -> {v:.3g}"
                                         for k, v in meta["balances"].items()))
        print("  balances, relative difference: " + ", ".join(
            f"{k} {abs(v - ref_meta['balances'][k]) / max(abs(ref_meta['balances'][k]), 1e-300):.1e}"
            for k, v in meta["balances"].items()))
        ra, rb = float(np.mean(ref["step_wall"])), float(np.mean(hist["step_wall"]))
        print(f"  wall per step {1e3 * ra:.0f} -> {1e3 * rb:.0f} ms (x {rb / ra:.2f}); Newton its/stage "
              f"{ref_meta['newton_iterations_per_stage']:.2f} -> {meta['newton_iterations_per_stage']:.2f}; "
              f"factorisations {ref_meta['factorizations']} -> {meta['factorizations']}")


def _nc(path, *names):
    import xarray as xr

    with xr.open_dataset(path) as ds:
        return {n: np.asarray(ds[n].values) for n in names}


def _balances(path) -> dict:
    s = json.loads(Path(path).read_text())
    return {k: float(v) for k, v in s.get("balance_errors", {}).items() if isinstance(v, (int, float))}


def _print_balances(ba: dict, bb: dict) -> None:
    print("  balances: " + ", ".join(f"{k} {ba[k]:.3g} -> {bb[k]:.3g}" for k in ba if k in bb))


def _warp_deflections(path):
    import xarray as xr

    with xr.open_dataset(path) as ds:
        warp = [i for i, n in enumerate(ds["fibril"].values) if str(n).startswith("warp")]
        pos = np.asarray(ds["position"].values, float)[:, warp]           # (time, warp, node, xyz)
        t = np.asarray(ds["time"].values, float)
    X = pos - pos[:1]
    return t, X.reshape(len(t), -1, 3).mean(axis=1), np.linalg.norm(X, axis=-1).reshape(len(t), -1).max(axis=1)


def do_results(a):
    base, other = Path(a.base), Path(a.other)
    imp = "results/impact/full"
    if (base / imp / "impact.nc").exists() and (other / imp / "impact.nc").exists():
        A = _nc(base / imp / "impact.nc", "step_time", "projectile_com_velocity")
        B = _nc(other / imp / "impact.nc", "step_time", "projectile_com_velocity")
        ia, ib = _common(A["step_time"], B["step_time"])
        va, vb = A["projectile_com_velocity"][ia], B["projectile_com_velocity"][ib]
        d = float(np.abs(va - vb).max())
        speed = float(np.abs(va[:, 2]).max())
        print(f"[impact] {len(ia)} common step times (of {len(A['step_time'])} / {len(B['step_time'])}), up to "
              f"t = {A['step_time'][ia[-1]]:.6g} ms: projectile v_com max |difference| {d:.3e} mm/ms "
              f"({d / speed:.2e} of the speed {speed:.4g}); final {np.round(va[-1], 7).tolist()} -> "
              f"{np.round(vb[-1], 7).tolist()}")
        _print_balances(_balances(base / imp / "summary.json"), _balances(other / imp / "summary.json"))
    for o in ("B1", "B2", "B3"):
        d_ = f"results/induced_deformation/{o}"
        fa, fb = base / d_ / "induced_deformation.nc", other / d_ / "induced_deformation.nc"
        if not (fa.exists() and fb.exists()):
            continue
        ta, ma, xa = _warp_deflections(fa)
        tb, mb, xb = _warp_deflections(fb)
        ia, ib = _common(ta, tb)
        dm = float(np.abs(ma[ia] - mb[ib]).max())
        dx = float(np.abs(xa[ia] - xb[ib]).max())
        print(f"[induced {o}] {len(ia)} common stored times up to t = {ta[ia[-1]]:.6g} ms: mean warp deflection "
              f"max |difference| {dm:.3e} mm (any component; {dm / float(np.abs(ma).max()):.2e} of its max "
              f"{float(np.abs(ma).max()):.4g}), largest deflection {dx:.3e} mm ({dx / float(xa.max()):.2e} of "
              f"{float(xa.max()):.4g}); final mean {np.round(ma[ia[-1]], 4).tolist()} -> "
              f"{np.round(mb[ib[-1]], 4).tolist()}, largest {xa[ia[-1]]:.4f} -> {xb[ib[-1]]:.4f}")
        _print_balances(_balances(base / d_ / "summary.json"), _balances(other / d_ / "summary.json"))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("scene", choices=["impact", "induced"])
    r.add_argument("--steps", type=int, required=True)
    r.add_argument("--orientation", default="B2")
    r.add_argument("--relaxed", default="/tmp/rve_impact_relaxed_full.npz")
    r.add_argument("--config", default=None)
    r.add_argument("--set", nargs="*", default=[])
    r.add_argument("--opt", nargs="*", default=[])
    r.add_argument("--out", required=True)
    d = sub.add_parser("diff")
    d.add_argument("files", nargs="+")
    rr = sub.add_parser("results")
    rr.add_argument("base")
    rr.add_argument("other")
    a = ap.parse_args()
    {"run": do_run, "diff": do_diff, "results": do_results}[a.cmd](a)


if __name__ == "__main__":
    main()
