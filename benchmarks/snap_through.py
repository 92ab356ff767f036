"""What snaps on the uniaxial path of the periodic 2 x 2 plain-weave cell (docs/snap_through.md):
the stored states before and after the step whose branch test found the limit point, for
both meshes of the work-precision study, compared fibril by fibril and contact by contact.

    python benchmarks/snap_through.py [--run12 STATES] [--run18 STATES] [--names RUN12 RUN18]
        [--jumps STEP12 STEP18] [--matched STEP ...]

``--names``: the configs/pipeline.yaml runs of the two state directories (default the
work-precision study's ``work_precision_default`` and ``work_precision_reference_18``),
``--jumps``: their uniaxial steps that hold the jump (default 4 and 3); ``--matched``: the
uniaxial steps of the unlabelled section matching (default 2 4 6 10).

For each mesh it prints

* the branch records of the jump step (the energy the jump releases: work minus energy
  change of the half step that holds the jump, ``mismatch``);
* per fibril, the non-affine displacement over the step: r_after - (c + F_a F_b^-1 (r_b - c)),
  c the held node, at the nodes both meshes share (s = 0, 1/3, ..., 4 mm: 12 and 18
  elements of p = 2 have nodes every 1/6 and 1/9 mm), its mean (the fibril's rigid
  translation against the affine field) and its largest magnitude; the same over the
  smooth step before, as the baseline;
* per yarn, the fibrils' cross-section at the two crossings (lateral and vertical offsets
  from the yarn's mean centroid) and which fibril pairs of a stack swap their order
  (lateral or vertical) across the step;
* per fibril pair in contact, the normal force (sum over points of w phi'(g), g the
  overlap shifted by the multiplier: the line load's integral, both half passes) before
  and after; the pairs that appear, vanish or change most; intra-yarn (stack) and
  crossing (warp-weft) totals;
* the correlation of the two meshes' jump fields (non-affine displacement of the jump step
  at the common nodes).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import pipeline_spec  # noqa: E402

RUN12 = Path("/work/kept-results/work_precision_default/base/states")
RUN18 = Path("/work/runs/ref/results/rve/work_precision_reference_18/base/states")
# (run name in configs/pipeline.yaml, the jump step of its uniaxial path)
JUMP = {"12": ("work_precision_default", 4), "18": ("work_precision_reference_18", 3)}


def setup(run, overrides=()):
    """(config, fabric, mesh) of a configs/pipeline.yaml run, ``overrides`` appended."""
    from rve.fabrics.setup import fabric_and_mesh
    from rve.homogenisation.sweeps import load_run_config

    spec = pipeline_spec(run, overrides)
    cfg = load_run_config(spec, "base")
    fab, mesh = fabric_and_mesh(cfg)
    return cfg, fab, mesh


def state(states: Path, step: int):
    from rve.homogenisation.checkpoint import load_state

    return load_state(states / ("relaxed.nc" if step == 0 else f"uniaxial_{step:02d}.nc"))


def common_nodes(mesh, spacing=1.0 / 3.0):
    """Per fibril, the node indices at s = 0, spacing, ..., L (nodes of both meshes)."""
    out = []
    for f in range(mesh.n_fibrils):
        nodes = np.asarray(mesh.fibril_nodes(f))
        s = mesh.node_s[nodes]
        targets = np.arange(0.0, s.max() + 1e-9, spacing)
        idx = [int(nodes[np.argmin(np.abs(s - t))]) for t in targets]
        assert np.allclose(mesh.node_s[idx], targets, atol=1e-9)
        out.append(idx)
    return np.asarray(out)   # (fibrils, 13)


def nonaffine(mesh, sb, sa):
    """(nodes, 3) displacement of state ``sa`` relative to the affine map of ``sb``."""
    from rve.homogenisation.periodic import macro_gradient

    xb, xa = sb.x.reshape(mesh.n_nodes, -1)[:, :3], sa.x.reshape(mesh.n_nodes, -1)[:, :3]
    Fb, Fa = macro_gradient("uniaxial", sb.strain), macro_gradient("uniaxial", sa.strain)
    held = int(mesh.node_offsets[0])
    c = xb[held]
    pred = c + (xb - c) @ (Fa @ np.linalg.inv(Fb)).T
    return xa - pred


def sections(fab, mesh, st):
    """{yarn: (n_cross, n_fib, 2)} lateral/vertical offsets at the crossings."""
    from rve.fabrics.stack import _yarn_sections

    xn = st.x.reshape(mesh.n_nodes, -1)
    # the warp yarns are cut where the weft yarns are (their mean x at this state)
    p = dict(fab.params)
    wx = [xn[np.concatenate([mesh.fibril_nodes(f) for f in y.fibrils]), 0].mean() for y in fab.yarns
          if y.direction == "weft"]
    import dataclasses
    fab2 = dataclasses.replace(fab, params=dict(p, weft_x=np.asarray(sorted(wx))))
    return {y.name: _yarn_sections(fab2, mesh, xn, y) for y in fab.yarns}


def pair_forces(cfg, fab, mesh, st):
    """{(f+, f-): normal force N} of a stored state (its multipliers seeded)."""
    from rve.homogenisation.multipliers import seed_multipliers
    from rve.homogenisation.periodic import cell_gradient, periodic_system
    from rve.physics.contact_forms import penalty_law

    x = st.x.reshape(-1)
    psys = periodic_system(cfg, fab, mesh, x, cell_gradient(fab, mesh, x))
    seed_multipliers(psys, st.multipliers)
    term = psys.full.term
    g = term.gaps(x)
    g = np.where(np.isfinite(g), g, -1.0)
    w = np.broadcast_to(np.asarray(term.weight, float).reshape(g.shape[0], -1), g.shape)
    f = (w * penalty_law(np.maximum(g, 0.0), term.params.penalty, term.onset)[1] * (g > 0)).sum(axis=1)
    pts = (g > 0).sum(axis=1)
    nf = mesh.n_fibrils
    pr = term.row_pair
    a, b = term.map.fibril_plus[pr].astype(np.int64), term.map.fibril_minus[pr].astype(np.int64)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key = lo * nf + hi
    uk, inv = np.unique(key, return_inverse=True)
    tot = np.bincount(inv, weights=f, minlength=uk.size)
    npts = np.bincount(inv, weights=pts, minlength=uk.size)
    return {(int(k // nf), int(k % nf)): (float(v), int(n)) for k, v, n in zip(uk, tot, npts) if v > 0}, \
        float(psys.energy(psys.restrict(x)))


def kind(fab, a, b):
    ya, yb = int(fab.fibril_yarn[a]), int(fab.fibril_yarn[b])
    if ya == yb:
        return "stack"
    if fab.yarns[ya].direction == fab.yarns[yb].direction:
        return "neighbour yarns"
    return "crossing"


def name(fab, f):
    return fab.names[f] if hasattr(fab, "names") else str(f)


def analyse(label, states, out: dict, top=8):
    run, jstep = JUMP[label]
    cfg, fab, mesh = setup(run)
    sb, sa, sp = state(states, jstep - 1), state(states, jstep), state(states, jstep - 2)
    print(f"\n===== {label} elements ({run}): uniaxial step {jstep}, strain {sb.strain:g} -> {sa.strain:g}")
    br = sa.solver.get("branch", {})
    for c in br.get("checks", []):
        print(f"  branch check {c['eps']}: jump {c['jump']}, energy change {c['energy_change']:.4e}, work "
              f"{c['work']:.4e}, mismatch {c['mismatch']:.4e} N mm (tolerance {c['tolerance']:.3e})"
              f"{' persists' if c.get('persists') else ''}")
    print(f"  kept {br.get('kept')}, naive-to-followed distance {br.get('naive_to_followed_distance', float('nan')):.4f} mm,"
          f" energy {br.get('naive_to_followed_energy', float('nan')):.3e} N mm")
    for s in (sb, sa):
        al = s.solver.get("static", {}).get("augmented_lagrangian", {})
        print(f"  state at {s.strain:g}: largest overlap {al.get('max_penetration_over_R', float('nan')):.2e} R "
              f"(al_tolerance {al.get('tolerance', float('nan')):g}), Uzawa penalties {al.get('penalties')}")
    cn = common_nodes(mesh)
    res = {}
    for what, s0, s1 in (("smooth step before", sp, sb), ("jump step", sb, sa)):
        d = nonaffine(mesh, s0, s1)
        dc = d[cn]                         # (fibrils, 13, 3)
        mean = dc.mean(axis=1)
        dmax = np.linalg.norm(d, axis=1)
        per = np.array([dmax[mesh.fibril_nodes(f)].max() for f in range(mesh.n_fibrils)])
        res[what] = dc
        print(f"  {what} ({s0.strain:g} -> {s1.strain:g}): non-affine displacement, largest {per.max():.4f} mm "
              f"(median over fibrils {np.median(per):.4f}); rms over all nodes {np.sqrt((d ** 2).sum(1).mean()):.4f} mm")
        if what == "jump step":
            order = np.argsort(-per)
            print(f"    {'fibril':10s} {'max|d|':>7s} {'mean dx':>8s} {'mean dy':>8s} {'mean dz':>8s}")
            for f in order[:12]:
                print(f"    {name(fab, f):10s} {per[f]:7.4f} {mean[f, 0]:8.4f} {mean[f, 1]:8.4f} {mean[f, 2]:8.4f}")
            for y in fab.yarns:
                fs = list(y.fibrils)
                print(f"    yarn {y.name}: mean of max|d| {per[fs].mean():.4f} mm, largest {per[fs].max():.4f}; "
                      f"mean translation ({mean[fs, 0].mean():+.4f}, {mean[fs, 1].mean():+.4f}, {mean[fs, 2].mean():+.4f}) mm")
    # stack order at the crossings
    secb, seca = sections(fab, mesh, sb), sections(fab, mesh, sa)
    print("  stack cross-sections at the crossings (lateral, vertical offset from the yarn's mean, mm):")
    swaps = []
    for y in fab.yarns:
        B, A = secb[y.name], seca[y.name]
        for ic in range(B.shape[0]):
            mv = np.linalg.norm(A[ic] - B[ic], axis=1)
            k = int(np.argmax(mv))
            print(f"    {y.name} crossing {ic}: largest fibril move {mv.max():.4f} mm ({name(fab, y.fibrils[k])}:"
                  f" ({B[ic, k, 0]:+.3f}, {B[ic, k, 1]:+.3f}) -> ({A[ic, k, 0]:+.3f}, {A[ic, k, 1]:+.3f})); "
                  f"height {np.ptp(B[ic, :, 1]):.3f} -> {np.ptp(A[ic, :, 1]):.3f}, width {np.ptp(B[ic, :, 0]):.3f} -> "
                  f"{np.ptp(A[ic, :, 0]):.3f}")
            n = len(y.fibrils)
            for i in range(n):
                for j in range(i + 1, n):
                    for ax, axn in ((0, "lateral"), (1, "vertical")):
                        db, da = B[ic, i, ax] - B[ic, j, ax], A[ic, i, ax] - A[ic, j, ax]
                        # a swap: the order changes by more than a tenth of a radius each way
                        if db * da < 0 and min(abs(db), abs(da)) > 0.015:
                            swaps.append((y.name, ic, name(fab, y.fibrils[i]), name(fab, y.fibrils[j]), axn, db, da))
    print(f"  order swaps within a stack (|offset difference| > 0.015 mm on both sides): {len(swaps)}")
    for s in swaps[:20]:
        print(f"    {s[0]} crossing {s[1]}: {s[2]} / {s[3]} {s[4]}: {s[5]:+.3f} -> {s[6]:+.3f} mm")
    # which yarn is on top at each of the four warp-weft crossings, before and after
    def sides(st):
        xn = st.x.reshape(mesh.n_nodes, -1)[:, :3]
        out = {}
        for wp in (y for y in fab.yarns if y.direction == "warp"):
            for wf in (y for y in fab.yarns if y.direction == "weft"):
                xw = xn[np.concatenate([mesh.fibril_nodes(f) for f in wf.fibrils]), 0].mean()
                zs = []
                for yarn, along, at in ((wp, 0, xw), (wf, 1, wp.position)):
                    z = []
                    for f in yarn.fibrils:
                        r = xn[mesh.fibril_nodes(f)]
                        o = np.argsort(r[:, along])
                        z.append(np.interp(at, r[o, along], r[o, 2]))
                    zs.append(np.mean(z))
                out[(wp.name, wf.name)] = zs[0] - zs[1]
        return out
    cb, ca = sides(sb), sides(sa)
    print("  warp minus weft mean height at the crossings (mm), before -> after: " + "; ".join(
        f"{k[0]}/{k[1]} {cb[k]:+.3f} -> {ca[k]:+.3f}" for k in cb))
    # contacts
    fb, eb = pair_forces(cfg, fab, mesh, sb)
    fa, ea = pair_forces(cfg, fab, mesh, sa)
    print(f"  potential (elastic + shifted-overlap penalty) {eb:.6e} -> {ea:.6e} N mm")
    keys = sorted(set(fb) | set(fa))
    rows = [(k, fb.get(k, (0.0, 0))[0], fa.get(k, (0.0, 0))[0], fb.get(k, (0.0, 0))[1], fa.get(k, (0.0, 0))[1])
            for k in keys]
    tot = {}
    for k, f0, f1, n0, n1 in rows:
        t = tot.setdefault(kind(fab, *k), [0.0, 0.0, 0, 0, 0, 0])
        t[0] += f0
        t[1] += f1
        t[2] += n0 > 0
        t[3] += n1 > 0
        t[4] += n0
        t[5] += n1
    for kd, t in tot.items():
        print(f"  {kd:15s}: fibril pairs in contact {t[2]} -> {t[3]}, contact points {t[4]} -> {t[5]}, "
              f"summed normal force {t[0]:.4e} -> {t[1]:.4e} N")
    new = [r for r in rows if r[3] == 0 and r[4] > 0]
    gone = [r for r in rows if r[3] > 0 and r[4] == 0]
    print(f"  pairs that come into contact: {len(new)}, that lose it: {len(gone)}")
    for lab, rr in (("new", new), ("lost", gone)):
        for k, f0, f1, n0, n1 in sorted(rr, key=lambda r: -max(r[1], r[2]))[:top]:
            print(f"    {lab:5s} {name(fab, k[0])}-{name(fab, k[1])} ({kind(fab, *k)}): {f0:.3e} -> {f1:.3e} N, "
                  f"points {n0} -> {n1}")
    print(f"  the {top} pairs whose normal force changes most:")
    for k, f0, f1, n0, n1 in sorted(rows, key=lambda r: -abs(r[2] - r[1]))[:top]:
        print(f"    {name(fab, k[0])}-{name(fab, k[1])} ({kind(fab, *k)}): {f0:.3e} -> {f1:.3e} N "
              f"({f1 - f0:+.3e}), points {n0} -> {n1}")
    out[label] = {"jump_field": res["jump step"], "smooth_field": res["smooth step before"], "fab": fab,
                  "forces": (fb, fa)}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--run12", type=Path, default=RUN12)
    ap.add_argument("--run18", type=Path, default=RUN18)
    ap.add_argument("--names", nargs=2, default=[JUMP["12"][0], JUMP["18"][0]])
    ap.add_argument("--jumps", nargs=2, type=int, default=[JUMP["12"][1], JUMP["18"][1]])
    ap.add_argument("--matched", nargs="+", type=int, default=[2, 4, 6, 10])
    a = ap.parse_args(argv)
    JUMP.update({"12": (a.names[0], a.jumps[0]), "18": (a.names[1], a.jumps[1])})
    out = {}
    analyse("12", a.run12, out)
    analyse("18", a.run18, out)
    # do the two meshes jump the same way? correlation of the non-affine fields at the common nodes
    j12, j18 = out["12"]["jump_field"].reshape(-1), out["18"]["jump_field"].reshape(-1)
    s12 = out["12"]["smooth_field"].reshape(-1)
    def corr(u, v):
        return float(u @ v / np.linalg.norm(u) / np.linalg.norm(v))
    print("\n===== the two meshes' jumps")
    print(f"  cosine of the jump steps' non-affine fields (12 el step 4 against 18 el step 3), at the 13 common "
          f"nodes of every fibril: {corr(j12, j18):.3f}")
    print(f"  for comparison, 12 el smooth step 3 against 18 el jump step: {corr(s12, j18):.3f}")
    n12 = np.linalg.norm(out["12"]["jump_field"], axis=2).max(axis=1)
    n18 = np.linalg.norm(out["18"]["jump_field"], axis=2).max(axis=1)
    print(f"  per-fibril largest move, correlation between the meshes: {np.corrcoef(n12, n18)[0, 1]:.3f}")
    fab = out["12"]["fab"]
    t12, t18 = np.argsort(-n12)[:10], np.argsort(-n18)[:10]
    print(f"  ten fibrils that move most: 12 el {[name(fab, f) for f in t12]}")
    print(f"                              18 el {[name(fab, f) for f in t18]}; in common {len(set(t12) & set(t18))}")
    (b12, a12), (b18, a18) = out["12"]["forces"], out["18"]["forces"]
    ch12 = {k: a12.get(k, (0, 0))[0] - b12.get(k, (0, 0))[0] for k in set(a12) | set(b12)}
    ch18 = {k: a18.get(k, (0, 0))[0] - b18.get(k, (0, 0))[0] for k in set(a18) | set(b18)}
    ks = sorted(set(ch12) | set(ch18))
    v12, v18 = np.array([ch12.get(k, 0.0) for k in ks]), np.array([ch18.get(k, 0.0) for k in ks])
    print(f"  pair normal-force changes over the jump step, cosine between the meshes: {corr(v12, v18):.3f} "
          f"({len(ks)} pairs)")
    path_table(a.run12, a.run18)
    mirror_asymmetry(a.run12, a.run18)
    matched_sections(a.run12, a.run18, tuple(a.matched))
    return 0


def stack_shape(fab, mesh, st):
    """{direction: (height, width)} of the yarns' sections at the crossings, mean over yarns
    and crossings (mm): ptp of the fibril centroids' vertical and lateral offsets."""
    secs = sections(fab, mesh, st)
    out = {}
    for d in ("warp", "weft"):
        S = np.concatenate([secs[y.name] for y in fab.yarns if y.direction == d])
        out[d] = (float(np.ptp(S[..., 1], axis=1).mean()), float(np.ptp(S[..., 0], axis=1).mean()))
    return out


