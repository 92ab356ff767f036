"""Contact on the chord vs on the centroid curve vs on the smooth (C¹ Hermite) contact curve:
analytic cases at p = 1, 2, 3 (docs/contact.md "Contact on the centroid curve", "The smooth
contact curve"). Prints:

(a) two straight crossed fibrils (rigid, held at a centre distance d = R+ + R- - delta):
    the contact force against the closed form of the linear penalty law,
    F(delta) = 2 P* d [ Rs asinh(L/d) - L ],  Rs = R+ + R-,  L = sqrt(Rs^2 - d^2)
    (the integral of P* g n_z along either fibril), for 4..64 elements per fibril, and the
    observed order;
(b) a fibril slid across another one over several element ends (rigid, constant approach):
    the exact force is constant; the relative spread of the force history, its largest jump
    between two steps and the largest jump of its slope;
(c) an augmented Lagrangian solve of two pressed fibrils (pinned ends): the largest overlap
    and the contact force for P* = 50 and 500, with each Newton solve's residuals;
(c2) the same augmented Lagrangian loop with the crossing placed at or next to element ends
    (P* = 50, p = 1, 2): the updates it takes and the largest overlap it ends with;
(d) the width and Holm conductance laws on the crossed pair against the contact force;
(e) a curved fibril (circular arc) crossing a straight one: the force against the continuous
    limit of the two half passes (adaptive quadrature), chord vs curve at p = 1, 2, 3: the
    order of the geometry;
(f) two parallel fibrils at a uniform overlap (the neighbours in a yarn): F = P* delta L;
(g) a straight fibril slid along the concave side of a circular arc (inside its circle, at a
    constant distance from the centre) over the arc's element ends: the exact force is
    constant in magnitude; the spread of |F| and the largest jump of the history when the
    step halves (the Lagrange curve's kinks count points twice on that side).

Usage: nice -n 10 python benchmarks/contact_order.py [--quick] [--cases a,b,...] [--geometries chord,curve,smooth]
       nice -n 10 python benchmarks/contact_order.py --cost   (the geometries on the weave)
"""
from __future__ import annotations

import argparse

import numpy as np

from rve.fem.mesh import fibril_mesh, straight_fibril
from rve.model import BeamMaterial, BeamModel, ContactParams, ContactSystem

R = 0.15
PSTAR = 50.0


def closed_form_force(delta, radius_sum=2 * R, penalty=PSTAR):
    d = radius_sum - delta
    L = np.sqrt(radius_sum**2 - d**2)
    return 2.0 * penalty * d * (radius_sum * np.arcsinh(L / d) - L)


def crossed_force(order, ne, geometry, delta, x0=0.0, y0=0.0, n_gp=4):
    """z-force on the upper fibril of two rigid straight crossed fibrils (a along x at z = 0,
    b along y at z = -(2R - delta), crossing at (x0, y0))."""
    fibs = [straight_fibril([-1, y0, 0], [1, y0, 0], R, "a"),
            straight_fibril([x0, -1, -(2 * R - delta)], [x0, 1, -(2 * R - delta)], R, "b")]
    mesh = fibril_mesh(fibs, ne, order)
    base = BeamModel(mesh, BeamMaterial(126.0))
    x = np.zeros(base.n)
    base.nodal(x)[:, :9] = mesh.X0
    sysm = ContactSystem(base, ContactParams(penalty=PSTAR, n_gp=n_gp, geometry=geometry), x)
    return float(sysm.fibril_contact_forces(x)[0, 2])


GEOMETRIES = ("chord", "curve", "smooth")


def case_a(quick: bool, geometries=GEOMETRIES):
    delta = 0.02
    F = closed_form_force(delta)
    nes = (4, 8, 16, 32) if quick else (4, 8, 16, 32, 64)
    print(f"(a) crossed fibrils, R = {R}, P* = {PSTAR}, approach delta = {delta} mm: closed form F = {F:.6f} N")
    print("    crossing at (0.0137, 0.0291) (inside elements); relative error of F, n_gp = 4")
    for geometry in geometries:
        for order in (1, 2, 3):
            errs = [crossed_force(order, ne, geometry, delta, 0.0137, 0.0291) / F - 1 for ne in nes]
            rates = [np.log2(abs(errs[k] / errs[k + 1])) if errs[k + 1] != 0 else np.nan for k in range(len(errs) - 1)]
            print(f"    {geometry:6s} p={order}: " + " ".join(f"{ne}:{e:+.2e}" for ne, e in zip(nes, errs))
                  + "   orders " + " ".join(f"{r:.2f}" for r in rates))


