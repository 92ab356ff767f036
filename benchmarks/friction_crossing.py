"""One crossing, stick then slip, at full size (configs/scenes/crossing.yaml): prints the
stick slope against the regularisation stiffness w eps_T P*, the slip plateau against mu N,
the dissipation of the closed cycle U -> -U -> U against mu N times the loop's slip and
against the supports' work, and Newton's residuals in a stick and a slip step.

    nice -n 10 python benchmarks/friction_crossing.py [overrides ...]
"""
import sys
from pathlib import Path

import numpy as np

from rve.config.loader import load_config
from rve.scenes import friction_crossing


def main(argv):
    cfg = load_config(Path(__file__).resolve().parents[1] / "configs/scenes/crossing.yaml", argv)
    s = friction_crossing.solve(cfg).summary
    path = s["path"]
    n = cfg.load.steps_per_leg
    u, F, slip, N, D, stick, slipping = (np.array([p[k] for p in path]) for k in
                                         ("u", "force", "slip", "normal", "dissipated", "stick", "slip_points"))
    kT, mu = s["stiffness"], s["mu"]
    first = int(np.flatnonzero(slipping[:n])[0])
    slope = np.polyfit(slip[:first], F[:first], 1)[0]
    on = slipping == 1
    print(f"crossing: mu = {mu}, eps_T/P* = {cfg.friction.stiffness}, P* = {cfg.contact.penalty} N/mm^2, "
          f"U = {cfg.load.amplitude} mm, {n} steps per leg, {len(path)} steps, wall {s['wall_time_s']:.1f} s")
    print(f"stick slope dF/dslip = {slope:.10g} N/mm; w eps_T P* = {kT:.10g} N/mm; ratio {slope / kT:.12f}")
    print(f"slip plateau: |F|/(mu N) over {on.sum()} slip steps in [{(np.abs(F[on]) / (mu * N[on])).min():.12f}, "
          f"{(np.abs(F[on]) / (mu * N[on])).max():.12f}], N = {N.mean():.6g} N (spread {np.ptp(N) / N.mean():.1e})")
    cyc = slice(n - 1, None)
    D_cycle = D[n:].sum()
    Nbar = N[cyc].mean()
    S = 0.5 * (slip[cyc].max() - slip[cyc].min())
    plastic = 4.0 * (S - mu * Nbar / kT)
    W = np.sum(0.5 * (F[cyc][1:] + F[cyc][:-1]) * np.diff(u[cyc]))
    print(f"closed cycle: dissipated (return map) = {D_cycle:.8e} N mm; mu N slip = {mu * Nbar * plastic:.8e} N mm "
          f"(slip {plastic:.6e} mm; ratio {D_cycle / (mu * Nbar * plastic):.6f}); supports' work (trapezoid) = "
          f"{W:.8e} N mm (ratio {W / D_cycle:.6f})")
    print("hysteresis loop (u mm, F N):", " ".join(f"({a:+.3f},{b:+.3e})" for a, b in zip(u[cyc][::n // 4],
                                                                                         F[cyc][::n // 4])))
    for label, k in (("stick", 0), ("slip", first + 1)):
        print(f"Newton residuals, {label} step {k + 1}:", " ".join(f"{r:.2e}" for r in path[k]["newton"]))


if __name__ == "__main__":
    main(sys.argv[1:])
