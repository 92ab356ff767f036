"""One relaxation-free strain step of the periodic cell between two strains, from a stored
state or from the result of an earlier call (docs/snap_through.md), with optional config
overrides, and the figures that tell the branches apart.

    python benchmarks/snap_step.py RUN FROM EPS_FROM EPS_TO OUT.npz [--set KEY=VALUE ...] [--reset] [--follow]

RUN: a run of configs/pipeline.yaml; FROM: a stored state (.nc) or an OUT.npz of an earlier
call (its x and multipliers); ``--reset`` drops the stored multipliers (a changed n_gp
cannot reuse them: the Uzawa loop rebuilds them from the penalty overlap). Prints CPU s,
|F|, the potential (true overlaps; ``periodic_energy``), the face forces and the stack
shapes of the end state; OUT.npz keeps x and the multipliers. ``--follow``: the step as the
pipeline takes it, through the one-path test (``strain_step``: the jump test and, on a
detection, ``strain.branch_method``'s following); it prints the test's record (the kept
state, and the continuation's folds, inertia and energy along its path).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from snap_through import setup as config, stack_shape  # noqa: E402


def start(path):
    from rve.homogenisation.checkpoint import load_state

    if str(path).endswith(".npz"):
        d = np.load(path)
        return d["x"], ((d["keys"], d["values"]) if "keys" in d else None)
    st = load_state(path)
    return st.x, st.multipliers


def figures(cfg, fab, mesh, x, mult, mode, eps):
    """(energy N mm, x+ x N, y+ y N, stack shapes) of an equilibrium of the cell: the
    potential with the true overlaps (``periodic_energy``), the face forces with the state's
    multipliers seeded, the yarns' section heights and widths."""
    from rve.homogenisation.checkpoint import State
    from rve.homogenisation.multipliers import seed_multipliers
    from rve.homogenisation.periodic import cell_gradient, cell_reactions, periodic_energy, periodic_system

    x = np.asarray(x, float).reshape(-1)
    e = float(periodic_energy(cfg, fab, mesh, x, mode, eps, mult)[0])
    psys = periodic_system(cfg, fab, mesh, x, cell_gradient(fab, mesh, x))
    seed_multipliers(psys, mult)
    rf = cell_reactions(fab, psys, psys.restrict(x))
    st = State(x=x.reshape(mesh.n_nodes, -1), w=None, origin=None, kind="strained", mode=mode, step=0, strain=eps)
    return e, float(rf["x+"][0]), float(rf["y+"][1]), stack_shape(fab, mesh, st)


def report(cfg, fab, mesh, x, mult, eps, label=""):
    e, fx, fy, sh = figures(cfg, fab, mesh, x, mult, "uniaxial", eps)
    print(f"{label:40s} strain {eps:.5f}: energy {e:.6e} N mm, x+ x {fx:.5f} N, y+ y {fy:.5f} N, "
          f"weft h/w {sh['weft'][0]:.3f}/{sh['weft'][1]:.3f}, warp h/w {sh['warp'][0]:.3f}/{sh['warp'][1]:.3f} mm")
    return e


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("run")
    ap.add_argument("start")
    ap.add_argument("eps_from", type=float)
    ap.add_argument("eps_to", type=float)
    ap.add_argument("out")
    ap.add_argument("--set", action="append", default=[])
    ap.add_argument("--reset", action="store_true")
    ap.add_argument("--follow", action="store_true")
    a = ap.parse_args()
    from rve.homogenisation.multipliers import multiplier_record
    from rve.homogenisation.periodic import periodic_strain_step

    cfg, fab, mesh = config(a.run, a.set)
    x0, m0 = start(a.start)
    if a.reset:
        m0 = None
    c0, t0 = time.process_time(), time.perf_counter()
    if a.follow:
        from rve.homogenisation.strain import strain_step

        x, system, info = strain_step(cfg, fab, mesh, x0, None, "uniaxial", 1, multipliers=m0,
                                      levels=(a.eps_from, a.eps_to))
    else:
        x, system, info = periodic_strain_step(cfg, fab, mesh, x0, None, "uniaxial", 1,
                                               eps_range=(a.eps_from, a.eps_to), multipliers=m0)
    cpu, wall = time.process_time() - c0, time.perf_counter() - t0
    rec = multiplier_record(system)   # None with the penalty
    np.savez(a.out, x=x, cpu=cpu, wall=wall, residual=info["residual_N"],
             **({} if rec is None else {"keys": rec[0], "values": rec[1]}))
    print(f"step {a.eps_from} -> {a.eps_to} from {a.start} ({' '.join(a.set) or 'run config'}"
          f"{', multipliers reset' if a.reset else ''}): converged {info['converged']}, |F| {info['residual_N']:.2e} N, "
          f"{cpu:.1f} CPU s, {wall:.1f} s wall")
    x0r = np.asarray(x0).reshape(mesh.n_nodes, -1)
    d = np.linalg.norm(np.asarray(x).reshape(mesh.n_nodes, -1)[:, :3] - x0r[:, :3], axis=1)
    print(f"  largest node move from the start state {d.max():.4f} mm (the affine part {abs(a.eps_to - a.eps_from) * 4.2:.4f} mm at most)")
    report(cfg, fab, mesh, x0, m0 if m0 is not None else start(a.start)[1], a.eps_from, "start")
    report(cfg, fab, mesh, x, rec, a.eps_to, "end")
    if a.follow:
        branch_record(info.get("branch") or {})


def branch_record(b):
    """The one-path test's record of a step, one line a check and one an arc point."""
    keys = ("detections", "branch_jumps", "limit_points", "limit_points_passed", "false_alarms", "kept")
    print("  branch: " + ", ".join(f"{k} {b.get(k)}" for k in keys))
    for c in b.get("checks", []):
        print(f"    check {c['eps']}: energy change {c['energy_change']:+.4e}, work {c['work']:.4e} N mm, "
              f"inertia {c['inertia']}, jump {c['jump']} {c.get('why', '')}")
    arc = b.get("arc") or {}
    if arc:
        print(f"    arc: converged {arc.get('converged')}, steps {arc.get('arc_steps')}, folds {arc.get('folds')}, "
              f"kinks {arc.get('kinks')}, rejected {arc.get('rejected')}, factorizations {arc.get('factorizations')}, "
              f"end inertia {arc.get('end_inertia')}, energy mismatch {arc.get('energy_mismatch')}")
        for p in arc.get("path") or []:
            print(f"      eps {p['eps']:.6f}  inertia {p['inertia']}  energy {p['energy']:.7e}  rate {p['energy_rate']:.5e}")


if __name__ == "__main__":
    main()


def per_crossing(run, npz):
    """Weft stack height / width at each of the four weft crossings of a snap_step result."""
    from rve.homogenisation.checkpoint import State
    from snap_through import sections

    cfg, fab, mesh = config(run, [])
    x = np.load(npz)["x"]
    st = State(x=x.reshape(mesh.n_nodes, -1), w=None, origin=None, kind="strained", mode="uniaxial", step=0,
               strain=0.0)
    secs = sections(fab, mesh, st)
    return {(y.name, i): (float(np.ptp(S[:, 1])), float(np.ptp(S[:, 0]))) for y in fab.yarns
            if y.direction == "weft" for i, S in enumerate(secs[y.name])}
