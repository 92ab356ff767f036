"""Friction in the dynamic scenes (docs/impact.md "Friction", docs/induced_deformation.md
"Friction"): run a scene on a small or a full case with a friction coefficient, save its
final state and balance series, compare two saved runs bit for bit, and set saved impact runs
side by side (a table and a figure).

    python benchmarks/friction_dynamic.py run impact --mu 0.2 --case tiny --out a.npz
    python benchmarks/friction_dynamic.py run induced --mu 0 --case small --out b.npz
    python benchmarks/friction_dynamic.py same a.npz b.npz
    python benchmarks/friction_dynamic.py side mu0.npz mu0.2.npz [--png docs/img/impact_friction.png]
    python benchmarks/friction_dynamic.py run impact --mu 0.2 --case small --set friction.projectile=0.2
      (friction at the projectile's sphere contact as well: docs/impact.md "Friction at the projectile")

``run`` loads the scene config of the ``rve`` it imports (so it runs unchanged against a
tree without the ``friction`` section when ``--mu 0``: no friction key is set then), on the
small cases with ``newton.jacobian_reuse=false`` (the ``auto`` reuse decisions weigh
measured wall times, so two runs of it are not bitwise equal; the full case keeps the
config's options), and prints the summary's balance errors and
energies. Cases: ``tiny`` (the checkpoint test's 4 x 4 weave, 40 steps of 0.5 µs for the
impact; the induced weave at 12 elements per fibril, B3, 100 steps of 5 µs into contact), ``small`` (the impact's
reduced 8 x 8 case, 100 steps; the induced scene's full weave, B3, 100 steps), ``full`` (the
configs, ``--t-end``/``--steps`` to truncate). ``same`` exits 1 unless every array of the
two files is bitwise equal.
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

import rve  # noqa: E402
from rve.config.loader import load_config  # noqa: E402

ROOT = Path(rve.__file__).resolve().parents[1]
CASES = {
    "impact": {
        "tiny": ["geometry.n_warp=4", "geometry.n_weft=4", "geometry.span=6.35 mm", "mesh.elements=8",
                 "projectile.radius=2 mm", "time.t_end=0.02 ms", "time.steps=40", "relaxation.steps=5",
                 "relaxation.t_end=0.2 ms"],
        "small": ["geometry.n_warp=8", "geometry.n_weft=8", "geometry.span=12.7 mm", "mesh.elements=16",
                  "projectile.radius=4.5 mm", "time.t_end=0.05 ms", "time.steps=100"],
        "full": [],
    },
    "induced": {
        "tiny": ["mesh.elements=12", "field.orientation=B3", "time.t_end=0.5 ms", "time.steps=100"],
        "small": ["field.orientation=B3", "time.t_end=0.5 ms", "time.steps=100"],
        "full": [],
    },
}


def run(args) -> dict:
    sets = list(CASES[args.scene][args.case]) + (["newton.jacobian_reuse=false"] if args.case != "full" else []) \
        + list(args.set)
    if args.t_end:
        sets.append(f"time.t_end={args.t_end}")
    if args.steps:
        sets.append(f"time.steps={args.steps}")
    if args.mu > 0:
        sets.append(f"friction.coefficient={args.mu}")
    t0 = time.perf_counter()
    if args.scene == "impact":
        from rve.scenes import impact

        cfg = load_config(str(ROOT / "configs/scenes/impact.yaml"), sets)
        x0, info = impact.relax(cfg)
        res = impact.solve(cfg, x_start=x0, relax_info=info, record=True)
    else:
        from rve.scenes.induced import scene as induced

        cfg = load_config(str(ROOT / "configs/scenes/induced_deformation.yaml"), sets)
        res = induced.solve(cfg, record=True)
    wall = time.perf_counter() - t0
    s = res.summary
    hist = s["history"]
    arrays = {f"state/{k}": np.asarray(v) for k, v in res.state.items() if v is not None}
    bal = hist["balances"]
    arrays.update({f"bal/{k}": np.asarray(v) for k, v in bal.items()})
    if "series" in hist:
        arrays.update({f"series/{k}": np.asarray(v) for k, v in hist["series"].items()})
    fr = getattr(cfg, "friction", None)
    out = {"scene": args.scene, "case": args.case, "mu": args.mu, "wall_s": wall,
           "mu_projectile": float(getattr(fr, "projectile", 0.0) or 0.0) if fr is not None else 0.0,
           "steps_accepted": s["steps_accepted"], "balance_errors": s["balance_errors"],
           "energies_mJ": s["energies_mJ"]}
    if args.scene == "impact":
        out["projectile_velocity_mm_per_ms"] = s["projectile_velocity_mm_per_ms"]
        out["momentum_balance_error"] = s["momentum_balance_error"]
    else:
        out["mean_displacement_mm"] = s["mean_displacement_mm"]
    if args.out:
        np.savez(args.out, summary=np.array(json.dumps(out)), **arrays)
    print(json.dumps(out, indent=1))
    return out


def same(args) -> int:
    a, b = np.load(args.a), np.load(args.b)
    names = sorted(set(a.files) | set(b.files) - {"summary"})
    bad = []
    for k in names:
        if k == "summary":
            continue
        if k not in a.files or k not in b.files:
            bad.append(f"{k}: only in {'first' if k in a.files else 'second'}")
        elif a[k].shape != b[k].shape or not np.array_equal(a[k], b[k]):
            d = np.max(np.abs(a[k].astype(float) - b[k].astype(float))) if a[k].shape == b[k].shape else "shape"
            bad.append(f"{k}: differs ({d})")
    print(f"{len(names) - 1} arrays compared; {'IDENTICAL' if not bad else 'DIFFERENT'}")
    for line in bad:
        print("  " + line)
    return 1 if bad else 0


def _impact_figures(path) -> dict:
    """The outcome of a saved impact run: projectile speed, the energies it gave up and where
    they went (mJ), the balance errors."""
    d = np.load(path)
    s = json.loads(str(d["summary"]))
    b = {k[4:]: d[k] for k in d.files if k.startswith("bal/")}
    kp = b["energy_kinetic_projectile"] + b.get("energy_strain_projectile", 0.0)
    fabric = b["energy_kinetic_fabric"] + b["energy_strain"] + b["energy_contact"] + b["energy_sphere_contact"] \
        - (b["energy_strain_projectile"] if "energy_strain_projectile" in b else 0.0)
    t = d["series/t"]
    dt = np.diff(t)

    def work(power):
        return float(np.sum(0.5 * (power[1:] + power[:-1]) * dt)) if power is not None else 0.0
    sphere = "power_friction_sphere" in b and bool(np.any(b["power_friction_sphere"]))
    mu_p = s.get("mu_projectile")
    label = f"mu = {s['mu']:g}" + (f", mu_p = {mu_p:g}" if mu_p is not None else (", mu_p > 0" if sphere else ""))
    return {"label": label,
            "t": t, "vz": d["series/v_com"][:, 2], "kinetic_lost": kp[0] - kp, "fabric": fabric - fabric[0],
            "friction": _cumulative(b.get("power_friction", 0.0 * t) + b.get("power_friction_sphere", 0.0 * t), dt),
            "v_end": float(d["series/v_com"][-1, 2]), "v_start": float(d["series/v_com"][0, 2]),
            "summary": s, "work_friction_sphere": work(b.get("power_friction_sphere"))}


def _cumulative(power, dt):
    """The trapezoid integral of a power series from its first sample."""
    return np.concatenate([[0.0], np.cumsum(0.5 * (power[1:] + power[:-1]) * dt)])


def side(args) -> int:
    runs = [_impact_figures(p) for p in args.runs]
    rows = [("projectile v_z at the start / end (mm/ms)", lambda r: f"{r['v_start']:.5f} / {r['v_end']:.5f}"),
            ("projectile energy given up (mJ)", lambda r: f"{r['kinetic_lost'][-1]:.2f}"),
            ("fabric mechanical energy gained (mJ)", lambda r: f"{r['fabric'][-1]:.2f}"),
            ("friction work, all / at the projectile (mJ)",
             lambda r: f"{r['summary']['energies_mJ'].get('friction_work_mJ', 0.0):.2f} / "
                       f"{r['summary']['energies_mJ'].get('friction_work_sphere_mJ', 0.0):.2f}"),
            ("Lorentz work / Joule heat (mJ)", lambda r: f"{r['summary']['energies_mJ']['work_lorentz_mJ']:.2f} / "
                                                      f"{r['summary']['energies_mJ']['joule_heat_mJ']:.2f}"),
            ("momentum balance: projectile / system", lambda r: f"{r['summary']['balance_errors']['momentum_projectile']:.2g}"
                                                              f" / {r['summary']['balance_errors']['momentum_total']:.2g}"),
            ("charge / thermal", lambda r: f"{r['summary']['balance_errors']['charge']:.2g} / "
                                           f"{r['summary']['balance_errors']['thermal']:.2g}"),
            ("mechanical / total energy balance", lambda r: f"{r['summary']['balance_errors']['mechanical']:.2g} / "
                                                            f"{r['summary']['balance_errors']['total']:.2g}"),
            ("accepted steps, wall (s)", lambda r: f"{r['summary']['steps_accepted']}, {r['summary']['wall_s']:.0f}")]
    print("| t = %.3g ms | " % runs[0]["t"][-1] + " | ".join(r["label"] for r in runs) + " |")
    print("|---|" + "---|" * len(runs))
    for name, fn in rows:
        print(f"| {name} | " + " | ".join(fn(r) for r in runs) + " |")
    if args.png:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        fig = Figure(figsize=(12, 3.4))
        FigureCanvasAgg(fig)
        axes = fig.subplots(1, 3)
        for k, r in enumerate(runs):
            axes[0].plot(r["t"], r["vz"], color=f"C{k}", label=r["label"])
            axes[1].plot(r["t"], r["kinetic_lost"], color=f"C{k}", label=f"projectile gave up, {r['label']}")
            axes[1].plot(r["t"], r["fabric"], "--", color=f"C{k}", label=f"fabric gained, {r['label']}")
            axes[2].plot(r["t"], r["friction"], color=f"C{k}", label=r["label"] + " (fibrils + projectile)")
        for ax, title, ylabel in zip(axes, ("projectile velocity", "mechanical energy", "work of friction"),
                                     ("v_z [mm/ms]", "energy [mJ]", "energy [mJ]")):
            ax.set_title(title, fontsize=10)
            ax.set_xlabel("t [ms]")
            ax.set_ylabel(ylabel)
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7)
        fig.subplots_adjust(left=0.075, right=0.98, bottom=0.15, top=0.82, wspace=0.42)
        fig.suptitle("Impact with and without friction")
        fig.savefig(args.png, dpi=110)
        print(f"figure: {args.png}")
    return 0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("scene", choices=sorted(CASES))
    r.add_argument("--mu", type=float, default=0.0)
    r.add_argument("--case", choices=("tiny", "small", "full"), default="tiny")
    r.add_argument("--t-end", default=None)
    r.add_argument("--steps", type=int, default=None)
    r.add_argument("--set", nargs="*", default=[])
    r.add_argument("--out", default=None)
    c = sub.add_parser("same")
    c.add_argument("a")
    c.add_argument("b")
    sd = sub.add_parser("side")
    sd.add_argument("runs", nargs="+")
    sd.add_argument("--png", default=None)
    args = p.parse_args(argv)
    if args.cmd == "run":
        run(args)
        return 0
    return side(args) if args.cmd == "side" else same(args)


if __name__ == "__main__":
    sys.exit(main())
