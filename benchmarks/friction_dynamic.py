"""Friction in the dynamic scenes (docs/impact.md "Friction", docs/induced_deformation.md
"Friction"): run a scene on a small or a full case with a friction coefficient, save its
final state and balance series, and compare two saved runs bit for bit.

    python benchmarks/friction_dynamic.py run impact --mu 0.2 --case tiny --out a.npz
    python benchmarks/friction_dynamic.py run induced --mu 0 --case small --out b.npz
    python benchmarks/friction_dynamic.py same a.npz b.npz
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
    out = {"scene": args.scene, "case": args.case, "mu": args.mu, "wall_s": wall,
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
    args = p.parse_args(argv)
    if args.cmd == "run":
        run(args)
        return 0
    return same(args)


if __name__ == "__main__":
    sys.exit(main())
