"""The friction law's figures on the tests' small cases, printed (docs/contact.md "The law",
"Friction in the RVE pipeline"): the cases are the tests' own (tests/test_rve_friction.py,
tests/test_rve_friction_al_periodic.py), run at more step sizes or angles than the tests do.

    python benchmarks/friction_path_checks.py cycle      # tiny cell, mu = 0.3: work - dPi against D, 4/8/16 steps per leg
    python benchmarks/friction_path_checks.py branch     # tiny cell: the energy test's miss at 3 step sizes, mu = 0.1, 0.3
    python benchmarks/friction_path_checks.py transient  # tiny cell, mu = 0.3: the stick transient at the loading start
    python benchmarks/friction_path_checks.py rotation [--geometry G --order p]   # periodic 2 x 2 stacked cell turned by 0.05 and 0.2 rad, mu = 0.3, both frames
    python benchmarks/friction_path_checks.py weave [--run R] [--mu 0.3] [--steps 3] [--start-up F]   # the frictional one-path test on a run
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))


def cycle():
    import tempfile

    import test_rve_friction as T

    with tempfile.TemporaryDirectory() as tmp:
        for n in (4, 8, 16):
            work, dpi, d = T._loop_balance(T._cycle(0.3, n, Path(tmp) / f"n{n}"))
            print(f"{n:3d} steps per leg: W - dPi = {work - dpi:.4e} N mm, D = {d:.4e} N mm, "
                  f"relative difference {abs(work - dpi - d) / d:.2%}")


def branch():
    from rve.config import validate_config
    from rve.fabrics.setup import fabric_and_mesh
    from rve.homogenisation.strain import (friction_start, mech_system, pinned_energy, relax_fabric, seed_friction,
                                           strain_step)
    from rve.solvers.system import friction_of
    from test_rve_friction import TINY

    for mu in (0.1, 0.3):
        cfg = validate_config({**TINY, "friction": {"coefficient": mu}})
        fab, mesh = fabric_and_mesh(cfg)
        x0, _, _ = relax_fabric(cfg, fab, mesh, fab.initial_state(mesh))
        record = friction_start(cfg, fab, mesh, x0)
        out = []
        for eps in (0.05, 0.025, 0.0125):
            c = validate_config({**TINY, "friction": {"coefficient": mu},
                                 "strain": {**TINY["strain"], "total": 2 * eps, "path": "quasi_static"}})
            xb, sb, _ = strain_step(c, fab, mesh, x0, x0, "shear", 1, friction=record)
            s0 = mech_system(fab, mesh, c, c.strain.relax_damping, x0.reshape(-1))
            seed_friction(s0, record, x0.reshape(-1))
            Pa, ra = pinned_energy(fab, mesh, s0, x0, x0, "shear", 0.0)
            Pb, rb = pinned_energy(fab, mesh, sb, xb, x0, "shear", eps)
            work = 0.5 * (ra + rb) * eps
            out.append(abs(work - (Pb - Pa + friction_of(sb).dissipated)) / abs(work))
        print(f"mu = {mu}: |work - (dPi + D)| / work at strain steps 0.05, 0.025, 0.0125: "
              + ", ".join(f"{v:.3f}" for v in out) + f" (the test's tolerance {cfg.strain.branch_energy_rtol})")


def transient():
    """The stick transient at the loading start of the tiny cell (mu = 0.3, quasi-static
    shear): for start-up strains from 1e-4 to 8e-3, the clamps' work rate, its secant over
    the strain and the stick / slip counts of the return map there."""
    from types import SimpleNamespace

    from rve.config import validate_config
    from rve.fabrics.setup import fabric_and_mesh
    from rve.homogenisation.friction_path import frictional_energy
    from rve.homogenisation.strain import (friction_start, mech_system, pinned_energy, relax_fabric, strain_step)
    from rve.solvers.system import friction_of
    from test_rve_friction import TINY

    cfg = validate_config({**TINY, "friction": {"coefficient": 0.3}, "strain": {**TINY["strain"], "path": "quasi_static"}})
    fab, mesh = fabric_and_mesh(cfg)
    x0, _, _ = relax_fabric(cfg, fab, mesh, fab.initial_state(mesh))
    rec = friction_start(cfg, fab, mesh, x0)
    cell = SimpleNamespace(periodic=False, system=lambda xf: mech_system(fab, mesh, cfg, cfg.strain.relax_damping, xf),
                           energy=lambda system, xf, e: pinned_energy(fab, mesh, system, xf, x0, "shear", e))
    for up in (1e-4, 2e-4, 5e-4, 1e-3, 2e-3, 4e-3, 8e-3):
        xu, su, _ = strain_step(cfg, fab, mesh, x0, x0, "shear", 1, friction=rec, levels=(0.0, up))
        rate = frictional_energy(cfg, cell, su, xu, up, None, None)[1]
        st = friction_of(su).points()
        print(f"strain {up:.0e}: work rate {rate:.4e} N mm, secant {rate / up:.5f} N mm, stick {st['stick']}, "
              f"slip {st['slip']}", flush=True)


def rotation():
    """Both frames of the law (``friction.frame``: chord, the position-based one; section, the
    - cross-section's). ``--geometry G --order p``: the contact geometry and mesh order
    (default the chords at p = 1)."""
    import argparse

    import test_rve_friction_al_periodic as T

    ap = argparse.ArgumentParser(prog="friction_path_checks.py rotation")
    ap.add_argument("--geometry", default="chord", choices=["chord", "curve", "smooth"])
    ap.add_argument("--order", type=int, default=1)
    a = ap.parse_args(sys.argv[2:])
    for frame in ("chord", "section"):
        for theta in (0.05, 0.2):
            P0, R, P_pred, P_solved, t_pred = T._rotation(0.3, theta, frame=frame, geometry=a.geometry, order=a.order)
            sc = np.abs(P0).max()
            print(f"{a.geometry}, p = {a.order}, frame {frame}, theta = {theta} rad: |P - R P0| / |P0| = {np.abs(P_pred - R @ P0).max() / sc:.2e} "
                  f"at the turned state, {np.abs(P_solved - R @ P0).max() / sc:.2e} after the static solve; largest "
                  f"friction force at the turned state {t_pred:.3e} N")


def weave():
    """The one-path test of the frictional steps on a pipeline run (default
    ``plain_weave_friction``, its quasi-static shear path): each step with the test and
    without it, from the same state; per step the checks' mismatches against their
    tolerances, detections, solves, which state is kept (and how far the followed state is
    from the one-step one) and the CPU seconds of both. ``--start-up F``: the start-up's
    share of step 1 (0: none)."""
    import argparse
    import tempfile
    import time

    from _harness import pipeline_spec, relaxed_state
    from rve.fabrics.setup import fabric_and_mesh
    from rve.homogenisation.checkpoint import load_state
    from rve.homogenisation.strain import friction_record, friction_start, strain_step
    from rve.homogenisation.multipliers import multiplier_record
    from rve.homogenisation.sweeps import load_run_config

    ap = argparse.ArgumentParser(prog="friction_path_checks.py weave")
    ap.add_argument("--run", default="plain_weave_friction")
    ap.add_argument("--mu", type=float, default=0.3)
    ap.add_argument("--steps", type=int, default=3)
    ap.add_argument("--mode", default="shear")
    ap.add_argument("--work", default=None)
    ap.add_argument("--start-up", type=float, default=None,
                    help="the start-up's share of a loading start's step (0: none; default friction_path.START_UP)")
    a = ap.parse_args(sys.argv[2:])
    import rve.homogenisation.friction_path as fpath

    if a.start_up is not None:
        fpath.START_UP = a.start_up
    spec = pipeline_spec(a.run, [f"friction.coefficient={a.mu}"])
    work = Path(a.work or tempfile.mkdtemp(prefix="fpath-"))
    st = load_state(relaxed_state(spec, "base", work / "relaxed"))
    cfg = load_run_config(spec)
    off = load_run_config({**spec, "overrides": spec["overrides"] + ["strain.follow_branch=false"]})
    fab, mesh = fabric_and_mesh(cfg)
    x, rec, lam = st.x, friction_start(cfg, fab, mesh, st.x), st.multipliers
    print(f"{a.run}, mu = {a.mu}, {a.mode}, {cfg.strain.steps} steps of {cfg.strain.total / cfg.strain.steps:g}, "
          f"path {cfg.strain.path}, energy_rtol {cfg.strain.branch_energy_rtol}")
    for k in range(1, a.steps + 1):
        c0 = time.process_time()
        _, _, plain = strain_step(off, fab, mesh, x, st.x, a.mode, k, multipliers=lam, friction=rec)
        c1 = time.process_time()
        x2, s2, info = strain_step(cfg, fab, mesh, x, st.x, a.mode, k, multipliers=lam, friction=rec,
                                   loading_start=k == 1 and fpath.START_UP > 0)
        c2 = time.process_time()
        b = info["branch"]
        if b.get("untested"):
            print(f"step {k}: untested ({b['untested']}: off the quasi-static path); CPU {c2 - c1:.1f} s, "
                  f"{c1 - c0:.1f} s with the test off", flush=True)
            x, rec, lam = x2, friction_record(s2), multiplier_record(s2)
            continue
        checks = "; ".join(f"[{c['eps'][0]:.4g}, {c['eps'][1]:.4g}] {abs(c['mismatch']) / c['tolerance']:.2f}"
                           for c in b["checks"])
        up = b.get("start_up")
        gap = b.get("naive_to_followed_distance")
        kept = b["kept"] + (f" ({gap:.3g} mm from the one-step state)" if gap is not None else "")
        print(f"step {k}: start-up {'to ' + format(up['strain'], '.4g') if up else 'none'}; |mismatch| / "
              f"tolerance {checks}; detections {b['detections']}, solves {b['solves']}, kept {kept}; "
              f"CPU {c2 - c1:.1f} s tested, {c1 - c0:.1f} s untested (ratio {(c2 - c1) / (c1 - c0):.2f}); "
              f"converged {info['converged']}", flush=True)
        x, rec, lam = x2, friction_record(s2), multiplier_record(s2)


if __name__ == "__main__":
    {"cycle": cycle, "branch": branch, "rotation": rotation, "weave": weave, "transient": transient}[sys.argv[1]]()
