"""Where the curve geometry's energy is not smooth at the weave relaxation's stalled state
(docs/contact.md "Kinks between C0 elements"): runs the plain-weave relaxation
(configs/scenes/plain_weave_relax.yaml) with ``contact.geometry=curve`` (or the geometry
given), then at the final state prints

* the contact points counted by two oriented rows at once (the same point of element a,
  the same fibril b, two adjacent elements of b both holding an interior closest point:
  the concave side of a kink), their number and their share of the penalty energy;
* the points that overlap another fibril's contact curve by more than 1e-3 R (brute force:
  the distance to 41 samples per element of that fibril's curve) but are owned by no row;
* the energy along the Newton direction of the final state, E(t) for t on a fine grid,
  against the trapezoid integral of its gradient F(t).dx: a step of E that the gradient does
  not account for is a discontinuity; per such interval, how many points changed their
  set of owning rows and the energy those points carried.

Usage: nice -n 10 python benchmarks/contact_kink_diagnosis.py [elements] [state.npy] [--geometry G]
(default 30 elements, curve; with a saved state, e.g. benchmarks/contact_relax_compare.py's,
the relaxation is skipped).
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from rve.config.loader import load_config
from rve.physics.contact_forms import penalty_law

ROOT = Path(__file__).resolve().parents[1]


def point_rows(system, x):
    """(keys (n, 6), row of each, owned & active (n,), energy (n,)) of every candidate point."""
    term = system.term
    ps = term.passes
    cand = term.curve_candidates(x)
    geo = term.geometry(x, cand)
    rows = ps.rows(cand)
    G = term.params.n_gp
    keys = np.column_stack([np.repeat(ps.a_elem[rows], G), np.tile(np.arange(G), rows.size),
                            np.repeat(system.mesh.elem_fibril[ps.b_elem[rows]], G),
                            np.repeat(np.round((ps.b_shift[rows] - ps.a_shift[rows]) * 1e6).astype(np.int64), G,
                                      axis=0)])
    act = geo.active.reshape(-1)
    e, _, _ = penalty_law(np.where(geo.active, geo.g, 0.0), term.params.penalty, term.onset)
    energy = (term.weight[rows] * e).reshape(-1)
    return keys, np.repeat(rows, G) * G + np.tile(np.arange(G), rows.size), act, energy


def unowned_points(system, x, owned_keys) -> tuple[int, int]:
    """(points overlapping another fibril's curve by > 1e-3 R by brute force, of them not in
    ``owned_keys``) over every element's contact points (a cell without periodic images)."""
    from scipy.spatial import cKDTree

    from rve.physics.contact_curve import curve_basis
    from rve.physics.contact_smooth import hermite_basis

    term, mesh = system.term, system.mesh
    ps = term.passes
    r = system.nodal(np.asarray(x, float))[:, :3]
    grid = np.linspace(0.0, 1.0, 41)
    if term.smooth:
        Y = ps.stencil.control(r)
        C, P = np.matmul(hermite_basis(grid)[0], Y), np.matmul(hermite_basis(ps.s)[0], Y)
    else:
        X = r[mesh.conn]
        C = np.einsum("ka,eai->eki", curve_basis(mesh.order, grid)[0], X)
        P = np.einsum("ga,eai->egi", curve_basis(mesh.order, ps.s)[0], X)
    fib, G, reach = mesh.elem_fibril, ps.s.size, 2.0 * float(mesh.radius.max())
    found = missing = 0
    for fb in range(mesh.n_fibrils):
        d, _ = cKDTree(C[fib == fb].reshape(-1, 3)).query(P.reshape(-1, 3), distance_upper_bound=reach)
        hit = np.flatnonzero(np.isfinite(d) & (reach - d > 1e-3 * float(mesh.radius.min())))
        e, g = np.divmod(hit, G)
        other = fib[e] != fb
        found += int(other.sum())
        missing += sum(1 for ee, gg in zip(e[other], g[other]) if (int(ee), int(gg), fb) not in owned_keys)
    return found, missing


def owners(system, x) -> dict:
    keys, rowpt, act, energy = point_rows(system, x)
    out = {}
    for k, r, e in zip(map(tuple, keys[act]), rowpt[act], energy[act]):
        out.setdefault(k, []).append((int(r), float(e)))
    return out