def case_b(quick: bool, geometries=GEOMETRIES):
    delta = 0.02
    F = closed_form_force(delta)
    ne = 8
    h = 2.0 / ne
    steps = 81 if quick else 241
    s = np.linspace(0.0, 2.5 * h, steps)  # the crossing moves over 2.5 elements of both fibrils
    print(f"(b) sliding: the crossing moves along the diagonal over 2.5 elements (h = {h} mm, {ne} el/fibril), "
          f"{steps} positions; exact F = {F:.6f} N (constant)")
    print("    a jump of F shows as a max step change that does not halve when the step halves (ratio ~1);"
          " a continuous history gives ratio ~2")
    fine = np.linspace(0.0, 2.5 * h, 2 * steps - 1)
    for order in (1, 2, 3):
        for geometry in geometries:
            hist = np.array([crossed_force(order, ne, geometry, delta, -0.3 + t, -0.3 + t) for t in s])
            hist2 = np.array([crossed_force(order, ne, geometry, delta, -0.3 + t, -0.3 + t) for t in fine])
            jump = np.abs(np.diff(hist)).max() / F
            jump2 = np.abs(np.diff(hist2)).max() / F
            slope = np.diff(hist) / np.diff(s)
            djump = np.abs(np.diff(slope)).max() * np.diff(s)[0] / F  # slope change per step, relative
            print(f"    p={order} {geometry:6s}: F/F_exact in [{hist.min() / F:.4f}, {hist.max() / F:.4f}], "
                  f"max |dF| per step {jump:.2e} F (half step {jump2:.2e} F, ratio {jump / jump2:.2f}), "
                  f"max |d(dF/ds)| per step x ds {djump:.2e} F")


def case_c():
    from rve.model import DirichletBC
    from rve.solvers.augmented import solve_with_multipliers
    from rve.solvers.static import static_solve

    print("(c) augmented Lagrangian, two fibrils pressed by prescribed end displacements (0.08 mm each), "
          "p = 2, 8 el/fibril, tolerance 1e-4 R")
    for geometry in ("chord", "curve"):
        for P in (50.0, 500.0):
            for enforcement in ("penalty", "augmented_lagrangian"):
                fibs = [straight_fibril([-1, 0, R], [1, 0, R], R, "a"),
                        straight_fibril([0.03, -1, -R], [0.03, 1, -R], R, "b")]
                mesh = fibril_mesh(fibs, 8, 2)
                ends = [n for f in (0, 1) for n in mesh.end_nodes(f)]
                pinned = np.array([n * 9 + k for n in ends for k in range(3)])
                gauge = np.array([mesh.end_nodes(0)[0] * 9 + 5, mesh.end_nodes(1)[0] * 9 + 5])
                base = BeamModel(mesh, BeamMaterial(126.0, density=1e-3),
                                 bcs=[DirichletBC(pinned, 0.0), DirichletBC(gauge, 0.0)])
                x = np.zeros(base.n)
                xn = base.nodal(x)
                xn[:, :9] = mesh.X0
                xn[list(mesh.end_nodes(0)), 2] -= 0.08
                xn[list(mesh.end_nodes(1)), 2] += 0.08
                sysm = ContactSystem(base, ContactParams(penalty=P, geometry=geometry, enforcement=enforcement), x)
                log = []

                def solve(y):
                    xs, _, res = static_solve(sysm, y, np.zeros(base.n), 0.0,
                                              {"atol": 1e-11, "rtol": 1e-13, "max_iter": 40})
                    log.append(res)
                    return xs

                xs, loop = solve_with_multipliers(sysm, solve, x)
                Fz = sysm.fibril_contact_forces(xs)[0, 2]
                print(f"    {geometry:5s} P*={P:5.0f} {enforcement:20s}: F = {Fz:.7f} N, max overlap "
                      f"{sysm.max_penetration(xs):.2e} R, updates {loop.updates}")
                for res in log:
                    print("        Newton residuals " + " ".join(f"{r:.1e}" for r in res.residuals))