def path_table(states12=RUN12, states18=RUN18):
    """Per uniaxial step of both meshes: energy, face forces, stack shapes, and the two meshes'
    geometric distance (rms over the fibrils' crossing-section points)."""
    print("\n===== the uniaxial path, both meshes (stack shape: height / width of the sections at the crossings, mm)")
    print(f"{'mesh':4s} {'step':>4s} {'strain':>6s} {'energy N mm':>11s} {'x+ x N':>9s} {'y+ y N':>9s} "
          f"{'warp h/w':>13s} {'weft h/w':>13s} {'points':>6s}")
    secs = {}
    for label, states in (("12", states12), ("18", states18)):
        cfg, fab, mesh = setup(JUMP[label][0])
        for step in range(0, 11):
            p = states / ("relaxed.nc" if step == 0 else f"uniaxial_{step:02d}.nc")
            if not p.exists():
                continue
            st = state(states, step)
            sh = stack_shape(fab, mesh, st)
            secs[(label, step)] = sections(fab, mesh, st)
            from rve.homogenisation.periodic import periodic_energy
            # the potential of the true overlaps (the branch test's Pi), comparable with any other
            # equilibrium at the same strain (benchmarks/snap_step.py prints the same)
            e = periodic_energy(cfg, fab, mesh, st.x, "uniaxial", st.strain, st.multipliers)[0]
            print(f"{label:4s} {step:4d} {st.strain:6.3f} {e:11.5e} {st.reaction_force['x+'][0]:9.5f} "
                  f"{st.reaction_force['y+'][1]:9.5f} {sh['warp'][0]:6.3f}/{sh['warp'][1]:5.3f} "
                  f"{sh['weft'][0]:6.3f}/{sh['weft'][1]:5.3f} {st.contact_count:6d}")
    print("  the meshes' crossing sections against each other (rms distance of the fibril centroids, mm):")
    for s12 in range(0, 11):
        row = []
        for s18 in range(0, 11):
            if ("12", s12) in secs and ("18", s18) in secs and abs(s12 - s18) <= 1:
                a, b = secs[("12", s12)], secs[("18", s18)]
                wf = np.sqrt(np.mean([((a[k] - b[k]) ** 2).sum(-1).mean() for k in a if k.startswith("weft")]))
                wp = np.sqrt(np.mean([((a[k] - b[k]) ** 2).sum(-1).mean() for k in a if k.startswith("warp")]))
                row.append(f"12el {s12} vs 18el {s18}: weft {wf:.4f} warp {wp:.4f}")
        if row:
            print("    " + "; ".join(row))


