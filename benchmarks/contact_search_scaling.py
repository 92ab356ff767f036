"""How the contact-map build scales (not O(N_fibril^2 N_elem^2): docs/contact_search.md "Scaling").

For a woven layout (``rve.fabrics.plain_weave``: n x n yarns of 10 fibrils in 3-4-3
stacks, in their crimped initial state) and a random layout (straight fibrils of length
8 mm at random positions and directions, box grown to keep the fibril density fixed), with
growing numbers of fibrils and elements per fibril, print:

* S, the number of element chords, and P, the number of candidate pairs;
* the median time of ``build_contact_map`` (KD-tree search + exact distance filter +
  quadrature table) over several repeats, and that time per chord and per (S + P);
* the time of the all-pairs O(S^2) reference ``candidate_pairs_bruteforce`` (measured up
  to S = --brute-max, extrapolated as c S^2 from the largest measured case beyond, marked
  ``~``) and the ratio brute / build;
* the peak resident memory of the process after that build (ru_maxrss; all builds run
  before any O(S^2) reference, so the column reflects the search alone).

Run: ``python benchmarks/contact_search_scaling.py [--quick]``. Never fails on a slow
machine; it only prints.
"""
from __future__ import annotations

import argparse
import resource
import statistics
import time

import numpy as np

from rve.contact import build_contact_map, candidate_pairs_bruteforce, element_segments
from rve.fabrics import plain_weave
from rve.fem.mesh import fibril_mesh, straight_fibril

CUTOFF = 0.3 + 0.1  # R+ + R- (0.15 + 0.15) + a 0.1 mm margin
N_GP = 4


def peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # KiB on Linux


def woven(n: int, n_el: int):
    fab = plain_weave(n, n)
    mesh = fab.mesh(n_el, 1)
    return mesh, fab.initial_state(mesh)


def random_layout(n_fib: int, n_el: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    # 80 fibrils of length 8 in an 8 x 8 x 1 mm slab ~ the thesis RVE density
    side = 8.0 * np.sqrt(n_fib / 80.0)
    fibs = []
    for f in range(n_fib):
        c = rng.uniform([-side / 2, -side / 2, -0.5], [side / 2, side / 2, 0.5])
        d = rng.normal(size=3)
        d[2] *= 0.1  # mostly in-plane, like a fabric
        d /= np.linalg.norm(d)
        fibs.append(straight_fibril(c - 4 * d, c + 4 * d, 0.15, f"r{f}"))
    mesh = fibril_mesh(fibs, n_el, 1)
    return mesh, mesh.X0


def time_build(mesh, x, repeats):
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        cmap = build_contact_map(x, mesh, CUTOFF, N_GP)
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts), cmap.n_pairs


def time_brute(mesh, x):
    a, b = element_segments(x, mesh)
    t0 = time.perf_counter()
    pairs = candidate_pairs_bruteforce(a, b, CUTOFF, mesh.elem_fibril, chunk=1024)
    return time.perf_counter() - t0, len(pairs)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="smaller sizes")
    ap.add_argument("--brute-max", type=int, default=6000,
                    help="largest S for which the O(S^2) reference is measured")
    args = ap.parse_args()
    if args.quick:
        cases = [("woven", n, e) for n in (2, 4) for e in (8, 16)]
        cases += [("random", f, e) for f in (40, 160) for e in (8, 16)]
    else:
        cases = [("woven", n, e) for n in (2, 4, 8, 16) for e in (16, 32, 64)]
        cases += [("random", f, e) for f in (80, 320, 1280) for e in (16, 32, 64)]

    print(f"cutoff = {CUTOFF} mm, n_gp = {N_GP}; times are medians; '~' = extrapolated c*S^2")
    # builds first (peak memory then reflects the search alone), references afterwards
    rows = []
    for layout, nf, ne in cases:
        mesh, x = woven(nf, ne) if layout == "woven" else random_layout(nf, ne)
        S = mesh.n_elements
        build_contact_map(x, mesh, CUTOFF, N_GP)  # warm-up
        t, P = time_build(mesh, x, 7 if S < 5000 else 3)
        rows.append(dict(layout=layout, nf=mesh.n_fibrils, ne=ne, S=S, P=P, t=t,
                         mb=peak_mb(), case=(layout, nf, ne)))
    c_brute = {}
    for row in rows:
        if row["S"] <= args.brute_max:
            layout, nf, ne = row["case"]
            mesh, x = woven(nf, ne) if layout == "woven" else random_layout(nf, ne)
            tb, Pb = time_brute(mesh, x)
            assert Pb == row["P"], (Pb, row["P"])
            c_brute[layout] = tb / row["S"] ** 2
            row["tb"], row["est"] = tb, False
        else:
            row["tb"], row["est"] = c_brute.get(row["layout"], np.nan) * row["S"] ** 2, True
    print(f"{'layout':7s} {'fibrils':>7s} {'el/fib':>6s} {'S':>7s} {'P':>8s} "
          f"{'build ms':>9s} {'us/S':>6s} {'us/(S+P)':>8s} {'brute ms':>10s} "
          f"{'brute/build':>11s} {'peak MB':>8s}")
    for r in rows:
        brute = (f"~{r['tb'] * 1e3:9.0f}" if r["est"] else f"{r['tb'] * 1e3:10.1f}")
        print(f"{r['layout']:7s} {r['nf']:7d} {r['ne']:6d} {r['S']:7d} {r['P']:8d} "
              f"{r['t'] * 1e3:9.2f} {r['t'] / r['S'] * 1e6:6.2f} "
              f"{r['t'] / (r['S'] + r['P']) * 1e6:8.2f} {brute} {r['tb'] / r['t']:11.1f} "
              f"{r['mb']:8.1f}")
    print(f"peak MB after the O(S^2) references: {peak_mb():.1f}")


if __name__ == "__main__":
    main()