def pressed_pair(order, penalty, ya, xb, **kw):
    """Fibril a along x at y = ya, fibril b along y at x = xb, pinned ends moved 0.08 mm
    towards each other (case (c)); returns (system, x)."""
    from rve.model import DirichletBC

    fibs = [straight_fibril([-1, ya, R], [1, ya, R], R, "a"), straight_fibril([xb, -1, -R], [xb, 1, -R], R, "b")]
    mesh = fibril_mesh(fibs, 8, order)
    ends = [n for f in (0, 1) for n in mesh.end_nodes(f)]
    pinned = np.array([n * 9 + k for n in ends for k in range(3)])
    gauge = np.array([mesh.end_nodes(0)[0] * 9 + 5, mesh.end_nodes(1)[0] * 9 + 5])
    base = BeamModel(mesh, BeamMaterial(126.0, density=1e-3), bcs=[DirichletBC(pinned, 0.0), DirichletBC(gauge, 0.0)])
    x = np.zeros(base.n)
    xn = base.nodal(x)
    xn[:, :9] = mesh.X0
    xn[list(mesh.end_nodes(0)), 2] -= 0.08
    xn[list(mesh.end_nodes(1)), 2] += 0.08
    return ContactSystem(base, ContactParams(penalty=penalty, **kw), x), x


def case_c2(geometries=GEOMETRIES):
    from rve.solvers.augmented import solve_with_multipliers
    from rve.solvers.static import static_solve

    print("(c2) augmented Lagrangian (P* = 50, tolerance 1e-4 R, at most 20 updates), the crossing (x_b, y_a) "
          "at / next to element ends (h = 0.25 mm): updates, last largest overlap / R")
    for geometry in geometries:
        for order in (1, 2):
            out = []
            for ya, xb in ((0.0, 0.0), (0.0, 0.03), (0.07, 0.03), (0.07, 0.11)):
                sysm, x = pressed_pair(order, 50.0, ya, xb, geometry=geometry, enforcement="augmented_lagrangian")
                ok = []

                def solve(y):
                    xs, _, res = static_solve(sysm, y, np.zeros(sysm.n), 0.0, {"atol": 1e-11, "rtol": 1e-13,
                                                                                "max_iter": 40})
                    ok.append(res.converged)
                    return xs

                _, loop = solve_with_multipliers(sysm, solve, x)
                tag = "" if all(ok) else " (a Newton solve failed)"
                out.append(f"({xb}, {ya}): {loop.updates}{'+' if loop.exhausted else ''} {loop.history[-1][1]:.1e}{tag}")
            print(f"    {geometry:6s} p={order}: " + "; ".join(out))


def arc_fibril(curvature_radius, length, y0, radius, name="arc"):
    """A circular arc in the plane y = y0, apex at the origin, centre (0, y0, rc) above it."""
    from rve.fem.mesh import Fibril, orthonormal_directors

    rc = float(curvature_radius)

    def frame(s):
        th = (np.asarray(s, float) - 0.5 * length) / rc
        r0 = np.stack([rc * np.sin(th), np.full_like(th, y0), rc * (1.0 - np.cos(th))], 1)
        t = np.stack([np.cos(th), np.zeros_like(th), np.sin(th)], 1)
        g1, g2 = orthonormal_directors(t)
        return r0, g1, g2

    return Fibril(length=float(length), radius=float(radius), frame=frame, name=name)