def mirror_asymmetry(states12=RUN12, states18=RUN18):
    """How far each stack section is from its own mirror image (lateral -> -lateral, the
    fibrils matched by the optimal assignment): rms of the matched centroid distances, mm.
    Zero: the section is mirror-symmetric, and an edge fibril rolling off to one side or to
    the other are two equivalent choices."""
    from scipy.optimize import linear_sum_assignment

    print("\n===== mirror asymmetry of the stack sections (rms distance to the mirrored section, mm; "
          "mean over the crossings)")
    for label, states, steps in (("12", states12, (0, 2, 3, 4)), ("18", states18, (0, 2, 3))):
        cfg, fab, mesh = setup(JUMP[label][0])
        for step in steps:
            st = state(states, step)
            secs = sections(fab, mesh, st)
            vals = {}
            for d in ("warp", "weft"):
                r = []
                for y in fab.yarns:
                    if y.direction != d:
                        continue
                    for S in secs[y.name]:
                        M = S * np.array([-1.0, 1.0])
                        C = np.linalg.norm(S[:, None, :] - M[None, :, :], axis=2)
                        i, j = linear_sum_assignment(C)
                        r.append(np.sqrt((C[i, j] ** 2).mean()))
                vals[d] = float(np.mean(r))
            print(f"  {label} el, strain {st.strain:.3f}: warp {vals['warp']:.4f}, weft {vals['weft']:.4f}")


