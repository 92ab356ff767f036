"""Benchmark of the impact scene (issue 12; docs/impact.md).

Prints, for the reduced run (8 x 8 yarns, 20 elements, the CI case) and optionally the full
thesis size (32 x 32, 80 elements) over ``--full-steps`` of its 1000 steps: dofs, contact
pairs (fabric and sphere, max active), steps accepted/rejected, Newton iterations and
factorisations per stage, wall time per phase (contact search/rebuild, fabric assembly,
fabric contact forms, sphere contact, matrix composition, linear solve + Newton, T
post-solve, balances), the relaxation separately, peak memory (ru_maxrss of the process;
the process's peak RSS) and the extrapolation of the per-step cost to the 0.5 ms impact.

    python benchmarks/impact.py [--reduced-steps 100] [--full] [--full-steps 20]
"""
import argparse
import json
import resource
import time

from rve.config.loader import load_config
from rve.scenes import impact

REDUCED = ["geometry.n_warp=8", "geometry.n_weft=8", "geometry.span=12.7 mm", "mesh.elements=20",
           "projectile.radius=4.5 mm"]


def report(tag, cfg, t_end, steps, nominal):
    t0 = time.perf_counter()
    x, rinfo = impact.relax(cfg)
    t_relax = time.perf_counter() - t0
    s = impact.solve(cfg, x_start=x, relax_info=rinfo, record=False, t_end=t_end, steps=steps).summary
    w = s["wall_time_s"]
    per_step = w["total"] / max(1, s["steps_accepted"])
    print(f"[{tag}] dofs {s['dofs']}")
    print(f"[{tag}] contact pairs: fabric active max {s['contact_pairs_max']}, sphere active max "
          f"{s['sphere_pairs_active_max']}")
    print(f"[{tag}] steps {s['steps_accepted']} accepted / {s['steps_rejected']} rejected over {t_end} ms; Newton "
          f"its/stage {s['newton_iterations_per_stage']:.2f}; factorisations/stage {s['factorizations_per_stage']:.2f}; "
          f"contact rebuilds {s['contact_rebuilds']} (+{s['extra_rebuilds']} early)")
    keys = ("contact_search", "assembly_fabric", "contact_fabric", "contact_sphere", "compose",
            "linear_solve_and_newton", "temperature", "balances", "checkpoint", "total")
    print(f"[{tag}] wall (s): " + ", ".join(f"{k} {w[k]:.2f}" for k in keys))
    print(f"[{tag}] relaxation {t_relax:.1f} s ({rinfo['steps']} steps); per impact step {per_step * 1e3:.0f} ms; "
          f"extrapolated to {nominal} steps: {per_step * nominal / 60:.1f} min")
    print(f"[{tag}] peak memory: ru_maxrss {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB "
          f"(the process so far)")
    print(f"[{tag}] balance errors {json.dumps({k: float(f'{v:.3g}') for k, v in s['balance_errors'].items()})}")
    print(f"[{tag}] v_com {s['projectile_velocity_mm_per_ms']}, omega_x {s['projectile_angular_velocity_x_rad_per_ms']:.4g}, "
          f"currents {s['yarn_current_A']}, max T {s['max_temperature_K']:.4g} K")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--config", default="configs/scenes/impact.yaml")
    ap.add_argument("--reduced-steps", type=int, default=100, help="steps of the reduced run (h = 0.5 us)")
    ap.add_argument("--full", action="store_true", help="also the full size (do not run it on a loaded machine)")
    ap.add_argument("--full-steps", type=int, default=20, help="steps of the full-size sample (h = 0.5 us)")
    a = ap.parse_args()
    ov = ["output.vtk=false", "output.png=false"]
    cfg = load_config(a.config, ov + REDUCED)
    report("reduced 8x8x20", cfg, 5e-4 * a.reduced_steps, a.reduced_steps, 1000)
    if a.full:
        cfg = load_config(a.config, ov)
        report("full 32x32x80", cfg, 5e-4 * a.full_steps, a.full_steps, 1000)


if __name__ == "__main__":
    main()