def arc_reference_force(rc, delta, x0, radius_sum=2 * R, penalty=PSTAR):
    """z-force on the arc of the two half passes' continuous limit: half the integral of
    P* g n_z along the arc (closest points on the straight fibril) plus half of it along the
    straight fibril (closest points on the arc), by adaptive quadrature."""
    from scipy.integrate import quad

    zb = -(radius_sum - delta)

    def on_arc(th):  # point on the arc, closest point on the line x = x0, z = zb
        jx, jz = rc * np.sin(th) - x0, rc * (1.0 - np.cos(th)) - zb
        rho = np.hypot(jx, jz)
        return max(radius_sum - rho, 0.0) * jz / rho * rc

    def on_line(y):  # point (x0, y, zb) on the line (y measured from the arc's plane)
        cx, cz = x0, zb - rc  # relative to the centre (0, rc)
        din = np.hypot(cx, cz) - rc
        rho = np.hypot(y, din)
        nz = -cz / np.hypot(cx, cz) * din / rho  # z of the unit vector from the line to the arc
        return max(radius_sum - rho, 0.0) * nz

    Ia = quad(on_arc, -0.5, 0.5, points=[0.0], limit=400, epsabs=1e-14, epsrel=1e-13)[0]
    Ib = quad(on_line, -radius_sum, radius_sum, points=[0.0], limit=400, epsabs=1e-14, epsrel=1e-13)[0]
    return 0.5 * penalty * (Ia + Ib)


def case_e(quick: bool, geometries=GEOMETRIES):
    rc, delta, x0 = 1.0, 0.02, 0.0137
    Fref = arc_reference_force(rc, delta, x0)
    nes = (4, 8, 16) if quick else (4, 8, 16, 32)
    print(f"(e) a circular arc (curvature radius {rc} mm, 2 mm long) crossing a straight fibril, approach "
          f"{delta} mm: reference F = {Fref:.6f} N (adaptive quadrature of the two half passes); "
          "relative error of F (n_gp = 64 isolates the geometry; n_gp = 4 is the default quadrature)")
    runs = [(g, n) for g in geometries for n in ((64,) if g == "chord" else (64, 4))]
    for geometry, n_gp in runs:
        for order in (1, 2, 3):
            errs = []
            for ne in nes:
                fibs = [arc_fibril(rc, 2.0, 0.0, R), straight_fibril([x0, -1, -(2 * R - delta)],
                                                                     [x0, 1, -(2 * R - delta)], R, "b")]
                mesh = fibril_mesh(fibs, ne, order)
                base = BeamModel(mesh, BeamMaterial(126.0))
                x = np.zeros(base.n)
                base.nodal(x)[:, :9] = mesh.X0
                sysm = ContactSystem(base, ContactParams(penalty=PSTAR, n_gp=n_gp, geometry=geometry), x)
                errs.append(sysm.fibril_contact_forces(x)[0, 2] / Fref - 1)
            rates = [np.log2(abs(errs[k] / errs[k + 1])) for k in range(len(errs) - 1)]
            print(f"    {geometry:6s} n_gp={n_gp:2d} p={order}: " + " ".join(f"{ne}:{e:+.2e}" for ne, e in zip(nes, errs))
                  + "   orders " + " ".join(f"{r:.2f}" for r in rates))


def case_f(geometries=GEOMETRIES):
    """Two straight parallel fibrils (8 mm, a yarn's neighbours) at a uniform overlap: the
    exact force is P* delta times the length."""
    print("(f) parallel fibrils, 8 mm long, uniform overlap delta: relative error of F against P* delta L "
          "(p = 1, n_gp = 4)")
    for delta in (0.0075, 0.0015):
        for ne in (8, 16, 32, 64):
            errs = {}
            for geometry in geometries:
                fibs = [straight_fibril([0, 0, 0], [8, 0, 0], R, "a"),
                        straight_fibril([0, 0, -(2 * R - delta)], [8, 0, -(2 * R - delta)], R, "b")]
                mesh = fibril_mesh(fibs, ne, 1)
                base = BeamModel(mesh, BeamMaterial(126.0))
                x = np.zeros(base.n)
                base.nodal(x)[:, :9] = mesh.X0
                sysm = ContactSystem(base, ContactParams(penalty=PSTAR, geometry=geometry), x)
                errs[geometry] = sysm.fibril_contact_forces(x)[0, 2] / (PSTAR * delta * 8.0) - 1
            print(f"    delta {delta / R:.3f} R, {ne:2d} el (h = {8 / ne:.3f} mm): "
                  + ", ".join(f"{g} {e:+.1e}" for g, e in errs.items()))


