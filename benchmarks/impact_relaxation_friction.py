"""A frictional relaxation of the impact fabric's straight natural state (docs/impact.md
"Relaxation with friction"): does the fibril friction bring the straight-reference weave,
which slides off its crossings without friction, to rest, and how does the relaxed state
compare with the crimped weave the thesis starts its impact from?

    python benchmarks/impact_relaxation_friction.py table --mu 0 0.2 0.3 --t-end "1 ms" --steps 20 \\
        --out-dir /tmp/relax_fric [--json out.json]
    python benchmarks/impact_relaxation_friction.py table --mu 0 0.3 --t-end "4 ms" --steps 80 --out-dir ...
    python benchmarks/impact_relaxation_friction.py picture /tmp/relax_fric/mu0.npz /tmp/relax_fric/mu0.3.npz \\
        --png docs/img/impact_relaxation_friction.png
    python benchmarks/impact_relaxation_friction.py run --mu 0.3 [--t-end ..] [--steps ..] [--out s.npz]

The case: ``configs/scenes/impact.yaml`` on 8 x 8 yarns, 16 elements (the config's "small
version": span 12.7 mm, projectile radius 4.5 mm), ``geometry.reference: straight`` with
``geometry.crimp_clearance: -0.02 mm`` (the crimp curves start 0.02 mm into each other: the
crossings are loaded at the start), the config's damped relaxation (γ/ρ = 10 /ms, 20 steps
per ms unless ``--steps``), ``relaxation.friction: true`` with ``friction.coefficient`` = mu
(mu = 0: the frictionless relaxation), ``newton.jacobian_reuse: false`` (the ``auto``
decisions weigh measured wall times: two runs would not be bitwise equal). ``--set`` adds
overrides.

``run``: one relaxation in this process; prints the relaxation's figures and, last, a JSON
record: the max centroid drift from the start (at the end and over the run), the max
centroid speed at the end, the stick / slip counts of the last commit, the mechanical
balance and its works, the mean crimp amplitude of the warps and wefts (half their
centroids' z range, the start's and the relaxed), the max in-plane and out-of-plane drift,
CPU time. ``--out``: the start and relaxed states for ``picture``.
``table``: every mu in a fresh process (wall, CPU, peak RSS of that process), one after the
other; the table of the records. ``picture``: tube renders (pyvista, off screen) of the start
and of each saved relaxed state, coloured by the centroid drift, seen obliquely and along -y.
"""
from __future__ import annotations

import os

