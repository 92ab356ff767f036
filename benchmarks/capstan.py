"""The capstan at full size (configs/scenes/capstan.yaml): T2/T1 against exp(mu theta) for
mu in {0.1, 0.3} and theta in {pi/2, pi}, with the mesh and the regularisation; then, for
mu = 0.3, theta = pi, the ratio under mesh refinement, a stiffer tangential penalty and a
fibril of half the radius (a quarter of the bending length's square: the bending influence).

    nice -n 10 python benchmarks/capstan.py [--quick] [overrides ...]
"""
import math
import sys
from pathlib import Path

from rve.config.loader import load_config
from rve.scenes import capstan
from rve.solvers.newton import convergence_rates

CONFIG = Path(__file__).resolve().parents[1] / "configs/scenes/capstan.yaml"


def case(overrides):
    cfg = load_config(CONFIG, overrides)
    s = capstan.solve(cfg).summary
    last = s["path"][-1]
    eps = cfg.load.tension / (cfg.material.youngs_modulus * math.pi * cfg.geometry.fibril_radius ** 2)
    lam = cfg.geometry.fibril_radius / (2 * math.sqrt(eps))
    return cfg, s, last, lam


def line(cfg, s, last, lam):
    g = cfg.geometry
    return (f"mu={cfg.friction.coefficient:.2f} theta={g.wrap_angle / math.pi:.2f} pi  T2/T1={s['ratio']:.6f}  "
            f"exp(mu theta)={s['exact']:.6f}  err={100 * s['relative_error']:+.4f} %  "
            f"[{cfg.mesh.elements_per_radian} el/rad, {s['elements']} el, order {cfg.mesh.order}, "
            f"n_gp {cfg.contact.n_gp}, eps_T/P*={cfg.friction.stiffness:g}, P*={cfg.contact.penalty:g} N/mm^2, "
            f"overlap/R_f={s['overlap'] / g.fibril_radius:.3f}, lambda/R={lam / g.cylinder_radius:.4f}, "
            f"stick/slip at the end {last['stick']}/{last['slip']}, {s['wall_time_s']:.1f} s]")


def main(argv):
    quick = "--quick" in argv
    extra = [a for a in argv if a != "--quick"]
    worst = 0.0
    print("capstan: T2/T1 once the whole wrap slides (the last pull step)")
    for mu in (0.1, 0.3):
        for theta in ("90 deg", "180 deg"):
            cfg, s, last, lam = case([f"friction.coefficient={mu}", f"geometry.wrap_angle={theta}"] + extra)
            worst = max(worst, abs(s["relative_error"]))
            print(line(cfg, s, last, lam))
            first = s["path"][0]["newton"]
            print(f"    Newton, first pull step (stick and slip): {' '.join(f'{r:.2e}' for r in first)}; rates "
                  f"{' '.join(f'{q:.2f}' for q in convergence_rates(first))}")
            print(f"    Newton, last step (all slip): {' '.join(f'{r:.2e}' for r in last['newton'])}; rates "
                  f"{' '.join(f'{q:.2f}' for q in convergence_rates(last['newton']))}")
    print(f"largest |error| of the four cases: {100 * worst:.4f} % (acceptance: 1 %)")
    if quick:
        return
    print("mu = 0.3, theta = pi: mesh, regularisation and bending")
    for label, ov in (("30 el/rad", ["mesh.elements_per_radian=30"]),
                      ("120 el/rad", ["mesh.elements_per_radian=120", "load.steps=60"]),
                      ("eps_T/P* = 10", ["friction.stiffness=10"]),
                      ("n_gp = 4", ["contact.n_gp=4"]),
                      ("R_f / 2 (same strain)", ["geometry.fibril_radius=0.0025 mm", "load.tension=1.9635e-4 N"])):
        cfg, s, last, lam = case(["friction.coefficient=0.3", "geometry.wrap_angle=180 deg"] + ov + extra)
        print(f"{label:22s} " + line(cfg, s, last, lam))


if __name__ == "__main__":
    main(sys.argv[1:])