def arc_slide_force(order, ne, geometry, theta, rc=1.0, delta=0.02, n_gp=4):
    """|contact force| on an arc (curvature radius ``rc``, 2 mm) from a straight fibril along
    y inside its circle, at the distance rc - (2R - delta) from the centre in the direction
    ``theta`` from the apex."""
    d = rc - (2 * R - delta)
    cx, cz = d * np.sin(theta), rc - d * np.cos(theta)
    fibs = [arc_fibril(rc, 2.0, 0.0, R), straight_fibril([cx, -1, cz], [cx, 1, cz], R, "b")]
    mesh = fibril_mesh(fibs, ne, order)
    base = BeamModel(mesh, BeamMaterial(126.0))
    x = np.zeros(base.n)
    base.nodal(x)[:, :9] = mesh.X0
    sysm = ContactSystem(base, ContactParams(penalty=PSTAR, n_gp=n_gp, geometry=geometry, margin=0.2), x)
    return float(np.linalg.norm(sysm.fibril_contact_forces(x)[0]))


def case_g(quick: bool, geometries=GEOMETRIES):
    ne = 8
    steps = 61 if quick else 121
    th = np.linspace(-0.3, 0.3, steps)  # over 1.2 arc elements (0.25 rad each)
    fine = np.linspace(-0.3, 0.3, 2 * steps - 1)
    print(f"(g) a straight fibril slid along the concave side of an arc (curvature radius 1 mm, {ne} el/fibril, "
          f"approach 0.02 mm), {steps} positions over the arc's element ends: |F| is constant in the continuum")
    for order in (1, 2, 3):
        for geometry in geometries:
            if geometry == "chord":
                continue
            hist = np.array([arc_slide_force(order, ne, geometry, t) for t in th])
            hist2 = np.array([arc_slide_force(order, ne, geometry, t) for t in fine])
            mean = hist.mean()
            jump, jump2 = np.abs(np.diff(hist)).max() / mean, np.abs(np.diff(hist2)).max() / mean
            print(f"    p={order} {geometry:6s}: mean |F| {mean:.6f} N, |F|/mean in [{hist.min() / mean:.4f}, "
                  f"{hist.max() / mean:.4f}], max |dF| per step {jump:.2e} (half step {jump2:.2e}, ratio "
                  f"{jump / jump2:.2f})")


def case_d():
    """The two conductance laws on the crossed pair (rigid, the approach varied)."""
    hard, spot, sigma0, sigma_c = 100.0, 1e-3, 10.0, 1.0
    print(f"(d) contact conductance of the crossed pair, width law (sigma_C = {sigma_c} A/(mm^2 V), Hertz width "
          f"of the line load) vs Holm a-spots (H = {hard} MPa, a_s = {spot} mm, sigma0 = {sigma0} S/mm); curve, p = 2, "
          "16 el/fibril")
    rows = []
    for delta in (0.0025, 0.005, 0.01, 0.02, 0.04):
        G = {}
        for law in ("width", "holm"):
            fibs = [straight_fibril([-1, 0.0291, 0], [1, 0.0291, 0], R, "a"),
                    straight_fibril([0.0137, -1, -(2 * R - delta)], [0.0137, 1, -(2 * R - delta)], R, "b")]
            mesh = fibril_mesh(fibs, 16, 2)
            base = BeamModel(mesh, BeamMaterial(126.0, electrical_conductivity=sigma0), fields=("mech", "V"))
            x = np.zeros(base.n)
            base.nodal(x)[:, :9] = mesh.X0
            sysm = ContactSystem(base, ContactParams(penalty=PSTAR, conductance=sigma_c, geometry="curve",
                                                     conductance_law=law, hardness=hard, spot_radius=spot), x)
            G[law] = sum(sysm.contact_conductance(x, "V").values())
            Fz = sysm.fibril_contact_forces(x)[0, 2]
        rows.append((delta, Fz, G["width"], G["holm"]))
    for k, (delta, Fz, gw, gh) in enumerate(rows):
        line = f"    delta {delta:.4f} mm  F {Fz:.4e} N  G_width {gw:.4e} A/V  G_holm {gh:.4e} A/V  holm/width {gh / gw:.3f}"
        if k:
            d0 = rows[k - 1]
            line += (f"   dlnG/dlnF: width {np.log(gw / d0[2]) / np.log(Fz / d0[1]):.2f},"
                     f" holm {np.log(gh / d0[3]) / np.log(Fz / d0[1]):.2f}")
        print(line)