def matched_sections(states12=RUN12, states18=RUN18, steps=(2, 4, 6, 10)):
    """The two meshes' weft sections at one strain compared without fibril labels: per
    crossing the optimal assignment of the 18-element section's fibrils to the 12-element
    one's, as it is and mirrored (lateral -> -lateral); rms of the matched distances, mm,
    mean over the four weft crossings (the smaller of the two per crossing in 'best')."""
    from scipy.optimize import linear_sum_assignment

    def rms(A, B):
        C = np.linalg.norm(A[:, None, :] - B[None, :, :], axis=2)
        i, j = linear_sum_assignment(C)
        return float(np.sqrt((C[i, j] ** 2).mean()))

    print("\n===== weft sections of the two meshes, matched without fibril labels (rms, mm; mean over the crossings)")
    c12, c18 = setup(JUMP["12"][0]), setup(JUMP["18"][0])
    for step in steps:
        s12 = sections(c12[1], c12[2], state(states12, step))
        s18 = sections(c18[1], c18[2], state(states18, step))
        plain, mirrored, best = [], [], []
        for y in c12[1].yarns:
            if y.direction != "weft":
                continue
            for A, B in zip(s12[y.name], s18[y.name]):
                p, m = rms(A, B), rms(A, B * np.array([-1.0, 1.0]))
                plain.append(p)
                mirrored.append(m)
                best.append(min(p, m))
        print(f"  strain {0.025 * step:.3f}: labelled fibrils {np.sqrt(np.mean([((s12[k] - s18[k]) ** 2).sum(-1).mean() for k in s12 if k.startswith('weft')])):.4f}; "
              f"unlabelled {np.mean(plain):.4f}, mirrored {np.mean(mirrored):.4f}, best of the two per crossing {np.mean(best):.4f}")


if __name__ == "__main__":
    raise SystemExit(main())