def newton_direction(system, x):
    F, K, _ = system.evaluate(x, np.zeros(system.n), 0.0, jacobian=True)
    idx, _ = system.constraints(0.0)
    free = np.setdiff1d(np.arange(system.n), np.asarray(idx, np.int64))
    K = sp.csr_matrix(K)[free][:, free]
    dx = np.zeros(system.n)
    dx[free] = spla.spsolve(K.tocsc(), -np.asarray(F)[free])
    Ff = np.asarray(F).copy()
    Ff[np.asarray(idx, np.int64)] = 0.0
    return dx, Ff


def main(argv=None) -> None:
    args = list(argv if argv is not None else sys.argv[1:])
    geometry = "curve"
    if "--geometry" in args:
        k = args.index("--geometry")
        geometry = args[k + 1]
        del args[k:k + 2]
    elements = int(args[0]) if args else 30
    cfg = load_config(ROOT / "configs/scenes/plain_weave_relax.yaml",
                      [f"mesh.elements={elements}", f"contact.geometry={geometry}"])
    if len(args) > 1:
        from rve.fabrics.relaxation import relaxation_system

        _, system, _ = relaxation_system(cfg)
        x = np.load(args[1])
        system.rebuild(x)
    else:
        from rve.scenes.fabric_relax import solve

        t0 = time.perf_counter()
        res = solve(cfg)
        system, x = res.model, np.asarray(res.state["x"], float).reshape(-1)
        np.save(f"/tmp/contact_kink_state_{elements}.npy", x)
        print(f"relaxation: {time.perf_counter() - t0:.1f} s, final |F| {res.summary['static_residuals'][-1]:.2e} N",
              flush=True)
    own = owners(system, x)
    twice = {k: v for k, v in own.items() if len(v) > 1}
    e_all = sum(e for v in own.values() for _, e in v)
    e_twice = sum(e for v in twice.values() for _, e in v)
    print(f"active points {len(own)}, counted by two rows {len(twice)} ({e_twice / max(e_all, 1e-300):.2%} of the "
          f"contact energy {e_all:.4e} N mm)", flush=True)
    found, missing = unowned_points(system, x, {k[:3] for k in own})
    print(f"points overlapping another fibril by > 1e-3 R (brute force) {found}, owned by no row {missing}", flush=True)
    dx, F0 = newton_direction(system, x)
    print(f"|F| {np.linalg.norm(F0):.3e} N, |dx| {np.abs(dx).max():.3e} mm, F.dx {F0 @ dx:.3e} N mm", flush=True)
    ts = np.concatenate([[0.0], np.geomspace(1e-6, 1.0, 121)])
    E = np.array([system.energy(x + t * dx) for t in ts])
    dE = []
    for t in ts:
        F, _, _ = system.evaluate(x + t * dx, np.zeros(system.n), 0.0, jacobian=False)
        idx, _ = system.constraints(0.0)
        F = np.asarray(F).copy()
        F[np.asarray(idx, np.int64)] = 0.0
        dE.append(F @ dx)
    dE = np.array(dE)
    trap = 0.5 * (dE[1:] + dE[:-1]) * np.diff(ts)
    mism = np.diff(E) - trap
    scale = np.abs(trap) + 1e-12 * np.abs(E[1:])   # round-off of E itself
    print("t_from t_to dE dE_trapezoid mismatch points_switched energy_of_switched", flush=True)
    prev = own
    for i in range(ts.size - 1):
        cur = owners(system, x + ts[i + 1] * dx)
        changed = [k for k in set(prev) | set(cur) if [r for r, _ in prev.get(k, [])] != [r for r, _ in cur.get(k, [])]]
        if abs(mism[i]) > 10 * scale[i] or (i % 20 == 0):
            e_sw = sum(abs(sum(e for _, e in cur.get(k, [])) - sum(e for _, e in prev.get(k, []))) for k in changed)
            dbl = sum(1 for k in changed if len(prev.get(k, [])) > 1 or len(cur.get(k, [])) > 1)
            print(f"{ts[i]:.3e} {ts[i + 1]:.3e} {np.diff(E)[i]:+.3e} {trap[i]:+.3e} {mism[i]:+.3e} {len(changed)} "
                  f"(of them counted twice before/after: {dbl}) {e_sw:.3e}", flush=True)
        prev = cur
    k = int(np.argmin(E))
    print(f"min E along the direction at t = {ts[k]:.3e}: E - E(0) = {E[k] - E[0]:+.3e} N mm", flush=True)


if __name__ == "__main__":
    main()