def case_cost(repeat: int = 9):
    """Wall time of the contact forms (mechanics only, residual + tangent), of a whole
    evaluate and of a rebuild on the plain-weave relaxation scene's designed state, chord vs
    curve vs smooth (compiled kernels when numba is available), 12 and 30 el/fibril, and the
    entries of the union pattern; wall and CPU time."""
    import time
    from dataclasses import replace
    from pathlib import Path

    from rve.config.loader import load_config
    from rve.scenes.fabric_relax import setup

    root = Path(__file__).resolve().parents[1]
    print("(cost) plain weave (configs/scenes/plain_weave_relax.yaml), designed state, p = 1; medians of "
          f"{repeat} calls")
    for el in (12, 30):
        cfg = load_config(root / "configs/scenes/plain_weave_relax.yaml", [f"mesh.elements={el}"])
        _, system, x = setup(cfg)
        w = np.zeros(system.n)
        for geometry in GEOMETRIES:
            sysm = ContactSystem(system.base, replace(system.params, geometry=geometry), x)
            sysm.evaluate(x, w, 0.0)

            def med(f):
                # wall and process CPU time (all threads): on a shared machine the CPU time
                # is the measure of the work, the wall time also counts the waits
                ts, cs = [], []
                for _ in range(repeat):
                    t0, c0 = time.perf_counter(), time.process_time()
                    f()
                    ts.append(time.perf_counter() - t0)
                    cs.append(time.process_time() - c0)
                return 1e3 * float(np.median(ts)), 1e3 * float(np.median(cs))

            tf, cf = med(lambda: sysm.term.forms(x, w, True))
            te, ce = med(lambda: sysm.evaluate(x, w, 0.0))
            tr, cr = med(lambda: sysm.rebuild(x))
            st = sysm.contact_state(x)
            nnz = sysm.evaluate(x, w, 0.0)[1].nnz
            print(f"    {el} el {geometry:6s}: pairs {sysm.map.n_pairs}, active {st['active_pairs']}, union nnz {nnz}, "
                  f"forms + tangent "
                  f"{tf:.1f} ms (CPU {cf:.1f}), evaluate {te:.1f} ms (CPU {ce:.1f}), "
                  f"rebuild {tr:.1f} ms (CPU {cr:.1f}); "
                  f"total normal force "
                  f"{st['total_normal_force']:.2f} N, max overlap {st['max_overlap_over_R']:.4f} R")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--cost", action="store_true", help="only the cost on the plain-weave scene")
    ap.add_argument("--cases", default="a,b,c,c2,d,e,f,g", help="comma-separated cases to run")
    ap.add_argument("--geometries", default=",".join(GEOMETRIES), help="geometries of cases a, b, e, f")
    args = ap.parse_args()
    if args.cost:
        case_cost()
        return
    cases = set(args.cases.split(","))
    geoms = tuple(args.geometries.split(","))
    if "a" in cases:
        case_a(args.quick, geoms)
    if "b" in cases:
        case_b(args.quick, geoms)
    if "c" in cases:
        case_c()
    if "c2" in cases:
        case_c2(tuple(g for g in geoms if g != "chord"))
    if "d" in cases:
        case_d()
    if "e" in cases:
        case_e(args.quick, geoms)
    if "f" in cases:
        case_f(geoms)
    if "g" in cases:
        case_g(args.quick, geoms)


if __name__ == "__main__":
    main()