for _k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "RVE_PARDISO_THREADS"):
    os.environ.setdefault(_k, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import ROOT, run_json, worker_env, write_json  # noqa: E402

CASE = ["geometry.n_warp=8", "geometry.n_weft=8", "geometry.span=12.7 mm", "mesh.elements=16",
        "projectile.radius=4.5 mm", "geometry.reference=straight", "geometry.crimp_clearance=-0.02 mm",
        "newton.jacobian_reuse=false"]


def _overrides(mu: float, t_end: str | None, steps: int | None, extra) -> list:
    ov = CASE + [f"friction.coefficient={mu}", f"relaxation.friction={'true' if mu > 0 else 'false'}"]
    if t_end:
        ov.append(f"relaxation.t_end={t_end}")
    if steps:
        ov.append(f"relaxation.steps={steps}")
    return ov + list(extra or [])


def _crimp(problem, x) -> dict:
    """Mean over the warps and over the wefts of half their centroids' z range (mm)."""
    sysm = problem.system
    r = sysm.fabric.base.nodal(sysm.split(x)[0])[:, 0:3]
    mesh, weave = problem.fabric.mesh, problem.weave
    out = {}
    for fam, fibrils in (("warp", weave.warp), ("weft", weave.weft)):
        amp = [0.5 * np.ptp(r[mesh.fibril_nodes(int(f)), 2]) for f in fibrils]
        out[fam] = float(np.mean(amp))
    return out


def run(args) -> dict:
    from rve.config.loader import load_config
    from rve.scenes import impact

    ov = _overrides(args.mu, args.t_end, args.steps, args.set)
    cfg = load_config(ROOT / "configs/scenes/impact.yaml", ov)
    problem = impact.setup(cfg, "relax")
    c0 = time.process_time()
    x, info = impact.relax(cfg)
    cpu = time.process_time() - c0
    sysm = problem.system
    r0 = sysm.fabric.base.nodal(sysm.split(problem.x0)[0])[:, 0:3]
    r1 = sysm.fabric.base.nodal(sysm.split(x)[0])[:, 0:3]
    d = r1 - r0
    crimp0, crimp1 = _crimp(problem, problem.x0), _crimp(problem, x)
    pts = info.get("friction_points", {"stick": 0, "slip": 0})
    rec = {"mu": args.mu, "t_end_ms": float(cfg.relaxation.t_end), "steps": int(cfg.relaxation.steps),
           "steps_accepted": info["steps"], "steps_rejected": info["rejected"],
           "drift_end_mm": info["max_centroid_drift_mm"], "drift_max_mm": info["max_centroid_drift_over_run_mm"],
           "speed_end_mm_per_ms": info["max_centroid_speed_mm_per_ms"],
           "stick": int(pts["stick"]), "slip": int(pts["slip"]), "active_pairs": info["active_pairs"],
           "drift_in_plane_mm": float(np.linalg.norm(d[:, :2], axis=1).max()),
           "drift_z_mm": float(np.abs(d[:, 2]).max()),
           "crimp_start_mm": crimp0, "crimp_relaxed_mm": crimp1,
           "mechanical_balance": info["mechanical_balance"], "energies_mJ": info["energies_mJ"],
           "relax_cpu_s": cpu, "relax_wall_s": info["wall_time_s"]}
    if args.out:
        np.savez(args.out, x0=problem.x0, x=x, overrides=np.array(json.dumps(ov)), record=np.array(json.dumps(rec)))
    print(json.dumps(rec))
    return rec


def table(args) -> list:
    out_dir = Path(args.out_dir) if args.out_dir else None
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
    recs = []
    for mu in args.mu:
        argv = [sys.executable, __file__, "run", "--mu", str(mu)]
        if args.t_end:
            argv += ["--t-end", args.t_end]
        if args.steps:
            argv += ["--steps", str(args.steps)]
        if out_dir is not None:
            argv += ["--out", str(out_dir / f"mu{mu:g}.npz")]
        for s in args.set or []:
            argv += ["--set", s]
        rec = run_json(argv, env=worker_env(), cwd=ROOT)
        recs.append(rec)
        print(f"  mu = {mu:g}: " + (rec["error"] if "error" in rec else f"{rec['wall_s']:.1f} s wall"),
              file=sys.stderr, flush=True)
    print(f"straight reference, 8 x 8 yarns, 16 elements, damped relaxation; relaxation.friction with mu > 0")
    head = ("mu", "t (ms)", "steps acc/rej", "drift end / max (mm)", "in-plane / z (mm)", "speed end (mm/ms)",
            "stick / slip", "crimp warp, weft (mm)", "mech. balance", "W_d / W_f / D (mJ)", "wall / CPU (s)",
            "peak RSS (MiB)")
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for r in recs:
        if "error" in r:
            print(f"| failed: {r['error']} |")
            continue
        e = r["energies_mJ"]
        print(f"| {r['mu']:g} | {r['t_end_ms']:g} | {r['steps_accepted']} / {r['steps_rejected']} | "
              f"{r['drift_end_mm']:.3f} / {r['drift_max_mm']:.3f} | {r['drift_in_plane_mm']:.3f} / "
              f"{r['drift_z_mm']:.3f} | {r['speed_end_mm_per_ms']:.2e} | {r['stick']} / {r['slip']} | "
              f"{r['crimp_relaxed_mm']['warp']:.3f}, {r['crimp_relaxed_mm']['weft']:.3f} "
              f"(start {r['crimp_start_mm']['warp']:.3f}) | {r['mechanical_balance']:.2g} | "
              f"{e['damping_mJ']:.2f} / {e.get('friction_work_mJ', 0.0):.2f} / "
              f"{e.get('friction_dissipated_mJ', 0.0):.2f} | {r['wall_s']:.1f} / {r['cpu_s']:.1f} | "
              f"{r['process_rss_mib']:.0f} |")
    if args.json:
        write_json(args.json, recs)
    return recs


def picture(args) -> str:
    import pyvista as pv

    from rve.config.loader import load_config
    from rve.io.vtk import tube_surface
    from rve.scenes import impact

    states = []
    for f in args.states:
        with np.load(f) as d:
            ov = json.loads(str(d["overrides"]))
            rec = json.loads(str(d["record"]))
            states.append((ov, rec, d["x0"].copy(), d["x"].copy()))
    ov0, _, x0, _ = states[0]
    cfg = load_config(ROOT / "configs/scenes/impact.yaml", ov0)
    p = impact.setup(cfg, "relax")
    sysm, mesh = p.system, p.fabric.mesh

    def tubes(x):
        xn = sysm.fabric.base.nodal(sysm.split(x)[0])
        drift = np.linalg.norm(xn[:, 0:3] - sysm.fabric.base.nodal(sysm.split(x0)[0])[:, 0:3], axis=1)
        return tube_surface(mesh, xn, 12, point_data={"drift": drift})

    panels = [("straight start (bent into the weave)", tubes(x0))]
    for ov, rec, _, x in states:
        panels.append((f"mu = {rec['mu']:g}, t = {rec['t_end_ms']:g} ms: drift {rec['drift_end_mm']:.2f} mm, "
                       f"speed {rec['speed_end_mm_per_ms']:.1e} mm/ms", tubes(x)))
    clim = [0.0, max(float(s.point_data["drift"].max()) for _, s in panels[1:])]
    views = (((0.55, -0.85, 0.6), (0.0, 0.0, 1.0), 1.5), ((0.0, -1.0, 0.0), (0.0, 0.0, 1.0), 1.45))
    w, h = 560, 380
    pl = pv.Plotter(off_screen=True, shape=(len(views), len(panels)), window_size=[w * len(panels), h * len(views)],
                    border=False)
    pl.set_background("white")
    for i, (view, up, zoom) in enumerate(views):
        for j, (title, surf) in enumerate(panels):
            pl.subplot(i, j)
            pl.add_mesh(surf.copy(), scalars="drift", cmap="viridis", clim=clim, smooth_shading=True,
                        show_scalar_bar=(i == len(views) - 1 and j == len(panels) - 1),
                        scalar_bar_args={"title": "centroid drift (mm)", "color": "black", "n_labels": 3,
                                         "fmt": "%.2f", "position_x": 0.2, "position_y": 0.05, "width": 0.6,
                                         "height": 0.08})
            pl.add_text(title if i == 0 else "seen along -y", font_size=8, color="black")
            pl.view_vector(view, viewup=up)
            pl.reset_camera()
            pl.camera.zoom(zoom)
    Path(args.png).parent.mkdir(parents=True, exist_ok=True)
    pl.screenshot(str(args.png))
    pl.close()
    print(args.png)
    return str(args.png)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("--mu", type=float, required=True)
    t = sub.add_parser("table")
    t.add_argument("--mu", type=float, nargs="+", default=[0.0, 0.2, 0.3])
    t.add_argument("--out-dir")
    t.add_argument("--json")
    for q in (r, t):
        q.add_argument("--t-end", help='relaxation.t_end, e.g. "4 ms" (default: the config\'s 1 ms)')
        q.add_argument("--steps", type=int, help="relaxation.steps (default: the config's 20)")
        q.add_argument("--set", action="append", help="an extra override key=value (repeatable)")
    r.add_argument("--out")
    p = sub.add_parser("picture")
    p.add_argument("states", nargs="+")
    p.add_argument("--png", required=True)
    args = ap.parse_args(argv)
    return {"run": run, "table": table, "picture": picture}[args.cmd](args)


if __name__ == "__main__":
    main()
