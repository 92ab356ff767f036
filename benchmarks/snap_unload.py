"""Is the flattened branch there in the 12-element model at 7.5 %? One relaxation-free strain
step *down* from the stored 12-element state at 10 % (past the snap) to 7.5 %, and its
energy, face forces and weft-stack shape against the stored 12-element state at 7.5 % (before
the snap) and the 18-element state at 7.5 % (after it); docs/snap_through.md.

    python benchmarks/snap_unload.py [OUT.npz]          # runs the step (~1-4 CPU min), then prints
    python benchmarks/snap_unload.py OUT.npz --print    # prints from a stored result
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from snap_through import JUMP, RUN12, RUN18, setup, stack_shape, state  # noqa: E402


def main():
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("/tmp/snap_unload_12.npz")
    from rve.homogenisation.checkpoint import State
    from rve.homogenisation.periodic import periodic_energy, periodic_strain_step

    cfg, fab, mesh = setup(JUMP["12"][0])
    st10 = state(RUN12, 4)
    if "--print" not in sys.argv:
        t0, c0 = time.perf_counter(), time.process_time()
        x, _, info = periodic_strain_step(cfg, fab, mesh, st10.x, st10.origin, "uniaxial", 4, eps_range=(0.1, 0.075),
                                          multipliers=st10.multipliers)
        from rve.homogenisation.multipliers import multiplier_record
        rec = multiplier_record(_)
        np.savez(out, x=x, keys=rec[0], values=rec[1], fx=info["reaction_force"]["x+"][0],
                 fy=info["reaction_force"]["y+"][1], residual=info["residual_N"], converged=info["converged"],
                 cpu=time.process_time() - c0, wall=time.perf_counter() - t0)
        print(f"unloading step 10 % -> 7.5 %: converged {info['converged']}, |F| {info['residual_N']:.2e} N, "
              f"{time.process_time() - c0:.1f} CPU s, {time.perf_counter() - t0:.1f} s wall")
    d = np.load(out)
    x = d["x"]
    un = State(x=x, w=np.zeros_like(x), origin=st10.origin, kind="strained", mode="uniaxial", step=3, strain=0.075)
    st75 = state(RUN12, 3)
    print(f"the step: converged {bool(d['converged'])}, |F| {float(d['residual']):.2e} N, {float(d['cpu']):.1f} CPU s "
          f"({float(d['wall']):.1f} s wall)")
    e_un = periodic_energy(cfg, fab, mesh, x, "uniaxial", 0.075, (d["keys"], d["values"]))[0]
    e_75 = periodic_energy(cfg, fab, mesh, st75.x, "uniaxial", 0.075, st75.multipliers)[0]
    sh_un, sh_75 = stack_shape(fab, mesh, un), stack_shape(fab, mesh, st75)
    cfg18, fab18, mesh18 = setup(JUMP["18"][0])
    s18 = state(RUN18, 3)
    sh18 = stack_shape(fab18, mesh18, s18)
    rows = [("12 el, stored (loaded from 5 %: before the snap)", e_75, st75.reaction_force["x+"][0],
             st75.reaction_force["y+"][1], sh_75),
            ("12 el, unloaded from 10 % (after the snap)", e_un, float(d["fx"]), float(d["fy"]), sh_un),
            ("18 el, stored (after the snap)", periodic_energy(cfg18, fab18, mesh18, s18.x, "uniaxial", 0.075,
                                                               s18.multipliers)[0],
             s18.reaction_force["x+"][0], s18.reaction_force["y+"][1], sh18)]
    print(f"{'state at 7.5 %':50s} {'energy N mm':>12s} {'x+ x N':>9s} {'y+ y N':>9s} {'weft h/w mm':>12s}")
    for lab, e, fx, fy, sh in rows:
        print(f"{lab:50s} {e:12.6e} {fx:9.5f} {fy:9.5f} {sh['weft'][0]:6.3f}/{sh['weft'][1]:5.3f}")
    print(f"energy, unloaded minus stored (12 el): {e_un - e_75:+.3e} N mm")
    for j, lab in ((2, "x+ x"), (3, "y+ y")):
        print(f"{lab}: 12 el unloaded against 18 el: {abs(rows[1][j] - rows[2][j]) / abs(rows[2][j]):.2%}; "
              f"12 el stored against 18 el: {abs(rows[0][j] - rows[2][j]) / abs(rows[2][j]):.2%}")


if __name__ == "__main__":
    main()
