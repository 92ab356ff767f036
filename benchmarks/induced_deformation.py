"""Benchmark of the induced-deformation scene (issue 11; docs/induced_deformation.md).

Per orientation: dofs, steps accepted/rejected, Newton iterations per stage, linear solves,
factorisations and Jacobian evaluations (modified Newton: newton.jacobian_reuse), wall time
split (assembly, contact, linear solves + other, T post-solve, balances), CPU time, peak
memory (ru_maxrss of the process); the post vs monolithic temperature path (``--repeat``
interleaved pairs: CPU and wall medians, their ratio, and max |T_post - T_mono| / max T);
and the balance-error convergence with the step size on a short horizon (orders).

    python benchmarks/induced_deformation.py [--steps 40] [--t-end 0.2] [--orientations B1,B2,B3]
        [--reduced] [--study-t 0.05] [--study-steps 10,20,40]
"""
import argparse
import json
import resource
import time

import numpy as np

from rve.config.loader import load_config
from rve.scenes.induced_deformation import solve


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--config", default="configs/scenes/induced_deformation.yaml")
    ap.add_argument("--t-end", type=float, default=0.1, help="horizon of the cost runs (ms)")
    ap.add_argument("--steps", type=int, default=20, help="steps of the cost runs (thesis h = 5 us: t/0.005)")
    ap.add_argument("--orientations", default="B1,B2,B3")
    ap.add_argument("--reduced", action="store_true", help="2 x 2 yarns, 10 elements (the test case)")
    ap.add_argument("--study-t", type=float, default=0.05)
    ap.add_argument("--study-steps", default="10,20,40")
    ap.add_argument("--skip-monolithic", action="store_true")
    ap.add_argument("--repeat", type=int, default=1, help="interleaved post/monolithic pairs (medians)")
    ap.add_argument("--set", action="append", default=[], help="config override KEY=VALUE (repeatable)")
    a = ap.parse_args()
    ov = ["output.vtk=false", "output.png=false"] + list(a.set)
    if a.reduced:
        ov += ["geometry.n_warp=2", "geometry.n_weft=2", "geometry.span=5 mm", "geometry.natural_length=6.25 mm",
               "mesh.elements=10"]
    for o in a.orientations.split(","):
        cfg = load_config(a.config, ov + [f"field.orientation={o}"])
        runs = {"post": [], "monolithic": []}
        for _ in range(max(1, a.repeat)):
            for mode in ("post",) + (() if a.skip_monolithic else ("monolithic",)):
                c0, t0 = time.process_time(), time.perf_counter()
                r = solve(cfg, t_end=a.t_end, steps=a.steps, record=False, mode=mode)
                runs[mode].append((r, time.process_time() - c0, time.perf_counter() - t0))
        r, cpu, _ = runs["post"][-1]
        s = r.summary
        wall = {k: round(v, 3) for k, v in s["wall_time_s"].items()}
        print(f"[{o}] dofs {s['dofs']}  steps {s['steps_accepted']} accepted / {s['steps_rejected']} rejected  "
              f"Newton its/stage {s['newton_iterations_per_stage']:.2f}  linear solves {s['linear_solves']}  "
              f"factorisations {s['factorizations']}  Jacobians {s['jacobian_evaluations']}  "
              f"T post solves {s['thermal_post_solves']}  peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB")
        print(f"[{o}] wall {wall}  per step {s['wall_time_s']['total'] / max(1, s['steps_accepted']) * 1e3:.1f} ms"
              f"  CPU {cpu:.2f} s")
        print(f"[{o}] balance errors {json.dumps({k: float(f'{v:.3g}') for k, v in s['balance_errors'].items()})}")
        if runs["monolithic"]:
            rm = runs["monolithic"][-1][0]
            dT = float(np.abs(rm.state["T"] - r.state["T"]).max() / max(np.abs(rm.state["T"]).max(), 1e-300))
            med = {m: (float(np.median([c for _, c, _ in v])), float(np.median([w for _, _, w in v])))
                   for m, v in runs.items()}
            print(f"[{o}] monolithic: dofs {rm.summary['dofs']['total']}  CPU {med['monolithic'][0]:.2f} s vs post "
                  f"{med['post'][0]:.2f} s (ratio {med['monolithic'][0] / med['post'][0]:.2f}); wall "
                  f"{med['monolithic'][1]:.2f} vs {med['post'][1]:.2f} s (ratio {med['monolithic'][1] / med['post'][1]:.2f}; "
                  f"medians of {len(runs['post'])} interleaved pairs)  max|T_post - T_mono|/max T = {dT:.2e}  "
                  f"Newton its/stage {rm.summary['newton_iterations_per_stage']:.2f} vs {s['newton_iterations_per_stage']:.2f}")
    steps = [int(v) for v in a.study_steps.split(",")]
    cfg = load_config(a.config, ov + ["field.orientation=B2"])
    errs = {k: [] for k in ("mechanical", "thermal", "total", "charge")}
    for n in steps:
        s = solve(cfg, t_end=a.study_t, steps=n, record=False).summary
        for k in errs:
            errs[k].append(s["balance_errors"][k])
    print(f"balance errors vs h (B2, t = {a.study_t} ms, steps {steps}):")
    for k, e in errs.items():
        e = np.array(e)
        if k == "charge":  # at solver tolerance, no order
            print(f"  {k:10s} " + "  ".join(f"{v:.3e}" for v in e))
            continue
        orders = np.log(e[:-1] / e[1:]) / np.log(np.array(steps[1:]) / np.array(steps[:-1]))
        print(f"  {k:10s} " + "  ".join(f"{v:.3e}" for v in e) + "   orders " + " ".join(f"{v:.2f}" for v in orders))


if __name__ == "__main__":
    main()
